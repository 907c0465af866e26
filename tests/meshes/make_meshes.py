"""Writes the test meshes of this directory with meshio (not parmps's generators), so
that the walls and fluid from files are tested on files another tool wrote:

- box.stl: the box [0, 0.2] x [0, 0.1] x [0, 0.1] m, 12 outward triangles (ASCII);
- open_box.stl: the same box without its top, 10 triangles facing in (ASCII): an open
  surface, a tank whose water is on the side its triangles face;
- cylinder.stl: a cylinder of radius 0.05 m about the vertical line x = y = 0.1 m,
  z in [0.05, 0.15] m, a 128-sided prism with fans on its ends (ASCII);
- pipe.stl: a pipe of radius 8 mm about the x axis, x in [-8, 20] mm, a 128-sided prism with
  fans on its ends (binary): the periodic pipe of cases/hagen_poiseuille_3d.toml, whose
  period [0, 12] mm it overhangs by 8 mm at each end, so its caps lie outside the domain;
- vessel.stl: a closed upright cylinder of radius 0.1 m about x = y = 0.1 m, z in [0, 0.3] m,
  a 128-sided prism with fans on its ends (binary): the still tank of
  cases/hydrostatic_cylinder_3d.toml.

Run it from anywhere: python tests/meshes/make_meshes.py
"""

import os

import meshio
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def box(lower, upper):
    x = np.array([[lower[0], upper[0]][i & 1] for i in range(8)])
    y = np.array([[lower[1], upper[1]][(i >> 1) & 1] for i in range(8)])
    z = np.array([[lower[2], upper[2]][(i >> 2) & 1] for i in range(8)])
    # Faces as outward quads (counter-clockwise seen from outside), two triangles each.
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2),
             (1, 3, 7, 5)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return np.column_stack([x, y, z]), np.array(triangles)


def open_box(lower, upper):
    """:func:`box` without its top (+z) face, triangles 2 and 3, the others reversed to
    face in."""
    points, triangles = box(lower, upper)
    keep = [t for k, t in enumerate(triangles) if k not in (2, 3)]
    return points, np.array(keep)[:, ::-1]


def cylinder(center, radius, low, high, sides):
    angle = 2 * np.pi * np.arange(sides) / sides
    ring = np.column_stack([center[0] + radius * np.cos(angle),
                            center[1] + radius * np.sin(angle)])
    points = np.vstack([np.column_stack([ring, np.full(sides, low)]),
                        np.column_stack([ring, np.full(sides, high)]),
                        [[center[0], center[1], low], [center[0], center[1], high]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    bottom, top = 2 * sides, 2 * sides + 1
    triangles = np.vstack([np.column_stack([i, j, j + sides]),
                           np.column_stack([i, j + sides, i + sides]),
                           np.column_stack([np.full(sides, bottom), j, i]),
                           np.column_stack([np.full(sides, top), i + sides, j + sides])])
    return points, triangles


def along_x(points, triangles):
    """A mesh about the vertical turned to lie along x (z -> x, x -> y, y -> z): a rotation,
    so its triangles stay outward."""
    return points[:, [2, 0, 1]], triangles


def main():
    for name, (points, triangles) in {
            "box.stl": box((0.0, 0.0, 0.0), (0.2, 0.1, 0.1)),
            "open_box.stl": open_box((0.0, 0.0, 0.0), (0.2, 0.1, 0.1)),
            "cylinder.stl": cylinder((0.1, 0.1), 0.05, 0.05, 0.15, 128)}.items():
        meshio.write(os.path.join(HERE, name), meshio.Mesh(points, [("triangle", triangles)]),
                     binary=False)
    points, triangles = along_x(*cylinder((0.0, 0.0), 0.008, -0.008, 0.020, 128))
    meshio.write(os.path.join(HERE, "pipe.stl"), meshio.Mesh(points, [("triangle", triangles)]),
                 binary=True)
    points, triangles = cylinder((0.1, 0.1), 0.1, 0.0, 0.3, 128)
    meshio.write(os.path.join(HERE, "vessel.stl"), meshio.Mesh(points, [("triangle", triangles)]),
                 binary=True)


if __name__ == "__main__":
    main()
