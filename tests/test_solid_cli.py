"""Solid-only cases through the command line: no PETSc, the solids' output
layout of docs/design.md §5, and bad bodies refused with one line and exit status 2."""

import pathlib
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest

from parmps import open_result, validation
from test_solid import BAD_BODIES, BASE

ROOT = pathlib.Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "mass_spring_7x7.toml"

# Runs the CLI in this interpreter, then reports whether PETSc was ever imported.
WRAPPER = """
import sys
from parmps.cli import main
status = main(sys.argv[1:])
print("PETSC_IMPORTED" if "petsc4py" in sys.modules else "PETSC_NOT_IMPORTED")
sys.exit(status)
"""


def parmps(*args):
    return subprocess.run([sys.executable, "-c", WRAPPER, *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def solid_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("solid") / "out"
    result = parmps(CASE, "-o", out, "--end-time", "0.2")
    return result, out


def test_solid_only_case_runs_without_petsc(solid_run):
    result, out = solid_run
    assert result.returncode == 0, result.stderr
    assert "PETSC_NOT_IMPORTED" in result.stdout


def test_solid_output_layout(solid_run):
    result, out = solid_run
    assert result.returncode == 0, result.stderr
    with open_result(out) as run:
        assert run.complete
        body = run.bodies["block"]
        steps = len(run.diagnostics["step"])
        assert steps == 200
        for name, shape in (("time", (steps,)), ("volume_error", (steps,)),
                            ("fluid_force", (steps, 2)), ("centroid", (steps, 2))):
            assert body[name].shape == shape, name
        assert np.allclose(body.time, run.diagnostics.time)
        assert np.all(body.fluid_force == 0.0)
        tolerance = validation.load("mass_spring_7x7").tolerance["volume_error"]
        assert np.max(np.abs(body.volume_error)) < tolerance
        assert body.springs.shape == (156, 2) and body.springs.dtype.kind == "i"
        frame = run.frames[-1]
        nodes = frame.bodies["block"]
        assert nodes["position"].shape == (49, 2) and nodes["velocity"].shape == (49, 2)
        assert np.all(frame.kind == 3)
        assert np.allclose(nodes["position"][:, 1].max(), frame.position[:, 1].max())
    xdmf = ElementTree.parse(out / "result.xdmf").getroot()
    polylines = [t for t in xdmf.iter("Topology") if t.get("TopologyType") == "Polyline"]
    assert polylines and all(t.get("NodesPerElement") == "2" for t in polylines)
    assert polylines[0].find("DataItem").text.endswith(":/solids/block/springs")


@pytest.mark.parametrize("name", sorted(BAD_BODIES))
def test_bad_bodies_exit_2_with_one_line(name, tmp_path):
    body, pattern = BAD_BODIES[name]
    case = tmp_path / "bad.toml"
    case.write_text(BASE + body)
    result = parmps(case, "-o", tmp_path / "out")
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    import re
    assert re.search(pattern, lines[0]), lines[0]
