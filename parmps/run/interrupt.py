"""Interruption by a signal: the handler only sets a flag; the ranks agree on it after
every step (:class:`parmps.run.observers.Checkpoints`) and stop together.

SIGTERM and SIGINT interrupt; so does SIGUSR1, which Open MPI's mpirun forwards to
the ranks without killing them afterwards (on SIGTERM or SIGINT mpirun sends the
ranks SIGTERM and kills them about 2 s later). After the first signal the previous
handlers are back, so a second one stops the process at once.
"""

import contextlib
import signal

SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)


class Interruption:
    def __init__(self):
        self.requested = False
        self.signal = None
        self._previous = {}

    def _handle(self, number, frame):
        self.requested = True
        self.signal = number
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)

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
