"""The fluid solver end to end: --check, hydrostatic pressure, output layout, PETSc options,
solver failure and Courant breaches (exit status 1 with the last good output kept)."""

import json
from pathlib import Path
import xml.etree.ElementTree as ElementTree

import h5py
import numpy as np
import pytest

from conftest import CASES, error_lines, run_parmps, run_python
from parmps import open_result, validation
from parmps.fluid import ppe as pressure
from parmps.tools import analysis
from parmps.io.frames import FRAME_FIELDS, read_frames
from parmps.run.driver import DRIVER_DIAGNOSTICS
from parmps.run.steppers import FluidStepper

# What a fluid run's diagnostics hold: the driver's columns and the fluid stepper's.
DIAGNOSTICS = tuple(DRIVER_DIAGNOSTICS) + tuple(FluidStepper.DIAGNOSTICS)

HYDROSTATIC = validation.load("hydrostatic")
DAM_BREAK = validation.load("dam_break")
# The dam break at a coarse resolution the test budget allows (a = 0.2 m, l0 = a/20).
COARSE_DAM_BREAK = ["--set", "particles.spacing=0.01"]


def test_check_prints_counts_reference_values_dt_and_memory(tmp_path):
    result = run_parmps([CASES / "dam_break.toml", "--check", "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["particles"]["fluid"] == 40 * 80
    assert summary["particles"]["total"] == sum(v for k, v in summary["particles"].items()
                                                if k != "total")
    # re = 2.3 l0 by hand: 4 neighbours at l0, 4 at sqrt(2) l0, 4 at 2 l0, 8 at sqrt(5) l0.
    n0 = 4 * (2.3 - 1) + 4 * (2.3 / 2 ** 0.5 - 1) + 4 * (2.3 / 2 - 1) + 8 * (2.3 / 5 ** 0.5 - 1)
    assert summary["n0"] == pytest.approx(n0, rel=1e-12)
    assert summary["lambda0"] > 0 and summary["initial_dt"] == pytest.approx(1e-3)
    assert summary["memory_estimate_mb"] > 0
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def hydrostatic_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("hydrostatic")
    # 2 s, averaged after 0.5 s: the column is still settling before that (the
    # 0.3-1 s mean sits 1.7 % low), and a longer window averages out the
    # whole-column pressure swings. Measured (validate hydrostatic, 2 ranks, the mixed source):
    # bottom -0.25 %, RMS 0.33 %, height -0.20 %.
    result = run_parmps([HYDROSTATIC.case_path, "-o", out,
                         "--end-time", HYDROSTATIC.run["end_time"]], timeout=300)
    assert result.returncode == 0, result.stderr
    return out, result


def test_hydrostatic_pressure_against_the_weight_above(hydrostatic_run):
    out, _ = hydrostatic_run
    measured = HYDROSTATIC.measure(out / "result.h5")
    assert abs(measured["bottom"]) < HYDROSTATIC.tolerance["bottom"], measured["bottom"]
    assert measured["rms"] < HYDROSTATIC.tolerance["rms"], measured["rms"]
    assert abs(measured["height_drift"]) < HYDROSTATIC.tolerance["height_drift"], \
        measured["height_drift"]
    # No fluid beyond the tank's inner walls and floor.
    case = HYDROSTATIC.case()
    tank = case["tank"][0]
    inside = (tank["lower"], [tank["upper"][0], case["domain"]["upper"][1]])
    assert analysis.escaped(out / "result.h5", *inside) == 0


@pytest.mark.slow
def test_hydrostatic_pressure_at_five_millimetres_meets_the_targets(tmp_path):
    """The still tank at l0 = 5 mm (6.4k particles, about 25 s): the bottom row's mean within
    0.5 % of rho g H, the RMS within 1 %, the bottom row's noise within 3 %, the column's height
    within 0.3 %."""
    tolerance = HYDROSTATIC.tolerance["fine"]
    result = run_parmps([HYDROSTATIC.case_path, "-o", tmp_path,
                         "--end-time", HYDROSTATIC.run["end_time"],
                         "--set", f"particles.spacing={HYDROSTATIC.run['fine_spacing']!r}",
                         "--set", "time.output_interval=0.01"], timeout=300)
    assert result.returncode == 0, result.stderr
    measured = HYDROSTATIC.measure(tmp_path / "result.h5")
    assert abs(measured["bottom"]) < tolerance["bottom"], measured["bottom"]
    assert measured["rms"] < tolerance["rms"], measured["rms"]
    assert measured["bottom_std"] < tolerance["bottom_noise"], measured["bottom_std"]
    assert abs(measured["height_drift"]) < tolerance["height_drift"], measured["height_drift"]


def test_dry_walls_hold_no_pressure_and_wet_walls_the_waters(hydrostatic_run):
    """The tank's walls more than two search radii above the water are left out of the step
    (P = 0, their number density not computed); the walls within one search radius of the
    water, and those within one of them, take part, and beside the water they carry its
    pressure. The still tank's last frame; the margins of half a spacing cover the last
    step's motion, a small fraction of it."""
    from scipy.spatial import cKDTree

    from parmps.core.particles import FLUID, WALL
    from parmps.fluid.constants import MPSConstants
    out, _ = hydrostatic_run
    constants = MPSConstants.from_case(HYDROSTATIC.case())
    frame = read_frames(out / "result.h5")[-1]
    fluid = frame["kind"] == FLUID
    wall = frame["kind"] == WALL
    distance, _ = cKDTree(frame["position"][fluid]).query(frame["position"][wall])
    margin = 0.5 * constants.spacing
    dry = distance > 2 * constants.search_radius + margin
    # Within one search radius of a wall within one of the water: a chain of two radii,
    # which a wall two radii away need not have (the side walls' top corners).
    wet = distance < constants.search_radius - margin
    to_wet, _ = cKDTree(frame["position"][wall][wet]).query(frame["position"][wall])
    taking_part = to_wet < constants.search_radius - margin
    # The walls' top rows, 10 l0 above the water; two layers on each side.
    assert dry.sum() >= 8 and taking_part.sum() > 100
    assert np.all(frame["pressure"][wall][dry] == 0.0)
    assert np.all(frame["number_density"][wall][dry] == 0.0)
    assert np.all(frame["number_density"][wall][taking_part] > 0.5 * constants.n0)
    # Below the surface's roughness, the walls beside the water read its pressure.
    deep = (distance < constants.re_laplacian) & (frame["position"][wall][:, 1] < 0.15)
    assert deep.sum() > 50 and np.all(frame["pressure"][wall][deep] > 0.0)
    # The particles carry the last step's flag (the load balance weighs them by it).
    from parmps.io.checkpoint import read_checkpoint
    saved = read_checkpoint(out).particles
    order = np.argsort(saved.id)
    assert np.array_equal(saved.id[order], frame["id"])
    flagged = saved.dry[order] == 1
    assert np.array_equal(flagged, wall & (frame["number_density"] == 0.0))
    assert np.all(flagged[wall][dry]) and not np.any(flagged[wall][taking_part])


def test_output_layout_and_xdmf(hydrostatic_run):
    out, result = hydrostatic_run
    assert "output: " in result.stderr
    with h5py.File(out / "result.h5", "r") as handle:
        assert handle.attrs["complete"]
        case = handle["case"].attrs
        assert "[[fluid_block]]" in case["toml"] and case["ranks"] == 1
        assert case["parmps_version"]
        frames = sorted(handle["frames"])
        # A frame every output interval to the end time, plus the initial frame (101).
        end = HYDROSTATIC.run["end_time"]
        interval = HYDROSTATIC.case()["time"]["output_interval"]
        assert frames[0] == "00000000" and len(frames) == round(end / interval) + 1
        last = handle["frames"][frames[-1]]
        assert last.attrs["time"] == pytest.approx(end)
        for name in FRAME_FIELDS:
            assert len(last[name]) == 752
        assert last["id"].dtype == np.int64 and last["kind"].dtype == np.int8
        assert last["position"].shape == (752, 2)
        steps = handle["diagnostics"]["step"][()]
        np.testing.assert_array_equal(steps, np.arange(1, len(steps) + 1))
        assert steps[-1] == last.attrs["step"]
        for name in DIAGNOSTICS:
            assert len(handle["diagnostics"][name]) == len(steps)
        assert np.all(handle["diagnostics"]["ksp_iterations"][()] > 0)
        assert np.all(handle["diagnostics"]["n_fluid"][()] == 400)
    root = ElementTree.parse(out / "result.xdmf").getroot()
    grids = root.findall(".//Grid[@GridType='Uniform']")
    assert len(grids) == len(frames)
    with h5py.File(out / "result.h5", "r") as handle:
        for item in root.iter("DataItem"):
            if item.get("Format") != "HDF":
                continue
            file_name, dataset = item.text.split(":")
            assert file_name == "result.h5"
            dims = tuple(int(d) for d in item.get("Dimensions").split())
            assert handle[dataset].shape == dims
        # Each particle is a vertex cell: the first N entries of /vertex_index.
        np.testing.assert_array_equal(handle["vertex_index"][()], np.arange(752))
        for grid in grids:
            (slab,) = grid.find("Topology")
            assert slab.get("ItemType") == "HyperSlab" and slab.get("Dimensions") == "752"
            assert slab[0].text.split() == ["0", "1", "752"]


SYMMETRY_CHECK = Path(__file__).parent / "mpi" / "symmetric_pressure_matrix.py"


@pytest.mark.parametrize("case, ranks, settings", [
    ("dam_break.toml", 2, ["particles.spacing=0.01"]),
    ("dam_break.toml", 1, ["particles.spacing=0.01", "mps.laplacian=higher_order"]),
    ("box_in_flow.toml", 2, []),
    ("hydrostatic_3d.toml", 2, []),
], ids=["walls-surface", "higher-order", "body-open-boundaries", "3d"])
def test_every_pressure_matrix_is_exactly_symmetric(tmp_path, case, ranks, settings):
    """The matrix is marked symmetric for GAMG, which then builds its graph from it as it
    is: every matrix of the first steps, whole across the ranks, equals its transpose bit
    for bit: with walls and a free surface, the higher-order Laplacian, a body's
    variable-density rows beside open boundaries, and in 3D."""
    overrides = [word for setting in settings + ["time.max_steps=8"]
                 for word in ("--set", setting)]
    result = run_python([SYMMETRY_CHECK, CASES / case, "-o", tmp_path] + overrides,
                        ranks=ranks, timeout=240)
    assert result.returncode == 0, result.stderr
    record = json.loads(result.stdout.strip().splitlines()[-1])
    assert record["matrices"] >= 8
    assert record["asymmetry"] == 0.0


RELAID_CHECK = Path(__file__).parent / "mpi" / "relaid_preconditioner.py"


@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_a_preconditioner_is_kept_across_a_new_layout_of_the_rows(ranks):
    """Rows that change rank (migration) or order keep the preconditioner set up for their
    earlier layout, matched by id (parmps.fluid.relaid; GAMG's finest level applies the
    step's matrix through the ids): the same system laid out anew takes the same CG
    iterations as in the set-up's layout, and one with a row gone and a row new since the
    set-up is solved, with one set-up; a set-up renewed on that layout (on 3 ranks some
    ranks' rows changed in number, others' not) does not hang. The answers are the
    system's (CG to rtol 1e-10 on a chain of condition number ~80: errors near 1e-9)."""
    result = run_python([RELAID_CHECK], ranks=ranks, timeout=120)
    assert result.returncode == 0, result.stderr
    record = json.loads(result.stdout.strip().splitlines()[-1])
    set_up, again, relaid, changed, renewed, kept = record["iterations"]
    assert again == set_up and relaid == again and changed <= again + 3
    assert record["setups_before_renewal"] == 1 and record["relaid"]
    assert record["finest_on_setup_layout"]
    # Renewed on layout C (some ranks' rows changed in number, others' not), then kept.
    assert record["setups"] == 2 and kept <= renewed + 3
    assert max(record["errors"]) < 1e-7


def test_petsc_options_reach_the_solver_and_divergence_exits_1(tmp_path):
    # One CG iteration cannot reach rtol 1e-14: the KSP reports DIVERGED_MAX_IT.
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.01",
                         "-pressure_ksp_max_it", "1", "-pressure_ksp_rtol", "1e-14"], timeout=120)
    assert result.returncode == 1, result.stderr
    (line,) = error_lines(result.stderr)
    assert "pressure solve diverged at step 1" in line and "DIVERGED_MAX_IT" in line
    with open_result(tmp_path) as run:
        assert not run.complete
        assert run.frames.steps[0] == 0


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_solve_whose_preconditioner_is_indefinite_is_done_with_the_diagonal(tmp_path, ranks):
    """Chebyshev bounds at 0.3 of GAMG's estimate make its smoother amplify the upper modes
    and the preconditioner indefinite (CG: DIVERGED_INDEFINITE_PC) at every step, as a
    mode on a few packed particles did at step 3842 of the SPHERIC tank on 1 rank
    (PressureSolver._solve_with_diagonal). Each step is then solved with the diagonal
    alone: the run ends, says so, and moves the particles as a run whose solves succeed
    (both to rtol 1e-12: the same by id within 1e-9 m)."""
    common = [CASES / "dam_break.toml", "--end-time", "0.02", "-pressure_ksp_rtol", "1e-12"]
    good = run_parmps(common + ["-o", tmp_path / "good"], timeout=120)
    assert good.returncode == 0, good.stderr
    bad = run_parmps(common + ["-o", tmp_path / "bad", "-pressure_mg_levels_ksp_chebyshev_esteig",
                               "0,0.1,0,0.3"], ranks=ranks, timeout=180)
    assert bad.returncode == 0, bad.stderr
    warnings = [line for line in bad.stderr.splitlines() if "with the diagonal alone" in line]
    assert len(warnings) == 20 and "DIVERGED_INDEFINITE_PC" in warnings[0]
    with open_result(tmp_path / "good") as a, open_result(tmp_path / "bad") as b:
        first, second = a.frames[-1], b.frames[-1]
        assert first.step == second.step == 20
        order_a, order_b = np.argsort(first.id), np.argsort(second.id)
        np.testing.assert_allclose(second.position[order_b], first.position[order_a],
                                   rtol=0, atol=1e-9)


