"""Observers: what looks at the run between steps, each at its own cadence.

An observer has ``start(state)`` (before the first step), ``observe(state)``
(after every step; it decides from its own cadence whether to act) and
``finish(state)`` (at the end, also after a failure, before the file closes).
Diagnostics, body series, frames and progress lines are observers; probes and
checkpoints plug in the same way, without touching the loop.
"""

import logging

import numpy as np

from parmps.io.series import Series
from parmps.run.schedule import SimulatedInterval, WallInterval

log = logging.getLogger("parmps.run")


class Observer:
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

    def __init__(self, result, columns, interval, end_time):
        self.result = result
        self.series = Series(result.file.create_group("diagnostics"),
                             {name: (dtype, ()) for name, dtype in columns.items()})
        self.cadence = SimulatedInterval(interval, end_time)

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

    def __init__(self, writer, interval, end_time, write_particles=True):
        self.writer = writer
        self.write_particles = write_particles
        self.cadence = SimulatedInterval(interval, end_time)

    def start(self, state):
        if self.write_particles:
            self.writer.write(0, 0.0, 0.0, state.particles)
            self.writer.publish()

    def observe(self, state):
        if self.cadence.due(state.time) and self.write_particles:
            self.writer.write(state.step, state.time, state.dt, state.particles)
            self.writer.publish()


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
