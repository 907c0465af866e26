"""Water column released through an elastic rubber gate (validation/elastic_gate/), on 2 ranks.

cases/elastic_gate.toml, at the defaults, to 0.4 s: no fluid particle's path crosses the gate's
mid-line (counted every step by the body_crossing check), the area constraint holds, the free
end's displacement is in the output every step, and the run reaches its end. The comparison
with Antoci et al.'s measured free-end curve (the validation's references) is computed here and
judged by `python -m parmps validate elastic_gate`, whose targets (peak within 15 %, RMS within
20 % of the peak) the defaults do not meet (README, "Measured"). About a minute on 2 ranks.
"""

import numpy as np
import pytest

from conftest import run_parmps
from parmps import validation
from parmps.tools import analysis

CHECK = validation.load("elastic_gate")


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.timeout(900)
def test_gate_holds_the_water_back_to_0_4_s_on_two_ranks(tmp_path):
    end = CHECK.run["end_time"]
    result = run_parmps([CHECK.case_path, "-o", tmp_path, "--end-time", str(end)], ranks=2,
                        timeout=800)
    assert result.returncode == 0, result.stderr[-3000:]
    measured = CHECK.measure(tmp_path / "result.h5")
    assert measured["end"] == pytest.approx(end, abs=1e-9)
    assert measured["crossings"] <= CHECK.tolerance["crossings"], measured["crossings"]
    assert measured["volume_error"] < CHECK.tolerance["volume_error"], measured["volume_error"]
    # The tip series has a row every step, and the water opens the gate downstream (+x).
    assert len(measured["time"]) > 100 and np.all(np.isfinite(measured["dx"]))
    assert measured["dx_max"] > 0.0
    for component in ("dx", "dy"):
        assert np.isfinite(measured[f"{component}_peak_error"])
        assert 0.0 < measured[f"{component}_rms_error"] < 1.0


def test_the_curve_errors_are_relative_to_the_records_peak():
    # A record peaking at 2 at t = 1; a run 10 % low everywhere: peak -10 %, and an RMS
    # of 0.1 times the record's RMS over its peak. A run that ends at t = 1 is compared
    # at the record's points it reached.
    t_ref = np.array([0.0, 0.5, 1.0, 1.5])
    v_ref = np.array([0.0, 1.0, 2.0, 1.0])
    time = np.linspace(0.0, 1.5, 301)
    value = 0.9 * np.interp(time, t_ref, v_ref)
    peak, rms = analysis.curve_errors(time, value, t_ref, v_ref)
    assert peak == pytest.approx(-0.1, abs=1e-12)
    assert rms == pytest.approx(0.1 * np.sqrt(np.mean(v_ref ** 2)) / 2.0, rel=1e-12)
    short = time <= 1.0
    _, rms_short = analysis.curve_errors(time[short], value[short], t_ref, v_ref)
    assert rms_short == pytest.approx(0.1 * np.sqrt(np.mean(v_ref[:3] ** 2)) / 2.0, rel=1e-12)


def test_the_validation_reads_the_experiments_two_curves():
    references = CHECK.metric_arguments["references"]
    for component in ("dx", "dy"):
        t_ref, v_ref = list(analysis.reference_table(references[component]).values())[:2]
        assert len(t_ref) == 9 and np.all(np.diff(t_ref) > 0) and t_ref[-1] < 0.4
    assert CHECK.tolerance["dx_peak_error"] == 0.15 and CHECK.tolerance["dx_rms_error"] == 0.2


def _case_body(path, **changes):
    from parmps import config, schema
    from parmps.solids.mass_spring.build import build_bodies
    raw = config.load_text(path.read_text())
    raw["body"][0].update(changes)
    (body,) = build_bodies(schema.validate(raw))
    return body


