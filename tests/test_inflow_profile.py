"""Profiled, ramped and tabulated inflow (parmps.boundaries.open, parmps.core.timeseries)
and the oscillating body force.

The inlet's lanes are driven here without a fluid step (update, then entering, as the
open boundaries apply them after each step): the particles that became fluid times
the particle volume l0^d against the mean times the area times the time, within 1 % and
within the lattice's discreteness (half a particle per lane); the lanes' speeds against
the analytic profiles; ids unique and a function of the time alone. Then the example
case runs: its inflow diagnostics against S(t) x area, the same particles by id on 2
ranks as on 1, and the oscillating body force whose work the energy watch counts.
"""

import math
import tomllib

import h5py
import numpy as np
import pytest

from conftest import CASES, error_lines, run_parmps
from parmps import schema
from parmps.boundaries.open import Inlet
from parmps.boundaries.profiles import duct
from parmps.core.particles import FLUID, INFLOW, Particles
from parmps.core.timeseries import Oscillation, Ramp, Table, read_table
from parmps.errors import CaseError
from parmps.result import open_result

CASE_2D = """
[domain]
lower = [0.0, 0.0]
upper = [1.0, 0.2]
[particles]
spacing = 0.01
[time]
end = 1.0
[[inlet]]
lower = [0.0, 0.0]
upper = [0.04, 0.2]
velocity = [0.1, 0.0]
"""

CASE_3D = """
[domain]
lower = [0.0, 0.0, 0.0]
upper = [1.0, 0.2, 0.12]
[particles]
spacing = 0.01
[time]
end = 1.0
[[inlet]]
lower = [0.96, 0.0, 0.0]
upper = [1.0, 0.2, 0.12]
velocity = [-0.1, 0.0, 0.0]
"""


def make_case(text, **keys):
    raw = tomllib.loads(text)
    raw["inlet"][0].update(keys)
    return schema.validate(raw)


def make_inlet(text, **keys):
    case = make_case(text, **keys)
    return Inlet(case["inlet"][0], 0, case, 0), case


def drive(inlet, times):
    """Apply the inlet's motion at ``times``; returns (ids ever created, ids turned fluid,
    the cumulative count turned fluid at each time)."""
    particles = inlet.initial()
    created, turned, counts = [particles.id.copy()], [], []
    total = 0
    for t in times:
        total += inlet.update(particles, t)
        fluid = particles.kind == FLUID
        turned.append(particles.id[fluid])
        particles = particles.select(np.flatnonzero(~fluid))
        entering = inlet.entering(t)
        created.append(entering.id)
        particles = Particles.concatenate([particles, entering])
        counts.append(total)
    return np.concatenate(created), np.concatenate(turned), np.array(counts), particles


def opening_area(spec, dimension):
    if spec["shape"] == "circle":
        return math.pi * spec["radius"] ** 2
    widths = np.subtract(spec["upper"], spec["lower"])
    axis = int(np.flatnonzero(spec["velocity"])[0])
    return float(np.prod(np.delete(widths, axis)))


@pytest.mark.parametrize("text, keys", [
    (CASE_2D, {}), (CASE_2D, {"profile": "parabolic"}),
    (CASE_2D, {"profile": "parabolic", "ramp": 0.5}),
    (CASE_3D, {}), (CASE_3D, {"profile": "parabolic"}),
    (CASE_3D, {"profile": "parabolic", "shape": "circle", "radius": 0.05}),
    (CASE_3D, {"shape": "circle", "radius": 0.05, "ramp": 0.3}),
])
def test_delivered_flow_rate_is_the_mean_times_the_area(text, keys):
    inlet, case = make_inlet(text, **keys)
    spec, d = case["inlet"][0], case["dimension"]
    times = np.arange(1, 2001) * 1e-3
    created, turned, counts, _ = drive(inlet, times)
    volume = counts * 0.01 ** d
    expected = np.array([inlet.mean.integral(t) for t in times]) * opening_area(spec, d)
    # Each lane has turned a whole number of particles: at most half a particle off.
    assert np.all(np.abs(volume - expected) <= 0.5 * inlet.count * 0.01 ** d + 1e-15)
    assert abs(volume[-1] / expected[-1] - 1.0) < 0.01, volume[-1] / expected[-1]
    assert len(np.unique(created)) == len(created)
    assert len(np.unique(turned)) == len(turned)


def test_parabolic_lanes_follow_the_channel_profile():
    inlet, _ = make_inlet(CASE_2D, profile="parabolic")
    y = inlet.across[:, 0]
    analytic = 1.5 * (1.0 - (2.0 * (y - 0.1) / 0.2) ** 2)
    # The lanes are the profile scaled so that their mean is exactly 1: the midpoint
    # rule's mean of 1.5 (1 - x^2) over n lanes is 1 + 1 / (2 n^2).
    n = len(y)
    np.testing.assert_allclose(inlet.shape, analytic / (1.0 + 0.5 / n ** 2), rtol=1e-12)
    assert inlet.shape.mean() == pytest.approx(1.0, rel=1e-12)


