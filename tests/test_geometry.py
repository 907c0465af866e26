"""Walls and fluid of any shape (issue 63): the surfaces' signed distances against analytic
answers, meshes refused when not closed or not oriented, a meshed box against a tank, a
meshed cylinder's wall layers, fills of meshes and shapes, bad input, and a 2D channel
with a circular cylinder on two ranks."""

import math
import shutil

import meshio
import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import ROOT, error_lines, run_parmps
from parmps import config, schema
from parmps.boundaries.walls import MovingWalls
from parmps.core.particles import DUMMY, FLUID, WALL
from parmps.errors import CaseError
from parmps.geometry import mesh, scene, shapes
from parmps.geometry.surfaces import Box, Cylinder, LatticeBlock, MeshSurface, Sphere

MESHES = ROOT / "tests" / "meshes"
L0 = 0.01


def build(text):
    case = schema.validate(config.load_text(text))
    return case, *scene.build(case)


# --------------------------------------------------------------------------
# Mesh queries against analytic answers


def test_a_meshed_sphere_gives_the_spheres_signed_distance_near_it():
    vertices, triangles = shapes.icosphere(1.0, frequency=16)
    lattice = LatticeBlock.covering(np.zeros(3), 0.05, [-1.3] * 3, [1.3] * 3)
    reach = 0.2
    meshed = MeshSurface(vertices, triangles).lattice_distance(lattice, reach)
    exact = Sphere([0.0, 0.0, 0.0], 1.0).lattice_distance(lattice)
    # The inscribed mesh lies within its sag of the sphere: R less its nearest face plane.
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    sag = 1.0 - np.min(np.abs(np.einsum("ij,ij->i", normal, a)) / np.linalg.norm(normal, axis=1))
    near = np.abs(exact) < reach - sag
    assert near.sum() > 1000
    assert np.abs(meshed[near] - exact[near]).max() <= sag + 1e-12
    # Beyond reach only the side is known; it is the sphere's away from the sag's shell.
    clear = np.abs(exact) > sag
    assert np.array_equal(np.sign(meshed[clear]), np.sign(exact[clear]))
    assert np.all(np.abs(meshed[~near & clear]) >= reach - sag)


def test_a_meshed_cylinder_gives_the_distance_to_its_axis():
    vertices, triangles = mesh.read_mesh(MESHES / "cylinder.stl")
    surface = MeshSurface(vertices, triangles)
    lattice = LatticeBlock.covering(np.zeros(3), L0, [0.0, 0.0, 0.07], [0.2, 0.2, 0.13])
    signed = surface.lattice_distance(lattice, 0.04)
    points = lattice.points()
    axial = np.hypot(points[:, 0] - 0.1, points[:, 1] - 0.1)
    values = lattice.values(signed, np.ones(lattice.shape, bool))
    # Away from the ends (z within 0.02 of the middle) the nearest point is on the side.
    side = (np.abs(points[:, 2] - 0.1) < 0.02) & (np.abs(axial - 0.05) < 0.03)
    sag = 0.05 * (1 - math.cos(math.pi / 128))
    assert np.abs(values[side] - (axial[side] - 0.05)).max() <= sag + 1e-12
    exact = Cylinder([0.1, 0.1, 0.1], 0.05, "z", 0.1).signed_distance(points)
    assert np.abs(values[side] - exact[side]).max() <= sag + 1e-12


