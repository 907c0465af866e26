"""MPI helpers: abort the whole job on an unexpected exception, agree on errors.

Two kinds of failure need different handling under MPI:

- an error every rank meets together (a bad case, a diverged solve whose
  verdict was reduced over ranks) is raised on every rank and ends the run
  normally with its exit status;
- an unexpected exception on one rank would leave the others waiting in the
  next collective call for ever. :func:`abort_on_exception` logs it with the
  rank and calls ``COMM_WORLD.Abort`` so ``mpirun`` ends the whole job.

:func:`agree` turns an error raised on some ranks into the same error on every
rank; :func:`assert_all` is its test-side cousin for assertions.
"""

import contextlib
import functools
import logging
import os
import signal
import subprocess
import sys
import traceback

log = logging.getLogger(__name__)


def _world():
    # Imported here: a process that only launches mpirun (pytest, bench.py) must
    # not start MPI itself.
    from mpi4py import MPI
    return MPI.COMM_WORLD


@contextlib.contextmanager
def abort_on_exception(comm=None, passthrough=(), errorcode=1):
    """Run a block; on an exception not in ``passthrough``, log it and abort every rank.

    With one rank there is nothing to hang, so the exception propagates
    unchanged. ``passthrough`` names exceptions known to be raised on every
    rank together (for instance ``(CaseError, RunFailure)`` after
    :func:`agree`); they propagate as well. ``SystemExit`` always propagates.
    """
    comm = _world() if comm is None else comm
    try:
        yield
    except SystemExit:
        raise
    except BaseException as error:  # noqa: BLE001 - KeyboardInterrupt must abort too
        if comm.size == 1 or (passthrough and isinstance(error, passthrough)):
            raise
        text = "".join(traceback.format_exception(type(error), error, error.__traceback__))
        log.critical("rank %d/%d: unexpected %s: %s; aborting all ranks\n%s",
                     comm.rank, comm.size, type(error).__name__, error, text.rstrip())
        # Also straight to stderr, in case logging is not configured or is filtered.
        sys.stderr.write(f"parmps: rank {comm.rank}/{comm.size}: {type(error).__name__}: "
                         f"{error}\n")
        sys.stderr.flush()
        for handler in logging.getLogger("parmps").handlers:
            handler.flush()
        comm.Abort(errorcode)


def aborting(function=None, *, passthrough=()):
    """Decorator form of :func:`abort_on_exception` on ``COMM_WORLD``."""
    def wrap(func):
        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            with abort_on_exception(passthrough=passthrough):
                return func(*args, **kwargs)
        return wrapper
    return wrap if function is None else wrap(function)


def agree(comm, func, *args, errors=None, **kwargs):
    """Call ``func`` on every rank; if it raised one of ``errors`` anywhere, raise it everywhere.

    The error of the lowest failing rank is re-raised on every rank (same type,
    same message), so every rank leaves through the same door with the same exit
    status. Other exceptions are not caught (wrap the caller in
    :func:`abort_on_exception`). Returns ``func``'s result on success.
    """
    if errors is None:
        from parmps.errors import CaseError, RunFailure
        errors = (CaseError, RunFailure)
    failure = None
    result = None
    try:
        result = func(*args, **kwargs)
    except errors as error:
        failure = error
    verdicts = comm.allgather(None if failure is None else (type(failure), str(failure)))
    for verdict in verdicts:
        if verdict is not None:
            kind, message = verdict
            if failure is not None and type(failure) is kind and str(failure) == message:
                raise failure
            raise kind(message)
    return result


def any_rank(comm, flag):
    """True on every rank if ``flag`` is true on at least one rank."""
    from mpi4py import MPI
    return bool(comm.allreduce(bool(flag), op=MPI.LOR))


