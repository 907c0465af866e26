"""Fluid-solid coupling, open boundaries and the seed's two scenes (issue 5).

Archimedes (a held body feels rho g V; a free body of the fluid's density stays
put), no fluid inside any solid at any step, the volume error of every
constrained body below 1e-5 on 1, 2 and 3 ranks, the same answer (by id) on 1,
2 and 3 ranks, balanced inflow and outflow, and the two scenes running to their
end time on 2 ranks at a coarse resolution.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import CASES, ROOT, error_lines, run_parmps
from parmps import open_result, validation
from parmps.io.frames import read_frame
from parmps.tools import analysis

CHECKS = {name: validation.load(name) for name in ("archimedes", "membrane_tube", "box_in_flow")}
ARCHIMEDES = Path(CHECKS["archimedes"].case_path)
MEMBRANE = Path(CHECKS["membrane_tube"].case_path)
BOX = Path(CHECKS["box_in_flow"].case_path)
VOLUME_TOLERANCE = {"membrane": CHECKS["membrane_tube"].tolerance["volume_error"],
                    "box": CHECKS["box_in_flow"].tolerance["volume_error"]}


def solids(path, body):
    with open_result(path) as run:
        return dict(run.bodies[body])


def diagnostics(path):
    with open_result(path) as run:
        return dict(run.diagnostics)


def check_run(result, out, end_time, bodies):
    """The run finished at its end time, no fluid inside any solid at any step,
    the volume error of every body within its validation's tolerance at every step."""
    assert result.returncode == 0, result.stderr[-3000:]
    series = diagnostics(out / "result.h5")
    assert series["time"][-1] == pytest.approx(end_time)
    for body in bodies:
        values = solids(out / "result.h5", body)
        assert len(values["time"]) == len(series["time"])
        assert values["fluid_inside"].max() == 0, f"fluid inside {body}"
        assert np.abs(values["volume_error"]).max() < VOLUME_TOLERANCE[body], body
    return series


# --- Archimedes ---------------------------------------------------------------------------------

def test_held_body_feels_rho_g_v(tmp_path):
    """All 25 nodes pinned in a still tank: the vertical fluid force, averaged
    after 0.4 s of settling, is rho g V with V = 25 l0^2 within 5 %."""
    out = tmp_path / "held"
    result = run_parmps([ARCHIMEDES, "-o", out], timeout=240)
    assert result.returncode == 0, result.stderr[-3000:]
    check = CHECKS["archimedes"]
    measured = check.measure(out / "result.h5")
    assert abs(measured["force"]) < check.tolerance["force"], measured
    assert measured["force_x"] < check.tolerance["force"], measured
    assert solids(out / "result.h5", "block")["fluid_inside"].max() == 0


def test_free_body_of_fluid_density_stays_put(tmp_path):
    """The same body free, node mass rho l0^2: its centroid moves less than one
    spacing in 1 s, and its area is kept."""
    out = tmp_path / "free"
    result = run_parmps([ARCHIMEDES, "-o", out, "--set", 'body.0.pinned="none"'], timeout=240)
    assert result.returncode == 0, result.stderr[-3000:]
    values = solids(out / "result.h5", "block")
    assert values["time"][-1] == pytest.approx(1.0)
    check = CHECKS["archimedes"]
    measured = check.measure(out / "result.h5")
    assert measured["drift"] < check.tolerance["drift"], measured["drift"]
    assert measured["volume_error"] < check.tolerance["volume_error"]
    assert values["fluid_inside"].max() == 0


# --- the two scenes on 2 ranks ------------------------------------------------------------------

@pytest.mark.mpi
def test_membrane_tube_on_two_ranks(tmp_path):
    """Through the load window and past the release: no leak, area kept, and every
    fluid particle still below the membrane's lower row at every frame.

    Stopped at 0.5 s to stay fast. The full 1.5 s run (the membrane's rebound, which
    peaks near t = 0.9 s) is not checked by the suite: it is checked by running the case
    to its end, ``./scripts/run -n N cases/membrane_tube.toml`` on 1, 2 and 3 ranks,
    against validation/membrane_tube (area error < 1e-5 at every step); the figures of
    those runs are in docs/membrane_tube.md."""
    out = tmp_path / "membrane"
    end = 0.5
    result = run_parmps([MEMBRANE, "-o", out, "--end-time", end,
                         "--set", "time.output_interval=0.05"], ranks=2, timeout=300)
    check_run(result, out, end, ["membrane"])
    values = solids(out / "result.h5", "membrane")
    # The load pushed the membrane in: its lower row's middle node moved down.
    with open_result(out) as run:
        for frame in run.frames:
            nodes = frame.bodies["membrane"]["position"]
            lower_row = nodes[:39]
            fluid = frame.position[frame.kind == 0]
            below = fluid[:, 1] < np.interp(fluid[:, 0], lower_row[:, 0], lower_row[:, 1])
            assert below.all(), f"fluid above the membrane's lower row at step {frame.step}"
            if frame.step == 0:
                start = nodes[19, 1]
            middle = nodes[19, 1]
    assert np.abs(values["fluid_force"][:, 1]).max() > 0
    assert middle != start


