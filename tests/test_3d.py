"""3D cases: the schema with 3-vectors and its refusals, the 3D scene, --check, probes on
a 3D lattice, and the same answer by particle id on 1, 2 and 3 ranks.

The 3D still tank against its targets is tests/test_hydrostatic_3d.py; a 3D restart on
another rank count is in tests/test_restart.py; ParaView's view of a 3D result in
tests/test_paraview.py. The SPHERIC dam break (cases/dam_break_3d.toml) to its end time is
checked by validation/dam_break_3d (its README gives the command and the figures).
"""

import json

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CASES, error_lines, run_parmps
from parmps import config, open_result, schema
from parmps.core import lattice
from parmps.geometry import scene
from parmps.core.particles import DUMMY, FLUID, WALL
from parmps.errors import CaseError
from parmps.probes.observer import Probe
from parmps.probes.sampling import SampleRows, kernel_sums, lattice_sum, shepard_pressure

TANK_3D = (CASES / "hydrostatic_3d.toml").read_text()
DAM_BREAK_3D = CASES / "dam_break_3d.toml"


def _validate(text):
    return schema.validate(config.load_text(text))


# -- the case file --------------------------------------------------------------------

def test_the_dimension_comes_from_the_domain_and_sets_the_vector_defaults():
    case = _validate(TANK_3D)
    assert case["dimension"] == 3
    assert case["physics"]["gravity"] == [0.0, 0.0, -9.81]
    assert case["fluid_block"][0]["velocity"] == [0.0, 0.0, 0.0]
    assert case["tank"][0]["velocity"] == [0.0, 0.0, 0.0]
    two = _validate((CASES / "hydrostatic.toml").read_text())
    assert two["dimension"] == 2 and two["physics"]["gravity"] == [0.0, -9.81]
    # The Laplacian's radius, measured for each dimension (docs/performance.md); a case's own
    # value holds in either.
    assert case["mps"]["re_laplacian"] == 2.3 and two["mps"]["re_laplacian"] == 3.1
    own = _validate(TANK_3D + "\n[mps]\nre_laplacian = 3.1\n")
    assert own["mps"]["re_laplacian"] == 3.1


@pytest.mark.parametrize("old, new, message", [
    ("lower = [0.0, 0.0, 0.0]\nupper = [0.2, 0.2, 0.2]",
     "lower = [0.0, 0.0]\nupper = [0.2, 0.2, 0.2]",
     "fluid_block[0].lower has 2 components but the case is 3D (domain.lower has 3): "
     "give [x, y, z]"),
    ("lower = [-0.1, -0.1, -0.1]", "lower = [-0.1, -0.1, -0.1, 0.0]",
     "domain.lower has 4 components: give [x, y] for a 2D case or [x, y, z] for a 3D one"),
    ("[fluid]", "[physics]\ngravity = [0.0, -9.81]\n\n[fluid]",
     "physics.gravity has 2 components but the case is 3D"),
])
def test_a_case_that_mixes_dimensions_is_refused_naming_the_key(old, new, message):
    assert old in TANK_3D
    with pytest.raises(CaseError) as caught:
        _validate(TANK_3D.replace(old, new, 1))
    assert message in str(caught.value)


def test_the_command_line_refuses_a_mixed_case_in_one_line(tmp_path):
    path = tmp_path / "mixed.toml"
    path.write_text(TANK_3D.replace("upper = [0.2, 0.2, 0.3]", "upper = [0.2, 0.3]"))
    result = run_parmps([path, "--check"], timeout=60)
    assert result.returncode == 2
    assert error_lines(result.stderr) == [
        f"parmps: error: {path}: tank[0].upper has 2 components but the case is 3D "
        f"(domain.lower has 3): give [x, y, z]"]
    assert "Traceback" not in result.stderr


def test_snapped_boxes_and_probes_lie_on_the_lattice_lines():
    case = _validate(DAM_BREAK_3D.read_text().replace(
        "spacing = 0.0366666666666666667", "spacing = 0.055"))
    spacing = 0.055
    for name in ("fluid_block", "tank", "wall_box"):
        for box in case[name]:
            for corner in (box["lower"], box["upper"]):
                steps = np.asarray(corner) / spacing
                np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    # The box's face towards the water: 0.8245 m given, 15 l0 = 0.825 m built; P1 follows
    # it along its normal (x) and keeps its height and its place across the box.
    assert case["wall_box"][0]["upper"][0] == pytest.approx(0.825)
    p1 = next(p for p in case["probe"] if p["name"] == "P1")
    assert p1["position"] == pytest.approx([0.825, 0.471, 0.021])
    # The water still touches the tank's far wall: both snapped to the same line.
    assert case["fluid_block"][0]["upper"][0] == case["tank"][0]["upper"][0]


