"""Command line: ``python -m parmps CASE.toml [-o OUTDIR] [--end-time T] [--max-steps N]
[--set S.K=V ...] [--check] [--debug] [PETSc options]``, or ``python -m parmps --restart
OUTDIR [CASE.toml] [--end-time T] [--max-steps N]`` to continue a run from its checkpoint
(docs/design.md §2.3, §5).
Two commands come before a case: ``python -m parmps validate NAME|--all|--list``
(:mod:`parmps.validation.command`) and ``python -m parmps bench``
(:mod:`parmps.validation.bench`); a case file that happens to be named ``validate`` or
``bench`` is still a case.

Exit status 0 done, 2 bad input (one line on stderr), 1 a run that failed, 3 a run
interrupted by a signal (its checkpoint written: ``--restart`` continues it).
The case is read and validated on rank 0 and the verdict broadcast, so every
rank stops together; an unexpected exception on any rank aborts the whole job.
"""

import argparse
import json
import logging
import os
import re
import shlex
import sys
import traceback

from parmps.errors import INTERRUPTED, CaseError, RunFailure
from parmps.parallel.mpi import one_blas_thread_per_rank
from parmps.petsc_options import value_follows

log = logging.getLogger("parmps")

# PETSc options are single-dash words such as -pressure_ksp_rtol or -log_view.
_PETSC_OPTION = re.compile(r"^-[A-Za-z][A-Za-z0-9]*_[A-Za-z0-9_]*$|^-(log_view|help_petsc)$")


def split_petsc_options(argv):
    """Separate PETSc options (and their values) from parmps's own arguments."""
    ours, petsc = [], []
    k = 0
    while k < len(argv):
        token = argv[k]
        if _PETSC_OPTION.match(token):
            petsc.append(token)
            if value_follows(argv, k):
                petsc.append(argv[k + 1])
                k += 1
        else:
            ours.append(token)
        k += 1
    return ours, petsc


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise CaseError(f"command line: {message}")


def build_parser():
    parser = _Parser(prog="parmps", description="Parallel MPS fluid / mass-spring solid solver. "
                     "PETSc options such as -pressure_ksp_rtol 1e-10 pass through to the "
                     "pressure solver.",
                     epilog="Also: 'parmps validate NAME|--all|--list' runs the validations, "
                            "'parmps bench' the benchmarks (each with --help).")
    parser.add_argument("case", nargs="?",
                        help="the case file (TOML); optional with --restart")
    parser.add_argument("--restart", metavar="OUTDIR",
                        help="continue the run whose output is in OUTDIR from its last "
                             "checkpoint, on any rank count (--end-time and --max-steps "
                             "may extend it)")
    parser.add_argument("-o", "--output", metavar="OUTDIR",
                        help="output directory (default out/<case file stem>/)")
    parser.add_argument("--end-time", type=float, metavar="T", help="override time.end")
    parser.add_argument("--max-steps", type=_step_count, metavar="N",
                        help="override time.max_steps: stop at step N of the run, counted from "
                             "its start (0: no limit)")
    parser.add_argument("--set", action="append", default=None, metavar="SECTION.KEY=VALUE",
                        help="override a case value (repeatable)")
    parser.add_argument("--check", action="store_true",
                        help="validate the case, print particle counts, n0, lambda0, the "
                             "initial dt and a memory estimate, and exit")
    parser.add_argument("--debug", action="store_true",
                        help="show tracebacks and debug logging")
    return parser


def _step_count(text):
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"not a step count (an integer >= 0): {text!r}")
    return value


def _override_limits(raw, args):
    """Apply --end-time and --max-steps to the raw case; whether either was given."""
    given = False
    for key, value in (("end", args.end_time), ("max_steps", args.max_steps)):
        if value is not None:
            raw.setdefault("time", {})[key] = value
            given = True
    return given


