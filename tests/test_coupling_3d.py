"""The fluid-solid coupling in 3D (issue 24, item 4): the inside test against a cube and a
sphere by hand, the fluid counted inside a body through its model's boundary, the 3D
crossing check (a particle pushed through a plate counts, one going round its edge does
not), both coupling schemes running a few steps in 3D, the same answer by id on 1, 2 and 3
ranks, and the refusals that remain. The 3D box in a duct to its end:
validation/box_in_flow_3d (README: the commands and figures).
"""

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CASES, error_lines, run_parmps
from parmps import open_result, schema
from parmps.checks.crossing import (count_crossings, lattice_mid_line, lattice_mid_surface,
                                    mid_line_sides, mid_surface_sides)
from parmps.core.geometry import (closed_surface_sides, inside_boundary, point_in_polygon,
                                  surface_distance)
from parmps.core.particles import FLUID, SOLID, WALL, Particles
from parmps.coupling.weak import fluid_inside
from parmps.errors import CaseError
from parmps.geometry.mesh import enclosed_volume
from parmps.geometry.shapes import icosphere
from parmps.io.frames import read_frame
from parmps.solids.mass_spring.lattice import lattice_geometry
from parmps.solids.mass_spring.model import MassSpringModel
import tomllib

# -- the inside test ------------------------------------------------------------------------


def test_inside_a_cube_by_hand():
    """The unit cube's outward lattice surface (3 x 3 x 3 nodes): inside exactly where
    every coordinate is in (0, 1), for points kept 1e-3 off its faces, and points just
    either side of a face centre and of an edge."""
    cube = lattice_geometry((3, 3, 3), 0.5, (0.0, 0.0, 0.0))
    rng = np.random.default_rng(24)
    points = rng.uniform(-0.5, 1.5, size=(4000, 3))
    gap = np.minimum(np.abs(points), np.abs(points - 1.0)).min(axis=1)
    points = points[gap > 1e-3]
    expected = np.all((points > 0.0) & (points < 1.0), axis=1)
    assert 0 < expected.sum() < len(points)
    np.testing.assert_array_equal(inside_boundary(points, cube.position, cube.boundary),
                                  expected)
    near = np.array([[0.5, 0.5, 1e-6], [0.5, 0.5, -1e-6], [1e-6, 0.5, 1e-6],
                     [-1e-6, 0.5, 1e-6], [0.5, 1.0 - 1e-6, 0.25]])
    assert list(inside_boundary(near, cube.position, cube.boundary)) == [True, False, True,
                                                                         False, True]


def test_inside_a_sphere_by_hand():
    """An icosphere of radius 0.1 about (1, 2, 3): its vertices lie on the sphere and its
    flat faces inside it, so points beyond r = 0.1 are outside and points within the
    faces' least distance from the centre are inside."""
    centre = np.array([1.0, 2.0, 3.0])
    vertices, triangles = icosphere(0.1, frequency=6, center=centre)
    corners = vertices[triangles] - centre
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inner = np.min(np.abs(np.einsum("ij,ij->i", corners[:, 0], normal))
                   / np.linalg.norm(normal, axis=1))
    assert 0.098 < inner < 0.1
    rng = np.random.default_rng(7)
    direction = rng.normal(size=(3000, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    radius = rng.uniform(0.0, 0.2, size=3000)
    points = centre + direction * radius[:, None]
    inside = inside_boundary(points, vertices, triangles)
    assert inside[radius < 0.999 * inner].all()
    assert not inside[radius > 0.1].any()
    assert inside.sum() > 0.1 * len(points)


def test_the_2d_edges_give_the_polygons_answer_bit_for_bit():
    """A non-convex loop (an L): the edge form the coupling now uses and point_in_polygon
    agree on every point, grid points on its edges and vertices included."""
    polygon = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.1], [0.1, 0.1], [0.1, 0.3],
                        [0.0, 0.3]])
    loop = np.arange(len(polygon))
    facets = np.column_stack([loop, np.roll(loop, -1)])
    grid = np.stack(np.meshgrid(np.linspace(-0.05, 0.35, 41),
                                np.linspace(-0.05, 0.35, 41)), axis=-1).reshape(-1, 2)
    points = np.concatenate([grid, np.random.default_rng(3).uniform(-0.1, 0.4, (500, 2))])
    np.testing.assert_array_equal(inside_boundary(points, polygon, facets),
                                  point_in_polygon(points, polygon))