def test_case_options_apply_and_command_line_wins(tmp_path):
    failing = ["--set", "pressure.options={ksp_max_it = 1, ksp_rtol = 1e-14}"]
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path / "a", "--end-time", "0.003"]
                        + failing, timeout=120)
    assert result.returncode == 1 and "DIVERGED_MAX_IT" in result.stderr
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path / "b", "--end-time", "0.003",
                         "-pressure_ksp_max_it", "500"] + failing, timeout=120)
    assert result.returncode == 0, result.stderr


def test_code_defaults_yield_to_case_options_and_the_command_line():
    gamg = {"pc_type": "gamg", "options": {}}
    assert pressure.option_values(gamg, lambda name: False) == pressure.code_defaults("gamg")
    assert pressure.option_values(gamg, lambda name: False, 3)["pc_gamg_threshold"] == "0.02"
    case = dict(gamg, options={"-mg_levels_ksp_max_it": 2, "pc_gamg_threshold": 0.1,
                               "ksp_monitor": True})
    values = pressure.option_values(case, lambda name: False)
    assert values == {"mg_levels_ksp_max_it": 2, "pc_gamg_threshold": 0.1, "ksp_monitor": "true"}
    values = pressure.option_values(case, lambda name: name == "pc_gamg_threshold")
    assert "pc_gamg_threshold" not in values and values["mg_levels_ksp_max_it"] == 2
    # Another preconditioner gets none of GAMG's defaults.
    assert pressure.option_values({"pc_type": "hypre", "options": {}}, lambda name: False) == {}


