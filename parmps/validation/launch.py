"""The one launcher of parmps runs: ``python -m parmps CASE ...`` as a user would type it,
serially or under ``mpirun``, with a timeout that kills every rank.

The validations, the benchmarks and the study scripts all run parmps through
:func:`run`, which returns a record of the outcome (the exit status, parmps's own error
line, the wall time and, when the run wrote one, the result file's summary). PETSc is
found by the package itself (:mod:`parmps.fluid.ppe`), so nothing here names its folder.
"""

import os
import shlex
import signal
import subprocess
import sys
import time

# parmps's own error lines start so (cli.main); mpirun may add notices of its own.
ERROR_PREFIX = "parmps: error: "


def command(case, out, sets=(), end_time=None, petsc=(), ranks=1):
    """The argv of one run: ``python -m parmps CASE -o OUT [--end-time T] [--set ...]
    [PETSc options]``, under ``mpirun -n RANKS`` when ranks > 1."""
    argv = [sys.executable, "-m", "parmps", os.fspath(case), "-o", os.fspath(out)]
    if end_time is not None:
        argv += ["--end-time", f"{end_time:.6g}"]
    for item in sets:
        argv += ["--set", item]
    argv += list(petsc)
    if ranks > 1:
        from parmps.parallel.mpi import mpirun_command
        argv = mpirun_command(ranks, argv)
    return argv


def environment(spin=False):
    """The environment a launched run gets: :func:`parmps.parallel.mpi.launch_environment`
    (no launcher variables of an MPI singleton, Open MPI's consent to root, one BLAS thread
    per rank) and, unless ``spin``, Open MPI's yield when idle (timed benchmarks keep Open
    MPI's default, spinning)."""
    from parmps.parallel.mpi import launch_environment
    env = launch_environment()
    # Containers often lack the kernel support of vader's single-copy transport (as
    # scripts/setup says too): Open MPI then fails at the first large message.
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    if not spin:
        # Ranks that spin while waiting lose badly on a machine busier than its cores.
        env.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")
    return env


def shown(argv, root=None):
    """The command as a user would type it (paths under ``root`` relative to it, ``python``
    for the interpreter, without mpirun's transport choice)."""
    words = []
    argv = [str(word) for word in argv]
    if "--mca" in argv:
        at = argv.index("--mca")
        del argv[at:at + 3]
    for word in argv:
        if word == sys.executable:
            word = "python"
        elif root and word.startswith(os.fspath(root) + os.sep):
            word = os.path.relpath(word, root)
        words.append(shlex.quote(word))
    return " ".join(words).replace("mpirun -n", "mpirun -q -n")


def execute(argv, timeout, cwd=None, spin=False):
    """Run ``argv`` in a session of its own; returns (status, stdout, stderr, seconds), the
    status None when it was killed after ``timeout`` seconds (every rank with it)."""
    start = time.perf_counter()
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=environment(spin), cwd=cwd,
                               start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=timeout)
        status = process.returncode
    except subprocess.TimeoutExpired:
        stdout = stderr = ""
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(process.pid, sig)
                process.communicate(timeout=5)
                break
            except (ProcessLookupError, subprocess.TimeoutExpired):
                continue
        status = None
    return status, stdout, stderr, time.perf_counter() - start


def outcome(status, stderr, timeout):
    """(outcome, message): what became of a run, in words, and parmps's error line."""
    errors = [line[len(ERROR_PREFIX):] for line in stderr.splitlines()
              if line.startswith(ERROR_PREFIX)]
    message = errors[0] if errors else ""
    if status is None:
        return f"hung: killed after {timeout} s", message
    if status == 0:
        return "ran to the end", message
    if errors:
        return "stopped: " + message, message
    tail = " | ".join(stderr.strip().splitlines()[-2:])
    return f"exit {status} without a message: {tail}", message


def run(case, out, sets=(), end_time=None, petsc=(), ranks=1, timeout=600, root=None,
        cwd=None):
    """Run one case (from ``cwd``, which relative paths are read against); returns a record:
    ``command`` (as shown), ``ranks``, ``status``, ``elapsed``, ``result``, ``outcome``,
    ``message`` and the result's summary (:func:`parmps.tools.analysis.run_summary`)."""
    from parmps.tools import analysis
    argv = command(case, out, sets, end_time, petsc, ranks)
    status, _, stderr, elapsed = execute(argv, timeout, cwd=cwd)
    result = os.path.join(os.fspath(cwd or ""), os.fspath(out), "result.h5")
    said, message = outcome(status, stderr, timeout)
    record = {"command": shown(argv, root), "ranks": ranks, "status": status,
              "elapsed": elapsed, "result": result, "outcome": said, "message": message}
    record.update(analysis.run_summary(result) if os.path.exists(result) else {})
    if status == 0 and not record.get("finite", False):
        record["outcome"] = "ran to the end with NON-FINITE values (no message)"
    return record