def _box_model(shape=(3, 4, 5), spacing=0.01, lower=(0.1, 0.2, 0.3)):
    """A solid-only 3D case of one lattice body, as the run builds its model."""
    case = schema.validate(tomllib.loads(
        "[domain]\nlower = [0.0, 0.0, 0.0]\nupper = [1.0, 1.0, 1.0]\n[time]\nend = 0.1\n"
        f"[[body]]\nname = \"b\"\nnx = {shape[0]}\nny = {shape[1]}\nnz = {shape[2]}\n"
        f"spacing = {spacing}\nlower = {list(lower)}\nnode_mass = 0.001\nstiffness = 1.0\n"))
    return MassSpringModel.from_case(case)


def test_the_model_gives_a_3d_bodys_closed_boundary_and_the_fluid_inside_is_counted():
    """A 3 x 4 x 5 lattice body: its boundary encloses its volume, and fluid_inside counts
    the fluid particles inside it (not its nodes, not a wall particle inside, not fluid
    outside)."""
    model = _box_model()
    vertices, facets = model.boundary(0)
    assert facets.shape[1] == 3
    assert enclosed_volume(vertices, facets) == pytest.approx(0.02 * 0.03 * 0.04, rel=1e-12)
    inside = np.array([[0.105, 0.215, 0.335], [0.115, 0.225, 0.305]])
    outside = np.array([[0.095, 0.215, 0.335], [0.105, 0.235, 0.345], [0.105, 0.215, 0.341]])
    position = np.concatenate([inside, outside, inside[:1], vertices])
    kind = np.concatenate([np.full(5, FLUID), [WALL], np.full(len(vertices), SOLID)])
    particles = Particles({"id": np.arange(len(position)), "position": position,
                           "kind": kind.astype(np.int8)})
    assert fluid_inside(particles, vertices, facets, MPI.COMM_SELF) == 2


# -- the crossing check in 3D -----------------------------------------------------------------

# A horizontal plate of 9 x 5 x 2 nodes, x in [0, 0.08], y in [0, 0.04], z in [0, 0.01]: its
# mid-surface is z = 0.005; the band reaches 2 l0 beyond the half-thickness.
PLATE = lattice_geometry((9, 5, 2), 0.01, (0.0, 0.0, 0.0)).position
PLATE_BAND = 0.005 + 0.02