def test_a_patch_must_be_an_axis_aligned_rectangle_with_a_normal_across_it():
    probe = ('\n[[probe]]\nname = "f"\nkind = "force"\npatch = [[0.0, 0.0, 0.0], '
             '[0.2, 0.2, 0.0]]\nnormal = [0.0, 0.0, 1.0]\n')
    case = _validate(TANK_3D + probe)
    assert case["probe"][-1]["patch"] == [[0.0, 0.0, 0.0], [0.2, 0.2, 0.0]]
    with pytest.raises(CaseError, match="is not perpendicular to its patch"):
        _validate(TANK_3D + probe.replace("normal = [0.0, 0.0, 1.0]", "normal = [1.0, 0.0, 0.0]"))
    with pytest.raises(CaseError, match="must be a rectangle in a plane"):
        _validate(TANK_3D + probe.replace("[0.2, 0.2, 0.0]", "[0.2, 0.2, 0.1]"))
    with pytest.raises(CaseError, match="segment is for a 2D case"):
        _validate(TANK_3D + probe.replace("patch", "segment"))


# -- the scene ------------------------------------------------------------------------

def test_a_3d_tank_has_a_floor_and_four_walls_with_their_layers_and_an_open_roof():
    spacing = 0.02
    spec = {"lower": [0.0, 0.0, 0.0], "upper": [0.2, 0.16, 0.3], "wall_layers": 2,
            "dummy_layers": 2, "open_top": True}
    position, kind, velocity = scene.tank(spec, spacing, "tank[0]")
    n = (10, 8, 15)

    def shell(layers):
        # The outer box of ``layers`` layers (none above the open top) less the inner box.
        return (n[0] + 2 * layers) * (n[1] + 2 * layers) * (n[2] + layers) - np.prod(n)

    assert len(position) == shell(4)
    assert np.count_nonzero(kind == WALL) == shell(2)
    assert np.count_nonzero(kind == DUMMY) == shell(4) - shell(2)
    assert velocity.shape == (shell(4), 3) and not velocity.any()
    inside = np.all((position > 0.0) & (position < np.array(spec["upper"])), axis=1)
    assert not inside.any()
    assert position[:, 2].max() < 0.3  # no roof
    closed, _, _ = scene.tank(dict(spec, open_top=False), spacing, "tank[0]")
    assert len(closed) == (n[0] + 8) * (n[1] + 8) * (n[2] + 8) - np.prod(n)


def test_a_3d_wall_box_is_walls_outside_and_dummies_inside():
    spec = {"lower": [0.0, 0.0, 0.0], "upper": [0.1, 0.12, 0.08], "wall_layers": 2}
    position, kind, _ = scene.wall_box(spec, 0.01, "wall_box[0]")
    assert len(position) == 10 * 12 * 8
    assert np.count_nonzero(kind == DUMMY) == 6 * 8 * 4


def test_check_prints_the_3d_reference_values(tmp_path):
    result = run_parmps([CASES / "hydrostatic_3d.toml", "--check"], timeout=120)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["dimension"] == 3
    assert summary["particles"]["fluid"] == 10 * 10 * 10
    # The Laplacian's radius is 2.3 l0 in 3D by default (3.1 in 2D), the number density's:
    # the cubic lattice within it has n0 = 19.53 and lambda0 / l0^2 = 1.932 (at 3.1 l0:
    # 54.32 and 3.243, DESIGN §7.2).
    assert summary["radii"]["laplacian"] == 2.3
    assert summary["n0_laplacian"] == pytest.approx(19.53, abs=0.005)
    assert summary["lambda0"] / 0.02 ** 2 == pytest.approx(1.932, abs=0.001)
    n0, _ = lattice.reference_values(1.0, summary["radii"]["number_density"], 3)
    assert summary["n0"] == pytest.approx(n0, rel=1e-12)
    assert summary["dt_limits"]["dt_max"] == pytest.approx(1e-3)
    assert summary["initial_dt"] == pytest.approx(1e-3)
    assert summary["memory_estimate_mb"] > 0


# -- probes on a 3D lattice -----------------------------------------------------------

SPACING = 0.01


def _cube(counts, lower=(0.0, 0.0, 0.0)):
    return scene.lattice_points(lower, counts, SPACING)


