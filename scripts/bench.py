#!/usr/bin/env python3
"""Benchmark: the dam break at several sizes and rank counts, one JSON line per run.

    scripts/bench.py [--particles N ...] [--ranks R ...] [--steps S] [--warmup W]
                     [--set SECTION.KEY=VALUE ...]

Each run builds cases/dam_break.toml at the spacing that gives about N particles
(fluid, walls and dummies), takes W warm-up steps (numba compilation, first
AMG set-ups), then times S steps. It prints particles, ranks, steps, seconds,
us_per_particle_step and a breakdown of seconds by part (the slowest rank's).
``--set`` applies case overrides as parmps does (a pressure scheme, say).
Runs with more ranks than cores oversubscribe, which the line records.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASE = os.path.join(ROOT, "cases", "dam_break.toml")


def spacing_for(target):
    """The l0 = a/m (a the case's column width) whose dam-break scene holds closest to
    ``target`` particles."""
    from parmps.core import scene
    from parmps.tools import analysis
    lower, upper = analysis.fluid_extent(_case(None))
    width, height = upper - lower
    best = None
    for m in range(10, 400):
        spacing = width / m
        fluid = m * round(height / spacing)
        if fluid > 2 * target:
            break
        if fluid < target / 4:
            continue
        case = _case(spacing)
        total = len(scene.build(case)[0])
        if best is None or abs(total - target) < abs(best[1] - target):
            best = (spacing, total)
    return best


def _case(spacing, steps=0, overrides=()):
    from parmps import config, schema
    with open(CASE, "rb") as handle:
        raw = config.load_text(handle.read().decode())
    for assignment in overrides:
        config.apply_override(raw, assignment)
    if spacing is not None:
        raw["particles"]["spacing"] = spacing
    # A tank twice as tall as the column, as the run-up needs for 25 steps, keeps the
    # count mostly fluid (the case's taller walls are for the splash at t > 0.4 s).
    tank, domain = raw["tank"][0], raw["domain"]
    headroom = domain["upper"][1] - tank["upper"][1]
    column = raw["fluid_block"][0]
    tank["upper"][1] = tank["lower"][1] + 2 * (column["upper"][1] - column["lower"][1])
    domain["upper"][1] = tank["upper"][1] + headroom
    raw["time"]["max_steps"] = steps
    raw.setdefault("output", {})["frames"] = False
    return schema.validate(raw)


def worker(args):
    """One timed run on the ranks of COMM_WORLD; rank 0 prints the JSON line."""
    import time

    from mpi4py import MPI

    from parmps.run.observers import Callback
    from parmps.run.simulation import Simulation
    comm = MPI.COMM_WORLD
    spacing = args.spacing
    case = _case(spacing, steps=args.warmup + args.steps, overrides=args.overrides)
    directory = comm.bcast(tempfile.mkdtemp(prefix="parmps-bench-") if comm.rank == 0 else None)
    run = Simulation(case, "", comm, directory)
    timers = run.fluid.timers
    decomposition = run.decomposition
    marks = {}

    def mark_warm(state):
        if state.step == args.warmup:
            comm.Barrier()
            marks["start"] = time.perf_counter()
            marks["fluid"] = dict(timers.seconds)
            marks["halo"] = decomposition.halo_seconds
            marks["migration"] = decomposition.migration_seconds

    run.execute(extra_observers=[Callback(mark_warm)])
    comm.Barrier()
    seconds = time.perf_counter() - marks["start"]
    breakdown = {part: timers.seconds[part] - marks["fluid"][part]
                 for part in ("neighbours", "operators", "assembly", "solve", "output")}
    breakdown["halo"] = decomposition.halo_seconds - marks["halo"]
    breakdown["migration"] = decomposition.migration_seconds - marks["migration"]
    breakdown = {k: comm.allreduce(v, op=MPI.MAX) for k, v in breakdown.items()}
    particles = comm.allreduce(run.state.particles.n_owned)
    if comm.rank == 0:
        line = {
            "particles": particles, "ranks": comm.size, "steps": args.steps,
            "seconds": round(seconds, 4),
            "us_per_particle_step": round(1e6 * seconds / (particles * args.steps), 3),
            "breakdown": {k: round(v, 4) for k, v in breakdown.items()},
            "spacing": spacing,
            "oversubscribed": comm.size > (os.cpu_count() or 1),
        }
        if args.overrides:
            line["set"] = list(args.overrides)
        print(json.dumps(line), flush=True)
        import shutil
        shutil.rmtree(directory, ignore_errors=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, nargs="+", default=[2500, 10000, 40000])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--set", action="append", default=[], dest="overrides",
                        metavar="SECTION.KEY=VALUE", help="a case override, as parmps --set")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--spacing", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args)
        return 0
    from parmps.parallel.mpi import launch_environment, mpirun_command
    status = 0
    for target in args.particles:
        spacing, _ = spacing_for(target)
        for ranks in args.ranks:
            argv = [sys.executable, os.path.abspath(__file__), "--worker", "--spacing",
                    repr(spacing), "--steps", str(args.steps), "--warmup", str(args.warmup)]
            argv += [word for override in args.overrides for word in ("--set", override)]
            command = mpirun_command(ranks, argv) if ranks > 1 else argv
            result = subprocess.run(command, capture_output=True, text=True,
                                    env=launch_environment(), cwd=ROOT)
            lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
            if result.returncode != 0 or not lines:
                print(json.dumps({"particles": target, "ranks": ranks,
                                  "error": result.stderr.strip().splitlines()[-3:]}), flush=True)
                status = 1
                continue
            print(lines[-1], flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