def test_the_mid_surface_is_the_mean_through_the_thinnest_direction():
    vertices, facets = lattice_mid_surface(PLATE, (9, 5, 2))
    assert vertices.shape == (45, 3) and facets.shape == (2 * 8 * 4, 3)
    np.testing.assert_allclose(vertices[:, 2], 0.005)
    # Every triangle faces the same way (+z here) and they tile the plate.
    a, b, c = (vertices[facets[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    assert (normal[:, 2] > 0).all()
    assert 0.5 * normal[:, 2].sum() == pytest.approx(0.08 * 0.04)
    # Stood up (thin along y), the same construction.
    upright = lattice_geometry((9, 2, 5), 0.01, (0.0, 0.0, 0.0)).position
    vertices, _ = lattice_mid_surface(upright, (9, 2, 5))
    np.testing.assert_allclose(vertices[:, 1], 0.005)
    # In 2D the mid-line of the existing check, bit for bit.
    gate = lattice_geometry((4, 11), 0.01, (0.0, 0.0)).position
    line, segments = lattice_mid_surface(gate, (4, 11))
    np.testing.assert_array_equal(line, lattice_mid_line(gate, 4, 11))
    assert len(segments) == 10


def test_sides_of_the_plate_beside_beyond_its_edges_and_outside_the_band():
    vertices, facets = lattice_mid_surface(PLATE, (9, 5, 2))
    points = [[0.04, 0.02, -0.01], [0.04, 0.02, 0.02],    # below and above
              [0.085, 0.02, 0.005], [0.04, -0.003, 0.0],  # beyond an edge (x, then y)
              [0.04, 0.02, 0.04]]                         # above the band
    sides = mid_surface_sides(points, vertices, facets, PLATE_BAND)
    assert sides[0] == -1 and sides[1] == 1
    assert list(sides[2:]) == [0, 0, 0]
    # In 2D the function is the mid-line's.
    gate = lattice_geometry((4, 11), 0.01, (0.0, 0.0)).position
    line, segments = lattice_mid_surface(gate, (4, 11))
    two = [[-0.005, 0.05], [0.035, 0.05], [-0.005, -0.001]]
    np.testing.assert_array_equal(mid_surface_sides(two, line, segments, 0.035),
                                  mid_line_sides(two, line, 0.035))


# The check's answer by brute force, every point against every triangle, in numpy: the
# reference the check's kernel and its grouping of the points are held to.
def _segment_distance2(points, start, end):
    """Squared distance of every point (n, 3) to every segment (k) start -> end: (n, k)."""
    direction = end - start
    length2 = np.einsum("ij,ij->i", direction, direction)
    offset = points[:, None, :] - start[None, :, :]
    along = np.clip(np.einsum("nkj,kj->nk", offset, direction) / length2, 0.0, 1.0)
    gap = offset - along[..., None] * direction[None, :, :]
    return np.einsum("nkj,nkj->nk", gap, gap)


def _triangle_distance2(points, a, b, c):
    """Squared distance of every point (n, 3) to every triangle (m) abc, and the signed
    height of the point over each triangle's plane along its normal (b - a) x (c - a)."""
    normal = np.cross(b - a, c - a)
    unit = normal / np.linalg.norm(normal, axis=1)[:, None]
    offset = points[:, None, :] - a[None, :, :]
    height = np.einsum("nmj,mj->nm", offset, unit)
    foot = offset - height[..., None] * unit[None, :, :]
    # The foot is inside when it lies on the inner side of all three edges.
    inside = np.ones(height.shape, bool)
    for p, q in ((a, b), (b, c), (c, a)):
        edge_normal = np.cross(unit, q - p)
        inside &= np.einsum("nmj,mj->nm", foot + (a - p)[None], edge_normal) >= 0.0
    edges = np.minimum(np.minimum(_segment_distance2(points, a, b),
                                  _segment_distance2(points, b, c)),
                       _segment_distance2(points, c, a))
    return np.where(inside, height * height, edges), height


def _reference_sides(points, vertices, facets, band):
    from parmps.checks.crossing import border_edges
    points = np.asarray(points, dtype=float)
    border = border_edges(facets)
    a, b, c = (vertices[facets[:, k]] for k in range(3))
    distance2, height = _triangle_distance2(points, a, b, c)
    nearest = np.argmin(distance2, axis=1)
    rows = np.arange(len(points))
    surface2 = distance2[rows, nearest]
    border2 = _segment_distance2(points, vertices[border[:, 0]],
                                 vertices[border[:, 1]]).min(axis=1)
    at_border = border2 <= surface2 * (1.0 + 1e-9) + 1e-30
    beside = ~at_border & (surface2 <= band * band)
    return np.where(beside, np.where(height[rows, nearest] > 0.0, 1, -1), 0).astype(np.int8)


def test_the_sides_are_those_against_every_triangle():
    vertices, facets = lattice_mid_surface(PLATE, (9, 5, 2))
    points = np.random.default_rng(5).uniform([-0.02, -0.02, -0.03], [0.1, 0.06, 0.04],
                                              size=(700, 3))
    whole = mid_surface_sides(points, vertices, facets, PLATE_BAND)
    assert set(np.unique(whole)) == {-1, 0, 1}
    np.testing.assert_array_equal(whole, _reference_sides(points, vertices, facets,
                                                          PLATE_BAND))


def test_the_sides_by_cubes_are_the_sides_against_every_triangle():
    # A wide plate bent into a trough, with points all round it: the cubes of 2 bands and
    # the triangles near each give every point the side that testing it against every
    # triangle gives (ties included: the same first triangle).
    plate = lattice_geometry((21, 15, 2), 0.01, (0.0, 0.0, 0.0)).position.copy()
    plate[:, 2] += 2.0 * (plate[:, 0] - 0.1) ** 2
    vertices, facets = lattice_mid_surface(plate, (21, 15, 2))
    rng = np.random.default_rng(11)
    points = rng.uniform(vertices.min(axis=0) - 0.03, vertices.max(axis=0) + 0.03,
                         size=(3000, 3))
    # Lattice points too: they tie between triangles and sit on cube edges.
    points = np.concatenate([points, lattice_geometry((25, 19, 7), 0.01,
                                                       (-0.02, -0.02, -0.03)).position])
    expected = _reference_sides(points, vertices, facets, PLATE_BAND)
    sides = mid_surface_sides(points, vertices, facets, PLATE_BAND)
    assert set(np.unique(expected)) == {-1, 0, 1}
    np.testing.assert_array_equal(sides, expected)


@pytest.mark.parametrize("surface", ["bent gate", "red blood cell"])
def test_the_fast_winding_number_classifies_as_the_exact_sum(surface):
    # The coupling counts the fluid inside a body with the patches' far field; off the
    # surface it is within 0.05 of the exact sum everywhere, so "inside" is the same.
    from parmps.core.geometry import fast_winding_number, winding_number
    from parmps.geometry.shapes import red_blood_cell
    if surface == "bent gate":
        body = lattice_geometry((3, 40, 36), 0.0025, (0.1, 0.0, 0.0))
        vertices, triangles = body.position.copy(), body.boundary
        vertices[:, 0] += 0.04 * (np.clip(0.08 - vertices[:, 2], 0.0, None) / 0.08) ** 2
    else:
        vertices, triangles = red_blood_cell(8.0, frequency=12, center=(0.3, -0.2, 0.1))
    rng = np.random.default_rng(7)
    points = rng.uniform(vertices.min(axis=0) - 0.005, vertices.max(axis=0) + 0.005,
                         size=(4000, 3))
    exact = winding_number(points, vertices, triangles)
    fast = fast_winding_number(points, vertices, triangles)
    assert np.abs(fast - exact).max() < 0.05
    np.testing.assert_array_equal(fast > 0.5, exact > 0.5)
    assert 0.02 < np.mean(exact > 0.5) < 0.98


def _crossings(path, vertices, facets):
    """Crossings along one particle's path (one position a step), as the check counts."""
    total, previous = 0, (np.zeros(0, np.int64), np.zeros(0, np.int8))
    for point in path:
        side = mid_surface_sides([point], vertices, facets, PLATE_BAND)
        ids, sides = np.array([11])[side != 0], side[side != 0]
        total += count_crossings(*previous, ids, sides)
        previous = (ids, sides)
    return total


def _leg(start, end, step=0.0025):
    """Points from ``start`` to ``end`` at most ``step`` apart (less than l0 a step)."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    count = int(np.ceil(np.linalg.norm(end - start) / step)) + 1
    return list(start + np.linspace(0.0, 1.0, count)[:, None] * (end - start))


def test_a_particle_pushed_through_the_plate_counts_and_one_round_its_edge_does_not():
    vertices, facets = lattice_mid_surface(PLATE, (9, 5, 2))
    through = _leg([0.035, 0.015, -0.02], [0.035, 0.015, 0.03])
    assert _crossings(through, vertices, facets) == 1
    # Through a triangle's diagonal and at a node of the mid-surface: still one each.
    assert _crossings(_leg([0.045, 0.025, -0.02], [0.045, 0.025, 0.03]), vertices, facets) == 1
    assert _crossings(_leg([0.03, 0.02, 0.03], [0.03, 0.02, -0.02]), vertices, facets) == 1
    # Round the free edge at x = 0.08: along beneath, up past the edge, back above.
    round_x = (_leg([0.04, 0.02, -0.005], [0.085, 0.02, -0.005])
               + _leg([0.085, 0.02, -0.005], [0.085, 0.02, 0.015])
               + _leg([0.085, 0.02, 0.015], [0.04, 0.02, 0.015]))
    assert _crossings(round_x, vertices, facets) == 0
    # Round the edge at y = 0, diagonally past a corner's neighbourhood.
    round_y = (_leg([0.02, 0.01, -0.005], [0.02, -0.004, -0.005])
               + _leg([0.02, -0.004, -0.005], [0.03, -0.004, 0.015])
               + _leg([0.03, -0.004, 0.015], [0.03, 0.01, 0.015]))
    assert _crossings(round_y, vertices, facets) == 0
    # The same paths' crossings count on a bent plate too (the middle row raised 3 mm).
    bent = PLATE.copy()
    bent[:, 2] += 0.003 * np.sin(np.pi * bent[:, 0] / 0.08)
    vertices, facets = lattice_mid_surface(bent, (9, 5, 2))
    assert _crossings(through, vertices, facets) == 1
    assert _crossings(round_x, vertices, facets) == 0


def test_a_particle_through_a_closed_shell_counts_and_one_beside_it_does_not():
    """The check's sides of a closed shell: inside +1, outside -1; out through the sphere
    and back in counts two, a path that stays outside (round it) or inside counts none."""
    vertices, facets = icosphere(0.03, 4)

    def crossings(path):
        total, previous = 0, (np.zeros(0, np.int64), np.zeros(0, np.int8))
        for point in path:
            now = (np.array([7]), closed_surface_sides([point], vertices, facets))
            total += count_crossings(*previous, *now)
            previous = now
        return total

    out_and_back = _leg([0.0, 0.0, 0.0], [0.045, 0.0, 0.0]) + _leg([0.045, 0.0, 0.0],
                                                                      [0.0, 0.0, 0.0])
    assert crossings(out_and_back) == 2
    # Through a vertex of the mesh (the icosphere has one on each axis' pole).
    assert crossings(_leg([0.0, 0.0, 0.01], [0.0, 0.0, 0.05])) == 1
    around = (_leg([-0.05, 0.0, 0.0], [-0.05, 0.05, 0.0]) + _leg([-0.05, 0.05, 0.0],
                                                                  [0.05, 0.05, 0.0]))
    assert crossings(around) == 0
    assert crossings(_leg([-0.02, 0.0, 0.0], [0.02, 0.0, 0.0])) == 0


# -- coupled 3D runs ----------------------------------------------------------------------------

# A still tank 16 x 6 x 8 l0 of water (l0 = 2 cm) around a 3 x 3 x 3-node box in its middle,
# half as dense as the water (it rises); the fluid blocks leave the box's place free.
TANK = """
title = "box in a still tank 3D"
[domain]
lower = [-0.1, -0.1, -0.1]
upper = [0.42, 0.22, 0.3]
[particles]
spacing = 0.02
[time]
end = 0.02
fixed_dt = 0.002
output_interval = 0.01
[[tank]]
lower = [0.0, 0.0, 0.0]
upper = [0.32, 0.12, 0.22]
[[fluid_block]]
lower = [0.0, 0.0, 0.0]
upper = [0.14, 0.12, 0.16]
[[fluid_block]]
lower = [0.20, 0.0, 0.0]
upper = [0.32, 0.12, 0.16]
[[fluid_block]]
lower = [0.14, 0.0, 0.0]
upper = [0.20, 0.04, 0.16]
[[fluid_block]]
lower = [0.14, 0.10, 0.0]
upper = [0.20, 0.12, 0.16]
[[fluid_block]]
lower = [0.14, 0.04, 0.0]
upper = [0.20, 0.10, 0.06]
[[fluid_block]]
lower = [0.14, 0.04, 0.12]
upper = [0.20, 0.10, 0.16]
[[body]]
name = "box"
nx = 3
ny = 3
nz = 3
spacing = 0.02
lower = [0.15, 0.05, 0.07]
density = 500.0
stiffness = 2.0
shear_stiffness = 1.0
[[check]]
kind = "body_crossing"
body = "box"
[[probe]]
name = "corner"
kind = "displacement"
body = "box"
nodes = [26]
"""

TIGHT = ["-pressure_ksp_rtol", "1e-12"]
BOX_3D = CASES / "box_in_flow_3d.toml"


@pytest.fixture(scope="module")
def tank_case(tmp_path_factory):
    path = tmp_path_factory.mktemp("tank3d") / "tank.toml"
    path.write_text(TANK)
    return path


def _check_run(result, out):
    """Ran to its end, no fluid inside the box at any step, its volume kept to 1e-8, no
    crossing; returns the box's series."""
    assert result.returncode == 0, result.stderr[-3000:]
    with open_result(out) as run:
        series = dict(run.bodies["box"])
        assert run.diagnostics.time[-1] == pytest.approx(0.02)
        assert run.checks["body_crossing_box"].total[-1] == 0
    assert series["fluid_inside"].max() == 0
    assert np.abs(series["volume_error"]).max() <= 1e-8
    assert np.isfinite(series["fluid_force"]).all()
    return series


@pytest.mark.parametrize("scheme", ["implicit_pressure", "weak"])
def test_both_schemes_run_a_few_steps_in_3d(tank_case, tmp_path, scheme):
    """Ten steps of each scheme: the box, lighter than the water, is pushed up (the
    vertical fluid force exceeds its weight, 27 m g)."""
    result = run_parmps([tank_case, "-o", tmp_path, "--set", f'coupling.scheme="{scheme}"']
                        + TIGHT, timeout=300)
    series = _check_run(result, tmp_path)
    weight = 27 * 500.0 * 0.02 ** 3 * 9.81
    assert series["fluid_force"][-1, 2] > weight
    assert np.abs(series["fluid_force"][-1, :2]).max() < 0.2 * series["fluid_force"][-1, 2]
    # A displacement probe on a 3D lattice follows node 26 (the far top corner) from its
    # rest position (0.19, 0.09, 0.11), risen with the box.
    with open_result(tmp_path) as run:
        moved = run.frames[-1].bodies["box"]["position"][26] - [0.19, 0.09, 0.11]
        value = run.probes["corner"].value[-1]
    np.testing.assert_allclose(value, moved, rtol=0, atol=1e-12)
    assert value[2] > 0.0


def test_at_the_fluids_density_the_schemes_agree_in_3d(tank_case, tmp_path):
    """With every node of the water's density the implicit scheme's matrix is the weak
    one's, so the runs agree to round-off, as in 2D."""
    frames = []
    for scheme in ("implicit_pressure", "weak"):
        out = tmp_path / scheme
        result = run_parmps([tank_case, "-o", out, "--set", f'coupling.scheme="{scheme}"',
                             "--set", "body.0.density=1000.0"] + TIGHT, timeout=300)
        _check_run(result, out)
        frames.append(read_frame(out / "result.h5"))
    a, b = frames
    np.testing.assert_array_equal(a["id"], b["id"])
    assert np.abs(a["position"] - b["position"]).max() <= 1e-12
    assert np.abs(a["pressure"] - b["pressure"]).max() <= 1e-9 * np.abs(a["pressure"]).max()


def _by_id(out):
    frame = read_frame(out / "result.h5")
    order = np.argsort(frame["id"])
    return (frame["id"][order], frame["position"][order], frame["pressure"][order],
            frame["kind"][order])


@pytest.mark.mpi
def test_the_same_answer_by_id_on_one_two_and_three_ranks(tmp_path):
    """The 3D box in its duct at solid/fluid density 0.1 (the implicit scheme's case), ten
    steps: node positions, fluid pressures and the fluid force on the box by id within
    1e-10 of their scale on 1, 2 and 3 ranks (measured: 1e-13 or better).

    Not the still tank above: there the wall particles beside the free surface differ by
    3e-5 of the largest pressure between 1 and 2 ranks with no body at all (a fluid matter,
    not the coupling's), where the duct has no free surface."""
    outs = []
    for ranks in (1, 2, 3):
        out = tmp_path / f"r{ranks}"
        result = run_parmps([BOX_3D, "-o", out, "--end-time", "0.02", "--set",
                             "time.output_interval=0.01", "--set", "body.0.density=100.0"]
                            + TIGHT, ranks=ranks, timeout=600)
        assert result.returncode == 0, result.stderr[-3000:]
        outs.append(out)
    ids, position, pressure, kind = _by_id(outs[0])
    nodes, fluid = kind == SOLID, kind == FLUID
    assert nodes.sum() == 5 * 9 * 5 and pressure[fluid].max() > 1.0
    with open_result(outs[0]) as run:
        force = run.bodies["box"]["fluid_force"]
        assert run.bodies["box"]["fluid_inside"].max() == 0
    assert np.abs(force).max() > 0.0
    scale = np.abs(position).max()
    for out in outs[1:]:
        other_ids, other_position, other_pressure, _ = _by_id(out)
        np.testing.assert_array_equal(other_ids, ids)
        assert np.abs(other_position[nodes] - position[nodes]).max() <= 1e-10 * scale
        assert np.abs(other_position - position).max() <= 1e-10 * scale
        assert (np.abs(other_pressure[fluid] - pressure[fluid]).max()
                <= 1e-10 * np.abs(pressure[fluid]).max())
        with open_result(out) as run:
            other_force = run.bodies["box"]["fluid_force"]
        assert np.abs(other_force - force).max() <= 1e-10 * np.abs(force).max()


# -- what is still refused -------------------------------------------------------------------

CAPSULE_3D = CASES / "capsule_3d.toml"


def test_a_shell_takes_the_place_of_the_water_at_its_surface_and_holds_the_rest():
    """The capsule case's scene: the fluid block fills the duct and the capsule; the points
    within half a spacing of the shell (its clearance, docs/shells.md) are left out, within
    four of as many as it has nodes, and the rest stay on both sides of it."""
    from parmps.geometry import scene
    from parmps.solids.mass_spring.shell import fluid_clearance
    case = schema.validate(tomllib.loads(CAPSULE_3D.read_text()))
    model = MassSpringModel.from_case(case)
    particles, _, _ = scene.build(case, model)
    body = model.bodies[0]
    fluid = particles.position[particles.kind == FLUID]
    assert fluid_clearance(body.position, body.facets, 0.01) == 0.005
    assert 36 * 13 * 13 - len(fluid) in range(body.n_nodes - 4, body.n_nodes + 1)
    assert body.n_nodes == 182
    distance = surface_distance(fluid, body.position, body.facets, 0.01)
    assert distance.min() >= 0.005
    inside = inside_boundary(fluid, body.position, body.facets)
    assert inside.sum() == 144


def test_a_shell_too_coarse_to_hold_the_water_is_refused_in_one_line(tmp_path):
    path = tmp_path / "coarse.toml"
    path.write_text(CAPSULE_3D.read_text().replace("spacing = 0.01             # target",
                                                   "spacing = 0.015            # target"))
    result = run_parmps([path, "--check"], timeout=60)
    assert result.returncode == 2
    assert error_lines(result.stderr) == [
        f"parmps: error: {path}: body[0] 'capsule': its mean edge 0.01409 m is 1.41 particle "
        f"spacings; in a fluid a shell's nodes are particles of it, standing for the water "
        f"they displace, and must lie at most 1.25 spacings apart on average: refine the "
        f"shell (spacing or refinement)"]


def test_a_3d_body_off_the_particle_spacing_is_refused(tank_case):
    with pytest.raises(CaseError, match=r"body\[0\] 'box': spacing 0.025 must equal "
                                        r"particles.spacing 0.02"):
        schema.validate(tomllib.loads(tank_case.read_text().replace(
            "spacing = 0.02\nlower = [0.15", "spacing = 0.025\nlower = [0.15")))


# -- the 3D box to its end ---------------------------------------------------------------------

@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.timeout(2400)
@pytest.mark.parametrize("density", [100.0])
def test_the_3d_box_meets_its_validation_on_two_ranks(tmp_path, density):
    """validation/box_in_flow_3d at solid/fluid density 0.1, the light body the implicit
    coupling is for, on 2 ranks to the case's end: every tolerance of its validation.toml
    (about 50 s on a quiet machine). Densities 1 and 10 to their end are checked by
    `python -m parmps validate box_in_flow_3d -n 2 --set body.0.density=RHO`; their figures
    are in validation/box_in_flow_3d/README.md (kept out of the suite's 15 minutes)."""
    from parmps import validation
    check = validation.load("box_in_flow_3d")
    result = run_parmps([check.case_path, "-o", tmp_path, "--set",
                         f"body.0.density={density}"], ranks=2, timeout=2300)
    assert result.returncode == 0, result.stderr[-3000:]
    measured = check.measure(tmp_path / "result.h5")
    assert measured["end"] == pytest.approx(check.case()["time"]["end"])
    verdicts = check.verdicts(measured)
    assert set(verdicts) == set(check.tolerance), verdicts
    assert all(verdict["pass"] for verdict in verdicts.values()), verdicts


def test_a_particle_through_a_shell_is_held_back_to_its_side():
    """hold_to_side: a particle found outside a sphere it was inside goes back a given depth
    below the surface's nearest point, and loses only the part of its velocity relative to
    the surface that points out of its side; one found inside that was outside goes out."""
    from parmps.coupling.weak import hold_to_side
    vertices, facets = icosphere(0.03, 8)
    node_velocity = np.tile([0.01, 0.0, 0.0], (len(vertices), 1))
    direction = np.array([[1.0, 2.0, 2.0], [-2.0, 1.0, -2.0]]) / 3.0
    position = direction * np.array([[0.0302], [0.0296]])
    velocity = np.array([[0.2, 0.1, 0.3], [0.05, -0.02, 0.01]])
    side = np.array([1, -1])  # the first was inside, the second outside
    before = velocity.copy()
    wrong = hold_to_side(position, velocity, side, vertices, node_velocity, facets, 0.0025,
                         0.02)
    assert len(wrong) == 0
    assert inside_boundary(position, vertices, facets).tolist() == [True, False]
    distance = surface_distance(position, vertices, facets, 0.01)
    np.testing.assert_allclose(distance, 0.0025, rtol=1e-9)
    # The mesh's normal is within its facets' tilt of the radial direction.
    radial = position / np.linalg.norm(position, axis=1)[:, None]
    for k, into in enumerate([-radial[0], radial[1]]):
        relative_before = (before[k] - node_velocity[0]) @ into
        relative_after = (velocity[k] - node_velocity[0]) @ into
        assert relative_before < 0.0 and abs(relative_after) < 0.05 * abs(relative_before)
        tangential = velocity[k] - before[k]
        assert np.linalg.norm(np.cross(tangential, into)) < 0.05 * np.linalg.norm(tangential)
    # A particle moving into its side keeps its velocity.
    position = np.array([[0.0, 0.0, 0.0301]])
    velocity = np.array([[0.0, 0.0, -0.1]])
    hold_to_side(position, velocity, np.array([1]), vertices, 0.0 * node_velocity, facets,
                 0.0025, 0.02)
    np.testing.assert_array_equal(velocity, [[0.0, 0.0, -0.1]])


# -- the fluid-filled capsule ----------------------------------------------------------------

@pytest.mark.mpi
def test_the_capsule_gives_the_same_answer_by_id_on_one_two_and_three_ranks(tmp_path):
    """validation/capsule_3d's case for ten steps (--end-time 0.02) on 1, 2 and 3 ranks:
    node positions and fluid pressures by id within 1e-10 of their scale, the shell's fluid
    force too, its water (144 particles) inside at every step and no crossing. The run to
    its end is `python -m parmps validate capsule_3d -n 2` (README there: 1, 2 and 3 ranks
    to 1 s), kept out of the suite for its minute and a half."""
    outs = []
    for ranks in (1, 2, 3):
        out = tmp_path / f"r{ranks}"
        result = run_parmps([CAPSULE_3D, "-o", out, "--end-time", "0.02", "--set",
                             "time.output_interval=0.01"] + TIGHT, ranks=ranks, timeout=600)
        assert result.returncode == 0, result.stderr[-3000:]
        outs.append(out)
    ids, position, pressure, kind = _by_id(outs[0])
    nodes, fluid = kind == SOLID, kind == FLUID
    assert nodes.sum() == 182 and pressure[fluid].max() > 1.0
    forces = []
    for out in outs:
        with open_result(out) as run:
            capsule = run.bodies["capsule"]
            forces.append(np.asarray(capsule["fluid_force"]))
            assert set(np.asarray(capsule["fluid_inside"])) == {144}
            assert run.checks["body_crossing_capsule"]["total"][-1] == 0
    assert np.abs(forces[0]).max() > 0.0
    scale = np.abs(position).max()
    for out, force in zip(outs[1:], forces[1:]):
        other_ids, other_position, other_pressure, _ = _by_id(out)
        np.testing.assert_array_equal(other_ids, ids)
        assert np.abs(other_position - position).max() <= 1e-10 * scale
        assert (np.abs(other_pressure[fluid] - pressure[fluid]).max()
                <= 1e-10 * np.abs(pressure[fluid]).max())
        assert np.abs(force - forces[0]).max() <= 1e-10 * np.abs(forces[0]).max()
