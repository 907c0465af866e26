"""Observers: what looks at the run between steps, each at its own cadence.

An observer has ``start(state)`` (before the first step), ``observe(state)``
(after every step; it decides from its own cadence whether to act) and
``finish(state)`` (at the end, also after a failure, before the file closes).
Diagnostics, body series, frames, progress lines and checkpoints are observers;
probes plug in the same way, without touching the loop.

An observer whose future depends on its past (a cadence, rows already written)
has a ``name`` and contributes to checkpoints through ``checkpoint_state()``
(collective; a dict of arrays and scalars, the same on every rank; it may
first bring the file up to date) and ``restore_state(saved)`` (a continued run,
before ``start``).
"""

import logging

import numpy as np

from parmps.core.particles import FLUID
from parmps.fluid import energy
from parmps.io.series import Series
from parmps.run.schedule import SimulatedInterval, WallInterval

log = logging.getLogger("parmps.run")


class Observer:
    name = None  # the group of its checkpoint state; None: it has none

    def checkpoint_state(self):
        return {}

    def restore_state(self, saved):
        pass

    def start(self, state):
        pass

    def observe(self, state):
        pass

    def finish(self, state):
        pass


class Diagnostics(Observer):
    """One row per step in ``/diagnostics/<name>``: the driver's columns and every
    stepper's own (nothing filled in for quantities a run does not have).

    Rows are flushed to the file every ``interval`` of simulated time (the frame
    interval, so a stopped run has its diagnostics up to its last frame) and at
    the end.
    """

    name = "diagnostics"

    def __init__(self, result, columns, interval, end_time):
        self.result = result
        self.series = Series(result.file.require_group("diagnostics"),
                             {name: (dtype, ()) for name, dtype in columns.items()})
        self.cadence = SimulatedInterval(interval, end_time)

    def checkpoint_state(self):
        self.series.flush(self.result.comm.rank)
        return {"rows": self.series.rows, "next_time": self.cadence.next_time}

    def restore_state(self, saved):
        self.series.truncate(int(saved["rows"]))
        self.cadence.next_time = float(saved["next_time"])

    def observe(self, state):
        self.series.add(state.diagnostics)
        if self.cadence.due(state.time):
            self.series.flush(self.result.comm.rank)

    def finish(self, state):
        self.series.flush(self.result.comm.rank)


class BodySeries(Observer):
    """One row per step in ``/solids/<body>/<name>``: the solid model's series (volume
    error, fluid force, centroid, ...) and the coupling's (fluid inside), with the time."""

    def __init__(self, result, model, extra, interval, end_time):
        """``extra``: None, or an object with ``SERIES`` (name -> shape) and ``series(state)``."""
        self.result = result
        self.model = model
        self.extra = extra
        shapes = {"time": (), **model.SERIES, **(extra.SERIES if extra is not None else {})}
        root = result.file.require_group("solids")
        self.series = {body.name: Series(root.require_group(body.name),
                                         {name: (np.float64, shape)
                                          for name, shape in shapes.items()})
                       for body in model.bodies}
        self.cadence = SimulatedInterval(interval, end_time)

    name = "body_series"

    def checkpoint_state(self):
        self.flush()
        return {"rows": next(iter(self.series.values())).rows if self.series else 0,
                "next_time": self.cadence.next_time}

    def restore_state(self, saved):
        for series in self.series.values():
            series.truncate(int(saved["rows"]))
        self.cadence.next_time = float(saved["next_time"])

    def observe(self, state):
        values = self.model.series()
        extra = self.extra.series(state) if self.extra is not None else {}
        for name, series in self.series.items():
            series.add({"time": state.time, **values[name], **extra.get(name, {})})
        if self.cadence.due(state.time):
            self.flush()

    def flush(self):
        for series in self.series.values():
            series.flush(self.result.comm.rank)

    def finish(self, state):
        self.flush()


class Frames(Observer):
    """A frame at t = 0 and every ``interval`` of simulated time (and at the end)."""

    name = "frames"

    def __init__(self, writer, interval, end_time, write_particles=True):
        self.writer = writer
        self.write_particles = write_particles
        self.cadence = SimulatedInterval(interval, end_time)
        self.resumed = False
        self.step = 0  # the last step seen

    def checkpoint_state(self):
        return {"next_time": self.cadence.next_time, "step": self.step}

    def restore_state(self, saved):
        """Frames after the checkpoint's step are written again, not twice."""
        self.cadence.next_time = float(saved["next_time"])
        self.step = int(saved["step"])
        self.writer.drop_after(self.step)
        self.resumed = True

    def start(self, state):
        if not self.write_particles:
            return
        if self.resumed:
            self.writer.publish()  # the sidecar names the frames the file holds
        else:
            self.writer.write(0, 0.0, 0.0, state.particles)
            self.writer.publish()

    def observe(self, state):
        self.step = state.step
        if self.cadence.due(state.time) and self.write_particles:
            self.writer.write(state.step, state.time, state.dt, state.particles)
            self.writer.publish()


