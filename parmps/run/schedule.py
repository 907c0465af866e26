"""When a run ends, and when something is due: in simulated time or in wall time.

The driver owns one :class:`EndCondition`; every observer owns its own cadence
(:class:`SimulatedInterval` for frames and series flushes, :class:`WallInterval`
for progress lines and, later, checkpoints), so each runs at its own rate
without the loop knowing any of them.
"""

import math
import time as wallclock

PROGRESS_SECONDS = 5.0

# Relative slack on time comparisons: a sum of steps meant to land on the end
# time or on a frame time lands a few ulps either side of it.
_SLACK = 1e-9
_END_SLACK = 1e-12
# Steps before the end over which a run evens out its step to land on the end time.
_APPROACH_STEPS = 10


class EndCondition:
    """The end time and the step limit of a run."""

    def __init__(self, end_time, max_steps=0):
        self.end_time = end_time
        self.max_steps = max_steps

    def running(self, time, step_number):
        """True while the run has time and steps left."""
        return time < self.end_time * (1 - _END_SLACK) and (
            self.max_steps == 0 or step_number < self.max_steps)

    def clip(self, time, dt):
        """The step length that lands on the end time without a short last step.

        Over the last ``_APPROACH_STEPS`` steps the time left is divided into
        equal steps, each at least (n - 1)/n of dt, instead of full steps and a
        remainder: a pressure source whose density-deviation term goes as
        1/dt^2 answers a step of a thousandth of dt with a million times the
        pressure.
        """
        remaining = self.end_time - time
        if remaining >= _APPROACH_STEPS * dt:
            return dt
        # A sum of steps lands a few ulps off a multiple of dt: that is n steps, not n + 1.
        steps = max(1, math.ceil(remaining / dt * (1 - _SLACK)))
        return remaining / steps


class SimulatedInterval:
    """Due every ``interval`` of simulated time, and at the end time."""

    def __init__(self, interval, end_time, start=0.0):
        self.interval = interval
        self.end_time = end_time
        self.next_time = start + interval

    def due(self, time):
        """True when ``time`` has reached the next due time (which then moves on)."""
        if time < self.next_time * (1 - _SLACK) and time < self.end_time * (1 - _END_SLACK):
            return False
        while self.next_time <= time * (1 + _SLACK):
            self.next_time += self.interval
        return True


class WallInterval:
    """Due every ``seconds`` of wall time."""

    def __init__(self, seconds=PROGRESS_SECONDS):
        self.seconds = seconds
        self.last = wallclock.perf_counter()

    def due(self):
        now = wallclock.perf_counter()
        if now - self.last < self.seconds:
            return False
        self.last = now
        return True


class Stopwatch:
    """Wall time since the loop started."""

    def __init__(self):
        self.start = wallclock.perf_counter()

    def elapsed(self):
        return wallclock.perf_counter() - self.start