def test_gamg_threshold_keeps_the_two_nearest_lattice_shells_in_2d_and_3d():
    from parmps.core.lattice import coupling_shells
    for dimension, expected in ((2, 0.04), (3, 0.02)):
        shells, relative = coupling_shells(3.1, dimension)
        np.testing.assert_allclose(shells[:3], [1.0, np.sqrt(2.0), np.sqrt(dimension) if
                                                dimension == 3 else 2.0])
        threshold = pressure.gamg_threshold(dimension, 3.1)
        assert threshold == expected
        # Kept: the first two shells; dropped: the rest.
        assert relative[1] > threshold > relative[2]
    # In 3D the 2D value would drop even the nearest neighbours (0.039 of the diagonal).
    assert coupling_shells(3.1, 3)[1][0] < 0.04


def test_fixed_dt_beyond_courant_stops_with_message_and_keeps_output(tmp_path):
    result = run_parmps([CASES / "dam_break.toml", "-o", tmp_path, "--set", "time.fixed_dt=0.004",
                         "--set", "time.output_interval=0.02"] + COARSE_DAM_BREAK, timeout=120)
    assert result.returncode == 1, result.stderr
    (line,) = error_lines(result.stderr)
    assert "breaks the Courant limit" in line and "time.fixed_dt" in line
    step = int(line.split("step ")[1].split(":")[0])
    with open_result(tmp_path) as run:
        assert not run.complete
        assert len(run.frames) >= 2
        assert all(run.frames.steps < step)
        assert np.all(np.isfinite(run.frames[-1].position))