def prepare_case(args):
    """Read, override and validate the case; returns (case, case_text). Raises CaseError."""
    from parmps import config, schema
    from parmps.tools import toml
    try:
        with open(args.case, "rb") as handle:
            text = handle.read().decode("utf-8")
    except FileNotFoundError:
        raise CaseError(f"case file {args.case} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CaseError(f"case file {args.case}: cannot read it ({exc})") from None
    raw = config.load_text(text, args.case)
    for assignment in args.set or []:
        config.apply_override(raw, assignment)
    from parmps.boundaries.settings import resolve_paths as resolve_tables
    from parmps.geometry.settings import resolve_paths
    # The stored case must find its meshes and tables from the output directory too.
    moved = resolve_paths(raw, args.case)
    moved = resolve_tables(raw, args.case) or moved
    limits = _override_limits(raw, args)
    try:
        case = schema.validate(raw)
    except CaseError as exc:
        raise CaseError(f"{args.case}: {exc}") from None
    check_memory(case, args.case)
    changed = bool(args.set) or limits or moved
    return case, toml.dumps(raw) if changed else text


def check_memory(case, name):
    """Refuse a case whose estimated memory exceeds the machine's, before anything is built."""
    from parmps.run.resources import machine_memory, memory_estimate, particle_estimate
    needed, available = memory_estimate(case), machine_memory()
    if available is not None and not needed < available:
        raise CaseError(f"{name}: the case makes about {particle_estimate(case):.3g} particles "
                        f"and needs about {needed / 2 ** 30:.3g} GiB, more than this machine's "
                        f"{available / 2 ** 30:.3g} GiB: use a coarser particles.spacing or a "
                        f"smaller geometry")


def prepare_output(directory):
    """Create the output directory (rank 0) or say in one line why it cannot be used."""
    if os.path.exists(directory) and not os.path.isdir(directory):
        raise CaseError(f"-o {directory}: exists and is not a directory")
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as exc:
        raise CaseError(f"-o {directory}: cannot create it ({exc.strerror})") from None
    if not os.access(directory, os.W_OK | os.X_OK):
        raise CaseError(f"-o {directory}: not writable")


def _verdict(comm, action):
    """Run ``action`` on rank 0 and share (result, error) with every rank."""
    result, error = None, None
    if comm.rank == 0:
        try:
            result = action()
        except CaseError as exc:
            error = str(exc)
    result, error = comm.bcast((result, error), root=0)
    if error is not None:
        raise CaseError(error)
    return result


# The commands that come before a case (``python -m parmps validate ...``): name -> module
# with ``main(argv)`` returning the exit status.
COMMANDS = {"validate": "parmps.validation.command", "bench": "parmps.validation.bench"}


def is_command(argv):
    """Whether argv starts with a command rather than a case: a command's name that is not
    also the path of a file."""
    return bool(argv) and argv[0] in COMMANDS and not os.path.exists(argv[0])


def run_command(argv):
    """Run ``validate`` or ``bench``; bad input is one line and exit status 2."""
    import importlib
    try:
        return importlib.import_module(COMMANDS[argv[0]]).main(argv[1:])
    except CaseError as exc:
        print(f"parmps: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except SystemExit as exc:  # --help
        return int(exc.code or 0)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if is_command(argv):
        return run_command(argv)
    one_blas_thread_per_rank(os.environ)
    ours, petsc_options = split_petsc_options(argv)
    debug = "--debug" in ours
    try:
        args = build_parser().parse_args(ours)
    except CaseError as exc:
        print(f"parmps: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except SystemExit as exc:  # --help
        return int(exc.code or 0)

    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    from parmps.tools.logging import configure
    configure(comm, verbose=debug)
    try:
        return _run(args, petsc_options, comm)
    except (CaseError, RunFailure) as exc:
        if comm.rank == 0:
            print(f"parmps: error: {exc}", file=sys.stderr)
            if debug:
                traceback.print_exc()
        sys.stderr.flush()
        return exc.exit_status
    except Exception as exc:  # noqa: BLE001 - any bug must stop every rank
        log.critical("rank %d failed: %s: %s", comm.rank, type(exc).__name__, exc)
        traceback.print_exc()
        sys.stderr.flush()
        if comm.size > 1:
            comm.Abort(1)
        return 1


def prepare_restart(args):
    """Check that ``--restart OUTDIR`` can continue a run; returns (case, case_text) from its
    checkpoint (with ``--end-time`` and ``--max-steps`` applied). Raises CaseError."""
    from parmps import config, schema
    from parmps.io.checkpoint import has_checkpoint, read_case_text
    from parmps.tools import toml
    directory = args.restart
    if args.output is not None and os.path.abspath(args.output) != os.path.abspath(directory):
        raise CaseError(f"--restart {directory} writes into {directory}: -o {args.output} "
                        f"cannot go with it")
    if args.set:
        raise CaseError("--restart continues a run with its own case: --set cannot change it")
    if not has_checkpoint(directory):
        raise CaseError(f"--restart {directory}: no checkpoint.h5 there, nothing to continue")
    if not os.path.isfile(os.path.join(directory, "result.h5")):
        raise CaseError(f"--restart {directory}: its checkpoint has no result.h5 beside it")
    text = read_case_text(directory)
    raw = config.load_text(text, f"{directory}/checkpoint.h5")
    if args.case is not None:
        given, _ = prepare_case(argparse.Namespace(case=args.case, set=None, end_time=None,
                                                   max_steps=None))
        # The end time and the step limit are what --end-time and --max-steps may change;
        # anything else is another run.
        ours = schema.validate(config.load_text(text, "checkpoint"))
        for case in (given, ours):
            case["time"].pop("end")
            case["time"].pop("max_steps")
        if given != ours:
            raise CaseError(f"{args.case} differs from the case of the run in {directory}: "
                            f"--restart continues that run with its own case (leave the case "
                            f"file out, or start a new run with -o)")
    if _override_limits(raw, args):
        text = toml.dumps(raw)
    try:
        case = schema.validate(raw)
    except CaseError as exc:
        raise CaseError(f"{directory}/checkpoint.h5: {exc}") from None
    return case, text


def continue_command(ranks, directory, petsc_options=()):
    """The command that continues the run in ``directory``, with the same solver options
    (they are not part of the case)."""
    options = "".join(f" {shlex.quote(option)}" for option in petsc_options)
    return f"mpirun -n {ranks} python -m parmps --restart {shlex.quote(directory)}{options}"


def _run(args, petsc_options, comm):
    checkpoint = None
    if args.restart is not None:
        case, case_text = _verdict(comm, lambda: prepare_restart(args))
        directory = args.restart
        from parmps.io.checkpoint import read_checkpoint
        checkpoint = read_checkpoint(directory)
        name = f"{directory} (continued)"
    else:
        if args.case is None:
            raise CaseError("command line: a case file is needed (or --restart OUTDIR)")
        case, case_text = _verdict(comm, lambda: prepare_case(args))
        stem = os.path.splitext(os.path.basename(args.case))[0]
        directory = args.output or os.path.join("out", stem)
        name = args.case
    from parmps.run.simulation import Simulation
    solver_options = {}
    if not args.check and petsc_options:
        from parmps.fluid.ppe import initialise
        solver_options = initialise(petsc_options)
    if not args.check:
        _verdict(comm, lambda: prepare_output(directory))
    # Geometry is checked while building the scene, on every rank alike.
    run = Simulation(case, case_text, comm, directory, solver_options=solver_options,
                     checkpoint=checkpoint)
    if args.check:
        summary = run.summary()
        if comm.rank == 0:
            print(json.dumps(summary, indent=2))
        return 0
    log.info("case %s: %s particles on %d rank(s), output in %s", name,
             ", ".join(f"{v} {k}" for k, v in run.counts.items()), comm.size, directory)
    path = run.execute()
    log.info("output: %s and %s", path, os.path.join(directory, "result.xdmf"))
    if run.state.outcome == "interrupted":
        if comm.rank == 0:
            command = continue_command(comm.size, directory, petsc_options)
            log.warning("interrupted: the checkpoint is in %s; continue the run with\n  %s\n"
                        "or  %s", directory, command,
                        command.replace(f"mpirun -n {comm.size} python -m parmps",
                                        f"scripts/run -n {comm.size}"))
        return INTERRUPTED
    return 0