def test_duct_series_gives_the_square_duct_and_the_wide_channel():
    # The square duct's centre-line velocity over its mean: 2.0963 (White, Table 3-2).
    assert duct(np.array([0.0]), np.array([0.0]), 1.0, 1.0)[0] == pytest.approx(2.0963,
                                                                                 abs=1e-4)
    # A very wide duct is a channel across its short side, 1.5 at the centre, but for
    # the side walls' share of the mean: 1 - (192 / pi^5) (a / b) sum_{n odd} n^-5
    # (White, eq. 3-49, tanh = 1), the sum (31 / 32) zeta(5).
    odd_sum = 31.0 / 32.0 * 1.0369277551433699
    wide = 1.5 / (1.0 - 192.0 / math.pi ** 5 * odd_sum / 200.0)
    assert duct(np.array([0.0]), np.array([0.0]), 1.0, 200.0)[0] == pytest.approx(wide,
                                                                                  rel=1e-6)
    # Zero on the walls; the mean over a fine midpoint grid is 1.
    assert abs(duct(np.array([1.0, 0.3]), np.array([0.2, 0.5]), 1.0, 0.5)).max() < 1e-9
    x = (np.arange(200) + 0.5) / 200 * 2.0 - 1.0
    y, z = np.meshgrid(x, 0.5 * x, indexing="ij")
    assert duct(y.ravel(), z.ravel(), 1.0, 0.5).mean() == pytest.approx(1.0, abs=1e-4)


def test_3d_lanes_follow_the_duct_and_the_pipe():
    inlet, _ = make_inlet(CASE_3D, profile="parabolic")
    centre = np.array([0.1, 0.06])
    offset = inlet.across - centre
    exact = duct(offset[:, 0], offset[:, 1], 0.1, 0.06)
    np.testing.assert_allclose(inlet.shape / exact, inlet.shape[0] / exact[0], rtol=1e-9)
    assert inlet.shape.mean() == pytest.approx(1.0, rel=1e-12)
    pipe, _ = make_inlet(CASE_3D, profile="parabolic", shape="circle", radius=0.05)
    r2 = np.sum((pipe.across - centre) ** 2, axis=1)
    assert r2.max() < 0.05 ** 2
    scale = pipe.shape[0] / (2.0 * (1.0 - r2[0] / 0.05 ** 2))
    np.testing.assert_allclose(pipe.shape, scale * 2.0 * (1.0 - r2 / 0.05 ** 2), rtol=1e-12)
    # The scale is the lattice's: the lanes' area over the circle's, within a few %.
    assert abs(scale - 1.0) < 0.05


def test_lanes_move_at_their_speed_and_ids_depend_on_the_time_alone():
    inlet, _ = make_inlet(CASE_2D, profile="parabolic", ramp=0.2)
    _, turned_a, _, left_a = drive(inlet, np.arange(1, 401) * 1e-3)
    other, _ = make_inlet(CASE_2D, profile="parabolic", ramp=0.2)
    times = np.cumsum(np.tile([0.7e-3, 1.9e-3, 1.4e-3], 100))
    _, turned_b, _, left_b = drive(other, np.append(times[times < 0.4], 0.4))
    np.testing.assert_array_equal(np.sort(turned_a), np.sort(turned_b))
    np.testing.assert_array_equal(np.sort(left_a.id), np.sort(left_b.id))
    # Every buffer particle sits where its lane's shape times S(0.4) carried it.
    order = np.argsort(left_a.id)
    lane = left_a.id[order] % inlet.count
    column = left_a.id[order] // inlet.count
    s = (inlet.columns - column - 0.5) * 0.01 + inlet.shape[lane] * inlet.mean.integral(0.4)
    np.testing.assert_allclose(left_a.position[order, 0], s, atol=1e-12)
    np.testing.assert_allclose(left_a.velocity[order, 0], inlet.shape[lane] * 0.1)
    assert np.all(left_a.kind == INFLOW) and np.all((s >= 0.0) & (s <= 0.04 + 1e-12))


def test_ramp_is_turek_and_hrons_start():
    ramp = Ramp(2.0, 0.5)
    assert ramp.value(0.0) == 0.0 and ramp.value(0.25) == pytest.approx(1.0)
    assert ramp.value(0.5) == 2.0 and ramp.value(3.0) == 2.0
    t = np.linspace(0.0, 1.2, 120001)
    numeric = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(t) * np.convolve(
        [ramp.value(x) for x in t], [1, 1], "valid"))])
    analytic = np.array([ramp.integral(x) for x in t])
    assert np.abs(analytic - numeric).max() < 1e-9
    assert ramp.integral(1.2) == pytest.approx(2.0 * (1.2 - 0.25), rel=1e-14)