def _probe(**keys):
    spec = {"name": "p", "kind": "pressure", "position": None, "normal": None, "line": [],
            "segment": [], "patch": [], "wall_box": -1, "body": "", "nodes": [],
            "interval": 0.0, "radius": 2.0, "min_fill": 0.5, "reading": "depth"}
    spec.update(keys)
    return spec


def _read(probe, position, kind, pressure):
    from parmps.probes.observer import Probes
    rows = Probes._as_sample_rows([(row, probe.radius) for row in probe.rows])
    sums = kernel_sums(rows, position, kind.astype(np.int8), pressure, len(position),
                       MPI.COMM_SELF)
    return probe.value(sums, {})


def test_a_3d_point_reads_a_linear_field_exactly_in_the_full_lattice():
    position = _cube((16, 16, 16))
    kind = np.full(len(position), FLUID)
    pressure = 1000.0 + 2.0e4 * position[:, 2] - 5.0e3 * position[:, 0] + 3.0e3 * position[:, 1]
    point = (8.5 * SPACING, 7.5 * SPACING, 8.5 * SPACING)
    rows = SampleRows([point], [[1.0, 0.0, 0.0]], [SPACING], [1], [2 * SPACING])
    sums = kernel_sums(rows, position, kind.astype(np.int8), pressure, len(position),
                       MPI.COMM_SELF)
    assert sums[0, 0] / lattice_sum(2.0, 3) == pytest.approx(1.0, rel=1e-12)
    expected = 1000.0 + 2.0e4 * point[2] - 5.0e3 * point[0] + 3.0e3 * point[1]
    assert shepard_pressure(sums, lattice_sum(2.0, 3), 0.5)[0] == pytest.approx(expected,
                                                                                 rel=1e-12)


def _tank_with_box(depth_cells=20):
    """Still water 20 l0 deep over a floor, around a box of 4 x 6 x 5 l0 on the floor; the
    hydrostatic pressure rho g (H - z) on every fluid particle."""
    water = _cube((24, 24, depth_cells))
    floor = _cube((24, 24, 4), lower=(0.0, 0.0, -0.04))
    box = _cube((4, 6, 5), lower=(0.10, 0.09, 0.0))
    in_box = np.all((water > [0.10, 0.09, 0.0]) & (water < [0.14, 0.15, 0.05]), axis=1)
    water = water[~in_box]
    position = np.vstack([water, floor, box])
    kind = np.r_[np.full(len(water), FLUID), np.full(len(floor) + len(box), WALL)]
    pressure = np.r_[1000.0 * 9.81 * (depth_cells * SPACING - water[:, 2]),
                     np.zeros(len(floor) + len(box))]
    return position, kind, pressure


def _brute_force(points, area, normal, position, kind, pressure, radius=2.0):
    """The force of a patch sampled at ``points`` (each standing for ``area``), by plain
    numpy: Shepard averages of the fluid's pressure, dry samples carrying nothing."""
    from parmps.core.pairs import wendland
    r = np.linalg.norm(points[:, None, :] - position[None, :, :], axis=2) / (radius * SPACING)
    w = np.where(r < 1.0, np.vectorize(wendland)(np.minimum(r, 1.0)), 0.0)
    fluid = kind == FLUID
    weight = w[:, fluid].sum(axis=1)
    wet = weight >= 0.5 * lattice_sum(radius, 3)
    sample = np.where(wet, (w[:, fluid] * pressure[fluid]).sum(axis=1) / np.maximum(weight, 1e-300),
                      0.0)
    return -np.asarray(normal, float) * sample.sum() * area


def _face_samples(lower, upper, axis, offset):
    """Sample points every half spacing over a face of [lower, upper] in the plane
    ``axis = lower[axis]``, shifted ``offset`` along that axis."""
    spans = [a for a in range(3) if a != axis]
    ticks = [lower[a] + (np.arange(round((upper[a] - lower[a]) / (0.5 * SPACING))) + 0.5)
             * 0.5 * SPACING for a in spans]
    grid = np.meshgrid(*ticks, indexing="ij")
    points = np.zeros((grid[0].size, 3))
    points[:, spans[0]], points[:, spans[1]] = grid[0].ravel(), grid[1].ravel()
    points[:, axis] = lower[axis] + offset
    return points, (0.5 * SPACING) ** 2


