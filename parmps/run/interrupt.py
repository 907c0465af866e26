"""Interruption by a signal: the handler only sets a flag; the ranks agree on it after
every step (:class:`parmps.run.observers.Checkpoints`) and stop together.

SIGTERM and SIGINT interrupt; so does SIGUSR1, which Open MPI's mpirun forwards to
the ranks without killing them afterwards (on SIGTERM or SIGINT mpirun sends the
ranks SIGTERM and kills them about 2 s later).

A rank often gets one interruption twice: Ctrl-C reaches the ranks directly and
mpirun adds its SIGTERM; ``timeout`` signals its whole process group. Signals
within ``REPEAT_SECONDS`` of the first are the same interruption; a later one
stops the process at once (the previous handlers, re-raised).
"""

import contextlib
import signal
import time

REPEAT_SECONDS = 5.0

SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)


class Interruption:
    def __init__(self):
        self.requested = False
        self.signal = None
        self.first = None
        self._previous = {}

    def _handle(self, number, frame):
        now = time.monotonic()
        if not self.requested:
            self.requested, self.signal, self.first = True, number, now
            return
        if now - self.first < REPEAT_SECONDS:
            return
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        signal.raise_signal(number)

    def describe(self):
        if self.signal is None:
            return "a signal to another rank"
        return signal.Signals(self.signal).name

    @contextlib.contextmanager
    def installed(self):
        """Handle the signals while the block runs (main thread only)."""
        self._previous = {sig: signal.signal(sig, self._handle) for sig in SIGNALS}
        try:
            yield self
        finally:
            for sig, previous in self._previous.items():
                signal.signal(sig, previous)
            self._previous = {}
