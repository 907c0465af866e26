"""A water layer on a square plate clamped on its four edges (validation/hydrostatic_plate_3d/),
the first steps on 2 ranks: the case runs, the clamp holds, and the metric reads Kirchhoff's
answer from the case.

The full run to t = 0.5 s (about 12 minutes on 2 ranks, too long for the suite) is checked by
``python -m parmps validate hydrostatic_plate_3d``; its figures are in the validation's README.
"""

import numpy as np
import pytest

from conftest import run_parmps
from parmps import open_result, validation
from parmps.solids.mass_spring.build import lattice_geometry

CHECK = validation.load("hydrostatic_plate_3d")


@pytest.mark.mpi
@pytest.mark.timeout(600)
def test_the_first_steps_load_the_plate_and_the_clamp_holds(tmp_path):
    result = run_parmps([CHECK.case_path, "-o", tmp_path, "--end-time", "0.006",
                         "--set", "time.output_interval=0.002"], ranks=2, timeout=500)
    assert result.returncode == 0, result.stderr
    measured = CHECK.measure(tmp_path / "result.h5")
    # 0.00126 x 9.81 (1000 x 0.1 + 1000 x 0.03) x 0.9^4 / (1.5e8 x 0.03^3 / 11.25)
    assert measured["expected"] == pytest.approx(2.9285e-3, rel=1e-4)
    assert measured["span"] == pytest.approx(0.9) and measured["load"] == pytest.approx(1275.3)
    # Suddenly loaded, the centre starts to sink, faster and faster.
    series = measured["series"]
    assert series[0] == 0.0 and np.all(np.diff(series) > 0) and np.all(np.diff(series, 2) > 0)
    # Every node on or outside the water's footprint stays where it started.
    with open_result(tmp_path / "result.h5") as run:
        case = run.case
        position = run.frames[-1].bodies["plate"]["position"]
    (spec,) = case["body"]
    rest = lattice_geometry((spec["nx"], spec["ny"], spec["nz"]), spec["spacing"],
                            spec["lower"])[0]
    held = ~np.all((rest[:, :2] > 1e-9) & (rest[:, :2] < 0.9 - 1e-9), axis=1)
    assert np.count_nonzero(held) == 97 * 97 * 4 - 89 * 89 * 4
    assert np.array_equal(position[held], rest[held])
    assert np.abs(position[~held] - rest[~held]).max() > 0.0
