"""Fluid leaving the domain (domain.escaped_fluid): spray is removed and counted, on any rank
count and across a restart; "stop", a flood past domain.max_escaped_fraction and any other
particle leaving stop the run with one line and exit status 1."""

from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import error_lines, run_parmps
from parmps import open_result, schema
from parmps.core.particles import FLUID, SOLID, WALL, Particles
from parmps.coupling.weak import REACH, WeakCoupling, light_bodies
from parmps.errors import RunFailure
from parmps.io.frames import read_frames
from parmps.run.escaped import EscapedFluid

SPRAY = Path(__file__).parent / "cases" / "spray.toml"
# The spray case's droplets: particle 400 leaves at step 9, particle 401 at step 13; the
# water is particles 0-399. One step length throughout, so runs split by a restart
# take the same steps.
DROPLETS = (400, 401)
FIXED_DT = ["--set", "time.fixed_dt=0.001"]
TIGHT = ["-pressure_ksp_rtol", "1e-12"]


def _diagnostics(path, *names):
    with open_result(path) as run:
        return [run.diagnostics[name] for name in names]


def _last_frame_ids(path):
    return read_frames(path)[-1]["id"]


@pytest.fixture(scope="module")
def spray_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("spray")
    result = run_parmps([SPRAY, "-o", out] + FIXED_DT + TIGHT, timeout=120)
    assert result.returncode == 0, result.stderr
    return out, result


def test_spray_is_removed_counted_and_the_run_goes_on(spray_run):
    out, result = spray_run
    with open_result(out) as run:
        assert run.complete
    step, escaped, fluid = _diagnostics(out / "result.h5", "step", "n_escaped", "n_fluid")
    assert step[-1] == 30
    # Cumulative: one from step 9, both from step 13.
    assert escaped[step == 8] == 0 and escaped[step == 9] == 1 and escaped[step == 13] == 2
    assert escaped[-1] == 2 and fluid[-1] == 400
    frames = read_frames(out / "result.h5")
    assert set(DROPLETS) <= set(frames[0]["id"])
    assert not set(DROPLETS) & set(frames[-1]["id"])
    assert len(frames[-1]["id"]) == len(frames[0]["id"]) - 2
    # One warning, for the first, naming the particle, where, the step and the time.
    warnings = [line for line in result.stderr.splitlines() if "WARNING" in line]
    assert len(warnings) == 1, warnings
    assert ("step 9, t = 0.009 s: fluid particle 400 left the domain at (0.025, 0.3616) and "
            "was removed") in warnings[0]
    assert "2 fluid particle(s) left the domain and were removed" in result.stderr


def test_stop_stops_at_the_first_with_one_line(tmp_path):
    result = run_parmps([SPRAY, "-o", tmp_path, "--set", 'domain.escaped_fluid="stop"']
                        + FIXED_DT, timeout=120)
    assert result.returncode == 1, result.stderr
    (line,) = error_lines(result.stderr)
    assert line.startswith("parmps: error: step 9: fluid particle 400 left the domain at "
                           "(0.025, 0.3616), above y = 0.36 (domain.upper[1]), moving at "), line
    assert line.endswith(" m/s (through a wall, or the domain is too small; "
                         "domain.escaped_fluid = \"remove\" removes fluid spray instead)"), line


def test_a_flood_past_the_fraction_stops_the_run(tmp_path):
    # 0.004 of 402 is 1.6 particles: the first is spray, the second a flood.
    result = run_parmps([SPRAY, "-o", tmp_path, "--set", "domain.max_escaped_fraction=0.004"]
                        + FIXED_DT, timeout=120)
    assert result.returncode == 1, result.stderr
    (line,) = error_lines(result.stderr)
    assert line.startswith("parmps: error: step 13: 2 fluid particles have left the domain, "
                           "more than domain.max_escaped_fraction = 0.004 of the 402 at t = 0 "
                           "(this step particle 401 at ("), line