def test_a_patch_on_the_floor_carries_the_weight_of_the_water_above_it():
    position, kind, pressure = _tank_with_box()
    probe = Probe(_probe(kind="force", patch=[[0.04, 0.04, 0.0], [0.08, 0.10, 0.0]],
                         normal=[0.0, 0.0, 1.0]), SPACING, 3)
    force = _read(probe, position, kind, pressure)
    points, area = _face_samples([0.04, 0.04, 0.0], [0.08, 0.10, 0.0], 2, 0.5 * SPACING)
    expected = _brute_force(points, area, [0.0, 0.0, 1.0], position, kind, pressure)
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-9)
    # The weight of the water above 4 cm x 6 cm of floor, rho g H A, as read within one
    # spacing of the floor: the samples half a spacing up average the water above them only,
    # which reads them higher (measured: 0.64 l0 up).
    weight = 1000.0 * 9.81 * 0.2 * 0.04 * 0.06
    assert force[:2] == pytest.approx([0.0, 0.0], abs=1e-9 * weight)
    assert weight * (1 - SPACING / 0.2) < -force[2] < weight


def test_the_force_on_a_wall_box_is_its_faces_loads_and_nothing_across():
    position, kind, pressure = _tank_with_box()
    lower, upper = [0.10, 0.09, 0.0], [0.14, 0.15, 0.05]
    probe = Probe(_probe(kind="force", wall_box=0), SPACING, 3, boxes=[(lower, upper)])
    force = _read(probe, position, kind, pressure)
    expected = np.zeros(3)
    for axis in range(3):
        for side, plane in ((-1.0, lower[axis]), (1.0, upper[axis])):
            face_lower = list(lower)
            face_lower[axis] = plane
            points, area = _face_samples(face_lower, upper, axis, side * 0.5 * SPACING)
            expected += _brute_force(points, area, side * np.eye(3)[axis], position, kind,
                                     pressure)
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-9)
    # The side faces' loads cancel in the symmetric tank; the top, pressed down by about
    # rho g (H - h) A, is not balanced by the bottom, which stands on the floor.
    top = 1000.0 * 9.81 * (0.2 - 0.05) * 0.04 * 0.06
    assert np.abs(force[:2]).max() < 1e-9 * top
    # As on the floor: read within one spacing above the face.
    assert top * (1 - SPACING / 0.15) < -force[2] < top


def test_a_3d_level_probe_reads_the_water_depth():
    position, kind, pressure = _tank_with_box()
    line = [[0.05, 0.05, -0.02], [0.05, 0.05, 0.4]]
    crossing = Probe(_probe(kind="level", line=line, reading="crossing"), SPACING, 3)
    assert _read(crossing, position, kind, pressure) == pytest.approx(0.2, abs=0.25 * SPACING)
    # The depth (the default) integrates the fill: within 2 % on a lattice (measured -1.5 %
    # with the line between columns of particles, as here; tests/test_probes.py).
    depth = Probe(_probe(kind="level", line=line), SPACING, 3)
    assert _read(depth, position, kind, pressure) == pytest.approx(0.2, rel=0.02)


# -- the same answer on any rank count --------------------------------------------------

# The SPHERIC dam break at 0.55/5 m (about 5k particles), 25 steps of 2 ms, converged solves.
COARSE_STEPS = ["--set", "particles.spacing=0.11", "--set", "time.fixed_dt=0.002",
                "--end-time", "0.05", "--set", "time.output_interval=0.05",
                "-pressure_ksp_rtol", "1e-12"]


def _last_frame(path):
    with open_result(path) as result:
        frame = result.frames[-1]
        return frame.id, frame.position, frame.pressure


@pytest.fixture(scope="module")
def one_rank_3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("dam3d1")
    result = run_parmps([DAM_BREAK_3D, "-o", out] + COARSE_STEPS, timeout=300)
    assert result.returncode == 0, result.stderr
    return _last_frame(out / "result.h5")


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_the_3d_dam_break_matches_one_rank_by_id(one_rank_3d, tmp_path, ranks):
    result = run_parmps([DAM_BREAK_3D, "-o", tmp_path] + COARSE_STEPS, ranks=ranks,
                        timeout=300)
    assert result.returncode == 0, result.stderr
    ids1, position1, pressure1 = one_rank_3d
    ids, position, pressure = _last_frame(tmp_path / "result.h5")
    np.testing.assert_array_equal(ids, ids1)
    domain = 4.02  # the case's longest domain side [m]
    assert np.abs(position - position1).max() < 1e-9 * domain
    assert np.abs(pressure - pressure1).max() < 1e-9 * np.abs(pressure1).max()
    assert pressure1.max() > 1000.0  # a real pressure field: 0.55 m of water


# -- open boundaries in 3D ------------------------------------------------------------

