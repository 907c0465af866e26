"""Checkpoints, --restart and interruption (README "Long runs", docs/design.md §3, §5).

A run continued from its checkpoint on another rank count must follow the
uninterrupted run particle by particle (to round-off: the pressure is solved to
rtol 1e-12), with every frame once and the series rows once.
"""

import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from conftest import CASES, error_lines, mpi_environment, run_parmps
from parmps import open_result
from parmps.io.frames import read_frame, read_frames
from parmps.parallel.mpi import launch_environment, mpirun_command

TIGHT = ["-pressure_ksp_rtol", "1e-12"]

# (case, extra arguments, first end time, end time, ranks before, ranks after).
# A run ending at the first end time clips its last step to land on it, which the
# uninterrupted run does not: the times differ by round-off from there on. So the
# end times stay where dt is dt_max (no step length differs but by round-off) and
# off the inlet's events (its columns enter and turn fluid at 0.05 + k 0.1 s, a tie
# that round-off in the time decides).
SCENES = {
    "box_in_flow": ("box_in_flow.toml", [], 0.16, 0.3, 2, 3),
    "membrane_tube": ("membrane_tube.toml", ["--set", "time.output_interval=0.05"],
                      0.1, 0.2, 1, 2),
    "dam_break": ("dam_break.toml", ["--set", "particles.spacing=0.01",
                                     "--set", "time.output_interval=0.025"], 0.05, 0.1, 2, 1),
    # SPHERIC's 3D dam break at 0.55/5 m (about 5k particles), 2 ranks, then 3.
    "dam_break_3d": ("dam_break_3d.toml", ["--set", "particles.spacing=0.11",
                                           "--set", "time.output_interval=0.02"],
                     0.03, 0.06, 2, 3),
}


def _run(args, ranks, timeout=600):
    result = run_parmps(list(args) + TIGHT, ranks=ranks, timeout=timeout)
    assert result.returncode == 0, result.stderr[-3000:]
    return result


def _domain_size(case_file):
    import tomllib
    with open(CASES / case_file, "rb") as handle:
        domain = tomllib.load(handle)["domain"]
    return float(np.max(np.subtract(domain["upper"], domain["lower"])))


def _series_steps(path):
    with open_result(path) as run:
        bodies = {name: body.time for name, body in run.bodies.items()}
        return run.diagnostics["step"], bodies, run.complete


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_restart_on_another_rank_count_follows_the_uninterrupted_run(scene, tmp_path):
    case_file, extra, first_end, end, before, after = SCENES[scene]
    case = str(CASES / case_file)
    whole, split = tmp_path / "whole", tmp_path / "split"
    _run([case, "-o", whole, "--end-time", end] + extra, before)
    _run([case, "-o", split, "--end-time", first_end] + extra, before)
    with h5py.File(split / "checkpoint.h5", "r") as handle:
        first_step = int(handle["state/run/step"][()])
    _run(["--restart", split, "--end-time", end], after)

    expected, got = read_frames(whole / "result.h5"), read_frames(split / "result.h5")
    steps = [int(frame["step"]) for frame in got]
    # The first run's end has a frame of its own, off the output interval or not.
    assert steps == sorted({int(frame["step"]) for frame in expected} | {first_step})
    last, reference = got[-1], expected[-1]
    assert last["time"] == pytest.approx(end)
    np.testing.assert_array_equal(last["id"], reference["id"])
    difference = np.abs(last["position"] - reference["position"]).max()
    assert difference < 1e-9 * _domain_size(case_file), difference

    steps_whole, bodies_whole, _ = _series_steps(whole / "result.h5")
    steps_split, bodies_split, complete = _series_steps(split / "result.h5")
    assert complete
    np.testing.assert_array_equal(steps_split, steps_whole)
    np.testing.assert_array_equal(steps_split, np.arange(1, len(steps_split) + 1))
    for name, times in bodies_whole.items():
        np.testing.assert_allclose(bodies_split[name], times, rtol=1e-12)
    text = (split / "result.xdmf").read_text()
    assert text.count('<Grid Name="step ') == len(steps)