@pytest.mark.parametrize("text, message", [
    ('escaped_fluid = "drop"', "domain.escaped_fluid must be one of 'remove', 'stop', got 'drop'"),
    ("max_escaped_fraction = 2.0", "domain.max_escaped_fraction must be <= 1.0, got 2.0"),
])
def test_bad_settings_are_refused_in_one_line(tmp_path, text, message):
    case = tmp_path / "case.toml"
    case.write_text(SPRAY.read_text().replace("upper = [0.26, 0.36]\n",
                                              f"upper = [0.26, 0.36]\n{text}\n", 1))
    result = run_parmps([case, "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 2, result.stderr
    (line,) = error_lines(result.stderr)
    assert line.endswith(message), line


@pytest.mark.mpi
def test_two_ranks_remove_the_same_particles(spray_run, tmp_path):
    # The droplets sit at either end of the tank: each rank removes one.
    out, _ = spray_run
    result = run_parmps([SPRAY, "-o", tmp_path] + FIXED_DT + TIGHT, ranks=2, timeout=180)
    assert result.returncode == 0, result.stderr
    assert "[rank 1/2]" not in result.stderr  # the warning is rank 0's alone
    one, two = read_frames(out / "result.h5")[-1], read_frames(tmp_path / "result.h5")[-1]
    np.testing.assert_array_equal(two["id"], one["id"])
    assert np.abs(two["position"] - one["position"]).max() < 1e-9
    np.testing.assert_array_equal(*[_diagnostics(path, "n_escaped")[0]
                                    for path in (out / "result.h5", tmp_path / "result.h5")])


@pytest.mark.mpi
def test_the_count_survives_a_restart_on_another_rank_count(spray_run, tmp_path):
    # Split after the first removal: the second comes after the restart.
    out, _ = spray_run
    result = run_parmps([SPRAY, "-o", tmp_path, "--end-time", "0.011"] + FIXED_DT + TIGHT,
                        timeout=120)
    assert result.returncode == 0, result.stderr
    with h5py.File(tmp_path / "checkpoint.h5", "r") as handle:
        assert handle["state/stepper/escaped_fluid/total"][()] == 1
    result = run_parmps(["--restart", tmp_path, "--end-time", "0.03"] + TIGHT, ranks=2,
                        timeout=180)
    assert result.returncode == 0, result.stderr
    # Counted on from 1, not from 0: no second "first" warning.
    assert "WARNING" not in result.stderr
    whole, split = (_diagnostics(path, "n_escaped")[0]
                    for path in (out / "result.h5", tmp_path / "result.h5"))
    np.testing.assert_array_equal(split, whole)
    np.testing.assert_array_equal(_last_frame_ids(tmp_path / "result.h5"),
                                  _last_frame_ids(out / "result.h5"))


# -- the check alone, on one rank --------------------------------------------------------------

def _case(**domain):
    return schema.validate({"domain": {"lower": [0.0, 0.0], "upper": [1.0, 1.0], **domain},
                            "particles": {"spacing": 0.1}, "time": {"end": 1.0},
                            "fluid_block": [{"lower": [0.0, 0.0], "upper": [0.5, 0.5]}]})


def _particles(kinds, positions):
    n = len(kinds)
    return Particles({"id": np.arange(10, 10 + n, dtype=np.int64),
                      "kind": np.array(kinds, np.int8), "position": np.array(positions, float),
                      "velocity": np.tile([0.0, 2.0], (n, 1))})


def _nobody(pid):
    return None


def test_fluid_outside_is_removed_and_the_particles_left_are_owned_only():
    escaped = EscapedFluid(_case(), MPI.COMM_SELF, initial_fluid=1000)
    particles = _particles([FLUID, FLUID, WALL, FLUID], [[0.5, 0.5], [0.5, 1.2], [0.0, 0.0],
                                                         [-0.1, 0.5]])
    particles.n_owned = 3  # the last is a ghost: a neighbour's to remove
    kept, speed = escaped.apply(particles, 5, 0.05, _nobody)
    assert kept.id.tolist() == [10, 12] and kept.n_owned == 2
    assert speed == 2.0 and escaped.total == 1
    # Nothing outside: the same particles back, ghosts and all.
    again, speed = escaped.apply(particles.select([0, 2, 3], n_owned=2), 6, 0.06, _nobody)
    assert again.n_ghost == 1 and speed == 0.0 and escaped.total == 1


def test_any_other_particle_outside_stops_with_its_owner():
    escaped = EscapedFluid(_case(), MPI.COMM_SELF, initial_fluid=1000)
    particles = _particles([FLUID, WALL], [[0.5, 1.2], [1.3, 0.5]])
    with pytest.raises(RunFailure, match=r"^step 5: particle 11 of the moving tank\[0\] left "
                                         r"the domain at \(1\.3, 0\.5\), above x = 1 "
                                         r"\(domain\.upper\[0\]\), moving at 2 m/s; "
                                         r"stop it earlier$"):
        escaped.apply(particles, 5, 0.05, lambda pid: ("the moving tank[0]", "stop it earlier"))
    assert escaped.total == 0


def test_a_body_node_outside_names_its_body_the_bound_and_the_domain_key():
    """The membrane tube's failure (node 97 of its membrane through the domain's top at
    0.1 m/s): the line names the node and its body, the bound crossed and the key to
    change, and says nothing of density."""
    case = _case()
    case["body"] = [{"name": "membrane"}]
    escaped = EscapedFluid(case, MPI.COMM_SELF, initial_fluid=1000)
    particles = _particles([FLUID, SOLID], [[0.5, 0.5], [0.195, 1.0001]])
    particles.body[1], particles.node[1] = 0, 97
    particles.velocity[1] = [0.0, 0.1]
    with pytest.raises(RunFailure) as caught:
        escaped.apply(particles, 893, 0.893, _nobody)
    assert str(caught.value) == (
        "step 893: node 97 of body 'membrane' (particle 11) left the domain at (0.195, 1), "
        "above y = 1 (domain.upper[1]), moving at 0.1 m/s: the body moved out of the domain "
        "box. If that motion is expected, enlarge the domain (domain.lower, domain.upper); "
        "if not, the body went unstable (its stiffness, damping and loads in [[body]] "
        "'membrane')")


def test_only_a_body_below_the_fluids_density_is_called_light():
    # The membrane's nodes of mass rho l0^2 average to 0.9999999999999998 of a fluid
    # particle's: not lighter, and no failure is blamed on it.
    assert light_bodies({"membrane": 0.9999999999999998, "gate": 1.1}) == ""
    assert light_bodies({"box": 0.1, "membrane": 1.0}) == "body 'box' (solid/fluid density 0.1)"


def test_a_failure_far_from_every_light_body_is_not_blamed_on_it():
    """The elastic gate at the defaults stopped with a fluid particle in the far wall,
    0.4 m (240 l0) from the gate, and the line blamed the gate (solid/fluid density 0.816):
    a light body is named only when the failure lies within REACH spacings of its nodes."""
    gate = SimpleNamespace(name="gate", position=np.array([[0.1, 0.0], [0.1, 0.08]]))
    coupling = SimpleNamespace(density_ratio={"gate": 0.816},
                               fluid=SimpleNamespace(constants=SimpleNamespace(spacing=0.01)),
                               model=SimpleNamespace(bodies=[gate]))
    named = "body 'gate' (solid/fluid density 0.816)"
    assert WeakCoupling.light_bodies(coupling) == named
    assert WeakCoupling.light_bodies(coupling, (0.1 + 0.99 * REACH * 0.01, 0.0)) == named
    assert WeakCoupling.light_bodies(coupling, (0.501, 0.0017)) == ""
