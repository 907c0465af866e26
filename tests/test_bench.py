"""python -m parmps bench --time-to-solution on a tiny run: the option works and its line says
what it should. Speed targets live in the command's output, never in a timed test."""

import json

import pytest

from conftest import run_parmps


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