@pytest.mark.mpi
def test_a_checkpoint_written_on_slabs_continues_on_blocks(tmp_path):
    """parallel.decomposition = "auto" runs the dam break's tank as slabs on 2 ranks and as
    a 2 x 2 grid of blocks on 4 (their modelled ghosts: 23 % and 14 %): the checkpoint of
    the slabs continues on the blocks and follows the uninterrupted run to 1e-9 of the
    domain's size, particle by particle."""
    case = str(CASES / "dam_break.toml")
    extra = ["--set", "particles.spacing=0.01", "--set", "time.fixed_dt=0.001",
             "--set", "time.output_interval=0.01"]
    whole, split = tmp_path / "whole", tmp_path / "split"
    _run([case, "-o", whole, "--end-time", "0.04"] + extra, 2)
    first = _run([case, "-o", split, "--end-time", "0.02"] + extra, 2)
    assert "decomposition: slabs" in first.stderr
    second = _run(["--restart", split, "--end-time", "0.04"], 4)
    assert "decomposition: blocks, 2 x 2 blocks" in second.stderr
    last, reference = read_frame(split / "result.h5"), read_frame(whole / "result.h5")
    assert last["step"] == reference["step"] == 40
    np.testing.assert_array_equal(last["id"], reference["id"])
    difference = np.abs(last["position"] - reference["position"]).max()
    assert difference < 1e-9 * _domain_size("dam_break.toml"), difference


