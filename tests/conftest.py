"""Shared helpers: run parmps as a user would, serially or under mpirun, with a timeout;
stand-ins for a decomposition and a communicator to run one fluid step without MPI."""

import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from parmps.parallel.mpi import mpirun_command
from parmps.validation import launch

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def mpi_environment():
    """The environment of a launched run (parmps.validation.launch): PETSc is found by the
    package itself, Open MPI gets its consent to root."""
    return launch.environment()


def run_parmps(args, ranks=1, timeout=300, cwd=None):
    """Run ``python -m parmps ARGS`` (under mpirun when ranks > 1); a hang fails the test."""
    return run_python(["-m", "parmps"] + list(args), ranks=ranks, timeout=timeout, cwd=cwd)


def run_python(args, ranks=1, timeout=300, cwd=None):
    """Run ``python ARGS`` (under mpirun when ranks > 1) with a timeout, through the package's
    launcher: on timeout the whole process group is killed, ranks included, and the test
    fails."""
    args = [str(a) for a in args]
    argv = [sys.executable] + args
    if ranks > 1:
        argv = mpirun_command(ranks, argv)
    status, stdout, stderr, _ = launch.execute(argv, timeout, cwd=cwd or ROOT)
    if status not in (None, 0) and ranks > 1 and lost_by_mpirun(stderr):
        # Open MPI 4.1 (Debian 12) now and then loses track of a rank that finished cleanly
        # while other mpiruns run beside it (scripts/test runs two at once): it reports the
        # rank "with PID 0" as having exited without MPI_Finalize and returns 1 (seen once in
        # a whole suite, after the run had written "done" and its output; upstream
        # open-mpi/ompi#12607, #9389). A rank of ours that really skipped MPI_Finalize is
        # reported with its own PID, so this runs the command once more only for that report.
        warnings.warn(f"mpirun lost a finished rank (PID 0); running again: {' '.join(args)}")
        status, stdout, stderr, _ = launch.execute(argv, timeout, cwd=cwd or ROOT)
    if status is None:
        pytest.fail(f"timed out after {timeout} s: {' '.join(args)}")
    return subprocess.CompletedProcess(argv, status, stdout, stderr)


def lost_by_mpirun(stderr):
    """Whether mpirun's report is Open MPI's notice of a rank it lost track of (PID 0)."""
    return bool(re.search(r"mpirun has exited due to process rank \d+ with PID 0 on\s", stderr))


def error_lines(stderr):
    """The lines parmps itself wrote for an error (mpirun may add its own notices)."""
    return [line for line in stderr.splitlines() if line.startswith("parmps: error:")]


def pytest_collection_modifyitems(config, items):
    """The files with slow tests first, each file's tests kept together and in order: under
    scripts/test's two test processes a file goes to one process whole, and a long file
    handed out last would leave the other process idle while it runs."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)


class NoHalo:
    """A decomposition's ghost refresh on one rank with no ghosts, for a fluid step run
    without MPI."""

    def refresh(self, arrays, positions=()):
        pass


class OneRank:
    """The communicator calls a fluid step makes, on one rank, without MPI."""

    rank = 0

    def exscan(self, value):
        return 0


def case_of(path, *overrides):
    """The validated case of the TOML file ``path`` with ``overrides`` applied (each
    ``section.key=value``, as ``--set`` takes them)."""
    from parmps import config, schema
    raw = config.load_text(Path(path).read_text(), str(path))
    for assignment in overrides:
        config.apply_override(raw, assignment)
    return schema.validate(raw)