def test_table_is_interpolated_and_integrated_exactly(tmp_path):
    path = tmp_path / "flow.txt"
    path.write_text("# t  U\n0.1, 0.0\n0.3 0.2\n\n0.4 0.05   # a dip\n0.8 0.3\n")
    rows = read_table(str(path), "inlet[0].table")
    table = Table(rows[:, 0], rows[:, 1])
    assert table.value(0.0) == 0.0 and table.value(0.2) == pytest.approx(0.1)
    assert table.value(0.35) == pytest.approx(0.125) and table.value(5.0) == 0.3
    # Exact for the piecewise-linear interpolant: trapezoids between the rows.
    assert table.integral(0.3) == pytest.approx(0.5 * 0.2 * 0.2, rel=1e-14)
    assert table.integral(0.8) == pytest.approx(0.02 + 0.0125 + 0.07, rel=1e-14)
    assert table.integral(1.0) == pytest.approx(0.1025 + 0.06, rel=1e-14)
    t = np.linspace(0.0, 1.0, 200001)
    values = np.array([table.value(x) for x in t])
    numeric = np.sum(0.5 * np.diff(t) * (values[1:] + values[:-1]))
    assert table.integral(1.0) == pytest.approx(numeric, abs=1e-9)
    assert table.peak(0.25, 0.5) == pytest.approx(0.2)


def test_oscillating_body_force_gives_the_steps_exact_impulse():
    force = Oscillation([0.0, -1.0], [2.0, 0.0], 0.5)
    assert force.varies
    np.testing.assert_allclose(force.value(0.0), [2.0, -1.0])
    np.testing.assert_allclose(force.value(1.0), [-2.0, -1.0], atol=1e-12)
    impulse = force.mean(0.2, 0.7) * 0.5
    exact = [2.0 * (math.sin(math.pi * 0.7) - math.sin(math.pi * 0.2)) / math.pi, -0.5]
    np.testing.assert_allclose(impulse, exact, rtol=1e-13)
    assert not Oscillation([0.0, -9.81]).varies


def _error(text, **keys):
    with pytest.raises(CaseError) as caught:
        make_case(text, **keys)
    return str(caught.value)


def test_bad_inlet_keys_are_one_line_errors(tmp_path):
    assert "inlet[0].profile must be one of 'uniform', 'parabolic'" in _error(
        CASE_2D, profile="poiseuille")
    assert "inlet[0].ramp must be > 0.0, got 0.0" in _error(CASE_2D, ramp=0.0)
    assert "inlet[0].ramp must be > 0.0" in _error(CASE_2D, ramp=-1.0)
    assert "no such file" in _error(CASE_2D, table=str(tmp_path / "none.txt"))
    bad = {"one row": "0 1\n", "three columns": "0 1 2\n1 1 2\n", "words": "0 1\n1 fast\n",
           "decreasing": "0 1\n2 1\n1 1\n", "repeated time": "0 1\n0 2\n",
           "negative": "0 1\n1 -1\n"}
    expected = {"one row": "has 1 row(s); a table needs at least 2",
                "three columns": "line 1 has 3 columns, expected 2",
                "words": "line 2 is not 2 numbers", "decreasing": "the times must increase",
                "repeated time": "the times must increase", "negative": "must be >= 0"}
    for label, text in bad.items():
        path = tmp_path / f"{label}.txt"
        path.write_text(text)
        message = _error(CASE_2D, table=str(path))
        assert message.startswith("inlet[0].table") and expected[label] in message, message
        assert "\n" not in message
    assert "give ramp or table, not both" in _error(
        CASE_2D, ramp=1.0, table=str(tmp_path / "one row.txt"))
    assert "circle\" is an opening of a 3D case" in _error(CASE_2D, shape="circle",
                                                            radius=0.05)
    assert "the circle must fit" in _error(CASE_3D, shape="circle", radius=0.07)
    assert "inlet[0].radius must be > 0" in _error(CASE_3D, shape="circle")


def test_bad_body_force_keys_are_one_line_errors():
    raw = tomllib.loads(CASE_2D)
    raw["physics"] = {"gravity_amplitude": [1.0, 0.0]}
    with pytest.raises(CaseError, match="physics.gravity_frequency is not"):
        schema.validate(raw)