def test_solid_only_restart_and_refusals(tmp_path):
    """A solid-only run continues exactly; a different case file, -o elsewhere and a
    directory without a checkpoint are refused in one line (exit 2)."""
    case = CASES / "mass_spring_7x7.toml"
    whole, split = tmp_path / "whole", tmp_path / "split"
    for args in ([case, "-o", whole, "--end-time", "0.3"],
                 [case, "-o", split, "--end-time", "0.15"],
                 # the same case file is accepted with --restart
                 ["--restart", split, case, "--end-time", "0.3"]):
        result = run_parmps(args, timeout=120)
        assert result.returncode == 0, result.stderr[-2000:]
    a, b = read_frame(whole / "result.h5"), read_frame(split / "result.h5")
    assert a["step"] == b["step"] == 300
    assert np.abs(a["position"] - b["position"]).max() < 1e-12
    assert len(read_frames(split / "result.h5")) == len(read_frames(whole / "result.h5"))

    # A run that crashed after its checkpoint left frames and rows behind it: the
    # continued run drops them and writes them again, once.
    shutil.copy(split / "checkpoint.h5", tmp_path / "early.h5")
    result = run_parmps(["--restart", split, "--end-time", "0.45"], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    shutil.copy(tmp_path / "early.h5", split / "checkpoint.h5")
    result = run_parmps(["--restart", split, "--end-time", "0.3"], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    frames = read_frames(split / "result.h5")
    assert [f["step"] for f in frames] == [f["step"] for f in read_frames(whole / "result.h5")]
    assert np.abs(frames[-1]["position"] - a["position"]).max() < 1e-12
    steps, _, complete = _series_steps(split / "result.h5")
    assert complete
    np.testing.assert_array_equal(steps, np.arange(1, 301))

    for args, words in (
            (["--restart", split, CASES / "box_in_flow.toml"], "differs from the case"),
            (["--restart", split, "-o", tmp_path / "other"], "cannot go with it"),
            (["--restart", tmp_path / "empty"], "no checkpoint.h5")):
        result = run_parmps(args, timeout=60)
        assert result.returncode == 2, result.stderr
        lines = error_lines(result.stderr)
        assert len(lines) == 1 and words in lines[0], result.stderr


def _start(args, log_path):
    command = mpirun_command(2, [sys.executable, "-m", "parmps"] + [str(a) for a in args])
    log = open(log_path, "w")
    process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                               start_new_session=True,
                               env=launch_environment(mpi_environment()))
    return process, log


def test_sigterm_to_mpirun_checkpoints_and_restart_finishes(tmp_path):
    output, log_path = tmp_path / "run", tmp_path / "run.log"
    # Far beyond the case's 2 s, so that the signal finds the run in its loop: the first
    # progress line comes after some 5 s of wall time, and on a fast machine the case's own
    # 2 s took 6.7 s in all, so the run had ended when the signal came.
    end_time = 30.0
    process, log = _start([CASES / "box_in_flow.toml", "-o", output, "--end-time", end_time],
                          log_path)
    try:
        deadline = time.monotonic() + 300
        # Into the time loop, past the first step (and any compilation): a progress line.
        while "particle-steps/s" not in log_path.read_text():
            assert process.poll() is None, log_path.read_text()
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.5)
        time.sleep(1.0)
        process.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        process.wait(timeout=30)
        seconds = time.monotonic() - sent
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        log.close()
    text = log_path.read_text()
    assert process.returncode != 0, text
    assert seconds < 30
    assert "--restart" in text and "interrupted" in text, text
    with open_result(output) as run:
        assert not run.complete
    frames = read_frames(output / "result.h5")
    assert frames and frames[0]["step"] == 0
    with h5py.File(output / "checkpoint.h5", "r") as handle:
        stopped = float(handle["state/run/time"][()])
    assert 0.0 < stopped < end_time

    end = stopped + 0.02
    result = run_parmps(["--restart", output, "--end-time", end], ranks=2, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    with open_result(output) as run:
        assert run.complete
        steps = run.diagnostics["step"]
    np.testing.assert_array_equal(steps, np.arange(1, len(steps) + 1))
    frames = read_frames(output / "result.h5")
    assert frames[-1]["time"] == pytest.approx(end)
    assert len({int(f["step"]) for f in frames}) == len(frames)


def test_probes_go_on_after_a_restart_without_repeating_rows(tmp_path):
    """A probe's series in result.h5 and its CSV hold every sample once across a restart."""
    case = tmp_path / "tank_with_probe.toml"
    case.write_text((CASES / "hydrostatic.toml").read_text() +
                    '\n[[probe]]\nname = "bottom"\nkind = "pressure"\nposition = [0.1, 0.05]\n')
    common = ["-pressure_ksp_rtol", "1e-12"]
    whole, split = tmp_path / "whole", tmp_path / "split"
    assert _run([case, "-o", whole, "--end-time", "0.1"] + common, 1).returncode == 0
    assert _run([case, "-o", split, "--end-time", "0.05"] + common, 1).returncode == 0
    result = _run(["--restart", split, "--end-time", "0.1"] + common, 2)
    assert result.returncode == 0, result.stderr
    rows = {}
    for name, out in (("whole", whole), ("split", split)):
        with open_result(out) as run:
            rows[name] = (run.probes["bottom"].time, run.probes["bottom"].value)
        table = np.loadtxt(out / "probes" / "bottom.csv", delimiter=",", comments="#",
                           skiprows=2)
        np.testing.assert_array_equal(table[:, 0], rows[name][0])
        np.testing.assert_array_equal(table[:, 1], rows[name][1])
    np.testing.assert_allclose(rows["split"][0], rows["whole"][0], rtol=1e-12)
    assert len(rows["whole"][0]) == 100
    # Pressures of about 500 Pa, continued on another rank count.
    np.testing.assert_allclose(rows["split"][1], rows["whole"][1], rtol=0, atol=1e-6)


def test_a_probe_with_no_sample_yet_is_continued(tmp_path):
    """A run stopped (here by its step limit; as well by a signal) before a probe's first
    sample leaves that probe no rows; continuing it starts from none (it once stopped with
    a traceback, reshaping the empty series)."""
    case = tmp_path / "tank_with_late_probe.toml"
    case.write_text((CASES / "hydrostatic.toml").read_text() +
                    '\n[[probe]]\nname = "late"\nkind = "pressure"\nposition = [0.1, 0.05]\n'
                    'interval = 0.08\n')
    out = tmp_path / "run"
    _run([case, "-o", out, "--set", "time.max_steps=5"], 1)
    with open_result(out) as run:
        assert len(run.probes["late"].time) == 0
    result = _run(["--restart", out], 2)
    assert "continuing from the checkpoint at step 5" in result.stderr
    lines = (out / "probes" / "late.csv").read_text().splitlines()
    assert lines[0].startswith("# probe late: pressure") and lines[1] == "time,value"
    assert len(lines) == 2


def test_a_run_stopped_by_its_step_limit_goes_on_with_max_steps(tmp_path):
    """``--max-steps N`` sets time.max_steps (steps counted from the run's start) for a new
    run and for a continued one: a run stopped by its step limit goes on past it to the
    uninterrupted run's answer. A limit that is not a step count is refused in one line."""
    case = CASES / "mass_spring_7x7.toml"
    whole, split = tmp_path / "whole", tmp_path / "split"
    result = run_parmps([case, "-o", whole, "--end-time", "0.2"], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    result = run_parmps([case, "-o", split, "--end-time", "0.2", "--max-steps", "80"],
                        timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert read_frame(split / "result.h5")["step"] == 80
    # Continued with its own limit the run has no step left; with none it goes on.
    result = run_parmps(["--restart", split], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert read_frame(split / "result.h5")["step"] == 80
    result = run_parmps(["--restart", split, "--max-steps", "0"], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    a, b = read_frame(whole / "result.h5"), read_frame(split / "result.h5")
    assert a["step"] == b["step"] == 200
    assert np.abs(a["position"] - b["position"]).max() < 1e-12

    for args in ([case, "--max-steps", "-3"], ["--restart", split, "--max-steps", "many"]):
        result = run_parmps(args, timeout=60)
        assert result.returncode == 2, result.stderr
        lines = error_lines(result.stderr)
        assert len(lines) == 1 and "--max-steps" in lines[0], result.stderr
