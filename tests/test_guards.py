"""Run-time guards (issue 6): each failure stops with exit status 1, one message naming the
step and the cause, and a result file readable up to the last good frame."""

import numpy as np
import pytest

import parmps
from conftest import CASES, error_lines, run_parmps
from parmps import config, schema
from parmps.run import guards
from parmps.solids.mass_spring.model import VOLUME_ERROR_LIMIT
from parmps.core.particles import FLUID, WALL, Particles

BIG_DOMAIN = ["--set", "domain.lower=[-1e3, -1e3]", "--set", "domain.upper=[1e3, 1e3]"]


def failed_step(result, *phrases):
    """The step named by the one error line, after checking it names every phrase."""
    assert result.returncode == 1, result.stderr
    (line,) = error_lines(result.stderr)
    for phrase in phrases:
        assert phrase in line, line
    return int(line.split("step ")[1].split(":")[0])


def assert_readable_up_to(path, step, fields=("position", "velocity")):
    """The file is marked incomplete, every frame precedes the failing step and is finite."""
    with parmps.open_result(path) as run:
        assert not run.complete
        frames = run.frames
        assert len(frames) and all(frames.steps < step)
        last = frames[-1]
        for field in fields:
            if field in last.names:
                assert np.all(np.isfinite(last[field]))
        for name in ("step", "time"):
            assert np.all(np.isfinite(run.diagnostics[name]))
        assert run.diagnostics["step"][-1] < step
        return list(frames.steps)


def test_fixed_dt_too_large_stops_at_the_step_with_the_courant_limit(tmp_path):
    # The density source (the default, named here because the test depends on it) lets
    # the first step through calmly, so the guard is seen stopping a run after good
    # steps; the mixed source already breaks the limit in step 1, with the same message.
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.3",
                         "--set", 'mps.source="density"',
                         "--set", "time.fixed_dt=0.02", "--set", "time.output_interval=0.02"],
                        timeout=120)
    step = failed_step(result, "breaks the Courant limit", "time.fixed_dt = 0.02")
    assert step >= 2
    frames = assert_readable_up_to(tmp_path / "result.h5", step)
    assert len(frames) == step  # frame 0 and one per good step


def test_blown_up_solid_stops_with_the_body_and_cause(tmp_path):
    # A press three thousand times the case's: the area constraint loses the polygon
    # within a few steps; without the guard the run went on to its end at 8 km/s. With
    # the seed's single solve of the multiplier: the Newton steps on it hold the area
    # further, until the springs are the first to give (a stretch of 20).
    result = run_parmps([CASES / "mass_spring_7x7.toml", "-o", tmp_path, "--end-time", "0.1",
                         "--set", "solid.constraint_prediction=linear",
                         "--set", "body.0.load.0.force=[0.0, -3000.0]",
                         "--set", "body.0.load.0.ramp=0.2",
                         "--set", "time.output_interval=0.002"] + BIG_DOMAIN, timeout=120)
    step = failed_step(result, "body 'block' blew up", "area constraint lost control")
    assert step > 2
    frames = assert_readable_up_to(tmp_path / "result.h5", step)
    with parmps.open_result(tmp_path) as run:
        last = run.frames.at_step(frames[-1]).bodies["block"]["position"]
        assert np.all(np.isfinite(last))
        assert np.all(np.abs(run.bodies["block"].volume_error) <= VOLUME_ERROR_LIMIT)


def test_fluid_through_a_wall_stops_with_the_particle_and_wall(tmp_path):
    # A PPE source a billion times too weak: nothing holds the water up, and it
    # sinks into the tank floor slowly enough (Courant < 1) to stay in the domain.
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.3",
                         "--set", 'mps.source="density"', "--set", "mps.density.relaxation=1e-9",
                         "--set", "time.output_interval=0.02"],
                        timeout=120)
    step = failed_step(result, "went through a wall", "inside tank[0] bottom")
    frames = assert_readable_up_to(tmp_path / "result.h5", step)
    assert len(frames) >= 3


