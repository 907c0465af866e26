"""Probes (docs/design.md §5.1): the kernel sums, their validation, a still tank, the
Lobovsky case's set-up, and the same values on 1, 2 and 3 ranks.

- Sums over a full lattice normalise to 1; a Shepard average reproduces a linear
  field at a lattice node; a point with too little fluid reads NaN, a point beside a
  wall once the water fills half of its support outside the wall.
- Splitting the particles between ranks changes no sum (each rank adds its owned ones).
- A level line reads a still layer's depth H within 2 % (its fill integrated) and its
  surface within l0/4 (the highest crossing), in 2D and 3D; over a jet passing above a
  shallow layer the depth reads the layer, the crossing the jet's top.
- The still tank: a pressure probe at y = H/4 reads rho g (H - y) within 2 % averaged
  over 0.5-2 s, a wall probe beside it too, the level reads H within 2 % (the crossing
  within a spacing) and the force on a side wall rho g H^2 / 2 per metre within 2 %.
- A force probe on a body reads the coupling's sum over its nodes.
- Under mpirun the dam break's probes, one with its support across a slab edge, read the
  same on 1, 2 and 3 ranks.
"""

import csv
import math

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CASES, error_lines, run_parmps
from parmps import config, open_result, schema, validation
from parmps.geometry import scene
from parmps.core.particles import FLUID, WALL
from parmps.errors import CaseError
from parmps.probes.sampling import (SampleRows, column_end, kernel_sums, lattice_sum,
                                    mean_sum, shepard_pressure, surface_height, water_depth)
from parmps.tools import analysis

SPACING = 0.01


def _lattice(nx, ny, spacing=SPACING, x0=0.0, y0=0.0):
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    return np.column_stack([x0 + (i.ravel() + 0.5) * spacing, y0 + (j.ravel() + 0.5) * spacing])


def _point(x, y, radius):
    return SampleRows([[x, y]], [[1.0, 0.0]], [SPACING], [1], [radius * SPACING])


def _sums(rows, position, kind, pressure, comm=MPI.COMM_SELF):
    return kernel_sums(rows, position, kind.astype(np.int8), pressure, len(position), comm)


@pytest.mark.parametrize("radius", [1.5, 2.0, 3.0])
def test_full_lattice_normalises_to_one_and_reproduces_a_linear_field(radius):
    position = _lattice(20, 20)
    kind = np.full(len(position), FLUID)
    pressure = 1000.0 + 3.0e4 * position[:, 1] - 2.0e4 * position[:, 0]
    x, y = 10.5 * SPACING, 9.5 * SPACING
    sums = _sums(_point(x, y, radius), position, kind, pressure)
    assert sums[0, 0] / lattice_sum(radius) == pytest.approx(1.0, rel=1e-12)
    expected = 1000.0 + 3.0e4 * y - 2.0e4 * x
    assert shepard_pressure(sums, lattice_sum(radius), 0.5)[0] == pytest.approx(expected,
                                                                                 rel=1e-12)


def test_a_point_with_too_little_fluid_reads_nan():
    position = _lattice(10, 10)
    kind = np.full(len(position), FLUID)
    pressure = np.full(len(position), 5.0)
    full = lattice_sum(2.0)
    # The fluid's corner: a quarter of the support holds fluid.
    corner = _sums(_point(0.0, 0.0, 2.0), position, kind, pressure)
    assert math.isnan(shepard_pressure(corner, full, 0.5)[0])
    assert shepard_pressure(corner, full, 0.1)[0] == pytest.approx(5.0)
    # Far away: no fluid at all.
    empty = _sums(_point(1.0, 1.0, 2.0), position, kind, pressure)
    assert math.isnan(shepard_pressure(empty, full, 0.5)[0])