@pytest.mark.filterwarnings("ignore")
def test_the_3d_gate_at_rest_bends_between_plane_stress_and_plane_strain():
    # The 3D case's gate (3 nodes through its 5 mm, 40 across 0.1 m, free length 0.08 m)
    # under the still column, statics (parmps/tools/gate_statics.py). The lattice is checked
    # at both limits first: with every node's sideways (y) motion held it is plane strain
    # (f = 1), as a strip one or two cells wide it is plane stress (f = 0), each within 0.2
    # of f, 1.3 % of the deflection. Free side edges put its mid-width between, nearer plane
    # strain (measured f = 0.66; validation/elastic_gate_3d/README.md).
    from conftest import CASES
    from parmps.solids.mass_spring.statics import static_displacement, stiffness_matrix
    from parmps.tools import gate_statics
    nu, height, mid = 0.25, 0.14, [57, 58, 59, 60, 61, 62]
    body = _case_body(CASES / "elastic_gate_3d.toml")
    result = gate_statics.gate_convention(body, height, 12.0e6, nu, mid)
    held = np.zeros_like(body.position, bool)
    held[body.pinned] = True
    held[:, 1] = True
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    force = gate_statics.face_loads(body.position, 0.0025, height)
    strain = static_displacement(matrix, force, held)[0][mid, 0].mean()
    assert (1.0 - strain / result["plane_stress"]) / nu ** 2 == pytest.approx(1.0, abs=0.2)
    for across in (2, 3):
        strip = _case_body(CASES / "elastic_gate_3d.toml", ny=across)
        tip = np.flatnonzero(np.isclose(strip.position[:, 2], strip.position[:, 2].min()))
        narrow = gate_statics.gate_convention(strip, height, 12.0e6, nu, tip)
        assert narrow["fraction"] == pytest.approx(0.0, abs=0.2)
    assert 0.5 < result["fraction"] < 0.8, result["fraction"]
    # The side edges bend less than the middle, and the profile is symmetric.
    profile = result["across"]
    assert len(profile) == 40 and profile[0] < profile[19]
    np.testing.assert_allclose(profile, profile[::-1], rtol=1e-9)


def test_the_2d_gate_at_rest_bends_as_its_plane_strain_beam():
    # The 2D case's gate (plane strain, built with E/(1 - nu^2) of nu = 0.4) under the same
    # still column: its tip within 0.5 % of Euler-Bernoulli with D = E t^3/12(1 - 0.4^2).
    from conftest import CASES
    from parmps.tools import gate_statics
    body = _case_body(CASES / "elastic_gate.toml")
    result = gate_statics.gate_convention(body, 0.14, 12.0e6, 0.4, [0, 1, 2, 3])
    assert result["lattice"] == pytest.approx(result["plane_strain"], rel=5e-3)


def test_the_3d_gate_clears_the_walls_and_its_probe_is_the_tip_at_mid_width():
    # cases/elastic_gate_3d.toml as built: its side faces and tip half a spacing clear of the
    # side walls and the floor (as the water's first layer), the clamp rows 32-35 pinned (free
    # length 32 a = 0.08 m), and the probe's 6 nodes the tip row's at mid-width.
    from conftest import CASES
    a = 0.0025
    body = _case_body(CASES / "elastic_gate_3d.toml")
    position = body.position
    assert len(position) == 3 * 40 * 36
    np.testing.assert_allclose(position.min(axis=0), [0.1 + a / 2, a / 2, a / 2], atol=1e-12)
    np.testing.assert_allclose(position.max(axis=0)[:2], [0.1 + 2.5 * a, 0.1 - a / 2],
                               atol=1e-12)
    pinned_rows = np.unique(np.round(position[body.pinned, 2] / a - 0.5).astype(int))
    assert list(pinned_rows) == [32, 33, 34, 35] and body.pinned.sum() == 4 * 120
    probe = validation.load("elastic_gate_3d").case()["probe"][0]["nodes"]
    np.testing.assert_allclose(position[probe, 2], a / 2, atol=1e-12)
    np.testing.assert_allclose(position[probe, 1].mean(), 0.05, atol=1e-12)
