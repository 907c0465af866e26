"""``python -m parmps validate``: run validations and judge them against their tolerances::

    python -m parmps validate --list
    python -m parmps validate NAME [NAME ...] | --all  [-n RANKS] [-o OUTDIR]
        [--end-time T] [--set SECTION.KEY=VALUE ...] [--timeout S]
    python -m parmps validate NAME --result RESULT.h5     # measure a run made before
    python -m parmps validate --cases [--case-ranks 1 2] [--all]   # every case to its end

Each validation runs its case as ``validation/<name>/validation.toml`` says (its end time,
output interval and settings, :meth:`parmps.validation.Validation.run_arguments`), through
the one launcher (:mod:`parmps.validation.launch`), measures the result with its metric and
prints one JSON line: the command, the outcome, the metric's figures and each tolerance's
verdict. Exit status 0 when every verdict passes, 1 when one fails or a run fails, 2 for
bad input (one line on stderr).

``--cases`` runs every case in ``cases/`` to its own end time on each of ``--case-ranks``
(1 and 2 by default) and prints one line per run: the case, the ranks, the outcome, the
simulated time reached, the steps and the seconds. With ``--all`` as well, every validation
follows: the one command that shows the defaults carry every scene to its end.
"""

import argparse
import json
import math
import os
import sys

from parmps.errors import CaseError


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise CaseError(f"validate: {message}")


