"""What every time loop shares: when to stop, when a frame and a progress line are due,
and how a run ends collectively.

The fluid loop (:mod:`parmps.run.simulation`) and the solid-only loop
(:mod:`parmps.run.solid_run`) differ in what a step does, not in these.
"""

import time as wallclock

from parmps.errors import CaseError, RunFailure
from parmps.parallel.mpi import abort_on_exception

PROGRESS_SECONDS = 5.0

# Relative slack on time comparisons: a sum of steps meant to land on the end
# time or on a frame time lands a few ulps either side of it.
_SLACK = 1e-9
_END_SLACK = 1e-12


class Schedule:
    """The end of a run, its frame times and its progress lines."""

    def __init__(self, end_time, max_steps, output_interval, progress_seconds=PROGRESS_SECONDS):
        self.end_time = end_time
        self.max_steps = max_steps
        self.output_interval = output_interval
        self.progress_seconds = progress_seconds
        self.next_frame = output_interval
        self.start = wallclock.perf_counter()
        self.last_progress = self.start

    def running(self, time, step_number):
        """True while the run has time and steps left."""
        return time < self.end_time * (1 - _END_SLACK) and (
            self.max_steps == 0 or step_number < self.max_steps)

    def clip(self, time, dt):
        """The step length that does not overshoot the end time."""
        return min(dt, self.end_time - time)

    def frame_due(self, time):
        """True when a frame is due at ``time`` (then the next frame time moves on)."""
        if time < self.next_frame * (1 - _SLACK) and time < self.end_time * (1 - _END_SLACK):
            return False
        while self.next_frame <= time * (1 + _SLACK):
            self.next_frame += self.output_interval
        return True

    def elapsed(self):
        return wallclock.perf_counter() - self.start

    def progress_due(self):
        """True every ``progress_seconds`` of wall time."""
        now = wallclock.perf_counter()
        if now - self.last_progress < self.progress_seconds:
            return False
        self.last_progress = now
        return True

    def seconds_left(self, time):
        """Wall time left, extrapolated from the simulated time done so far."""
        return self.elapsed() / time * (self.end_time - time) if time > 0 else 0.0


def run_collectively(comm, output, loop):
    """Run ``loop()``, then close ``output`` on every rank, marked complete or not.

    An unexpected exception on one rank aborts the job: the collective close
    would otherwise wait for ranks still inside the loop. Case errors and run
    failures are raised on every rank together, so they close normally and keep
    the frames already written.
    """
    complete = False
    try:
        with abort_on_exception(comm, passthrough=(CaseError, RunFailure)):
            loop()
        complete = True
    finally:
        output.close(complete)
    return output.path
