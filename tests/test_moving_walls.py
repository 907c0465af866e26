"""Walls with prescribed motion (parmps.boundaries.walls): exact positions, dummies along, a piston
that pushes water without leaking, the same result on 1, 2 and 3 ranks.

Tolerances:
- wall and dummy positions: 1e-12 m from x0 + v (clip(t, start, end) - start), whatever
  the step sizes (the increments telescope; only round-off remains);
- wall particles on 2 and 3 ranks: bit-identical to one rank (every rank adds the same
  shift); fluid: 1e-9 relative, as tests/test_parallel.py, with -pressure_ksp_rtol 1e-12;
- piston physics: the mean water height within 5 % of the area-conserving level (the
  0.2 m/s push leaves a small wave: 2.4 % measured), the water at the piston's face
  moving with it within 20 % (2 % measured), no fluid particle behind the face.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import error_lines, run_parmps
from parmps import config, schema
from parmps.geometry import scene
from parmps.run import guards
from parmps.io.frames import read_frames
from parmps.tools import analysis
from parmps.core.particles import DUMMY, FLUID, WALL
from parmps.boundaries.walls import MovingWalls, travel

PISTON = Path(__file__).parent / "cases" / "piston.toml"
PISTON_SPEED = 0.2
PISTON_FACE = 0.06  # x of the piston's right face at t = 0
POOL = (0.24, 0.1)  # initial width and depth of the water

BOX_CASE = """
title = "a box moving over a pool"
[domain]
lower = [-0.06, -0.06]
upper = [0.46, 0.5]
[particles]
spacing = 0.01
[time]
end = 0.05
output_interval = 0.01
[[fluid_block]]
lower = [0.0, 0.0]
upper = [0.4, 0.05]
[[tank]]
lower = [0.0, 0.0]
upper = [0.4, 0.3]
[[wall_box]]
lower = [0.05, 0.15]
upper = [0.11, 0.21]
wall_layers = 1
velocity = [1.0, 0.5]
move_start = 0.0104
move_end = 0.0333
"""


def _case(**sections):
    raw = {"domain": {"lower": [-1.0, -1.0], "upper": [2.0, 2.0]},
           "particles": {"spacing": 0.1}, "time": {"end": 1.0},
           "fluid_block": [{"lower": [0.0, 0.0], "upper": [0.5, 0.5]}]}
    raw.update(sections)
    return schema.validate(raw)


def test_travel_is_piecewise_linear():
    spec = {"velocity": [2.0, -1.0], "move_start": 0.5, "move_end": 1.5}
    for time, expected in [(0.0, [0, 0]), (0.5, [0, 0]), (1.0, [1.0, -0.5]),
                           (1.5, [2.0, -1.0]), (9.0, [2.0, -1.0])]:
        np.testing.assert_allclose(travel(spec, time), expected, rtol=0, atol=1e-15)
    endless = dict(spec, move_end=float("inf"))
    np.testing.assert_allclose(travel(endless, 10.5), [20.0, -10.0], rtol=0, atol=1e-15)


def test_advance_moves_walls_and_dummies_of_the_moving_entry_only():
    case = _case(tank=[{"lower": [0.0, 0.0], "upper": [1.0, 1.2]}],
                 wall_box=[{"lower": [0.6, 0.6], "upper": [1.0, 1.0], "wall_layers": 1,
                            "velocity": [0.3, 0.1], "move_start": 0.013, "move_end": 0.171}])
    particles, origin, sources = scene.build(case)
    walls = MovingWalls.from_scene(case, particles, origin, sources)
    box = origin == sources.index("wall_box[0]")
    assert set(particles.kind[box]) == {WALL, DUMMY}
    start = particles.position.copy()
    # Uneven steps that straddle move_start and move_end.
    steps = np.random.default_rng(3).uniform(1e-3, 7e-3, 60)
    time = 0.0
    for dt in steps:
        walls.advance(particles, time, dt)
        shift = travel(case["wall_box"][0], time + dt) - travel(case["wall_box"][0], time)
        np.testing.assert_array_equal(particles.velocity[box], np.tile(shift / dt, (box.sum(), 1)))
        time += dt
    assert time > 0.171
    moved = particles.position - start
    np.testing.assert_allclose(moved[box], np.tile([0.3 * 0.158, 0.1 * 0.158], (box.sum(), 1)),
                               rtol=0, atol=1e-12)
    assert np.all(moved[~box] == 0.0) and np.all(particles.velocity[~box] == 0.0)
    assert walls.name_of(int(particles.id[box][0])) == "wall_box[0]"
    assert walls.name_of(int(particles.id[~box][0])) is None


def test_speed_counts_walls_moving_within_the_horizon():
    case = _case(wall_box=[{"lower": [0.6, 0.6], "upper": [1.0, 1.0],
                            "velocity": [3.0, 4.0], "move_start": 0.5, "move_end": 1.0}])
    walls = MovingWalls.from_scene(case, *scene.build(case))
    assert walls.speed(0.0, 0.4) == 0.0      # not started yet
    assert walls.speed(0.0, 0.6) == 5.0      # starts within the step
    assert walls.speed(0.9, 1.1) == 5.0
    assert walls.speed(1.0, 1.1) == 0.0      # stopped
    assert MovingWalls.from_scene(_case(), *scene.build(_case())) is None


def test_wall_rectangles_follow_the_wall():
    case = _case(wall_box=[{"lower": [0.6, 0.0], "upper": [0.8, 0.2],
                            "velocity": [0.0, 1.0], "move_end": 0.5}])
    lower, upper, name = guards.wall_rectangles(case, 0.75)[0]
    assert name == "wall_box[0]"
    np.testing.assert_allclose(lower, [0.6, 0.5], atol=1e-15)
    np.testing.assert_allclose(upper, [0.8, 0.7], atol=1e-15)


def test_box_ends_where_it_should_with_its_dummies(tmp_path):
    path = tmp_path / "box.toml"
    path.write_text(BOX_CASE)
    result = run_parmps([path, "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 0, result.stderr
    frames = read_frames(tmp_path / "out" / "result.h5")
    first = frames[0]
    x, y = first["position"].T
    box = (first["kind"] != FLUID) & (x > 0.05) & (x < 0.11) & (y > 0.15) & (y < 0.21)
    assert set(first["kind"][box]) == {WALL, DUMMY} and box.sum() == 36
    spec = {"velocity": [1.0, 0.5], "move_start": 0.0104, "move_end": 0.0333}
    for frame in frames:
        moved = frame["position"][box] - first["position"][box]
        expected = travel(spec, frame["time"])
        assert np.abs(moved - expected).max() < 1e-12, frame["time"]
        # The tank stays put.
        np.testing.assert_array_equal(frame["position"][~box & (frame["kind"] != FLUID)],
                                      first["position"][~box & (first["kind"] != FLUID)])
    velocity = {round(f["time"], 6): np.unique(f["velocity"][box], axis=0) for f in frames}
    np.testing.assert_array_equal(velocity[0.0], [[0.0, 0.0]])      # before move_start
    np.testing.assert_allclose(velocity[0.02], [[1.0, 0.5]], rtol=1e-12)
    np.testing.assert_array_equal(velocity[0.05], [[0.0, 0.0]])     # stopped
    assert abs(frames[-1]["position"][box][0, 0] - first["position"][box][0, 0] - 0.0229) < 1e-12


def test_check_takes_the_wall_speed_into_the_first_step(tmp_path):
    path = tmp_path / "box.toml"
    path.write_text(BOX_CASE.replace("velocity = [1.0, 0.5]", "velocity = [0.0, 8.0]")
                    .replace("move_start = 0.0104", "move_start = 0.0"))
    result = run_parmps([path, "--check"], timeout=60)
    assert result.returncode == 0, result.stderr
    # dt = cfl l0 / |v| = 0.5 x 0.01 / 8 (the default cfl).
    assert json.loads(result.stdout)["initial_dt"] == pytest.approx(6.25e-4, rel=1e-12)


def _piston_frames(path):
    return read_frames(path / "result.h5")


@pytest.fixture(scope="module")
def one_rank_piston(tmp_path_factory):
    out = tmp_path_factory.mktemp("piston1")
    result = run_parmps([PISTON, "-o", out, "-pressure_ksp_rtol", "1e-12"], timeout=60)
    assert result.returncode == 0, result.stderr
    return out


def test_piston_pushes_the_water_without_leaks(one_rank_piston):
    frames = _piston_frames(one_rank_piston)
    assert frames[-1]["time"] == pytest.approx(0.25)
    for frame in frames:
        face = PISTON_FACE + PISTON_SPEED * frame["time"]
        fluid = frame["kind"] == FLUID
        # Nothing behind the face (the guard, which stopped no step, allows half a spacing).
        assert frame["position"][fluid, 0].min() > face, frame["time"]
    last = frames[-1]
    fluid = last["kind"] == FLUID
    face = PISTON_FACE + PISTON_SPEED * last["time"]
    width = POOL[0] - PISTON_SPEED * last["time"]
    level = POOL[0] * POOL[1] / width
    mean_height = last["position"][fluid, 1].mean()
    assert abs(mean_height - 0.5 * level) < 0.05 * 0.5 * level, (mean_height, 0.5 * level)
    at_face = fluid & (last["position"][:, 0] < face + 0.02)
    assert abs(last["velocity"][at_face, 0].mean() - PISTON_SPEED) < 0.2 * PISTON_SPEED


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_piston_on_several_ranks_matches_one_rank(one_rank_piston, tmp_path, ranks):
    # Frequent rebalancing and a piston that crosses slab edges (3 ranks) exercise
    # migration, halo and rebalance with moving wall particles.
    result = run_parmps([PISTON, "-o", tmp_path, "-pressure_ksp_rtol", "1e-12",
                         "--set", "parallel.imbalance_tolerance=1.05",
                         "--set", "parallel.rebalance_interval=10"], ranks=ranks, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "rebalanced slabs" in result.stderr
    for one, many in zip(_piston_frames(one_rank_piston), _piston_frames(tmp_path),
                         strict=True):
        np.testing.assert_array_equal(many["id"], one["id"])
        walls = one["kind"] != FLUID
        np.testing.assert_array_equal(many["position"][walls], one["position"][walls])
        np.testing.assert_array_equal(many["velocity"][walls], one["velocity"][walls])
        error = np.abs(many["position"] - one["position"]).max() / np.abs(one["position"]).max()
        assert error < 1e-9, (one["time"], error)


def test_wall_leaving_the_domain_is_refused(tmp_path):
    path = tmp_path / "box.toml"
    path.write_text(BOX_CASE.replace("move_end = 0.0333", "move_end = 10.0")
                    .replace("end = 0.05", "end = 1.0"))
    result = run_parmps([path, "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 2, result.stderr
    (line,) = error_lines(result.stderr)
    # The box's right column (x = 0.105) reaches the domain's x = 0.46 after 0.355 s of
    # motion, from move_start = 0.0104 s.
    assert "wall_box[0] moves out of the domain" in line and "t = 0.3654 s" in line, line
    assert not (tmp_path / "out" / "result.h5").exists()
