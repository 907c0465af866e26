"""What a new user meets first: the design card's command in an activated venv, and bad
paths or extreme values answered with one line and exit status 2, never a traceback."""

import os
import subprocess

import pytest

from conftest import CASES, ROOT, error_lines, run_parmps

VENV = ROOT / ".venv"


def _bare_environment():
    """A login shell's environment: no PETSC_DIR, no venv, only what a user has."""
    env = {"HOME": os.environ.get("HOME", "/root"), "PATH": "/usr/local/bin:/usr/bin:/bin",
           "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_btl_vader_single_copy_mechanism": "none"}
    return env


@pytest.mark.mpi
@pytest.mark.skipif(not (VENV / "bin" / "activate").exists(), reason="no .venv: run scripts/setup")
def test_mpirun_in_an_activated_venv_finds_petsc_without_petsc_dir(tmp_path):
    command = (f"source {VENV}/bin/activate && test -z \"${{PETSC_DIR:-}}\" && "
               f"mpirun -n 2 python -m parmps {CASES / 'hydrostatic.toml'} --end-time 0.01 "
               f"-o {tmp_path / 'mpirun'} && "
               f"parmps {CASES / 'hydrostatic.toml'} --end-time 0.01 -o {tmp_path / 'script'}")
    result = subprocess.run(["bash", "-c", command], capture_output=True, text=True,
                            timeout=240, env=_bare_environment(), cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert (tmp_path / "mpirun" / "result.h5").exists()
    assert (tmp_path / "script" / "result.xdmf").exists()


def _one_line_exit_2(result, *phrases):
    assert result.returncode == 2, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    (line,) = error_lines(result.stderr)
    for phrase in phrases:
        assert phrase in line, line
    return line


def test_output_path_that_is_a_file(tmp_path):
    target = tmp_path / "taken"
    target.write_text("not a directory")
    result = run_parmps([CASES / "hydrostatic.toml", "-o", target, "--end-time", "0.01"])
    _one_line_exit_2(result, "-o", "not a directory")
    assert target.read_text() == "not a directory"


def test_output_path_that_cannot_be_created(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = run_parmps([CASES / "hydrostatic.toml", "-o", blocker / "below", "--end-time",
                         "0.01"])
    _one_line_exit_2(result, "-o", "cannot create it")


def test_a_viscosity_that_makes_dt_vanish(tmp_path):
    # With the viscous term explicit: under the default "auto" a step beyond the viscous limit
    # takes viscosity implicitly and the limit limits nothing (docs/design.md).
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.01",
                         "--set", "fluid.viscosity=1e300",
                         "--set", 'mps.viscosity_scheme="explicit"'])
    _one_line_exit_2(result, "time step", "fluid.viscosity")


def test_a_scene_larger_than_the_memory_is_refused_before_it_is_built():
    result = run_parmps([CASES / "hydrostatic.toml", "--check",
                         "--set", "fluid_block.0.upper=[1e300, 0.2]"], timeout=60)
    _one_line_exit_2(result, "GiB", "more than this machine's")


@pytest.mark.mpi
def test_bad_output_path_under_mpi_stops_every_rank(tmp_path):
    target = tmp_path / "taken"
    target.write_text("")
    result = run_parmps([CASES / "hydrostatic.toml", "-o", target, "--end-time", "0.01"],
                        ranks=2, timeout=120)
    _one_line_exit_2(result, "-o", "not a directory")
