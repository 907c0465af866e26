"""Generated closed surfaces: geodesic spheres, capsules and the red blood cell.

Each generator returns ``(vertices (n, 3), triangles (m, 3))`` with outward
triangles; the shell bodies (parmps.solids.mass_spring.shell) and the walls and
fluid of any shape (parmps.geometry.walls) build on them.

Geodesic spheres: every face of a base polyhedron (icosahedron or octahedron) is
cut into frequency^2 triangles on a barycentric grid and the grid points are
projected on the sphere. Frequency 2^k is k levels of midpoint subdivision.
"""

import math

import numpy as np

from parmps.errors import CaseError

# Evans & Fung (1972), the resting human red blood cell: half-thickness
# z(r) = D sqrt(1 - 4 r^2/D^2) (c0 + c1 r^2/D^2 + c2 r^4/D^4), D = 7.82 um.
# (Written with (2r/D)^2 the same shape reads (D/4) sqrt(1 - (2r/D)^2)
# (0.2072 + 2.0026 (2r/D)^2 - 1.1228 (2r/D)^4).) It gives the measured
# thicknesses: 0.81 um at the centre, 2.57 um at the rim.
RBC_DIAMETER = 7.82e-6
RBC_COEFFICIENTS = (0.0518, 2.0026, -4.491)

# A generated shell larger than this is a unit mistake (spacing in mm for a body in
# m), not a body: a mass-spring body of a case has thousands of nodes, and this many
# triangles already take gigabytes to build.
MAX_TRIANGLES = 2_000_000


def _icosahedron():
    t = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
                         [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=float)
    faces = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                      [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                      [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                      [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    return vertices / np.linalg.norm(vertices, axis=1, keepdims=True), faces


def _octahedron():
    vertices = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0],
                         [0, 0, 1], [0, 0, -1]], dtype=float)
    faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4],
                      [1, 0, 5], [2, 1, 5], [3, 2, 5], [0, 3, 5]])
    return vertices, faces


