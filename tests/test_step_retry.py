"""A step that fails its checks is redone from its start with half its dt (time.retries)."""

import numpy as np
import pytest

import parmps
from conftest import CASES, error_lines, run_parmps
from parmps.core.particles import Particles
from parmps.errors import RunFailure
from parmps.run.driver import RunState, advance, take_step
from parmps.run.schedule import EndCondition


class OneRank:
    rank = 0
    size = 1

    def allreduce(self, value, op=None):
        return value


class StepperFailingAbove:
    """Moves every particle by dt along x and counts its steps; a step longer than
    ``longest`` fails its check, as a Courant breach does."""

    def __init__(self, longest):
        self.longest = longest
        self.counter = np.zeros(1)  # state kept in an array: a restore must not share it
        self.restored = 0

    def checkpoint_state(self):
        return {"counter": self.counter}

    def restore_state(self, saved):
        self.counter = saved["counter"]
        self.restored += 1

    def start(self, state):
        pass

    def dt_limits(self, state):
        return []

    def advance(self, state, dt):
        state.particles.position[:, 0] += dt
        self.counter += 1

    def check(self, state):
        if state.dt > self.longest:
            raise RunFailure(f"step {state.step}: dt {state.dt:g} s too long")

    def diagnostics(self, state):
        return {}

    def failure_cause(self, where=None):
        return None


def _state():
    return RunState(particles=Particles({"id": np.arange(3), "position": np.zeros((3, 2))}))


def test_a_failed_step_is_redone_from_its_start_with_half_the_dt():
    state, stepper = _state(), StepperFailingAbove(longest=0.3)
    redone = take_step(OneRank(), state, stepper, 1.0, retries=3)
    # 1.0 and 0.5 fail, 0.25 passes: the particles moved by 0.25 only, once.
    assert redone == 2
    assert stepper.restored == 2
    assert state.dt == 0.25 and state.time == 0.25 and state.step == 1
    np.testing.assert_array_equal(state.particles.position[:, 0], 0.25)
    # The stepper's state is the start's, advanced once: not the failed attempts'.
    assert stepper.counter[0] == 1


def test_a_step_that_fails_at_every_dt_stops_with_its_last_failure():
    state, stepper = _state(), StepperFailingAbove(longest=0.01)
    with pytest.raises(RunFailure, match=r"step 1: dt 0.125 s too long \(the step failed 4 "
                                         r"times, down to dt = 0.125 s\)"):
        take_step(OneRank(), state, stepper, 1.0, retries=3)


def test_no_retries_stops_at_the_first_failure():
    state, stepper = _state(), StepperFailingAbove(longest=0.3)
    with pytest.raises(RunFailure, match=r"^step 1: dt 1 s too long$"):
        take_step(OneRank(), state, stepper, 1.0, retries=0)
    assert stepper.restored == 0


def test_a_fixed_dt_is_never_shortened():
    state, stepper = _state(), StepperFailingAbove(longest=0.3)
    settings = {"fixed_dt": 0.5, "dt_max": 1.0, "retries": 3}
    with pytest.raises(RunFailure, match=r"^step 1: dt 0.5 s too long$"):
        advance(OneRank(), state, stepper, [], EndCondition(10.0), settings)


def test_the_redone_steps_are_in_the_diagnostics():
    state, stepper = _state(), StepperFailingAbove(longest=0.3)
    settings = {"fixed_dt": 0.0, "dt_max": 0.5, "retries": 3}
    rows = []

    class Recorder:
        def start(self, state):
            pass

        def observe(self, state):
            rows.append(dict(state.diagnostics))

    advance(OneRank(), state, stepper, [Recorder()], EndCondition(10.0, max_steps=3), settings)
    assert [(row["dt"], row["retries"]) for row in rows] == [(0.25, 1)] * 3


@pytest.mark.mpi
def test_a_step_that_fails_at_the_impact_is_redone_and_the_run_goes_on(tmp_path):
    """cases/dam_break.toml (5 mm) with the MPS number density in the source (kernel =
    "mps", the default until the smooth measure) and steps longer than the default's (cfl
    0.8, dt_max 2 ms): at the impact on the far wall (t = 0.36 s) a particle is kicked to
    several times the speed the step was sized for (Courant 7 on 2 ranks); each such step
    is redone at half its dt and the run goes on. (With dt_max at its default 1 ms, steps
    at the impact had let a particle at the corner into the wall, 9 redone steps, until
    the wall collisions closed a wall layer's gaps above its plane: that run no longer
    needs a redo.)"""
    out = tmp_path / "out"
    result = run_parmps([CASES / "dam_break.toml", "-o", out, "--end-time", "0.37",
                         "--set", 'mps.density.kernel="mps"', "--set", "time.cfl=0.8",
                         "--set", "time.dt_max=0.002"],
                        ranks=2, timeout=300)
    assert result.returncode == 0, error_lines(result.stderr) or result.stderr[-2000:]
    with parmps.open_result(out) as run:
        assert run.complete
        diagnostics = run.diagnostics
        courant = diagnostics["max_speed"] * diagnostics["dt"] / 0.005
        assert courant.max() <= 1.0
        assert diagnostics["retries"].sum() >= 1