def test_dam_break_front_against_martin_moyce(tmp_path):
    # T = 3.11 is reached at t = 3.11 / sqrt(2 g / a) = 0.314 s for a = 0.2 m.
    result = run_parmps([CASES / "dam_break.toml", "-o", tmp_path, "--end-time", "0.33",
                         "--set", "time.output_interval=0.01"] + COARSE_DAM_BREAK, timeout=600)
    assert result.returncode == 0, result.stderr
    # The simulated front leads the experiment most early on (T < 2), however fine l0 is:
    # the record's release and t = 0 are undefined, so its course is judged with the best
    # constant delay, and the delay against the leads of other published codes.
    measured = DAM_BREAK.measure(tmp_path / "result.h5")
    assert measured["rms_delayed"] < DAM_BREAK.tolerance["rms_delayed"], measured
    low, high = DAM_BREAK.tolerance["delay"]
    assert low <= measured["delay"] <= high, measured


def test_end_time_is_reached_without_a_short_last_step():
    from parmps.run.schedule import EndCondition
    end = EndCondition(1.0)
    assert end.clip(0.0, 0.01) == 0.01
    # 2.0001 steps left: three equal steps, not two full ones and 1e-4 of one.
    assert end.clip(1.0 - 0.020001, 0.01) == pytest.approx(0.020001 / 3, rel=1e-12)
    # 9.5 steps left: ten of 0.95 dt.
    assert end.clip(1.0 - 0.095, 0.01) == pytest.approx(0.0095, rel=1e-12)
    # A sum of steps a few ulps short of a multiple of dt: that many steps, not one more.
    assert end.clip(1.0 - 0.03 * (1 + 1e-14), 0.01) == pytest.approx(0.01, rel=1e-12)