def _face_grid(n):
    """One face cut n times: grid (i, j) with i + j <= n, and its n^2 triangles."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    local = np.full((n + 1, n + 1), -1)
    local[i, j] = np.arange(len(i))
    up = (i + j) <= n - 1
    down = (i + j) <= n - 2
    iu, ju, idn, jdn = i[up], j[up], i[down], j[down]
    # Both kinds run counter-clockwise in (i, j), as the face's corners a, b, c do.
    cells = np.concatenate([
        np.column_stack([local[iu, ju], local[iu + 1, ju], local[iu, ju + 1]]),
        np.column_stack([local[idn + 1, jdn], local[idn + 1, jdn + 1], local[idn, jdn + 1]])])
    return i, j, cells


def geodesic(base_vertices, base_faces, frequency):
    """Unit geodesic sphere: each base face cut ``frequency`` times along each edge.

    A grid point is an integer combination of the base vertices (weights summing
    to n); points on shared edges have the same weights from both faces, so they
    are merged exactly, without a tolerance.
    """
    n = int(frequency)
    if n < 1:
        raise ValueError(f"frequency must be >= 1, got {frequency}")
    i, j, cells = _face_grid(n)
    faces, points = len(base_faces), len(i)
    weights = np.zeros((faces, points, len(base_vertices)), dtype=np.int32)
    f = np.arange(faces)[:, None]
    weights[f, np.arange(points)[None, :], base_faces[:, 0:1]] = n - i - j
    weights[f, np.arange(points)[None, :], base_faces[:, 1:2]] = i
    weights[f, np.arange(points)[None, :], base_faces[:, 2:3]] = j
    unique, inverse = np.unique(weights.reshape(faces * points, -1), axis=0,
                                return_inverse=True)
    inverse = inverse.ravel()
    vertices = unique @ base_vertices / n
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    triangles = inverse[cells[None, :, :] + points * np.arange(faces)[:, None, None]]
    return vertices, triangles.reshape(-1, 3)


def _frequency(arc, edge_length, frequency, what, faces, extra=0):
    """The geodesic frequency: given, or the least whose base-edge arc / n <= edge_length;
    refused if ``faces`` n^2 + ``extra`` triangles would exceed MAX_TRIANGLES."""
    if frequency is not None:
        if int(frequency) < 1:
            raise CaseError(f"{what}: refinement must be >= 1, got {frequency}")
        n = int(frequency)
    elif edge_length is None or not edge_length > 0:
        raise CaseError(f"{what}: give a target edge length > 0 or a refinement")
    else:
        n = max(1, math.ceil(arc / edge_length * (1.0 - 1e-12)))
    if faces * n * n + extra > MAX_TRIANGLES:
        raise CaseError(f"{what}: refinement {n} makes {faces * n * n + extra:.3g} triangles "
                        f"(more than {MAX_TRIANGLES:.0e}); check the units of spacing")
    return n


def icosphere(radius, frequency=None, edge_length=None, center=(0.0, 0.0, 0.0)):
    """Sphere of ``radius`` from the icosahedron: 10 n^2 + 2 vertices, 20 n^2 triangles.

    ``frequency`` n, or the least n whose edges are about ``edge_length`` (the
    icosahedron's edge spans an arc of arccos(1/sqrt5) radians).
    """
    n = _frequency(radius * math.acos(1.0 / math.sqrt(5.0)), edge_length, frequency,
                   "sphere", 20)
    vertices, triangles = geodesic(*_icosahedron(), n)
    return radius * vertices + np.asarray(center, dtype=float), triangles


def _ring_order(vertices, ring):
    """The ring's vertices counter-clockwise seen from +z."""
    angle = np.arctan2(vertices[ring, 1], vertices[ring, 0])
    return ring[np.argsort(angle)]


def _bands(rings):
    """Outward triangles between consecutive rings (rows of ``rings``, each
    counter-clockwise seen from +z, bottom to top): two per quad."""
    lower, upper = rings[:-1], rings[1:]
    q = np.arange(rings.shape[1])
    r = np.roll(q, -1)
    return np.concatenate([np.stack([lower[:, q], lower[:, r], upper[:, r]], axis=-1),
                           np.stack([lower[:, q], upper[:, r], upper[:, q]], axis=-1)]
                          ).reshape(-1, 3)


def capsule(radius, length, edge_length=None, frequency=None, center=(0.0, 0.0, 0.0)):
    """Capsule along z: a cylinder of ``radius`` and ``length`` closed by hemispheres.

    The caps are halves of an octahedral geodesic sphere, whose equator is a ring
    of 4n vertices at z = 0 exactly; the cylinder is rings of those 4n azimuths,
    about ``edge_length`` apart. Total height: length + 2 radius.
    """
    if not radius > 0 or length < 0:
        raise CaseError(f"capsule: radius must be > 0 and length >= 0, got {radius}, {length}")
    n = _frequency(radius * math.pi / 2.0, edge_length, frequency, "capsule", 8,
                   extra=2 * (length / edge_length) * (2 * math.pi * radius / edge_length)
                   if edge_length else 0)
    unit, triangles = geodesic(*_octahedron(), n)
    vertices = radius * unit
    equator = _ring_order(vertices, np.flatnonzero(unit[:, 2] == 0.0))
    if length == 0.0:
        return vertices + np.asarray(center, dtype=float), triangles
    segments = max(1, round(length / (edge_length or 2.0 * math.pi * radius / len(equator))))
    top = unit[:, 2] >= 0.0
    vertices[:, 2] += np.where(top, 0.5, -0.5) * length
    # The equator belongs to the top cap; the bottom cap gets copies of it below,
    # and the cylinder's inner rings come after those.
    k = len(equator)
    heights = -0.5 * length + length * np.arange(segments) / segments
    rings_xy = np.tile(vertices[equator, :2], (segments, 1))
    new = np.column_stack([rings_xy, np.repeat(heights, k)])
    first = len(vertices)
    rings = np.concatenate([first + np.arange(segments * k).reshape(segments, k),
                            equator[None, :]])
    relabel = np.arange(len(vertices))
    relabel[equator] = rings[0]
    centroid_z = unit[triangles, 2].mean(axis=1)
    triangles = np.where((centroid_z < 0.0)[:, None], relabel[triangles], triangles)
    vertices = np.concatenate([vertices, new]) + np.asarray(center, dtype=float)
    return vertices, np.concatenate([triangles, _bands(rings)])


def rbc_half_thickness(r, diameter=RBC_DIAMETER, coefficients=RBC_COEFFICIENTS):
    """Evans & Fung's half-thickness z(r) of a red blood cell of ``diameter``; arrays."""
    s = (np.asarray(r, dtype=float) / diameter) ** 2
    c0, c1, c2 = coefficients
    return diameter * np.sqrt(np.clip(1.0 - 4.0 * s, 0.0, None)) * (c0 + c1 * s + c2 * s * s)


def red_blood_cell(diameter=RBC_DIAMETER, edge_length=None, frequency=None,
                   center=(0.0, 0.0, 0.0), coefficients=RBC_COEFFICIENTS, base="octahedron"):
    """The biconcave disc of Evans & Fung (1972), axis z, scaled to ``diameter``.

    An octahedral geodesic unit sphere mapped (x, y, z) -> (R x, R y, z g(x^2 + y^2))
    with R = D/2 and g = D (c0 + c1 rho^2/4 + c2 rho^4/16): since |z| = sqrt(1 - rho^2)
    on the sphere, every vertex lands on the profile. g > 0, so the map keeps the
    triangles' orientation; the rim is the sphere's exact equator ring. ``base =
    "icosahedron"`` maps an icosahedral sphere instead (10 n^2 + 2 vertices): no ring
    on the rim, but no grid lines along x and y either.
    """
    if not diameter > 0:
        raise CaseError(f"red_blood_cell: diameter must be > 0, got {diameter}")
    if base == "icosahedron":
        n = _frequency(diameter / 2.0 * math.acos(1.0 / math.sqrt(5.0)), edge_length,
                       frequency, "red_blood_cell", 20)
        unit, triangles = geodesic(*_icosahedron(), n)
    else:
        n = _frequency(math.pi * diameter / 4.0, edge_length, frequency, "red_blood_cell", 8)
        unit, triangles = geodesic(*_octahedron(), n)
    rho2 = unit[:, 0] ** 2 + unit[:, 1] ** 2
    c0, c1, c2 = coefficients
    g = diameter * (c0 + c1 * rho2 / 4.0 + c2 * rho2 ** 2 / 16.0)
    if np.any(g <= 0.0):
        raise CaseError(f"red_blood_cell: the coefficients {coefficients} give a profile "
                        f"that crosses the mid-plane")
    vertices = np.column_stack([0.5 * diameter * unit[:, 0], 0.5 * diameter * unit[:, 1],
                                g * unit[:, 2]])
    return vertices + np.asarray(center, dtype=float), triangles