def test_a_missing_table_exits_2_from_the_case_files_directory(tmp_path):
    text = (CASES / "channel_inlet_2d.toml").read_text().replace(
        "ramp = 0.2", 'table = "pulse.txt"')
    (tmp_path / "case.toml").write_text(text)
    result = run_parmps([tmp_path / "case.toml", "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 2, result.stderr
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and "inlet[0].table: no such file" in lines[0], result.stderr
    assert str(tmp_path / "pulse.txt") in lines[0]
    # The same file found next to the case, whatever the working directory.
    (tmp_path / "pulse.txt").write_text("0 0\n0.1 0.1\n")
    result = run_parmps([tmp_path / "case.toml", "-o", tmp_path / "out", "--end-time",
                         "0.2"], timeout=120)
    assert result.returncode == 0, result.stderr
    with open_result(tmp_path / "out") as run:
        d = run.diagnostics
        delivered = d["inflow"][-1] * 0.005 ** 2
        expected = (0.005 + 0.1 * (d["time"][-1] - 0.1)) * 0.1
        # A short run: within the 20 lanes' discreteness, half a particle each.
        assert abs(delivered - expected) <= 0.5 * 20 * 0.005 ** 2


def test_example_channel_delivers_its_flow_rate(tmp_path):
    result = run_parmps([CASES / "channel_inlet_2d.toml", "-o", tmp_path / "out"],
                        timeout=300)
    assert result.returncode == 0, result.stderr
    assert "mechanical energy" not in result.stderr
    with open_result(tmp_path / "out") as run:
        d = run.diagnostics
        t = d["time"][-1]
        delivered = d["inflow"][-1] * 0.005 ** 2
        expected = Ramp(0.1, 0.2).integral(t) * 0.1
        assert abs(delivered / expected - 1.0) < 0.01, delivered / expected


def test_an_oscillating_body_force_does_work_the_watch_counts(tmp_path):
    # A still tank shaken up and down: g(t) = -9.81 + 4 cos(2 pi 2 t). The potential
    # energy follows g(t); its explicit change is the body force's work, not a source.
    result = run_parmps([CASES / "hydrostatic.toml", "--end-time", "0.5", "-o",
                         tmp_path / "out", "--set", "physics.gravity_amplitude=[0.0, 4.0]",
                         "--set", "physics.gravity_frequency=2.0"], timeout=300)
    assert result.returncode == 0, result.stderr
    assert "mechanical energy" not in result.stderr
    with open_result(tmp_path / "out") as run:
        d = run.diagnostics
        work = d["body_force_work"]
        # The potential energy swings by about 4 / 9.81 of itself; the work balances it.
        swing = np.ptp(d["potential_energy"])
        assert swing > 0.5 * 4.0 / 9.81 * np.abs(d["potential_energy"]).max()
        budget = d["fluid_energy"] - d["boundary_work"] - work
        assert np.ptp(budget) < 0.02 * swing, (np.ptp(budget), swing)


def _last_frame(path):
    with h5py.File(path, "r") as handle:
        group = handle["frames"][sorted(handle["frames"])[-1]]
        ids = group["id"][()]
        order = np.argsort(ids)
        return ids[order], group["position"][()][order]


@pytest.mark.mpi
def test_two_ranks_give_the_same_particles_by_id(tmp_path):
    frames = []
    for ranks in (1, 2):
        out = tmp_path / f"r{ranks}"
        result = run_parmps([CASES / "channel_inlet_2d.toml", "-o", out, "--end-time", "0.3",
                             "-pressure_ksp_rtol", "1e-12"], ranks=ranks, timeout=300)
        assert result.returncode == 0, result.stderr[-3000:]
        frames.append(_last_frame(out / "result.h5"))
    (ids1, x1), (ids2, x2) = frames
    np.testing.assert_array_equal(ids1, ids2)
    assert np.abs(x1 - x2).max() < 1e-9 * 0.6


def test_checkpoints_keep_every_lanes_count():
    from mpi4py import MPI

    from parmps.boundaries.open import OpenBoundaries
    raw = tomllib.loads(CASE_2D)
    raw["inlet"][0]["profile"] = "parabolic"
    raw["inlet"].append({"lower": [0.96, 0.0], "upper": [1.0, 0.1], "velocity": [-0.2, 0.0]})
    case = schema.validate(raw)
    boundaries = OpenBoundaries(case, MPI.COMM_SELF)
    for inlet in boundaries.inlets:
        drive(inlet, np.arange(1, 301) * 1e-3)
    assert len(np.unique(boundaries.inlets[0].created)) > 1  # the lanes went apart
    saved = boundaries.checkpoint_state()
    restored = OpenBoundaries(case, MPI.COMM_SELF)
    restored.restore_state(saved)
    for inlet, again in zip(boundaries.inlets, restored.inlets):
        np.testing.assert_array_equal(inlet.created, again.created)
    # A checkpoint from before the lanes: one column count per inlet.
    restored.restore_state({"created": np.array([7, 9]), "inflow_total": 0,
                            "outflow_total": 0})
    assert np.all(restored.inlets[0].created == 7) and np.all(restored.inlets[1].created == 9)