class EnergyWatch(Observer):
    """A warning, once, when the mechanical energy of the fluid and its bodies rises between
    two outputs by more than ``tolerance`` of the fluid's initial energy, beyond the work
    that inlets, outlets and moving walls did on it (docs/design.md §1.8): with fixed walls
    the energy can only fall, so a rise is a numerical source. The warning names the step,
    the time and the fastest fluid particle, where such a source shows first."""

    name = "energy_watch"

    def __init__(self, comm, interval, end_time, tolerance=0.01):
        self.comm = comm
        self.cadence = SimulatedInterval(interval, end_time)
        self.tolerance = tolerance
        self.initial = None  # the fluid's energy after the first step
        self.last = None  # the budget at the last output
        self.scale = 0.0  # what a rise is measured against (energy.rise_scale)
        self.warned = False

    def checkpoint_state(self):
        return {"initial": np.nan if self.initial is None else self.initial,
                "last": np.nan if self.last is None else self.last,
                "warned": int(self.warned), "next_time": self.cadence.next_time}

    def restore_state(self, saved):
        self.initial = None if np.isnan(saved["initial"]) else float(saved["initial"])
        self.last = None if np.isnan(saved["last"]) else float(saved["last"])
        self.warned = bool(saved["warned"])
        self.cadence.next_time = float(saved["next_time"])

    def observe(self, state):
        row = state.diagnostics
        if "fluid_energy" not in row:
            return
        budget = energy.budget(row)
        if self.initial is None:
            self.initial, self.last = row["fluid_energy"], budget
        self.scale = energy.rise_scale(self.initial, row)
        if not self.cadence.due(state.time):
            return
        rise = budget - self.last
        self.last = budget
        if self.warned or not rise > self.tolerance * self.scale:
            return
        self.warned = True
        where = fastest_fluid(state.particles, self.comm)
        if self.comm.rank == 0:
            log.warning("step %d, t = %.6g s: the mechanical energy of the fluid%s rose by "
                        "%.3g %% of its initial value since the last output with no work "
                        "done on it: a numerical source (docs/design.md §1.8)%s",
                        state.step, state.time, " and its bodies" if "body_energy" in row
                        else "", 100.0 * rise / self.scale, where)


def fastest_fluid(particles, comm):
    """", the fastest fluid particle N at (x, y) moving at V m/s" (collective), or ""."""
    n = particles.n_owned
    fluid = np.flatnonzero(particles.kind[:n] == FLUID)
    best = None
    if len(fluid):
        speed = np.einsum("ij,ij->i", particles.velocity[fluid], particles.velocity[fluid])
        i = fluid[np.argmax(speed)]
        best = (float(np.sqrt(speed.max())), -int(particles.id[i]),
                tuple(float(x) for x in particles.position[i]))
    found = [item for item in comm.allgather(best) if item is not None]
    if not found:
        return ""
    speed, pid, where = max(found)
    place = ", ".join(f"{x:.4g}" for x in where)
    return f"; the fastest fluid particle, {-pid}, is at ({place}) moving at {speed:.3g} m/s"


class Progress(Observer):
    """A progress line on rank 0 every few seconds of wall time."""

    def __init__(self, describe, seconds=None):
        """``describe(state)``: the line's text."""
        self.describe = describe
        self.cadence = WallInterval() if seconds is None else WallInterval(seconds)

    def observe(self, state):
        if self.cadence.due():
            log.info("%s", self.describe(state))


class Callback(Observer):
    """Calls ``function(state)`` after every step (benchmarks, tests)."""

    def __init__(self, function):
        self.function = function

    def observe(self, state):
        self.function(state)


class Checkpoints(Observer):
    """A checkpoint every ``seconds`` of wall time (0: none), at the end and on an
    interruption; and the ranks' agreement, after every step, on whether one was
    interrupted (docs/design.md §3).

    ``write(state)`` writes one (collective). ``interruption``: an object whose
    ``requested`` is set by a signal handler on any rank. One allreduce of two
    flags per step: an interruption anywhere, and rank 0's wall clock saying a
    checkpoint is due (the ranks' clocks differ, so rank 0's alone decides).
    """

    def __init__(self, comm, write, seconds, interruption):
        from mpi4py import MPI
        self.mpi = MPI
        self.comm = comm
        self.write = write
        self.cadence = WallInterval(seconds) if seconds > 0 else None
        self.interruption = interruption
        self.flags = np.zeros(2, np.int8)

    def observe(self, state):
        self.flags[0] = bool(self.interruption.requested)
        self.flags[1] = self.comm.rank == 0 and self.cadence is not None and self.cadence.due()
        self.comm.Allreduce(self.mpi.IN_PLACE, self.flags, op=self.mpi.MAX)
        if self.flags[0]:
            state.stop = "interrupted"
            if self.comm.rank == 0:
                log.warning("interrupted (%s) after step %d at t = %.6g s: writing the "
                            "checkpoint", self.interruption.describe(), state.step, state.time)
        elif self.flags[1]:
            self.write(state)

    def finish(self, state):
        # A failed run keeps its last good checkpoint.
        if state.outcome in ("complete", "interrupted"):
            self.write(state)