def build_parser():
    parser = _Parser(prog="parmps validate",
                     description="Run parmps's validations and judge them against their "
                                 "tolerances (validation/<name>/validation.toml).")
    parser.add_argument("names", nargs="*", metavar="NAME", help="validations to run")
    parser.add_argument("--list", action="store_true", help="list the validations and exit")
    parser.add_argument("--all", action="store_true", help="run every validation")
    parser.add_argument("-n", "--ranks", type=int, default=2, help="MPI ranks (default 2)")
    parser.add_argument("-o", "--output", metavar="OUTDIR", default=os.path.join("out", "validate"),
                        help="runs go to OUTDIR/<name>/ (default out/validate)")
    parser.add_argument("--end-time", type=float, metavar="T",
                        help="stop every run at T [s] (a quick look: the metric may then "
                             "have too little to measure)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="a case override for every run (repeatable)")
    parser.add_argument("--result", metavar="RESULT",
                        help="measure this result (file or output directory) instead of running")
    parser.add_argument("--cases", action="store_true",
                        help="run every case in cases/ to its end time on each of "
                             "--case-ranks, one line per run")
    parser.add_argument("--case-ranks", type=int, nargs="+", default=[1, 2], metavar="RANKS",
                        help="with --cases: the rank counts (default 1 2)")
    parser.add_argument("--case-glob", default="*", metavar="PATTERN",
                        help="with --cases: only the case files matching cases/PATTERN.toml")
    parser.add_argument("--timeout", type=float, default=24 * 3600.0,
                        help="seconds before a run is killed (default one day)")
    return parser


def listing():
    """One line per validation: name, case (relative to the data root) and metric."""
    from parmps import validation
    lines = []
    for name in validation.names():
        check = validation.load(name)
        case = os.path.relpath(check.case_path, validation.ROOT)
        lines.append(f"{name:20s} {case:36s} {check.metric['function']}")
    return lines


def scalars(value):
    """The JSON-friendly figures of a metric's result: numbers, strings and nested tables of
    them; arrays and series are left out."""
    if isinstance(value, dict):
        out = {key: scalars(item) for key, item in value.items()}
        return {key: item for key, item in out.items() if item is not None}
    if isinstance(value, bool) or isinstance(value, (int, str)):
        return value
    if isinstance(value, float) or hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0:
        value = float(value)
        return value if math.isfinite(value) else str(value)
    return None


def run_settings(check, args):
    """(end time, --set overrides) of a validation's runs: its own, ``--end-time`` first."""
    end_time, sets = check.run_arguments(args.set)
    return (args.end_time if args.end_time is not None else end_time), sets


def run_beside(check, args, path):
    """The results of the other cases ``[run] beside`` names (keys of ``[other_cases]``),
    run as the validation's own case is, for a metric that compares with them
    (``beside = {name: result}``): {} when it names none, None when one did not run. With
    ``--result`` (``path``, the validation's own result) they are read from beside it,
    ``<its folder>/../<validation>-<name>/``, where a validation run puts them."""
    from parmps import validation
    from parmps.validation import launch
    names = check.run.get("beside", [])
    if not names:
        return {}
    out = {}
    for name in names:
        if args.result is not None:
            other = os.path.join(os.path.dirname(os.path.abspath(path)), os.pardir,
                                 f"{check.name}-{name}", "result.h5")
        else:
            end_time, sets = run_settings(check, args)
            folder = os.path.abspath(os.path.join(args.output, f"{check.name}-{name}"))
            other = launch.run(check.other_cases[name], folder, sets, end_time,
                               ranks=args.ranks, timeout=args.timeout,
                               root=validation.ROOT)["result"]
        if not os.path.isfile(other):
            return None
        out[name] = os.path.normpath(other)
    return out


def measure(check, path, beside=None):
    """(figures, verdicts, error) of a result: the metric's scalars and each tolerance's
    verdict, or the reason it could not be measured; ``beside``: the other runs it is
    compared with, if any."""
    try:
        measured = check.measure(path, **({"beside": beside} if beside else {}))
    except (CaseError, ValueError, KeyError, IndexError) as exc:
        return {}, {}, f"{type(exc).__name__}: {exc}"
    return scalars(measured), check.verdicts(measured), ""


def not_judged(check, verdicts):
    """The tolerances no verdict applied: those the tests judge from the run itself (a
    sub-table, a second case's, a figure the metric does not return)."""
    left = []
    for key in check.tolerance:
        name = check.judge.get(key, key)
        paths = name if isinstance(name, list) else [name]
        if key != "judged" and not any(v in paths or v.endswith(f".{name}_error")
                                       for v in verdicts for name in paths):
            left.append(key)
    return sorted(left)


def validate_one(check, args):
    """Run (or read) one validation; returns its JSON record."""
    from parmps import validation
    from parmps.validation import launch
    record = {"validation": check.name}
    if args.result is not None:
        from parmps.result import result_path
        path = result_path(args.result)
    else:
        end_time, sets = run_settings(check, args)
        out = os.path.abspath(os.path.join(args.output, check.name))
        run = launch.run(check.case_path, out, sets, end_time, ranks=args.ranks,
                         timeout=args.timeout, root=validation.ROOT)
        record.update({key: run[key] for key in ("command", "outcome", "elapsed")})
        record["elapsed"] = round(record["elapsed"], 2)
        path = run["result"]
        if not os.path.isfile(path):
            record["passed"] = False
            return record
    beside = run_beside(check, args, path)
    if beside is None:
        record["passed"] = False
        return record
    figures, verdicts, error = measure(check, path, beside)
    record.update(result=path, measured=figures, verdicts=verdicts,
                  not_judged=not_judged(check, verdicts))
    if error:
        record["error"] = error
    # Passed: the run ended, it was measured, and at least one verdict was given, all passing.
    record["passed"] = (not error and record.get("outcome", "ran to the end") == "ran to the end"
                        and bool(verdicts) and all(v["pass"] for v in verdicts.values()))
    return record


def run_cases(args):
    """Every case file in cases/ to its end on each rank count; yields one record a run."""
    import glob

    from parmps import config, schema
    from parmps.validation import ROOT, launch
    paths = sorted(glob.glob(os.path.join(ROOT, "cases", args.case_glob + ".toml")))
    if not paths:
        raise CaseError(f"validate: no case matches cases/{args.case_glob}.toml")
    for path in paths:
        name = os.path.splitext(os.path.basename(path))[0]
        with open(path, "rb") as handle:
            end = schema.validate(config.load_text(handle.read().decode(), path))["time"]["end"]
        if args.end_time is not None:
            end = min(end, args.end_time)
        for ranks in args.case_ranks:
            out = os.path.abspath(os.path.join(args.output, "cases", f"{name}-{ranks}"))
            run = launch.run(path, out, args.set, end_time=end, ranks=ranks,
                             timeout=args.timeout, root=ROOT)
            reached = run.get("end", 0.0)
            yield {"case": os.path.relpath(path, ROOT), "ranks": ranks,
                   "outcome": run["outcome"], "end_time": end, "reached": reached,
                   "steps": run.get("steps", 0), "elapsed": round(run["elapsed"], 1),
                   "passed": run["outcome"] == "ran to the end" and reached >= end * (1 - 1e-9),
                   "command": run["command"]}


def main(argv):
    """The ``validate`` command; returns the exit status."""
    from parmps import validation
    args = build_parser().parse_args(argv)
    if args.list:
        print("\n".join(listing()))
        return 0
    if args.case_ranks and min(args.case_ranks) < 1:
        raise CaseError(f"validate: --case-ranks must be at least 1, got {min(args.case_ranks)}")
    status = 0
    if args.cases:
        for record in run_cases(args):
            print(json.dumps(record), flush=True)
            status = status or int(not record["passed"])
        if not args.all and not args.names:
            return status
    if args.all == bool(args.names):
        raise CaseError("validate: name one or more validations, or --all (--list names them)")
    if args.result is not None and (args.all or len(args.names) != 1):
        raise CaseError("validate: --result measures one validation's run: name one")
    if args.ranks < 1:
        raise CaseError(f"validate: --ranks must be at least 1, got {args.ranks}")
    known = validation.names()
    unknown = [name for name in args.names if name not in known]
    if unknown:
        raise CaseError(f"validate: no validation '{unknown[0]}' (known: {', '.join(known)})")
    checks = [validation.load(name) for name in (known if args.all else args.names)]
    for check in checks:
        record = validate_one(check, args)
        print(json.dumps(record), flush=True)
        status = status or int(not record["passed"])
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
