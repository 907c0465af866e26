"""Hydrostatic water column on an elastic plate (validation/hydrostatic_plate/), on 2 ranks.

An aluminium plate 1 m long and 0.05 m thick, clamped at both ends, under 2 m of water
(cases/hydrostatic_plate.toml, l0 = 1/60 m, 4 nodes through the plate): the mid-span
deflection averaged over 0.25-0.5 s against Euler-Bernoulli's q L^4/(384 D) = 7.06e-5 m.
About 20 s on 2 ranks (measured +4.8 %, tolerance 5 %: validation/hydrostatic_plate).
"""

import pytest

from conftest import run_parmps
from parmps import validation

CHECK = validation.load("hydrostatic_plate")


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_mid_span_deflection_on_two_ranks(tmp_path):
    result = run_parmps([CHECK.case_path, "-o", tmp_path, "--end-time",
                         str(CHECK.run["end_time"])], ranks=2, timeout=1100)
    assert result.returncode == 0, result.stderr
    measured = CHECK.measure(tmp_path / "result.h5")
    assert measured["expected"] == pytest.approx(7.06e-5, rel=1e-3)
    assert abs(measured["error"]) < CHECK.tolerance["deflection"], measured["deflection"]