def test_the_last_pressure_of_a_run_is_not_a_spike(tmp_path):
    """A still tank whose end leaves 1e-1 of a step: the last frame's pressures are
    those of a normal step (a short last step answered with 1.8 times the
    pressure, a shorter one with more: the density source's deviation term goes
    as 1/dt^2)."""
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.0501",
                         "--set", "time.fixed_dt=0.001", "--set", "time.output_interval=0.01"],
                        timeout=120)
    assert result.returncode == 0, result.stderr
    frames = read_frames(tmp_path / "result.h5")
    assert abs(frames[-1]["time"] - 0.0501) < 1e-12
    before, last = (frames[-2]["pressure"].max(), frames[-1]["pressure"].max())
    # rho g H = 1962 Pa; the column still settles at 0.05 s: its peak swings by 10 %.
    assert last < 1.2 * before, (before, last)


def test_a_preconditioner_is_renewed_once_a_solve_costs_more_than_the_average_since_its_setup():
    from parmps.fluid.ppe import keep_preconditioner
    # Set-up worth 40 iterations, then solves of 10: the average per solve falls
    # (50, 30, 23.3, ...) and a solve of 10 stays below it: keep.
    assert keep_preconditioner(0, 10, 10, 40.0, 50)
    assert keep_preconditioner(3, 40, 10, 40.0, 50)
    # Solves grown to 25 after 4 of 10, 12, 15, 20 (average (40 + 57)/4 = 24.25): renew.
    assert not keep_preconditioner(3, 57, 25, 40.0, 50)
    # A free set-up is renewed as soon as a solve costs more than the mean.
    assert not keep_preconditioner(1, 20, 11, 0.0, 50)
    # Never more than the limit of reuses; a limit of 0 sets up every solve.
    assert not keep_preconditioner(50, 500, 1, 40.0, 50)
    assert not keep_preconditioner(0, 10, 1, 40.0, 0)


