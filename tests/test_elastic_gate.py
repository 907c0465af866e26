"""Water column released through an elastic rubber gate (validation/elastic_gate/), on 2 ranks.

cases/elastic_gate.toml to 0.4 s: no fluid particle's path crosses the gate's mid-line
(counted every step by the body_crossing check), the area constraint holds, the free end's
displacement is in the output every step, and the run reaches its end. Antoci et al.'s measured
tip curve is not among the shared reference data, so the curve is reported (README,
docs/elastic_gate.png), not judged. About 12 minutes on 2 ranks of a shared 2-core machine.
"""

import numpy as np
import pytest

from conftest import run_parmps
from parmps import validation

CHECK = validation.load("elastic_gate")


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_gate_holds_the_water_back_to_0_4_s_on_two_ranks(tmp_path):
    end = CHECK.run["end_time"]
    result = run_parmps([CHECK.case_path, "-o", tmp_path, "--end-time", str(end)], ranks=2,
                        timeout=2300)
    assert result.returncode == 0, result.stderr[-3000:]
    measured = CHECK.measure(tmp_path / "result.h5")
    assert measured["end"] == pytest.approx(end, abs=1e-9)
    assert measured["crossings"] <= CHECK.tolerance["crossings"], measured["crossings"]
    assert measured["volume_error"] < CHECK.tolerance["volume_error"], measured["volume_error"]
    # The tip series has a row every step, and the water opens the gate downstream (+x).
    assert len(measured["time"]) > 100 and np.all(np.isfinite(measured["dx"]))
    assert measured["dx_max"] > 0.0
