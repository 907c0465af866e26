"""parmps.open_result: every dataset of a result by name, read lazily, frames sorted by id."""

import h5py
import numpy as np
import pytest

import parmps
from conftest import ROOT, run_parmps
from parmps.errors import CaseError
from parmps.io.frames import read_frame, read_frames

PROBE = """
[[probe]]
name = "P1"
kind = "pressure"
position = [0.1, 0.03]
"""


@pytest.fixture(scope="module")
def archimedes(tmp_path_factory):
    """A short real run: a held body in a still tank, with one pressure probe."""
    directory = tmp_path_factory.mktemp("archimedes")
    case = directory / "case.toml"
    case.write_text((ROOT / "tests" / "cases" / "archimedes.toml").read_text() + PROBE)
    result = run_parmps([case, "-o", directory / "out", "--end-time", "0.02",
                         "--set", "time.output_interval=0.01"], timeout=240)
    assert result.returncode == 0, result.stderr[-2000:]
    return directory / "out"


def test_a_real_run_reads_by_name(archimedes):
    with parmps.open_result(archimedes) as result:     # the directory, or its result.h5
        assert len(result.frames) == 3
        np.testing.assert_allclose(result.time, [0.0, 0.01, 0.02], atol=1e-12)
        last = result.frames[-1]
        assert np.all(np.diff(last.id) > 0)            # sorted by id
        assert last.position.shape == (len(last), 2)
        assert np.isfinite(last.pressure).all()
        assert result.diagnostics["time"][-1] == pytest.approx(0.02, abs=1e-12)
        assert len(result.diagnostics.dt) == len(result.diagnostics["step"])
        probe = result.probes["P1"]
        assert probe.attrs["kind"] == "pressure" and probe.value.shape == probe.time.shape
        block = result.bodies["block"]
        assert np.abs(block.volume_error).max() < 1e-5
        assert last.bodies["block"]["position"].shape == (25, 2)
        assert list(result.checks) == []
        assert result.case["body"][0]["name"] == "block" and result.complete


def test_the_shorthands_read_through_the_same_reader(archimedes):
    path = archimedes / "result.h5"
    frames = read_frames(path)
    with parmps.open_result(path) as result:
        first = result.frames[0]
        np.testing.assert_array_equal(frames[0]["position"], first.position)
        assert frames[-1]["step"] == result.frames[-1].step
        assert read_frame(path, step=first.step)["time"] == first.time


def _synthetic(path):
    """A file in the documented layout with frames written out of id order."""
    with h5py.File(path, "w") as handle:
        handle.create_group("case").attrs["toml"] = "title = 'x'"
        frame = handle.create_group("frames/00000007")
        frame.attrs.update(time=0.5, step=7, dt=1e-3)
        frame["id"] = np.array([2, 0, 1], np.int64)
        frame["kind"] = np.array([0, 1, 0], np.int8)
        frame["position"] = np.array([[2.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
        frame["pressure"] = np.array([20.0, 0.0, 10.0])
        handle["diagnostics/step"] = np.arange(7)
        check = handle.create_group("checks/gate_crossing")
        check.attrs["body"] = "gate"
        check["total"] = np.array([0, 0, 1])


def test_fields_are_sorted_by_id_and_read_only_when_asked(tmp_path):
    path = tmp_path / "result.h5"
    _synthetic(path)
    with parmps.open_result(path) as result:
        frame = result.frames[0]
        assert frame._fields == {}                      # nothing read yet
        np.testing.assert_array_equal(frame.pressure, [0.0, 10.0, 20.0])
        assert set(frame._fields) == {"pressure"}
        np.testing.assert_array_equal(frame["position"][:, 0], [0.0, 1.0, 2.0])
        assert result.frames.at_step(7) is frame and result.frames.nearest(0.4) is frame
        assert result.checks["gate_crossing"]["total"][-1] == 1
        assert result.checks["gate_crossing"].attrs["body"] == "gate"
        with pytest.raises(KeyError, match="there are: gate_crossing"):
            result.checks["other"]
        with pytest.raises(AttributeError, match="no dataset 'dt'"):
            result.diagnostics.dt
        assert list(result.probes) == []


def test_a_missing_result_is_one_line(tmp_path):
    with pytest.raises(CaseError, match="no result file there"):
        parmps.open_result(tmp_path)


def test_importing_the_package_loads_no_numpy():
    # The command line sets BLAS to one thread per rank before NumPy loads OpenBLAS.
    import subprocess
    import sys
    code = "import sys, parmps, parmps.cli; assert 'numpy' not in sys.modules, 'numpy loaded'"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