@pytest.mark.parametrize("dimension", [2, 3])
def test_a_wall_sample_is_wet_once_half_its_open_support_is(dimension):
    """A sensor on a wall just below the waterline: the sample, half a spacing from the
    wall and a tenth of one below the water's top, has water filling a little over half of
    its support outside the wall, but less than half of a full lattice's (the wall holds
    the rest). It reads the water's
    pressure; a spacing higher, above the waterline, it reads NaN."""
    n = 12
    axes = [np.arange(-3, n) + 0.5] + [np.arange(-n, n) + 0.5] * (dimension - 1)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dimension)
    surface = 0.3                  # the top row's centre is 0.5 below: the waterline at 0
    wall = grid[:, 0] < 0.0        # the wall: x < 0; the water: x > 0 below the waterline
    keep = wall | (grid[:, -1] < surface)
    position = grid[keep] * SPACING
    kind = np.where(wall[keep], WALL, FLUID).astype(np.int8)
    pressure = np.where(kind == FLUID, 5.0, 0.0)
    full = lattice_sum(2.0, dimension)

    def sums_at(height):
        point = np.zeros(dimension)
        point[0], point[-1] = 0.5 * SPACING, height * SPACING
        rows = SampleRows([point], [np.eye(dimension)[0]], [SPACING], [1], [2.0 * SPACING])
        return kernel_sums(rows, position, kind, pressure, len(position), MPI.COMM_SELF)

    below = sums_at(-0.1)
    fluid, occupied = below[0, 0], below[0, 2]
    # Measured against the whole support it would read dry; against its open part, wet.
    assert fluid / full < 0.5 < fluid / (full - (occupied - fluid)) < 0.6
    assert shepard_pressure(below, full, 0.5)[0] == pytest.approx(5.0, rel=1e-12)
    assert math.isnan(shepard_pressure(sums_at(1.0), full, 0.5)[0])


def test_splitting_the_particles_between_ranks_changes_no_sum():
    rng = np.random.default_rng(3)
    position = _lattice(30, 20) + rng.normal(0, 0.1 * SPACING, (600, 2))
    kind = np.where(position[:, 1] < 0.02, WALL, FLUID)
    pressure = rng.random(600) * 1e3
    rows = SampleRows([[0.095, 0.0], [0.1, 0.05]], [[0.0, 1.0], [1.0, 0.0]],
                      [SPACING / 4, SPACING], [80, 1], [2 * SPACING, 2 * SPACING])
    whole = _sums(rows, position, kind, pressure)
    # A slab edge through the middle of both rows' supports.
    left = position[:, 0] < 0.1
    parts = [_sums(rows, position[m], kind[m], pressure[m]) for m in (left, ~left)]
    np.testing.assert_allclose(parts[0] + parts[1], whole, rtol=1e-13, atol=1e-15)
    for part in parts:
        assert part[80, 0] > 0 and part[:80, 2].any()


def _layers(d, layers, spacing=SPACING):
    """Fluid layers (bottom, top) 0.2 m wide (square in 3D) on a floor of 4 wall layers;
    positions (n, d), the last axis vertical."""
    def block(count, lower):
        index = np.meshgrid(*[np.arange(c) for c in count], indexing="ij")
        return np.column_stack([lower[a] + (index[a].ravel() + 0.5) * spacing
                                for a in range(d)])
    fluid = [block([20] * (d - 1) + [round((top - bottom) / spacing)],
                   [0.0] * (d - 1) + [bottom]) for bottom, top in layers]
    wall = block([24] * (d - 1) + [4], [-0.02] * (d - 1) + [-0.04])
    position = np.vstack(fluid + [wall])
    kind = np.r_[np.full(len(position) - len(wall), FLUID), np.full(len(wall), WALL)]
    return position, kind


def _level_row(d, x, heights):
    return SampleRows([[x] * (d - 1) + [heights[0]]], [[0.0] * (d - 1) + [1.0]],
                      [heights[1] - heights[0]], [len(heights)], [2 * SPACING])


def _readings(d, x, layers):
    heights = np.arange(0.0, 0.3, SPACING / 4)
    position, kind = _layers(d, layers)
    sums = _sums(_level_row(d, x, heights), position, kind, np.zeros(len(position)))
    return (water_depth(sums, mean_sum(2.0, d), heights),
            surface_height(sums, lattice_sum(2.0, d), heights))


# The line between two columns of particles (x = 0.1), a quarter spacing off one, on one.
LINES = (0.1, 0.1025, 0.105)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("x", LINES)
def test_level_of_a_still_layer_reads_its_depth(d, x):
    depth = 0.2
    gauged, crossing = _readings(d, x, [(0.0, depth)])
    # The depth integrates the fill, whose mean on a square lattice depends on where the
    # line lies among the particles: measured -1.5 % between two columns, +1.5 % on one.
    assert gauged == pytest.approx(depth, rel=0.02)
    assert crossing == pytest.approx(depth, abs=0.25 * SPACING)
    dry = _readings(d, x, [])
    assert dry[0] == 0.0 and dry[1] < 0.5 * SPACING


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("gap", [10, 3])
def test_a_jet_above_a_shallow_layer_reads_the_layers_depth(d, gap):
    """A sheet of water ``gap`` spacings above a 5 cm layer, 5 cm thick: the gauge reads the
    layer (its support of 2 l0 reaches across a gap of 3), the crossing reads the jet's top."""
    layer, jet = 0.05, (0.05 + gap * SPACING, 0.10 + gap * SPACING)
    gauged, crossing = _readings(d, 0.1, [(0.0, layer), jet])
    assert gauged == pytest.approx(layer, rel=0.02)
    assert crossing == pytest.approx(jet[1], abs=0.25 * SPACING)