def box_bend(nodes):
    """How far the box's middle row (across the flow) runs ahead of its end rows
    along the flow (-x): > 0 for a parachute open upstream."""
    return analysis.lattice_bend(nodes, CHECKS["box_in_flow"].case()["body"][0])


@pytest.mark.mpi
def test_box_in_flow_on_two_ranks(tmp_path):
    """The box is carried by the developing channel flow without a leak and with its
    area kept, and bends into a cup open upstream; the P = 0 outflow buffer keeps the
    closed channel's pressure level bounded (it crept to ~3 kPa without it)."""
    out = tmp_path / "box"
    end = 0.6
    result = run_parmps([BOX, "-o", out, "--end-time", end,
                         "--set", "time.output_interval=0.1"], ranks=2, timeout=300)
    series = check_run(result, out, end, ["box"])
    values = solids(out / "result.h5", "box")
    tolerance = CHECKS["box_in_flow"].tolerance
    # Carried along -x.
    assert values["centroid"][-1, 0] < values["centroid"][0, 0] - tolerance["carried"]
    frame = read_frame(out / "result.h5")
    with open_result(out) as run:
        nodes = run.frames[-1].bodies["box"]["position"]
    # The full run bends 7 mm by 0.6 s and 20 mm by 2 s (README); a rigid carry, 0.
    assert box_bend(nodes) > tolerance["bend"], box_bend(nodes)
    fluid = frame["kind"] == 0
    # Poiseuille drop 12 mu U0 L / H^2 ~ 200 Pa along the channel: the mean is about half.
    assert frame["pressure"][fluid].mean() < tolerance["mean_pressure"]
    time, inflow = series["time"], series["inflow"]
    late = time >= 0.2
    rate_in = (inflow[late][-1] - inflow[late][0]) / (time[late][-1] - time[late][0])
    expected = analysis.inflow_rate(CHECKS["box_in_flow"].case())
    assert rate_in == pytest.approx(expected, rel=tolerance["flux"])
    # New particles got new, unique ids.
    assert len(np.unique(frame["id"])) == len(frame["id"])
    assert frame["id"].max() > 2640


@pytest.mark.mpi
def test_inflow_and_outflow_balance_on_two_ranks(tmp_path):
    """In a steady plug flow (the box case at water's viscosity: the profile stays
    uniform) the inlet and the outlet pass the same flux, U0 H / l0^2 particles per
    second, and the fluid particle count stays level."""
    out = tmp_path / "plug"
    end = 0.5
    result = run_parmps([BOX, "-o", out, "--end-time", end, "--set", "fluid.viscosity=1e-6",
                         "--set", "time.output_interval=0.25"], ranks=2, timeout=300)
    series = check_run(result, out, end, ["box"])
    time, inflow, outflow = series["time"], series["inflow"], series["outflow"]
    late = time >= 0.1
    span = time[late][-1] - time[late][0]
    rate_in = (inflow[late][-1] - inflow[late][0]) / span
    rate_out = (outflow[late][-1] - outflow[late][0]) / span
    expected = analysis.inflow_rate(CHECKS["box_in_flow"].case())
    flux = CHECKS["box_in_flow"].tolerance["flux"]
    assert rate_in == pytest.approx(expected, rel=flux)
    assert rate_out == pytest.approx(rate_in, rel=flux)
    counts = series["n_fluid"]
    assert np.ptp(counts[late]) < 0.02 * counts[0]


# --- the same answer on 1, 2 and 3 ranks --------------------------------------------------------

def compare(reference, other):
    a, b = read_frame(reference / "result.h5"), read_frame(other / "result.h5")
    assert np.array_equal(a["id"], b["id"])
    scale = np.abs(a["position"]).max()
    assert np.abs(a["position"] - b["position"]).max() <= 1e-9 * scale
    assert np.abs(a["pressure"] - b["pressure"]).max() <= 1e-7 * max(np.abs(a["pressure"]).max(),
                                                                   1.0)


