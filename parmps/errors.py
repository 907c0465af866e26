"""The ways a run ends early, each with its exit status (docs/design.md §2.3)."""

# A run stopped by a signal after writing its checkpoint: --restart continues it.
INTERRUPTED = 3


class CaseError(Exception):
    """Bad input: the case file, an override or the rank count. Exit status 2.

    The message is one line that names the offending key and the problem.
    """

    exit_status = 2


class RunFailure(Exception):
    """A run that started but could not go on (unstable, solver diverged). Exit status 1.

    ``where``: the position the failure was seen at (a particle through a wall or out of
    the domain), or None; a likely cause is then judged by what lies near it.
    """

    exit_status = 1

    def __init__(self, message, where=None):
        super().__init__(message)
        self.where = where