def test_the_fill_column_ends_at_the_gap_below_water_passing_over():
    fill = np.array([1.0, 1.0, 0.6, 0.3, 0.1, 0.05, 0.08, 0.5, 1.0, 0.4, 0.0])
    assert column_end(fill) == 5
    # A ripple smaller than the rise of a separate body of water does not end the column.
    assert column_end(np.array([1.0, 0.45, 0.1, 0.15, 0.05, 0.0, 0.0])) == 6
    assert column_end(np.ones(4)) == 3


# -- the case section -----------------------------------------------------------------

BASE = (CASES / "hydrostatic.toml").read_text()


def _validate(text):
    return schema.validate(config.load_text(text))


BAD_PROBES = {
    "no name": ('kind = "pressure"\nposition = [0.1, 0.1]', "missing key 'probe[0].name'"),
    "bad kind": ('name = "a"\nkind = "speed"\nposition = [0.1, 0.1]', "probe[0].kind must be"),
    "no position": ('name = "a"\nkind = "pressure"', "missing key 'probe[0] 'a'.position'"),
    "line for pressure": ('name = "a"\nkind = "pressure"\nposition = [0.1, 0.1]\n'
                          'line = [[0.1, 0.0], [0.1, 0.3]]', "probe[0] 'a'.line is not a key"),
    "slanted line": ('name = "a"\nkind = "level"\nline = [[0.1, 0.0], [0.2, 0.3]]',
                     "probe[0] 'a'.line must be vertical"),
    "outside": ('name = "a"\nkind = "pressure"\nposition = [5.0, 0.1]', "outside the domain"),
    "force without target": ('name = "a"\nkind = "force"',
                             "probe[0] 'a' needs exactly one of 'segment', 'wall_box', 'wall' and "
                             "'body'"),
    "force on no body": ('name = "a"\nkind = "force"\nbody = "gate"', "'gate' is not a body"),
    "segment without normal": ('name = "a"\nkind = "force"\nsegment = [[0.2, 0.0], [0.2, 0.2]]',
                               "missing key 'probe[0] 'a'.normal'"),
    "normal along the segment": ('name = "a"\nkind = "force"\nsegment = [[0.2, 0.0], '
                                 '[0.2, 0.2]]\nnormal = [0.0, 1.0]', "is not perpendicular"),
    "reading for pressure": ('name = "a"\nkind = "pressure"\nposition = [0.1, 0.1]\n'
                             'reading = "crossing"', "probe[0] 'a'.reading is a key of a level"),
    "bad reading": ('name = "a"\nkind = "level"\nline = [[0.1, 0.0], [0.1, 0.3]]\n'
                    'reading = "top"', "probe[0].reading must be"),
    "bad name": ('name = "a/b"\nkind = "pressure"\nposition = [0.1, 0.1]', "probe[0].name"),
    "unknown key": ('name = "a"\nkind = "pressure"\nposition = [0.1, 0.1]\nradus = 2.0',
                    "did you mean 'radius'"),
}


@pytest.mark.parametrize("label", sorted(BAD_PROBES))
def test_bad_probe_is_one_line_naming_the_key(label):
    body, message = BAD_PROBES[label]
    with pytest.raises(CaseError) as caught:
        _validate(BASE + "\n[[probe]]\n" + body + "\n")
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_duplicate_probe_names_are_refused_on_the_command_line(tmp_path):
    probe = '\n[[probe]]\nname = "p"\nkind = "pressure"\nposition = [0.1, 0.1]\n'
    path = tmp_path / "case.toml"
    path.write_text(BASE + probe + probe)
    result = run_parmps([path, "-o", tmp_path / "out", "--check"], timeout=60)
    assert result.returncode == 2
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and lines[0].endswith("probe[1].name 'p' is used by an earlier probe")