def test_primitives_signed_distances():
    sphere = Sphere([0.0, 0.0], 1.0)
    assert sphere.signed_distance(np.array([[0.0, 0.0], [2.0, 0.0]])).tolist() == [-1.0, 1.0]
    cylinder = Cylinder([0.0, 0.0, 0.0], 1.0, "x", 2.0)
    np.testing.assert_allclose(cylinder.signed_distance(np.array(
        [[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [0.9, 0.0, 0.5]])),
        [-1.0, 2.0, 1.0, math.sqrt(2.0), -0.1])
    circle = Cylinder([0.0, 0.0], 0.5)
    assert circle.signed_distance(np.array([[1.0, 0.0]])).tolist() == [0.5]
    box = Box([0.0, 0.0, 0.0], [2.0, 1.0, 1.0])
    np.testing.assert_allclose(box.signed_distance(np.array(
        [[1.0, 0.5, 0.5], [3.0, 0.5, 0.5], [3.0, 2.0, 0.5], [0.1, 0.5, 0.5]])),
        [-0.5, 1.0, math.sqrt(2.0), -0.1])


def test_closed_meshes_enclose_their_volume():
    vertices, triangles = mesh.read_mesh(MESHES / "box.stl")
    assert mesh.check_closed_surface("box", vertices, triangles) == pytest.approx(0.002,
                                                                                   rel=1e-12)
    vertices, triangles = mesh.read_mesh(MESHES / "cylinder.stl")
    prism = 0.5 * 128 * 0.05 ** 2 * math.sin(2 * math.pi / 128) * 0.1
    assert mesh.check_closed_surface("cyl", vertices, triangles) == pytest.approx(prism,
                                                                                   rel=1e-9)


def test_open_and_flipped_meshes_are_refused():
    vertices, triangles = mesh.read_mesh(MESHES / "box.stl")
    with pytest.raises(CaseError, match="not closed: 3 open edges"):
        mesh.check_closed_surface("box", vertices, triangles[1:])
    flipped = triangles.copy()
    flipped[0] = flipped[0, ::-1]
    with pytest.raises(CaseError, match="inconsistent orientation"):
        mesh.check_closed_surface("box", vertices, flipped)
    with pytest.raises(CaseError, match="oriented inward"):
        mesh.check_closed_surface("box", vertices, triangles[:, ::-1])


def test_an_open_surface_is_signed_by_its_pseudo_normals_and_ends_at_its_rim():
    # open_box.stl: box.stl less its top, facing in. Inside is the side it faces (> 0),
    # behind a face, an edge or a corner < 0 (behind an edge or a corner as deep as from
    # the farthest of its faces' planes, a tank's layers), and a point nearest to the rim
    # has no side.
    vertices, triangles = mesh.read_mesh(MESHES / "open_box.stl")
    assert mesh.check_wall_surface("open box", vertices, triangles)
    surface = MeshSurface(vertices, triangles, open=True)
    points = np.array([[0.1, 0.05, 0.005], [0.1, 0.05, -0.005], [-0.003, 0.05, 0.05],
                       [-0.003, -0.004, 0.05], [-0.003, -0.004, -0.001], [0.1, 0.05, 0.12],
                       [-0.003, 0.05, 0.101], [0.1, 0.05, 0.099]])
    expected = [0.005, -0.005, -0.003, -0.004, -0.004, np.inf, np.inf, 0.05]
    assert surface.open_signed_distance(points) == pytest.approx(expected, rel=1e-12)
    lattice = LatticeBlock.covering([0.0, 0.0, 0.0], L0, [-0.05] * 3, [0.25, 0.15, 0.15])
    on_lattice = surface.lattice_distance(lattice, 0.03)
    band = np.isfinite(on_lattice)
    assert np.allclose(on_lattice.T[band.T],
                       surface.open_signed_distance(lattice.points(band)), atol=1e-15)
    assert mesh.check_wall_surface("box", *mesh.read_mesh(MESHES / "box.stl")) is False


def test_an_open_surfaces_mistakes_are_refused():
    vertices, triangles = mesh.read_mesh(MESHES / "open_box.stl")
    flipped = triangles.copy()
    flipped[0] = flipped[0, ::-1]
    with pytest.raises(CaseError, match="inconsistent orientation: 3 edges"):
        mesh.check_wall_surface("open box", vertices, flipped)
    with pytest.raises(CaseError, match=r"wall\[0\]\.fluid does not apply to an open surface"):
        build(DOMAIN_3D + f'[[wall]]\nmesh = "{MESHES / "open_box.stl"}"\nfluid = "inside"\n')
    with pytest.raises(CaseError, match=r"missing key 'wall\[0\]\.fluid': which side of the "
                                        r"closed surface"):
        build(DOMAIN_3D + f'[[wall]]\nmesh = "{MESHES / "box.stl"}"\n')
    # A fluid of a shape needs a closed one.
    with pytest.raises(CaseError, match="not closed: 4 open edges"):
        build(DOMAIN_3D.replace("upper = [0.2, 0.1, 0.05]\n", f'upper = [0.2, 0.1, 0.05]\n'
                                f'mesh = "{MESHES / "open_box.stl"}"\n'))


# --------------------------------------------------------------------------
# Walls from meshes and shapes

DOMAIN_3D = """
[domain]
lower = [-0.05, -0.05, -0.05]
upper = [0.25, 0.15, 0.15]
[particles]
spacing = 0.01
[time]
end = 0.01
[[fluid_block]]
lower = [0.0, 0.0, 0.0]
upper = [0.2, 0.1, 0.05]
"""
TANK = """
[[tank]]
lower = [0.0, 0.0, 0.0]
upper = [0.2, 0.1, 0.1]
open_top = false
"""


def _keys(position, spacing=L0):
    return {tuple(k) for k in np.round(position / spacing * 2).astype(np.int64)}


def _same_particles(one, other):
    """The same points, each of the same kind, in any order."""
    def ordered(particles):
        key = np.round(particles.position / L0 * 2).astype(np.int64)
        order = np.lexsort(key.T[::-1])
        return key[order], particles.kind[order]
    (key, kind), (other_key, other_kind) = ordered(one), ordered(other)
    return np.array_equal(key, other_key) and np.array_equal(kind, other_kind)


def test_a_meshed_box_lays_a_tanks_particles():
    # A mesh's layers go by distance, squared at its edges and corners (the farthest of
    # their faces' planes), so a box on the lattice's lines lays a tank's every particle.
    _, tank, _, _ = build(DOMAIN_3D + TANK)
    _, meshed, origin, sources = build(
        DOMAIN_3D + f'[[wall]]\nname = "box"\nmesh = "{MESHES / "box.stl"}"\nfluid = "inside"\n')
    assert sources == ["fluid_block[0]", "wall[0]"]
    assert _same_particles(meshed, tank)
    mine = (meshed.kind == WALL) | (meshed.kind == DUMMY)
    depth = Box([0.0, 0.0, 0.0], [0.2, 0.1, 0.1]).signed_distance(meshed.position[mine])
    assert depth.min() > 0 and depth.max() <= 4 * math.sqrt(3) * L0 * (1 + 1e-9)


def test_an_open_box_mesh_lays_an_open_tanks_particles():
    # The tank without a roof as an open surface: its walls stop where its faces do.
    _, tank, _, _ = build(DOMAIN_3D + TANK.replace("open_top = false\n", ""))
    _, meshed, _, _ = build(DOMAIN_3D + f'[[wall]]\nname = "tank"\n'
                                        f'mesh = "{MESHES / "open_box.stl"}"\n')
    assert _same_particles(meshed, tank)


@pytest.mark.parametrize("given", ["mesh", "shape"])
def test_a_cylinders_wall_layers_lie_at_their_distance_from_its_axis(given):
    surface = (f'mesh = "{MESHES / "cylinder.stl"}"' if given == "mesh" else
               'shape = "cylinder"\ncenter = [0.1, 0.1, 0.1]\nradius = 0.05\nlength = 0.1')
    text = DOMAIN_3D.replace("upper = [0.25, 0.15, 0.15]", "upper = [0.25, 0.25, 0.2]") \
        + f'[[wall]]\nname = "post"\n{surface}\nfluid = "outside"\n'
    text = text.replace("upper = [0.2, 0.1, 0.05]", "upper = [0.2, 0.2, 0.2]")
    _, particles, origin, _ = build(text)
    post = origin == 1
    position, kind = particles.position[post], particles.kind[post]
    radial = np.hypot(position[:, 0] - 0.1, position[:, 1] - 0.1)
    middle = np.abs(position[:, 2] - 0.1) < 0.05 - 4 * L0
    sag = 0.05 * (1 - math.cos(math.pi / 128)) if given == "mesh" else 0.0
    walls, dummies = middle & (kind == WALL), middle & (kind == DUMMY)
    assert walls.sum() > 0 and dummies.sum() > 0
    assert radial[walls].max() <= 0.05 + 1e-12 and radial[walls].min() >= 0.03 - sag - 1e-12
    assert radial[dummies].max() < 0.03 and radial[dummies].min() >= 0.01 - sag - 1e-12
    # The water keeps a spacing from the wall's particles and stays out of the post.
    fluid = particles.position[particles.kind == FLUID]
    assert cKDTree(position).query(fluid)[0].min() >= L0 * (1 - 1e-6)
    inside = (np.hypot(fluid[:, 0] - 0.1, fluid[:, 1] - 0.1) < 0.05) & \
        (np.abs(fluid[:, 2] - 0.1) < 0.05)
    assert not inside.any()


def test_the_mesh_and_the_shape_of_a_cylinder_lay_nearly_the_same_points():
    base = DOMAIN_3D.replace("upper = [0.25, 0.15, 0.15]", "upper = [0.25, 0.25, 0.2]")
    meshed = build(base + f'[[wall]]\nmesh = "{MESHES / "cylinder.stl"}"\nfluid = "outside"\n')
    shaped = build(base + '[[wall]]\nshape = "cylinder"\ncenter = [0.1, 0.1, 0.1]\n'
                   'radius = 0.05\nlength = 0.1\nfluid = "outside"\n')
    a, b = (_keys(p.position[o == 1]) for _, p, o, _ in (meshed, shaped))
    assert len(a ^ b) <= 0.02 * len(b)


def test_a_wall_keeps_clear_of_an_earlier_wall_and_a_moving_wall_moves():
    # A sphere resting in the tank's floor: its points on the floor's are the floor's.
    text = DOMAIN_3D + TANK + ('[[wall]]\nname = "ball"\nshape = "sphere"\n'
                               'center = [0.1, 0.05, 0.02]\nradius = 0.03\nfluid = "outside"\n')
    case, particles, origin, sources = build(text)
    assert sources == ["fluid_block[0]", "tank[0]", "wall[0]"]
    pairs = cKDTree(particles.position).query_pairs(0.5 * L0)
    assert not pairs
    fluid = particles.position[particles.kind == FLUID]
    assert np.linalg.norm(fluid - [0.1, 0.05, 0.02], axis=1).min() > 0.03
    moving = build(text + "velocity = [0.1, 0.0, 0.0]\nmove_end = 0.05\n")
    walls = MovingWalls.from_scene(moving[0], moving[1], moving[2], moving[3])
    assert [name for name, *_ in walls.walls] == ["wall[0]"]
    before = moving[1].position.copy()
    walls.advance(moving[1], 0.0, 0.01)
    shifted = np.flatnonzero(np.any(moving[1].position != before, axis=1))
    assert np.array_equal(np.unique(moving[2][shifted]), [sources.index("wall[0]")])


# --------------------------------------------------------------------------
# Fluid of any shape


def test_fluid_fills_a_mesh_and_a_shape_on_the_lattice():
    no_block = DOMAIN_3D.split("[[fluid_block]]")[0]
    _, boxed, _, _ = build(DOMAIN_3D.replace("upper = [0.2, 0.1, 0.05]", "upper = [0.2, 0.1, 0.1]"))
    _, meshed, _, _ = build(no_block + f'[[fluid_block]]\nmesh = "{MESHES / "box.stl"}"\n')
    np.testing.assert_allclose(meshed.position, boxed.position, rtol=0, atol=1e-12)
    _, clipped, _, _ = build(no_block + f'[[fluid_block]]\nmesh = "{MESHES / "box.stl"}"\n'
                             'lower = [0.0, 0.0, 0.0]\nupper = [0.2, 0.1, 0.05]\n')
    assert len(clipped.position) == 1000 and clipped.position[:, 2].max() < 0.05
    _, ball, _, _ = build(no_block + '[[fluid_block]]\nshape = "sphere"\n'
                          'center = [0.1, 0.05, 0.05]\nradius = 0.05\n')
    # The lattice points (i + 1/2) l0 within 5 l0 of the centre, counted directly.
    i = np.arange(-6, 6) + 0.5
    assert len(ball.position) == np.count_nonzero(
        np.add.outer(np.add.outer(i ** 2, i ** 2), i ** 2) < 25)
    assert np.linalg.norm(ball.position - [0.1, 0.05, 0.05], axis=1).max() < 0.05
    # In a tank of a mesh the water keeps a spacing from the walls.
    _, tank, _, _ = build(no_block + f'[[fluid_block]]\nshape = "sphere"\ncenter = [0.1, 0.05, '
                          f'0.05]\nradius = 0.08\n' + TANK)
    fluid, walls = tank.position[tank.kind == FLUID], tank.position[tank.kind != FLUID]
    assert cKDTree(walls).query(fluid)[0].min() >= L0 * (1 - 1e-6)


def test_a_2d_circle_of_fluid():
    text = ("[domain]\nlower = [0.0, 0.0]\nupper = [0.2, 0.2]\n[particles]\nspacing = 0.01\n"
            "[time]\nend = 0.01\n[[fluid_block]]\nshape = \"cylinder\"\n"
            "center = [0.1, 0.1]\nradius = 0.05\n")
    _, particles, _, _ = build(text)
    assert len(particles.position) == pytest.approx(math.pi * 25, rel=0.05)


# --------------------------------------------------------------------------
# Bad input: one line, exit status 2


def _broken_meshes(tmp_path):
    vertices, triangles = mesh.read_mesh(MESHES / "box.stl")
    open_box = tmp_path / "open.stl"
    meshio.write(open_box, meshio.Mesh(vertices, [("triangle", triangles[2:])]), binary=False)
    flipped = triangles.copy()
    flipped[0] = flipped[0, ::-1]
    flip = tmp_path / "flipped.stl"
    meshio.write(flip, meshio.Mesh(vertices, [("triangle", flipped)]), binary=False)
    millimetres = tmp_path / "mm.stl"
    meshio.write(millimetres, meshio.Mesh(vertices * 1000, [("triangle", triangles)]),
                 binary=False)
    (tmp_path / "garbage.stl").write_text("solid nothing\n this is not an STL\n")
    return {"open": open_box, "flipped": flip, "mm": millimetres,
            "garbage": tmp_path / "garbage.stl"}


BAD_GEOMETRY = {
    "open fluid mesh": ('[[fluid_block]]\nmesh = "open.stl"\n',
                        "open.stl': the surface is not closed: 4 open edges"),
    "flipped triangle": ('[[wall]]\nmesh = "flipped.stl"\nfluid = "inside"\n',
                         "inconsistent orientation"),
    "millimetres": ('[[wall]]\nmesh = "mm.stl"\nfluid = "inside"\n',
                    "the mesh lies outside the domain: its bounding box [0, 0, 0]-[200, 100, "
                    "100] against the domain's [-0.05, -0.05, -0.05]-[0.25, 0.15, 0.15]; it is "
                    "667 times the domain's size: a file in millimetres"),
    "unreadable": ('[[wall]]\nmesh = "garbage.stl"\nfluid = "inside"\n', "cannot be read"),
    "missing file": ('[[wall]]\nmesh = "nowhere.stl"\nfluid = "inside"\n', "no such file"),
    "no room for the dummies": ('[[wall]]\nshape = "sphere"\ncenter = [0.1, 0.05, 0.05]\n'
                                'radius = 0.08\nfluid = "inside"\n',
                                "wall[0]: no room for its 2 wall and 2 dummy layers"),
    "missing radius": ('[[wall]]\nname = "post"\nshape = "cylinder"\ncenter = [0.1, 0.05, '
                       '0.05]\nlength = 0.1\nfluid = "outside"\n',
                       "missing key 'wall[0].radius': shape = \"cylinder\" needs radius > 0"),
    "missing side": ('[[wall]]\nshape = "sphere"\ncenter = [0.1, 0.05, 0.05]\n'
                     'radius = 0.02\n', "missing key 'wall[0].fluid'"),
    "a key the shape does not read": ('[[wall]]\nshape = "sphere"\ncenter = [0.1, 0.05, 0.05]\n'
                                      'radius = 0.02\nlength = 0.1\nfluid = "outside"\n',
                                      "wall[0].length does not apply to shape = \"sphere\""),
}


@pytest.mark.parametrize("name", BAD_GEOMETRY)
def test_bad_geometry_is_one_line_and_exit_2(tmp_path, name):
    _broken_meshes(tmp_path)
    extra, expected = BAD_GEOMETRY[name]
    case = tmp_path / "case.toml"
    case.write_text(DOMAIN_3D + extra)
    # Relative mesh paths are from the case file's directory, not the working directory.
    result = run_parmps([case, "--check"], cwd=ROOT)
    lines = error_lines(result.stderr)
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and expected in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_a_relative_mesh_path_is_from_the_case_file(tmp_path):
    shutil.copy(MESHES / "box.stl", tmp_path / "box.stl")
    case = tmp_path / "case.toml"
    case.write_text(DOMAIN_3D + '[[wall]]\nname = "box"\nmesh = "box.stl"\nfluid = "inside"\n')
    result = run_parmps([case, "--check"], cwd=ROOT)
    assert result.returncode == 0, result.stderr


# --------------------------------------------------------------------------
# A run


CHANNEL = """
title = "a channel with a circular cylinder"
[domain]
lower = [0.0, -0.04]
upper = [0.4, 0.24]
[particles]
spacing = 0.01
[physics]
gravity = [0.0, 0.0]
[fluid]
viscosity = 1.0e-2
[time]
end = 0.01
dt_max = 2.0e-3
output_interval = 0.01
[[fluid_block]]
lower = [0.0, 0.0]
upper = [0.36, 0.2]
velocity = [-0.1, 0.0]
[[wall_box]]
lower = [0.0, -0.04]
upper = [0.4, 0.0]
[[wall_box]]
lower = [0.0, 0.2]
upper = [0.4, 0.24]
[[wall]]
name = "cylinder"
shape = "cylinder"
center = [0.15, 0.1]
radius = 0.04
fluid = "outside"
[[inlet]]
lower = [0.36, 0.0]
upper = [0.4, 0.2]
velocity = [-0.1, 0.0]
[[outlet]]
side = "left"
velocity = [-0.1, 0.0]
[[check]]
kind = "wall_crossing"
wall = "cylinder"
"""


@pytest.mark.mpi
def test_a_channel_with_a_circular_cylinder_runs_on_two_ranks(tmp_path):
    from parmps import open_result

    case = tmp_path / "channel.toml"
    case.write_text(CHANNEL)
    result = run_parmps([case, "-o", tmp_path / "out"], ranks=2, timeout=240)
    assert result.returncode == 0, result.stderr
    assert "done: 5 steps" in result.stderr
    with open_result(tmp_path / "out") as run:
        check = run.checks["wall_crossing_cylinder"]
        assert len(check.time) == len(run.diagnostics.time) == 5
        assert check.total[-1] == 0


@pytest.mark.parametrize("extra, message", [
    ('kind = "wall_crossing"\nwall = "pillar"', "check[0].wall 'pillar' is not the name of a "
                                                "[[wall]] of the case (cylinder)"),
    ('kind = "wall_crossing"', "missing key 'check[0].wall'"),
    ('kind = "wall_crossing"\nwall = "cylinder"\nbody = "gate"', "check[0].body is not a key"),
])
def test_a_bad_wall_crossing_check_is_one_line(extra, message):
    text = CHANNEL.split("[[check]]")[0] + "[[check]]\n" + extra + "\n"
    with pytest.raises(CaseError) as caught:
        schema.validate(config.load_text(text))
    assert message in str(caught.value) and "\n" not in str(caught.value)


# --------------------------------------------------------------------------
# A force probe on a wall of any shape

STILL_2D = """
[domain]
lower = [-0.05, -0.05]
upper = [0.45, 0.35]
[particles]
spacing = 0.01
[time]
end = 0.01
output_interval = 0.01
[[fluid_block]]
lower = [0.0, 0.0]
upper = [0.4, 0.2]
[[tank]]
lower = [0.0, 0.0]
upper = [0.4, 0.3]
"""


def _force(tmp_path, text, name):
    case = tmp_path / f"{name}.toml"
    case.write_text(text)
    result = run_parmps([case, "-o", tmp_path / name], timeout=240)
    assert result.returncode == 0, result.stderr
    rows = (tmp_path / name / "probes" / "force.csv").read_text().splitlines()[2:]
    return np.array([[float(v) for v in row.split(",")] for row in rows])


def test_a_force_probe_on_a_box_wall_reads_as_on_a_wall_box(tmp_path):
    box = "lower = [0.16, 0.06]\nupper = [0.24, 0.14]\n"
    # The water round the box in four blocks (a wall box refuses water on it).
    water = STILL_2D.replace("upper = [0.4, 0.2]\n", "upper = [0.16, 0.2]\n").replace(
        "[[tank]]", "".join(f"[[fluid_block]]\nlower = {lower}\nupper = {upper}\n" for lower, upper
                            in (([0.24, 0.0], [0.4, 0.2]), ([0.16, 0.0], [0.24, 0.06]),
                                ([0.16, 0.14], [0.24, 0.2]))) + "[[tank]]")
    probe = '[[probe]]\nname = "force"\nkind = "force"\n'
    as_box = _force(tmp_path, water + f"[[wall_box]]\n{box}" + probe + "wall_box = 0\n",
                    "wall_box")
    as_wall = _force(tmp_path, water + f'[[wall]]\nname = "block"\nshape = "box"\n{box}'
                     'fluid = "outside"\n' + probe + 'wall = "block"\n', "wall")
    # The same particles and samples, summed in another order: round-off apart.
    np.testing.assert_allclose(as_wall, as_box, rtol=1e-9, atol=1e-6)


def test_a_force_probe_on_a_submerged_circle_reads_its_buoyancy(tmp_path):
    force = _force(tmp_path, STILL_2D + '[[wall]]\nname = "post"\nshape = "cylinder"\n'
                   'center = [0.2, 0.1]\nradius = 0.04\nfluid = "outside"\n'
                   '[[probe]]\nname = "force"\nkind = "force"\nwall = "post"\n', "circle")
    # The probe reads the pressure half a spacing into the water, as on a wall box: on a
    # circle of radius r it integrates rho g (r + l0/2) over the surface, pi r (r + l0/2).
    r = 0.04
    expected = 1000.0 * 9.81 * math.pi * r * (r + 0.5 * L0)
    assert abs(force[-1, 2] / expected - 1) < 0.08, (force[-1], expected)
    assert abs(force[-1, 1]) < 1e-3 * expected


# --------------------------------------------------------------------------
# The run-time guard on a wall of any shape


@pytest.mark.parametrize("given", ["mesh", "shape"])
def test_the_guard_stops_fluid_deep_in_a_walls_material(given):
    from mpi4py import MPI

    from parmps.core.particles import Particles
    from parmps.errors import RunFailure
    from parmps.geometry.walls import MaterialDepth
    from parmps.run import guards

    surface = (f'mesh = "{MESHES / "cylinder.stl"}"' if given == "mesh" else
               'shape = "cylinder"\ncenter = [0.1, 0.1, 0.1]\nradius = 0.05\nlength = 0.1')
    text = DOMAIN_3D.replace("upper = [0.25, 0.15, 0.15]", "upper = [0.25, 0.25, 0.2]") \
        + f'[[wall]]\nname = "post"\n{surface}\nfluid = "outside"\n'
    case = schema.validate(config.load_text(text))
    walls = MaterialDepth(case)
    # On the axis's level, at 0.2 l0 and 0.8 l0 inside the side, and outside it.
    radius = np.array([0.05 - 0.002, 0.05 - 0.008, 0.06])
    position = np.column_stack([0.1 + radius, np.full(3, 0.1), np.full(3, 0.1)])
    depth, which = walls.depth(position, [np.zeros(3)])
    # A mesh's depth is interpolated between lattice points: within 0.05 l0 of the
    # cylinder's on a radius of 5 l0 (a shape's is exact).
    np.testing.assert_allclose(depth, [0.002, 0.008, -0.01],
                               atol=0.05 * L0 if given == "mesh" else 1e-12)
    particles = Particles({"id": np.arange(3), "kind": np.full(3, FLUID),
                           "position": position})
    with pytest.raises(RunFailure, match="fluid particle 1 went through a wall: it is inside "
                                         "wall\\[0\\] 'post'"):
        guards.check_shaped_walls(particles, walls, case, 0.0, L0, MPI.COMM_SELF, 7)
    particles.position[1] = particles.position[2]
    guards.check_shaped_walls(particles, walls, case, 0.0, L0, MPI.COMM_SELF, 7)


def test_the_wall_crossing_check_counts_particles_going_into_the_material(tmp_path):
    import types

    import h5py
    from mpi4py import MPI

    from parmps.checks.walls import WallCrossing
    from parmps.core.particles import Particles

    case = schema.validate(config.load_text(CHANNEL))
    position = np.array([[0.2, 0.1], [0.15, 0.145], [0.3, 0.1]])
    particles = Particles({"id": np.array([5, 6, 7]), "kind": np.full(3, FLUID),
                           "position": position})
    with h5py.File(tmp_path / "r.h5", "w") as file:
        result = types.SimpleNamespace(file=file, comm=MPI.COMM_SELF)
        check = WallCrossing(case["check"][0], case, result, None, 0.01, 1.0)
        state = types.SimpleNamespace(particles=particles, time=0.0, step=0)
        check.start(state)
        # Particle 6 goes 0.7 l0 into the cylinder (radius 0.04 about (0.15, 0.1)): through
        # its surface; 5 goes 0.2 l0 in, level with the first layer of its particles where it
        # lies deepest: contact, recorded as the deepest, not counted; 7 stays.
        particles.position[1] = [0.15, 0.133]
        particles.position[0] = [0.15 + 0.038, 0.1]
        for step in (1, 2):  # in the material for two steps: counted once
            state.step, state.time = step, 0.002 * step
            check.observe(state)
        check.finish(state)
        assert file["checks/wall_crossing_cylinder/crossings"][:].tolist() == [1, 0]
        assert file["checks/wall_crossing_cylinder/deepest"][:] == pytest.approx([0.007] * 2)
        assert check.total == 1


def test_a_clipped_fill_may_come_from_a_surface_larger_than_the_domain(tmp_path):
    vertices, triangles = mesh.read_mesh(MESHES / "box.stl")
    large = tmp_path / "large.stl"
    meshio.write(large, meshio.Mesh(2 * vertices, [("triangle", triangles)]), binary=False)
    no_block = DOMAIN_3D.split("[[fluid_block]]")[0]
    _, clipped, _, _ = build(no_block + f'[[fluid_block]]\nmesh = "{large}"\n'
                             'lower = [0.0, 0.0, 0.0]\nupper = [0.2, 0.1, 0.05]\n')
    assert len(clipped.position) == 1000
    with pytest.raises(CaseError, match="the mesh lies outside the domain"):
        build(no_block + f'[[fluid_block]]\nmesh = "{large}"\n')


# --------------------------------------------------------------------------
# 2D walls from curves (line cells)

def _write_curve(path, points, closed):
    segments = [(k, k + 1) for k in range(len(points) - 1)]
    if closed:
        segments.append((len(points) - 1, 0))
    meshio.write(path, meshio.Mesh(np.column_stack([points, np.zeros(len(points))]),
                                   [("line", np.array(segments))]))
    return path


def test_an_open_curve_lays_a_2d_tanks_particles(tmp_path):
    # The 2D tank of STILL_2D as a curve down its right wall, along the floor, up its left
    # one (each segment facing the water on its right-hand side), no lid: a tank's every
    # particle, each of the same kind.
    curve = _write_curve(tmp_path / "tank.vtk", [[0.4, 0.3], [0.4, 0.0], [0.0, 0.0],
                                                 [0.0, 0.3]], closed=False)
    case, tank, _, _ = build(STILL_2D)
    case, meshed, _, _ = build(STILL_2D.replace("[[tank]]\nlower = [0.0, 0.0]\n"
                                                "upper = [0.4, 0.3]\n",
                                                f'[[wall]]\nmesh = "{curve}"\n'))
    assert _same_particles(meshed, tank)


def test_a_closed_curve_lays_a_circles_wall_as_its_shape_does(tmp_path):
    # A 512-gon of the circle r = 0.05 about (0.2, 0.12), counter-clockwise: the wall of the
    # same circle given as a shape, but for points within a hair of a layer's edge.
    angle = 2.0 * math.pi * np.arange(512) / 512
    ring = np.column_stack([0.2 + 0.05 * np.cos(angle), 0.12 + 0.05 * np.sin(angle)])
    curve = _write_curve(tmp_path / "post.vtk", ring, closed=True)
    water = STILL_2D.replace("upper = [0.4, 0.2]\n", "upper = [0.4, 0.25]\n")
    _, meshed, _, _ = build(water + f'[[wall]]\nmesh = "{curve}"\nfluid = "outside"\n')
    _, shaped, _, _ = build(water + '[[wall]]\nshape = "cylinder"\ncenter = [0.2, 0.12]\n'
                                    'radius = 0.05\nfluid = "outside"\n')
    for kind in (FLUID, WALL, DUMMY):
        assert abs((meshed.kind == kind).sum() - (shaped.kind == kind).sum()) <= 4, kind
    # The post's particles (the tank's lie farther off) within its layers' depth inside it.
    radius = np.linalg.norm(meshed.position - [0.2, 0.12], axis=1)
    mine = ((meshed.kind == WALL) | (meshed.kind == DUMMY)) & (radius < 0.1)
    depth = 0.05 - radius[mine]
    assert depth.min() >= -1e-4 and depth.max() <= 4 * L0 + 1e-4


@pytest.mark.parametrize("points, closed, phrase", [
    ([[0.1, 0.1], [0.3, 0.1], [0.3, 0.2], [0.1, 0.2]][::-1], True, "runs clockwise"),
    ([[0.1, 0.1], [0.3, 0.1], [0.3, 0.2]], False, None),
])
def test_a_2d_curves_mistakes_are_refused(tmp_path, points, closed, phrase):
    curve = _write_curve(tmp_path / "c.vtk", np.array(points), closed)
    text = STILL_2D + f'[[wall]]\nmesh = "{curve}"\n' + ('fluid = "outside"\n' if closed else '')
    if phrase is None:  # an open curve given a side
        phrase = "fluid does not apply to an open surface"
        text += 'fluid = "outside"\n'
    with pytest.raises(CaseError, match=phrase):
        build(text)
    flipped = np.array(points)
    segments = np.array([(0, 1), (2, 1)])
    with pytest.raises(CaseError, match="inconsistent orientation or a branch"):
        mesh.check_polyline("c", flipped[:3], segments)
