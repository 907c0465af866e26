"""python -m parmps bench --time-to-solution on a tiny run: the option works and its line says
what it should. Speed targets live in the command's output, never in a timed test."""

import json

import numpy as np

import pytest

from conftest import error_lines, run_parmps


def test_time_to_solution_prints_one_line_per_run():
    # l0 = 12.5 mm and 10 ms: a few dozen steps of the peer dam break.
    result = run_parmps(["bench", "--time-to-solution", "--spacing", "0.0125", "--ranks", "1",
                         "--end-time", "0.01", "--set", "time.output_interval=0.005"],
                        timeout=240)
    assert result.returncode == 0, result.stderr
    (line,) = [json.loads(text) for text in result.stdout.splitlines() if text.startswith("{")]
    assert line["case"] == "cases/dam_break_2d_peer.toml"
    assert line["spacing"] == 0.0125 and line["ranks"] == 1 and line["end_time"] == 0.01
    assert line["set"] == ["time.output_interval=0.005"]
    assert line["steps"] >= 10 and line["wall_seconds"] > 0 and line["ksp_iterations"] > 0
    assert line["us_per_particle_step"] == pytest.approx(
        1e6 * line["wall_seconds"] / (line["particles"] * line["steps"]), rel=0.01)
    # The column (0.25 m wide) has barely started to move at 10 ms.
    assert line["front_m"] == pytest.approx(0.25, abs=0.02)
    # Martin & Moyce are compared only for runs that reach T = 2.8.
    assert "front_rms" not in line
    # Speed targets are for the full runs to t = 0.5 s only.
    assert "target_seconds" not in line and "within_target" not in line


def test_time_to_solution_reports_a_failed_run():
    result = run_parmps(["bench", "--time-to-solution", "--spacing", "0.0125", "--ranks", "1",
                         "--end-time", "0.01", "--set", "time.cfl=2"], timeout=120)
    assert result.returncode == 1
    (line,) = [json.loads(text) for text in result.stdout.splitlines() if text.startswith("{")]
    assert "time.cfl" in " ".join(line["error"])


def test_scaling_counts_the_messages_of_a_step(tmp_path):
    """--scaling on 1 and 2 ranks of a small dam break: no traffic on one rank; on two,
    every step sends halo and solve messages both ways, and the ghosts are a small share."""
    result = run_parmps(["bench", "--scaling", "--particles", "2500", "--ranks", "1", "2",
                         "--steps", "2", "--warmup", "2"], timeout=300)
    assert result.returncode == 0, result.stderr
    one, two = [json.loads(text) for text in result.stdout.splitlines() if text.startswith("{")]
    assert one["ranks"] == 1 and one["p2p_messages"] == 0 and one["ghosts_per_owned"] == 0
    assert two["ranks"] == 2 and two["neighbours"] == 1
    # At least a halo build and four refreshes a step, each a message per direction.
    assert two["p2p_messages"] >= 5 and two["p2p_bytes"] > 0
    # Both ranks send the same kinds of message: the mean is within the largest.
    assert 0 < two["p2p_bytes_mean"] <= two["p2p_bytes"]
    assert 0 < two["ghosts_per_owned"] < 0.5
    # The rows of the step: every fluid particle, some walls, no dummy.
    for line in (one, two):
        assert 0 < line["fluid"] < line["rows_per_step"] < line["particles"]
        assert line["us_per_row_step"] > line["us_per_particle_step"]
    assert two["ksp_iterations_per_step"] > 0
    # Every CG iteration multiplies by the matrix at least once: a message each.
    assert two["solve_messages"] >= two["ksp_iterations_per_step"]
    assert two["solve_reductions"] >= two["ksp_iterations_per_step"]
    assert one["solve_messages"] == 0


def test_monitoring_files_are_read_per_rank(tmp_path):
    from parmps.validation import scaling
    (tmp_path / "t.0.prof").write_text(
        "# POINT TO POINT\nE\t0\t1\t8000 bytes\t3 msgs sent\t0,0\n"
        "E\t0\t2\t100 bytes\t1 msgs sent\t0,0\nI\t0\t1\t21 bytes\t5 msgs sent\n"
        "# COLLECTIVES\nC\t0\t1\t21 bytes\t5 msgs sent\n")
    (tmp_path / "t.1.prof").write_text("# POINT TO POINT\nE\t1\t0\t40 bytes\t2 msgs sent\t0\n")
    counts = scaling.read_monitoring(str(tmp_path / "t"))
    assert counts == {0: (4, 8100, 5), 1: (2, 40, 0)}
    # Two runs 4 steps apart: the difference per step.
    step = scaling.traffic_per_step({0: (2, 100, 1), 1: (0, 0, 0)}, counts, 4)
    assert step["p2p_messages"] == 0.5 and step["p2p_bytes"] == 2000
    assert step["p2p_bytes_mean"] == round((2000 + 10) / 2)
    assert step["collective_messages"] == 1.0


def test_the_projection_is_perfect_on_one_rank_and_falls_with_the_halo():
    from parmps.validation import scaling
    terms = dict(cost=1e-5, ghost_cost=3e-6, halo_width=4.2, messages=20, message_bytes=150,
                 reductions=60)
    efficiency, ghosts, shares = scaling.projection(particles=1e6, ranks=1, **terms)
    assert efficiency == 1.0 and ghosts == 0.0
    # 1,000 particles a rank: a 10-spacing cube with a 4.2-spacing halo holds 5.2 ghosts
    # per owned particle, (18.4^3 - 10^3)/10^3.
    efficiency, ghosts, shares = scaling.projection(particles=1e7, ranks=1e4, **terms)
    assert ghosts == pytest.approx((18.4 ** 3 - 1000) / 1000)
    assert efficiency < 0.5 and max(shares, key=shares.get) == "ghosts"
    assert sum(shares.values()) == pytest.approx(1.0)


