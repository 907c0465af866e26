"""A wheel (a non-editable install) carries the validations and the cases they run."""

import subprocess
import sys
import zipfile

from conftest import ROOT, lost_by_mpirun
from parmps import validation


def test_a_wheel_carries_the_validation_data(tmp_path):
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                             "--no-build-isolation", "--disable-pip-version-check", "-q",
                             "-w", str(tmp_path), str(ROOT)],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    (wheel,) = tmp_path.glob("parmps-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for name in validation.names():
        check = validation.load(name)
        assert f"parmps/_data/validation/{name}/validation.toml" in names
        case = check.case_path[len(validation.ROOT) + 1:]
        assert f"parmps/_data/{case}" in names, case
    assert "parmps/_data/validation/dam_break/martin_moyce_1952_surge_front.csv" in names


def test_the_installed_data_is_preferred_to_the_checkout(tmp_path, monkeypatch):
    package = tmp_path / "parmps"
    (package / "_data" / "validation").mkdir(parents=True)
    monkeypatch.setattr(validation, "PACKAGE", str(package))
    assert validation.data_root() == str(package / "_data")
    (package / "_data" / "validation").rmdir()
    assert validation.data_root() == str(tmp_path)


def test_only_open_mpis_lost_rank_notice_is_run_again():
    """The test helper runs a command again only on mpirun's notice of a rank it lost track of
    (PID 0); a rank that exited without MPI_Finalize is reported with its PID and fails."""
    notice = ("mpirun has exited due to process rank {} with PID {} on\n"
              "node vm exiting improperly. There are three reasons this could occur:\n")
    assert lost_by_mpirun("...\n" + notice.format(0, 0))
    assert lost_by_mpirun(notice.format(1, 0))
    assert not lost_by_mpirun(notice.format(0, 41230))
    assert not lost_by_mpirun("parmps: error: particle 779 left the domain")