def _case(**sections):
    raw = {"domain": {"lower": [-1.0, -1.0], "upper": [2.0, 2.0]},
           "particles": {"spacing": 0.1}, "time": {"end": 1.0},
           "fluid_block": [{"lower": [0.0, 0.0], "upper": [0.5, 0.5]}],
           "tank": [{"lower": [0.0, 0.0], "upper": [1.0, 1.0]}]}
    raw.update(sections)
    return schema.validate(raw)


def test_wall_rectangles_cover_tank_walls_and_boxes_only():
    case = _case(wall_box=[{"lower": [0.6, 0.0], "upper": [0.8, 0.2]}])
    rectangles = guards.wall_rectangles(case)
    names = [name for _, _, name in rectangles]
    assert names == ["tank[0] left wall", "tank[0] right wall", "tank[0] bottom", "wall_box[0]"]
    margin = guards.WALL_MARGIN * 0.1
    points = np.array([[0.05, 0.05],     # fluid touching the floor: fine
                       [-0.01, 0.5],     # a little behind the left wall's surface: tolerated
                       [-0.1, 0.5],      # on the first wall layer: through
                       [0.5, -0.2],      # in the floor's dummies: through
                       [0.7, 0.1],       # inside the box
                       [0.5, 1.5],       # above the open tank: fine
                       [-0.1, 1.5]])     # above the left wall's top: fine
    which = guards.inside_rectangles(points, rectangles, margin)
    assert which.tolist() == [-1, -1, 0, 2, 3, -1, -1]


def test_wall_check_sees_fluid_only_and_agrees_on_the_first_id():
    from mpi4py import MPI
    case = _case()
    rectangles = guards.wall_rectangles(case)
    particles = Particles({
        "id": np.array([7, 3, 5], np.int64),
        "kind": np.array([WALL, FLUID, FLUID], np.int8),
        "position": np.array([[-0.15, 0.5], [0.5, 0.5], [0.5, 0.5]]),
        "velocity": np.zeros((3, 2))})
    guards.check_wall_penetration(particles, rectangles, 0.1, MPI.COMM_SELF, 4)
    particles.position[1] = [1.15, 0.5]
    particles.position[2] = [0.5, -0.15]
    with pytest.raises(guards.RunFailure, match=r"^step 4: fluid particle 3 went through a wall: "
                                                r"it is inside tank\[0\] right wall .*\(2 fluid"):
        guards.check_wall_penetration(particles, rectangles, 0.1, MPI.COMM_SELF, 4)


@pytest.mark.parametrize("dimension", [2, 3])
def test_the_compiled_box_tests_are_numpys(dimension):
    """The driver's box tests (compiled, one pass) against numpy's masks: points on a
    box's faces, inside two overlapping boxes, outside every box, NaN, and left out by the
    mask."""
    from parmps.core.geometry import first_box_holding, outside_box
    rng = np.random.default_rng(dimension)
    points = rng.uniform(-0.2, 1.2, (5000, dimension))
    points[:50] = np.round(points[:50] * 4) / 4          # on the faces at multiples of 0.25
    points[50] = 0.5
    points[50, 0] = np.nan
    lower = np.array([[0.0] * dimension, [0.25] * dimension, [0.5] * dimension])
    upper = np.array([[0.5] * dimension, [0.75] * dimension, [1.0] * dimension])
    mask = rng.uniform(size=len(points)) < 0.8
    expected = np.full(len(points), -1)
    for k in reversed(range(len(lower))):
        expected[np.all((points > lower[k]) & (points < upper[k]), axis=1) & mask] = k
    assert np.array_equal(first_box_holding(points, lower, upper, mask), expected)
    assert set(expected) == {-1, 0, 1, 2}
    box = (np.full(dimension, 0.25), np.full(dimension, 1.0))
    numpy_outside = np.any((points < box[0]) | (points > box[1]), axis=1)
    assert np.array_equal(outside_box(points, *box), numpy_outside)
    assert not outside_box(points[50:51], *box)[0]          # NaN: no comparison holds
    assert np.array_equal(outside_box(points[0], *box), numpy_outside[:1])
