"""The one time loop of every run: fluid-only, solid-only and coupled.

A run is a :class:`RunState` (time, step, the last dt, the particles, the
diagnostics of the last step), one stepper that advances it (see
:mod:`parmps.run.steppers`) and observers that look at it after each step,
each at its own cadence (see :mod:`parmps.run.observers`). The loop knows
nothing of what a step does or what is written.
"""

import copy
import logging
from dataclasses import dataclass, field

from parmps.core.particles import Particles
from parmps.errors import CaseError, RunFailure
from parmps.parallel.mpi import abort_on_exception
from parmps.run.schedule import Stopwatch
from parmps.run.timestep import choose_dt

log = logging.getLogger("parmps.run")


@dataclass
class RunState:
    time: float = 0.0
    step: int = 0
    dt: float = 0.0  # the last step's length
    particles: Particles = field(default_factory=Particles.empty)
    diagnostics: dict = field(default_factory=dict)  # the last step's row
    particle_steps: int = 0
    elapsed: float = 0.0  # wall seconds in the loop so far (over every restart)
    # Set by an observer, the same on every rank, to end the run after this step
    # (an interruption: "interrupted").
    stop: str = None
    # How the loop ended, for the observers' finish: "complete", "interrupted" or "failed".
    outcome: str = None

    def checkpoint_state(self):
        return {"time": self.time, "step": self.step, "dt": self.dt,
                "particle_steps": self.particle_steps, "elapsed": self.elapsed}

    def restore_state(self, saved):
        self.time = float(saved["time"])
        self.step = int(saved["step"])
        self.dt = float(saved["dt"])
        self.particle_steps = int(saved["particle_steps"])
        self.elapsed = float(saved["elapsed"])


DRIVER_DIAGNOSTICS = {"step": "int64", "time": "float64", "dt": "float64",
                      # how often the step was redone with half its dt
                      "retries": "int64",
                      "wall_seconds": "float64"}


def advance(comm, state, stepper, observers, end, time_settings):
    """Step ``state`` until ``end`` says stop; observers see every step. Returns the state."""
    watch = Stopwatch()
    before = state.elapsed  # a restarted run's wall time so far
    total_particles = comm.allreduce(state.particles.n_owned)
    stepper.start(state)
    for observer in observers:
        observer.start(state)
    # A fixed step is the user's: it is never shortened.
    retries = 0 if time_settings["fixed_dt"] > 0 else time_settings["retries"]
    while state.stop is None and end.running(state.time, state.step):
        try:
            dt = end.clip(state.time, choose_dt(time_settings, stepper.dt_limits(state),
                                                state.step + 1))
            redone = take_step(comm, state, stepper, dt, retries)
        except RunFailure as failure:
            # A blow-up shows as whatever breaks first (a spring, a particle out of the
            # domain, dt); the stepper may know the physics behind it.
            cause = stepper.failure_cause(failure.where)
            if cause is None:
                raise
            raise RunFailure(f"{failure}. Likely cause: {cause}", failure.where) from None
        state.particle_steps += total_particles
        state.elapsed = before + watch.elapsed()
        state.diagnostics = {"step": state.step, "time": state.time, "dt": state.dt,
                             "retries": redone, "wall_seconds": state.elapsed,
                             **stepper.diagnostics(state)}
        for observer in observers:
            observer.observe(state)
    if state.stop is not None and not end.running(state.time, state.step):
        state.stop = None  # stopped after the last step: the run is complete all the same
    state.elapsed = before + watch.elapsed()
    return state


def take_step(comm, state, stepper, dt, retries):
    """Advance ``state`` by one step of ``dt``; a step that fails its checks is redone from
    its start with half the dt, up to ``retries`` times. Returns how often it was redone.

    A failure is a run failure raised on every rank together, so every rank redoes the
    step. Why: in the MPS step a particle's pressure answers to where it is predicted to
    be, and the weight re/r - 1 is singular, so one fluid particle driven at a wall's
    corner by a step of the Courant limit can come out with ten times the flow's speed
    (the 5 mm dam break at time.cfl = 0.5, step 391, t = 0.355 s, at the far wall) while
    the same step at half the dt is harmless: that is a step too long, not an unstable run.
    An unstable run fails again at every dt and stops with the last failure's message.
    """
    if retries == 0:
        _advance_and_check(state, stepper, dt)
        return 0
    # The start of the step, as a checkpoint keeps it (the particles: owned, no ghosts).
    run_at_start = state.checkpoint_state()
    particles_at_start = state.particles.owned_copy()
    stepper_at_start = copy.deepcopy(stepper.checkpoint_state())
    for attempt in range(retries + 1):
        try:
            _advance_and_check(state, stepper, dt)
            return attempt
        except RunFailure as failure:
            if attempt == retries:
                raise RunFailure(f"{failure} (the step failed {retries + 1} times, "
                                 f"down to dt = {dt:.3g} s)", failure.where) from None
            if comm.rank == 0:
                log.warning("redoing step %d with dt = %.3g s, half its dt; it failed: %s",
                            run_at_start["step"] + 1, dt / 2, failure)
            state.restore_state(run_at_start)
            # Copies again: the next attempt changes them in place.
            state.particles = particles_at_start.owned_copy()
            stepper.restore_state(copy.deepcopy(stepper_at_start))
            dt /= 2


def _advance_and_check(state, stepper, dt):
    stepper.advance(state, dt)
    state.time += dt
    state.step += 1
    state.dt = dt
    stepper.check(state)


def run_collectively(comm, result, observers, state, loop):
    """Run ``loop()``, then let the observers finish and close ``result`` on every rank,
    marked complete only when the loop ended neither by a failure nor by an interruption
    (``state.outcome`` tells the observers which).

    An unexpected exception on one rank aborts the job: the collective close
    would otherwise wait for ranks still inside the loop. Case errors and run
    failures are raised on every rank together, so they close normally and keep
    the frames already written.
    """
    state.outcome = "failed"
    try:
        with abort_on_exception(comm, passthrough=(CaseError, RunFailure)):
            loop()
        state.outcome = state.stop or "complete"
    finally:
        try:
            with abort_on_exception(comm, passthrough=(CaseError, RunFailure)):
                for observer in observers:
                    observer.finish(state)
        finally:
            result.close(state.outcome == "complete")
    return result.path