def test_lobovsky_case_has_its_sensors_and_gauges():
    check = validation.load("dam_break_lobovsky")
    case = check.case()
    probes = {p["name"]: p for p in case["probe"]}
    wall = case["tank"][0]["upper"][0]
    assert wall == pytest.approx(1.61) and case["tank"][0]["upper"][1] >= 0.6
    for name, y in zip(("P1", "P2", "P3", "P4"), (0.003, 0.015, 0.030, 0.080)):
        assert probes[name]["kind"] == "pressure"
        assert probes[name]["position"] == pytest.approx([wall, y])
        assert probes[name]["normal"] == pytest.approx([-1.0, 0.0])
    for name, x in zip(("H1", "H2", "H3", "H4"), (0.300, 0.865, 1.114, 1.3625)):
        assert probes[name]["kind"] == "level" and probes[name]["line"][0][0] == x
    lower, upper = analysis.fluid_extent(case)
    assert list(lower) == [0.0, 0.0] and list(upper) == pytest.approx([0.6, 0.3])
    references = check.metric_arguments["references"]
    assert sorted(references) == ["P1", "P2", "P3", "P4"]
    for path in references.values():
        t, p = list(analysis.reference_table(path).values())[:2]
        assert len(t) > 1000 and t[-1] >= 7.0


# -- the still tank ---------------------------------------------------------------------

STILL_TANK_PROBES = """
[[probe]]
name = "quarter"
kind = "pressure"
position = [0.1, 0.05]

[[probe]]
name = "wall_quarter"
kind = "pressure"
position = [0.2, 0.05]
normal = [-1.0, 0.0]

[[probe]]
name = "level"
kind = "level"
line = [[0.1, 0.0], [0.1, 0.3]]
interval = 0.01

[[probe]]
name = "level_crossing"
kind = "level"
line = [[0.1, 0.0], [0.1, 0.3]]
reading = "crossing"
interval = 0.01

[[probe]]
name = "right_wall"
kind = "force"
segment = [[0.2, 0.0], [0.2, 0.3]]
normal = [-1.0, 0.0]
interval = 0.01
"""


@pytest.fixture(scope="module")
def still_tank(tmp_path_factory):
    directory = tmp_path_factory.mktemp("still")
    path = directory / "hydrostatic_probes.toml"
    path.write_text(BASE + STILL_TANK_PROBES)
    out = directory / "out"
    result = run_parmps([path, "-o", out, "--set", "output.frames=false"], timeout=600)
    assert result.returncode == 0, result.stderr
    return out


def test_still_tank_probes_read_hydrostatics(still_tank):
    result = still_tank / "result.h5"
    case = analysis.result_case(result)
    lower, upper = analysis.fluid_extent(case)
    depth = upper[1] - lower[1]
    rho, g = case["fluid"]["density"], analysis.gravity(case)
    for name in ("quarter", "wall_quarter"):
        t, p = analysis.read_probe(result, name)
        assert np.all(np.isfinite(p[t > 0.1])), name
        mean = analysis.window_mean(t, p, 0.5, 2.0)
        assert abs(mean / (rho * g * (depth - 0.05)) - 1.0) < 0.02, (name, mean)
    t, level = analysis.read_probe(result, "level")
    # The depth between two columns of particles (-1.5 % on a lattice, the test above).
    assert abs(analysis.window_mean(t, level, 0.5, 2.0) / depth - 1.0) < 0.02
    t, level = analysis.read_probe(result, "level_crossing")
    gauged = analysis.window_mean(t, level, 0.5, 2.0)
    assert abs(gauged - depth) < case["particles"]["spacing"]
    t, force = analysis.read_probe(result, "right_wall")
    assert force.shape == (len(t), 2)
    mean_fx = analysis.window_mean(t, force[:, 0], 0.5, 2.0)
    # Against the water the crossing reads (measured: level 0.1995 m for 0.2 m; the force
    # +0.03 % of rho g level^2 / 2, -0.51 % of rho g H^2 / 2; with P = 0 on the surface
    # particles, the condition before, 0.1983 m, -1.4 % and -3.1 %).
    assert abs(mean_fx / (0.5 * rho * g * gauged ** 2) - 1.0) < 0.02, (mean_fx, gauged)
    assert abs(analysis.window_mean(t, force[:, 1], 0.5, 2.0)) < 1e-9
    # The CSV holds the same rows as result.h5.
    with open(still_tank / "probes" / "quarter.csv") as handle:
        rows = [row for row in csv.reader(line for line in handle if not line.startswith("#"))]
    assert rows[0] == ["time", "value"]
    t, p = analysis.read_probe(result, "quarter")
    np.testing.assert_array_equal(np.array(rows[1:], float), np.column_stack([t, p]))
    with open_result(result) as run:
        attrs = run.probes["wall_quarter"].attrs
        assert attrs["kind"] == "pressure" and attrs["units"] == "Pa"
        assert list(attrs["position"]) == [0.2, 0.05]


