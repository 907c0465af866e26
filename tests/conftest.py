"""Shared helpers: run parmps as a user would, serially or under mpirun, with a timeout."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def mpi_environment():
    env = dict(os.environ)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    env.setdefault("PETSC_DIR", "/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real")
    return env


def mpirun_prefix(ranks):
    if ranks <= 1:
        return [sys.executable]
    prefix = ["mpirun", "-n", str(ranks)]
    if ranks > (os.cpu_count() or 1):
        prefix.append("--oversubscribe")
    return prefix + [sys.executable]


def run_parmps(args, ranks=1, timeout=300, cwd=None):
    """Run ``python -m parmps ARGS`` (under mpirun when ranks > 1); a hang fails the test."""
    command = mpirun_prefix(ranks) + ["-m", "parmps"] + [str(a) for a in args]
    try:
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                              env=mpi_environment(), cwd=cwd or ROOT)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"timed out after {timeout} s: {' '.join(command)}\n{exc.stderr}")


def run_python(args, ranks=1, timeout=300, cwd=None):
    """Run ``python ARGS`` (under mpirun when ranks > 1) with a timeout."""
    command = mpirun_prefix(ranks) + [str(a) for a in args]
    try:
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                              env=mpi_environment(), cwd=cwd or ROOT)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"timed out after {timeout} s: {' '.join(command)}\n{exc.stderr}")


def error_lines(stderr):
    """The lines parmps itself wrote for an error (mpirun may add its own notices)."""
    return [line for line in stderr.splitlines() if line.startswith("parmps: error:")]