DUCT_3D = """
title = "3D duct: an inlet on the right, an outlet on the left"
[domain]
lower = [0.0, -0.06, -0.06]
upper = [0.3, 0.16, 0.16]
[particles]
spacing = 0.02
[physics]
gravity = [0.0, 0.0, 0.0]
[fluid]
viscosity = 1.0e-3
[time]
end = 0.3
dt_max = 2.0e-3
output_interval = 0.1
[[fluid_block]]
lower = [0.0, 0.0, 0.0]
upper = [0.22, 0.1, 0.1]
velocity = [-0.1, 0.0, 0.0]
[[wall_box]]
lower = [0.0, 0.0, -0.06]
upper = [0.3, 0.1, 0.0]
[[wall_box]]
lower = [0.0, 0.0, 0.1]
upper = [0.3, 0.1, 0.16]
[[wall_box]]
lower = [0.0, -0.06, -0.06]
upper = [0.3, 0.0, 0.16]
[[wall_box]]
lower = [0.0, 0.1, -0.06]
upper = [0.3, 0.16, 0.16]
[[inlet]]
lower = [0.22, 0.0, 0.0]
upper = [0.3, 0.1, 0.1]
velocity = [-0.1, 0.0, 0.0]
[[outlet]]
side = "left"
velocity = [-0.1, 0.0, 0.0]
"""


def test_a_3d_duct_takes_in_and_lets_out_whole_cross_sections(tmp_path):
    case = tmp_path / "duct.toml"
    case.write_text(DUCT_3D)
    result = run_parmps([case, "-o", tmp_path / "out"], timeout=300)
    assert result.returncode == 0, result.stderr
    with open_result(tmp_path / "out") as result:
        inflow = result.diagnostics.inflow
        outflow = result.diagnostics.outflow
        fluid = result.diagnostics.n_fluid
    # 0.3 s at 0.1 m/s moves 1.5 spacings: a cross-section is 5 x 5 particles, and
    # whole sections enter and leave.
    assert inflow[-1] > 0 and inflow[-1] % 25 == 0
    assert outflow[-1] > 0
    assert abs(fluid[-1] - fluid[0]) <= 0.1 * fluid[0]


# -- every registered scheme in 3D ----------------------------------------------------

def _schemes():
    from parmps.fluid.schemes import GRADIENTS, LAPLACIANS, SOURCES, SURFACES
    return ([("source", name) for name in SOURCES] + [("laplacian", name) for name in LAPLACIANS]
            + [("gradient", name) for name in GRADIENTS]
            + [("free_surface", name) for name in SURFACES])


@pytest.mark.parametrize("key, name", _schemes())
def test_every_registered_scheme_runs_the_3d_dam_break(tmp_path, key, name):
    """10 steps of the SPHERIC dam break at 0.55/5 m with one scheme changed from the
    defaults: a finite, positive pressure field under the water and no particle lost."""
    result = run_parmps([DAM_BREAK_3D, "-o", tmp_path, "--set", "particles.spacing=0.11",
                         "--set", f"mps.{key}={name!r}".replace("'", '"'),
                         "--end-time", "0.02", "--set", "time.fixed_dt=0.002",
                         "--set", "time.output_interval=0.02"], timeout=300)
    assert result.returncode == 0, result.stderr
    ids, position, pressure = _last_frame(tmp_path / "result.h5")
    with open_result(tmp_path) as result:
        assert len(result.frames[0]) == len(ids)
    assert np.isfinite(position).all() and np.isfinite(pressure).all()
    # The water column 0.55 m deep: its floor reads about rho g H.
    assert 0.5 * 1000 * 9.81 * 0.55 < pressure.max() < 3 * 1000 * 9.81 * 0.55


@pytest.mark.parametrize("open_top, periodic", [(True, []), (False, []), (True, ["y"])])
def test_the_memory_estimate_counts_a_tanks_walls_as_the_scene_lays_them(open_top, periodic):
    """The estimate's tank is the scene's own tank geometry (geometry.scene.tank_material):
    its wall and dummy count is the built one's exactly, open or closed, and a periodic
    axis the tank spans has no walls across it in either."""
    from parmps.run.resources import particle_estimate
    top = "true" if open_top else "false"
    case = _validate(f"""
[domain]
lower = [-0.1, {0.0 if periodic else -0.1}, -0.1]
upper = [0.3, {0.16 if periodic else 0.26}, 0.5]
periodic = {json.dumps(periodic)}
[particles]
spacing = 0.02
[time]
end = 0.1
[[tank]]
lower = [0.0, 0.0, 0.0]
upper = [0.2, 0.16, 0.3]
open_top = {top}
""")
    built = scene.build(case)[0]
    assert particle_estimate(case) == pytest.approx(len(built.position), rel=1e-9)