def _chain_rows(n, shift):
    """CSR rows of a chain's Laplacian plus ``shift`` on the diagonal (SPD), diagonal
    first, global columns on one rank."""
    indptr, columns, values = [0], [], []
    for i in range(n):
        neighbours = [j for j in (i - 1, i + 1) if 0 <= j < n]
        columns += [i] + neighbours
        values += [2.0 + shift] + [-1.0] * len(neighbours)
        indptr.append(len(columns))
    return np.array(indptr), np.array(columns, np.int32), np.array(values)


def _dense(indptr, columns, values):
    """The CSR rows as a dense matrix."""
    n = len(indptr) - 1
    dense = np.zeros((n, n))
    for row in range(n):
        dense[row, columns[indptr[row]:indptr[row + 1]]] = values[indptr[row]:indptr[row + 1]]
    return dense


# One rank: no columns of other ranks.
_NO_OTHER = (None, np.zeros(0, np.int32), np.zeros(0))


def test_a_kept_gamg_hierarchy_holds_no_matrix_between_solves():
    """GAMG applies a matrix on its finest level only, so a kept hierarchy is pointed at each
    step's matrix for its solve and holds none between solves: while a step solves, its
    matrix's arrays are the only ones alive (not the set-up's beside them), and after it
    none are (docs/performance.md, memory in 3D). The answers are the equations', with the
    preconditioner set up once."""
    import weakref

    from mpi4py import MPI

    from parmps import config, schema
    with open(CASES / "hydrostatic.toml") as handle:
        case = schema.validate(config.load_text(handle.read()))
    solver = pressure.PressureSolver(MPI.COMM_SELF, case["pressure"])
    n, alive, seen = 60, [], []
    solve_with = solver._solve_with

    def watching(ksp, matrix, b, x, guess, reuse, report_unused=False):
        def first_iteration(ksp, iteration, residual):
            if iteration == 0:
                seen.append([ref() is not None for ref in alive])
        ksp.cancelMonitor()
        ksp.setMonitor(first_iteration)
        return solve_with(ksp, matrix, b, x, guess, reuse, report_unused)

    solver._solve_with = watching
    for step, shift in enumerate((0.10, 0.11, 0.12)):
        indptr, columns, values = _chain_rows(n, shift)
        rhs = np.sin(np.arange(n))
        expected = np.linalg.solve(_dense(indptr, columns, values), rhs)
        alive.append(weakref.ref(values))
        p, _, _ = solver.solve((indptr, columns, values), _NO_OTHER, rhs, np.zeros(n), step,
                               np.arange(n))
        # CG stops at a residual of rtol 1e-6; the chain's condition number is about 40.
        assert np.linalg.norm(p - expected) <= 1e-4 * np.linalg.norm(expected)
        del indptr, columns, values
    assert solver.setups == 1
    pc = solver.ksp.getPC()
    assert pc.getType() == "gamg" and pc.getMGLevels() > 1
    assert seen == [[True], [False, True], [False, False, True]]
    assert [ref() is not None for ref in alive] == [False, False, False]
    # What the KSP and the finest level point at between solves has no entries.
    assert solver.ksp.getOperators()[0].getType() == "shell"
    assert pc.getMGSmoother(pc.getMGLevels() - 1).getOperators()[0].getType() == "shell"
    solver.destroy()


