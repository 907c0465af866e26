"""Shared helpers: run parmps as a user would, serially or under mpirun, with a timeout."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from parmps.parallel.mpi import launch_environment, run_mpirun

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def mpi_environment():
    env = dict(os.environ)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    env.setdefault("PETSC_DIR", "/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real")
    return env


def run_parmps(args, ranks=1, timeout=300, cwd=None):
    """Run ``python -m parmps ARGS`` (under mpirun when ranks > 1); a hang fails the test."""
    return run_python(["-m", "parmps"] + list(args), ranks=ranks, timeout=timeout, cwd=cwd)


def run_python(args, ranks=1, timeout=300, cwd=None):
    """Run ``python ARGS`` (under mpirun when ranks > 1) with a timeout.

    Under mpirun the whole process group is killed on timeout, ranks included.
    """
    args = [str(a) for a in args]
    try:
        if ranks > 1:
            return run_mpirun(ranks, [sys.executable] + args, timeout, cwd=cwd or ROOT,
                              env=launch_environment(mpi_environment()))
        return subprocess.run([sys.executable] + args, capture_output=True, text=True,
                              timeout=timeout, env=mpi_environment(), cwd=cwd or ROOT)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"timed out after {timeout} s: {' '.join(args)}\n{exc.stderr}")


def error_lines(stderr):
    """The lines parmps itself wrote for an error (mpirun may add its own notices)."""
    return [line for line in stderr.splitlines() if line.startswith("parmps: error:")]