@pytest.mark.mpi
@pytest.mark.parametrize("case, end, body", [(MEMBRANE, 0.05, "membrane"), (BOX, 0.1, "box")])
def test_same_answer_on_one_two_three_ranks(tmp_path, case, end, body):
    outs = []
    for ranks in (1, 2, 3):
        out = tmp_path / f"r{ranks}"
        result = run_parmps([case, "-o", out, "--end-time", end, "-pressure_ksp_rtol", "1e-12"],
                            ranks=ranks, timeout=240)
        check_run(result, out, end, [body])
        outs.append(out)
    for other in outs[1:]:
        compare(outs[0], other)
    forces = [solids(out / "result.h5", body)["fluid_force"] for out in outs]
    for force in forces[1:]:
        assert np.abs(force - forces[0]).max() <= 1e-7 * np.abs(forces[0]).max()


# --- bad input and lean scenes ------------------------------------------------------------------

ARCHIMEDES_TEXT = ARCHIMEDES.read_text()
BOX_TEXT = BOX.read_text()
BAD = {
    "body overlapping fluid": (
        ARCHIMEDES_TEXT.replace("lower = [0.075, 0.075]", "lower = [0.055, 0.075]"),
        "body[0] 'block' overlaps fluid_block"),
    "body spacing not l0": (
        ARCHIMEDES_TEXT.replace("spacing = 0.01\nlower = [0.075", "spacing = 0.02\nlower = [0.075"),
        "must equal particles.spacing"),
    "inlet outside the domain": (
        BOX_TEXT.replace("lower = [0.76, 0.0]\nupper = [0.8, 0.21]",
                         "lower = [0.78, 0.0]\nupper = [0.82, 0.21]"),
        "inlet[0] [0.78, 0]-[0.82, 0.21] is outside the domain"),
    "inlet velocity oblique": (
        BOX_TEXT.replace("velocity = [-0.1, 0.0]\n\n[[outlet]]", "velocity = [-0.1, 0.1]\n\n"
                                                                   "[[outlet]]"),
        "inlet[0].velocity"),
    "inlet too shallow": (
        BOX_TEXT.replace("lower = [0.76, 0.0]\nupper = [0.8, 0.21]",
                         "lower = [0.78, 0.0]\nupper = [0.8, 0.21]"),
        "needs at least 4"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_coupled_input(tmp_path, name):
    text, message = BAD[name]
    path = tmp_path / "case.toml"
    path.write_text(text)
    result = run_parmps([path, "--check"], timeout=60)
    assert result.returncode == 2, result.stderr
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr


LEAN = """
import sys
from parmps.cli import main
status = main(sys.argv[1:])
print(sorted(m for m in ("parmps.coupling.weak", "parmps.boundaries.open") if m in sys.modules))
sys.exit(status)
"""


def test_pure_fluid_case_builds_no_solid_or_inflow_machinery():
    result = subprocess.run([sys.executable, "-c", LEAN, CASES / "hydrostatic.toml", "--check"],
                            cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "[]"


def test_a_bodys_substeps_count_in_its_owners_load():
    """The coupling reports each body's node-substeps on its owner (body k on rank k mod P),
    and the fluid stepper hands them, times parallel.node_substep_weight, to the
    decomposition's balance as each rank's extra work."""
    from types import SimpleNamespace

    from parmps.coupling.weak import WeakCoupling
    from parmps.run.steppers import FluidStepper
    from parmps.solids import solid_model

    case = CHECKS["box_in_flow"].case()
    case["body"] = [case["body"][0], dict(case["body"][0], name="second")]
    model = solid_model(case)
    coupling = WeakCoupling.__new__(WeakCoupling)
    coupling.model, coupling.comm, coupling.owners = model, SimpleNamespace(size=3), [2, 0]
    dt = 1e-3
    counts = model.substep_counts(dt)
    nodes = [len(body.position) for body in model.bodies]
    work = coupling.node_substeps(dt)
    np.testing.assert_array_equal(work, [nodes[1] * counts["second"], 0,
                                         nodes[0] * counts["box"]])
    assert work.sum() > 0

    received = []
    stepper = FluidStepper.__new__(FluidStepper)
    stepper.case = {"parallel": {"node_substep_weight": 0.02}}
    stepper.participants = [coupling, SimpleNamespace(node_substeps=lambda dt: None)]
    stepper.decomposition = SimpleNamespace(set_extra_work=received.append)
    stepper._count_extra_work(dt)
    np.testing.assert_allclose(received[0], 0.02 * work)
