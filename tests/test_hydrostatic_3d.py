"""The 3D still tank (cases/hydrostatic_3d.toml, validation/hydrostatic_3d) against the weight
of the water above each particle, with the 2D still tank's targets.

The run here is the validation's full 2 s at its coarser spacing (2 cm, 10 layers) on 2
ranks. Of the targets, that spacing meets the bottom row's noise and the column's height,
which are asserted; it misses the bottom row's mean (-2.4 %), the RMS (2.2 %) and the
probe (-3.7 %), which converge with the spacing (1 cm, the validation's second run in its
README: bottom -1.04 %, RMS 0.78 %, probe -1.4 %, noise 0.27 %, height -0.30 %). Those
misses are recorded in the README and the 3D issue, not asserted here.
"""

import pytest

from conftest import run_parmps
from parmps import validation

HYDROSTATIC_3D = validation.load("hydrostatic_3d")


@pytest.mark.mpi
@pytest.mark.slow
def test_the_3d_still_tank_holds_its_noise_and_height_targets_at_the_coarser_spacing(tmp_path):
    tolerance = HYDROSTATIC_3D.tolerance
    spacing = HYDROSTATIC_3D.run["spacings"][0]
    result = run_parmps([HYDROSTATIC_3D.case_path, "-o", tmp_path,
                         "--set", f"particles.spacing={spacing!r}",
                         "--end-time", HYDROSTATIC_3D.run["end_time"]], ranks=2, timeout=600)
    assert result.returncode == 0, result.stderr
    measured = HYDROSTATIC_3D.measure(tmp_path / "result.h5")
    assert measured["bottom_std"] < tolerance["bottom_noise"], measured["bottom_std"]
    assert abs(measured["height_drift"]) < tolerance["height_drift"], measured["height_drift"]