# -- the same values on 1, 2 and 3 ranks --------------------------------------------------

DAM_BREAK_PROBES = "".join(f"""
[[probe]]
name = "p{k}"
kind = "pressure"
position = [{x}, 0.05]
""" for k, x in enumerate((0.03, 0.07, 0.1, 0.13, 0.17))) + """
[[probe]]
name = "floor"
kind = "force"
segment = [[0.0, 0.0], [1.0, 0.0]]
normal = [0.0, 1.0]

[[probe]]
name = "level"
kind = "level"
line = [[0.1, 0.0], [0.1, 0.5]]
interval = 0.005
"""
FIFTY_STEPS = ["--set", "particles.spacing=0.01", "--set", "time.fixed_dt=0.001",
               "--end-time", "0.05", "--set", "time.output_interval=0.05",
               "--set", "output.frames=false", "-pressure_ksp_rtol", "1e-12"]


def _probe_values(path):
    with open_result(path) as run:
        return {name: (probe.time, probe.value) for name, probe in run.probes.items()}


@pytest.fixture(scope="module")
def dam_break_case(tmp_path_factory):
    path = tmp_path_factory.mktemp("dam") / "dam_break_probes.toml"
    path.write_text((CASES / "dam_break.toml").read_text() + DAM_BREAK_PROBES)
    return path


@pytest.fixture(scope="module")
def one_rank_probes(dam_break_case, tmp_path_factory):
    out = tmp_path_factory.mktemp("dam1")
    result = run_parmps([dam_break_case, "-o", out] + FIFTY_STEPS, timeout=180)
    assert result.returncode == 0, result.stderr
    return _probe_values(out / "result.h5")


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_probes_read_the_same_on_any_rank_count(dam_break_case, one_rank_probes, tmp_path,
                                                ranks):
    result = run_parmps([dam_break_case, "-o", tmp_path] + FIFTY_STEPS, ranks=ranks,
                        timeout=300)
    assert result.returncode == 0, result.stderr
    # The slab edges at the start: the x quantiles of the particles (parallel/slabs.py);
    # some pressure probe's support (2 l0) must reach across one.
    raw = config.apply_override(config.load_text(dam_break_case.read_text()),
                                "particles.spacing=0.01")
    built, _, _ = scene.build(schema.validate(raw), None, None)
    x = np.sort(built.position[:, 0])
    edges = [x[int(len(x) * k / ranks)] for k in range(1, ranks)]
    probe_x = np.array([0.03, 0.07, 0.1, 0.13, 0.17])
    assert any(np.min(np.abs(probe_x - edge)) < 2 * 0.01 for edge in edges), edges
    values = _probe_values(tmp_path / "result.h5")
    assert sorted(values) == sorted(one_rank_probes)
    for name, (t1, v1) in one_rank_probes.items():
        t, v = values[name]
        np.testing.assert_array_equal(t, t1)
        assert np.all(np.isfinite(v1)) or name == "level", name
        np.testing.assert_allclose(v, v1, rtol=1e-8, atol=1e-6, err_msg=name)


# -- the force on a body ----------------------------------------------------------------

def test_force_on_a_body_is_the_couplings_sum_over_its_nodes(tmp_path):
    path = tmp_path / "archimedes_probe.toml"
    path.write_text((CASES.parent / "tests" / "cases" / "archimedes.toml").read_text() + """
[[probe]]
name = "block_force"
kind = "force"
body = "block"
""")
    out = tmp_path / "out"
    result = run_parmps([path, "-o", out, "--end-time", "0.05", "--set", "output.frames=false"],
                        timeout=300)
    assert result.returncode == 0, result.stderr
    t, force = analysis.read_probe(out / "result.h5", "block_force")
    with open_result(out) as run:
        body = run.bodies["block"]
        np.testing.assert_array_equal(t, body.time)
        np.testing.assert_array_equal(force, body.fluid_force)
    assert force.shape == (len(t), 2) and np.any(force[:, 1] > 0)