def assert_all(comm, condition, message=""):
    """A collective assert: if it fails on any rank it fails on every rank.

    The AssertionError names the failing ranks and their messages, so a test
    worker under ``mpirun`` never leaves one rank waiting for a failed one.
    """
    ok = bool(condition)
    verdicts = comm.allgather(None if ok else str(message() if callable(message) else message))
    failed = [(rank, text) for rank, text in enumerate(verdicts) if text is not None]
    if failed:
        raise AssertionError("; ".join(f"rank {rank}: {text}" for rank, text in failed))


def mpirun_command(ranks, argv, quiet=True):
    """``mpirun -n ranks [--oversubscribe] argv...``, oversubscribing past the core count."""
    command = ["mpirun", "-n", str(int(ranks))]
    if int(ranks) > (os.cpu_count() or 1):
        command.append("--oversubscribe")
    if quiet:
        command += ["--mca", "btl", "^openib"]
    return command + [str(a) for a in argv]


# Set by an MPI launcher or by a singleton MPI_Init for the process itself; a child
# mpirun that inherits them fails at once, silently.
_LAUNCH_VARIABLES = ("PMIX_", "OMPI_COMM_WORLD_", "OMPI_APP_CTX_", "OMPI_MCA_ess",
                     "OMPI_MCA_orte_", "OMPI_MCA_pmix", "OMPI_FIRST_RANKS", "OMPI_NUM_APP_CTX",
                     "OMPI_UNIVERSE_SIZE", "OMPI_FILE_LOCATION", "OMPI_COMMAND", "OMPI_ARGV",
                     "OMPI_MCA_initial_wdir", "OMPI_MCA_shmem_RUNTIME_QUERY_hint")


# parmps runs one MPI rank per core; a BLAS library that starts its own worker
# threads (Debian's OpenBLAS, loaded with numpy and PETSc, spins one per rank after
# GAMG's coarse solves) would put two busy threads on each core.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def one_blas_thread_per_rank(environ):
    """Ask BLAS for a single thread unless the user has chosen a count.

    Must run before numpy (and with it OpenBLAS) is loaded: OpenBLAS reads the
    variable once, when the library is loaded.
    """
    for variable in BLAS_THREAD_VARIABLES:
        environ.setdefault(variable, "1")


def launch_environment(environ=None):
    """The environment for starting ``mpirun`` from a process that may itself be an MPI rank.

    Importing mpi4py initialises MPI as a singleton, which puts launcher
    variables into the C environment that ``subprocess`` passes on by default;
    ``os.environ`` is the copy from before, minus any launcher variables, plus
    Open MPI's consent to run as root when this process is root, and one BLAS thread
    per rank unless the user chose a count: not every launched program is ``python -m
    parmps`` (the benchmark's worker, the tests' MPI programs), and each loads OpenBLAS
    with numpy before it could ask.
    """
    environ = dict(os.environ if environ is None else environ)
    clean = {key: value for key, value in environ.items()
             if not key.startswith(_LAUNCH_VARIABLES)}
    if os.geteuid() == 0:
        # Open MPI refuses root without both; a root user running parmps's own
        # launchers (bench, tests) has accepted that by running them.
        clean.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        clean.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    one_blas_thread_per_rank(clean)
    return clean


def run_mpirun(ranks, argv, timeout, **kwargs):
    """Run ``argv`` on ``ranks`` ranks; on timeout kill the whole process group.

    Returns the CompletedProcess (text output captured). A job still running
    after ``timeout`` seconds is terminated, ranks included, and
    ``subprocess.TimeoutExpired`` is raised, so a deadlock fails a test instead
    of hanging it.
    """
    command = mpirun_command(ranks, argv)
    kwargs.setdefault("env", launch_environment())
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, start_new_session=True, **kwargs)
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        stdout = stderr = ""
        for sig in (signal.SIGTERM, signal.SIGKILL):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, sig)
            try:
                stdout, stderr = process.communicate(timeout=5)
                break
            except subprocess.TimeoutExpired:
                continue
        raise subprocess.TimeoutExpired(command, timeout, output=stdout, stderr=stderr) from None
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)