def test_a_preconditioner_that_applies_the_set_ups_matrix_keeps_it():
    """A preconditioner other than GAMG may apply the matrix it was set up on (SOR does): the
    KSP holds the set-up's matrix between solves and lets each later step's go with it."""
    import weakref

    from mpi4py import MPI

    from parmps import config, schema
    with open(CASES / "hydrostatic.toml") as handle:
        raw = config.load_text(handle.read())
    config.apply_override(raw, "pressure.pc_type=sor")
    solver = pressure.PressureSolver(MPI.COMM_SELF, schema.validate(raw)["pressure"])
    n, alive = 60, []
    for step, shift in enumerate((0.10, 0.11, 0.12)):
        indptr, columns, values = _chain_rows(n, shift)
        rhs = np.sin(np.arange(n))
        alive.append(weakref.ref(values))
        p, _, _ = solver.solve((indptr, columns, values), _NO_OTHER, rhs, np.zeros(n), step,
                               np.arange(n))
        residual = _dense(indptr, columns, values) @ p - rhs
        assert np.linalg.norm(residual) <= 1e-5 * np.linalg.norm(rhs)
        del indptr, columns, values
    assert solver.setups == 1
    assert solver.ksp.getOperators()[0].handle == solver.setup_matrix.handle
    assert [ref() is not None for ref in alive] == [True, False, False]
    solver.destroy()


def test_a_new_set_up_lets_the_last_set_ups_matrix_go_before_it_builds():
    """A set-up replaces the hierarchy built on the last set-up's matrix: that matrix, and
    the arrays it is made on, are gone once the new one is set up, not only after its
    solve (the set-up is the step's largest allocation; docs/performance.md, memory in
    3D)."""
    import weakref

    from mpi4py import MPI

    from parmps import config, schema
    with open(CASES / "hydrostatic.toml") as handle:
        raw = config.load_text(handle.read())
    # No reuse: every solve sets its preconditioner up afresh.
    config.apply_override(raw, "pressure.reuse_preconditioner=0")
    solver = pressure.PressureSolver(MPI.COMM_SELF, schema.validate(raw)["pressure"])
    n, alive, seen = 60, [], []
    solve_with = solver._solve_with

    def watching(ksp, matrix, b, x, guess, reuse, report_unused=False):
        # CG's first iteration comes after the set-up: which matrices' arrays live then.
        def first_iteration(ksp, iteration, residual):
            if iteration == 0:
                seen.append((reuse, [ref() is not None for ref in alive]))
        ksp.cancelMonitor()
        ksp.setMonitor(first_iteration)
        return solve_with(ksp, matrix, b, x, guess, reuse, report_unused)

    solver._solve_with = watching
    for step, shift in enumerate((0.10, 0.11, 0.12)):
        indptr, columns, values = _chain_rows(n, shift)
        alive.append(weakref.ref(values))
        solver.solve((indptr, columns, values), _NO_OTHER, np.sin(np.arange(n)), np.zeros(n),
                     step, np.arange(n))
        del indptr, columns, values
    assert solver.setups == 3
    assert seen == [(False, [True]), (False, [False, True]), (False, [False, False, True])]
    solver.destroy()