def test_the_model_terms_come_from_the_record():
    from parmps.validation import scaling
    lines = [
        {"ranks": 1, "particles": 1000, "us_per_particle_step": 10.0},
        {"ranks": 2, "particles": 1000, "neighbours": 1, "ghosts_per_owned": 0.1,
         "p2p_messages": 20, "solve_messages": 80, "p2p_bytes": 3000, "solve_bytes": 7000,
         "collective_messages": 50},
        {"ranks": 4, "particles": 1000, "neighbours": 2, "ghosts_per_owned": 0.2,
         "p2p_messages": 40, "solve_messages": 160, "p2p_bytes": 1500, "solve_bytes": 3500,
         "collective_messages": 100},
    ]
    terms = scaling.terms_from_record(lines)
    # 100 messages per neighbour; 10,000 bytes for 50 ghosts, 5,000 for 50; an allreduce
    # is log2 P messages a rank.
    assert terms == {"cost": pytest.approx(1e-5), "messages": 100.0,
                     "message_bytes": 150.0, "reductions": 50.0}


def test_the_solid_cost_scenes_differ_only_by_the_body(monkeypatch):
    """--solid-cost's pair: the body's nodes sit exactly where the water variant's seventh
    block is, on the fluid's lattice, and nowhere else do the two scenes differ (the
    timed comparison is of the body's cost alone)."""
    from parmps.geometry import scene
    from parmps.core.particles import FLUID
    from parmps.solids.mass_spring.model import MassSpringModel
    from parmps.validation import bench
    monkeypatch.setattr(bench, "FLUID_CELLS", 10)
    monkeypatch.setattr(bench, "BODY_NODES", 4)
    cases = {name: bench._case(None, steps=1, scene_name=name) for name in bench.BUILT_SCENES}
    built = {name: scene.build(case)[0] for name, case in cases.items()}

    def points(position):
        return {tuple(p) for p in np.round(np.asarray(position) / bench.BODY_SPACING, 6)}
    nodes = MassSpringModel.from_case(cases["body_3d"]).bodies[0].position
    assert len(nodes) == 4 ** 3
    water, with_body = built["body_3d_fluid"], built["body_3d"]
    assert len(water) == len(with_body) + len(nodes)
    assert points(with_body.position) | points(nodes) == points(water.position)
    assert not points(with_body.position) & points(nodes)
    # The water around the body comes first in both, in the same order.
    around = np.count_nonzero(with_body.kind == FLUID)
    np.testing.assert_array_equal(water.position[:around], with_body.position[:around])


def test_the_paired_speed_up_is_the_median_of_the_rounds_ratios():
    from parmps.validation.bench import paired_speed_up

    def run(ranks, seconds):
        return {"particles": 40022, "ranks": ranks, "seconds": seconds}
    # A machine 30 % slower in the second round, and a failed fourth round left out.
    rounds = [[run(1, 10.0), run(2, 5.5)], [run(1, 13.0), run(2, 7.0)],
              [run(1, 10.0), run(2, 6.0)], [run(1, 9.0), {"ranks": 2, "error": ["x"]}]]
    summary = paired_speed_up(rounds)
    assert summary["particles"] == 40022 and summary["base_ranks"] == 1
    assert summary["rounds"] == 4
    ratios = sorted([10.0 / 5.5, 13.0 / 7.0, 10.0 / 6.0])
    assert summary["speed_up"] == {"2": round(ratios[1], 3)}
    assert summary["speed_up_range"] == {"2": [round(ratios[0], 3), round(ratios[2], 3)]}


def test_repeat_runs_the_rank_counts_in_turn_then_prints_the_speed_up(monkeypatch, capsys):
    """The command's wiring, with the timed runs stood in for (a machine 10 % slower in
    the second round): A B A B, one line each, then the summary line."""
    from parmps.validation import bench
    calls = []

    def timed_run(args, scene, spacing, ranks):
        calls.append(ranks)
        slow = 1.1 if len(calls) > 2 else 1.0
        return {"particles": 2500, "ranks": ranks, "seconds": slow * 4.0 / ranks ** 0.8}
    monkeypatch.setattr(bench, "_timed_run", timed_run)
    assert bench.main(["--particles", "2500", "--ranks", "1", "2", "--repeat", "2"]) == 0
    lines = [json.loads(text) for text in capsys.readouterr().out.splitlines()]
    assert calls == [1, 2, 1, 2] and [line.get("ranks") for line in lines[:4]] == calls
    summary = lines[4]
    assert summary["rounds"] == 2 and summary["scene"] == "dam_break"
    assert summary["speed_up"]["2"] == pytest.approx(2 ** 0.8, abs=1e-3)


def test_a_repeat_count_below_one_is_refused_in_one_line():
    result = run_parmps(["bench", "--repeat", "0"], timeout=60)
    assert result.returncode == 2
    assert error_lines(result.stderr) == [
        "parmps: error: bench: argument --repeat: expected a whole number of at least 1, "
        "not '0'"]


def test_the_periodic_cost_pair_holds_the_same_particles():
    """--periodic-cost compares like with like: the periodic duct and the open one (its inlet
    buffer's particles included) hold the same count of fluid and wall particles."""
    from parmps.boundaries.open import OpenBoundaries
    from parmps.geometry import scene
    from parmps.validation import bench
    periodic = scene.build(bench._case(bench.BODY_SPACING, 10, (), "duct_periodic"))[0]
    case = bench._case(bench.BODY_SPACING, 10, (), "duct_open")
    from mpi4py import MPI
    opened = scene.build(case, open_boundaries=OpenBoundaries(case, MPI.COMM_SELF))[0]
    assert len(opened) == len(periodic)
