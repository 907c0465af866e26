"""The ways a run ends early, each with its exit status (docs/design.md §2.3)."""

# A run stopped by a signal after writing its checkpoint: --restart continues it.
INTERRUPTED = 3


class CaseError(Exception):
    """Bad input: the case file, an override or the rank count. Exit status 2.

    The message is one line that names the offending key and the problem.
    """

    exit_status = 2


class RunFailure(Exception):
    """A run that started but could not go on (unstable, solver diverged). Exit status 1."""

    exit_status = 1
