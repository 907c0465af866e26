#!/usr/bin/env python3
"""What probes cost: a run with its probes timed apart from the rest of the step.

    [mpirun -n R] scripts/bench_probes.py [CASE] [--spacing L0] [--steps S] [--warmup W]
                                          [--extra-probes]

Runs CASE (default cases/dam_break.toml with four probes: two pressure points, one on
the left wall, a level gauge and the force on the floor; --extra-probes adds them to a
case that has its own) for W warm-up steps (numba compilation, first AMG set-ups) and S
timed steps, without frames, and prints one JSON line: the steps' wall seconds, the
seconds in the probe observer (the slowest rank's) and their ratio in per cent.
"""

import argparse
import json
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

FOUR_PROBES = """
[[probe]]
name = "bench_p_column"
kind = "pressure"
position = [0.1, 0.05]

[[probe]]
name = "bench_p_wall"
kind = "pressure"
position = [0.0, 0.02]
normal = [1.0, 0.0]

[[probe]]
name = "bench_level"
kind = "level"
line = [[0.1, 0.0], [0.1, 0.6]]

[[probe]]
name = "bench_floor_force"
kind = "force"
segment = [[0.0, 0.0], [1.0, 0.0]]
normal = [0.0, 1.0]
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", nargs="?", default=os.path.join(ROOT, "cases", "dam_break.toml"))
    parser.add_argument("--spacing", type=float, default=None)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--extra-probes", action="store_true")
    args = parser.parse_args()

    from mpi4py import MPI

    from parmps import config, schema
    from parmps.probes import observer as probe_observer
    from parmps.run.simulation import Simulation
    from parmps.tools.logging import configure

    comm = MPI.COMM_WORLD
    configure(comm)
    with open(args.case) as handle:
        text = handle.read()
    if args.extra_probes or "[[probe]]" not in text:
        text += FOUR_PROBES
    raw = config.load_text(text)
    if args.spacing is not None:
        raw["particles"]["spacing"] = args.spacing
    raw["time"]["max_steps"] = args.warmup + args.steps
    raw.setdefault("output", {})["frames"] = False
    case = schema.validate(raw)

    spent = {"probes": 0.0, "loop_at_warmup": None, "probe_at_warmup": None}
    original = probe_observer.Probes.observe

    def timed(self, state):
        start = time.perf_counter()
        original(self, state)
        spent["probes"] += time.perf_counter() - start
        if state.step == args.warmup:
            spent["loop_at_warmup"] = state.elapsed
            spent["probe_at_warmup"] = spent["probes"]

    probe_observer.Probes.observe = timed
    directory = tempfile.mkdtemp(prefix="bench_probes_") if comm.rank == 0 else None
    directory = comm.bcast(directory)
    simulation = Simulation(case, text, comm, directory)
    simulation.execute()
    state = simulation.state
    steps_seconds = state.elapsed - spent["loop_at_warmup"]
    probe_seconds = comm.allreduce(spent["probes"] - spent["probe_at_warmup"], op=MPI.MAX)
    steps_seconds = comm.allreduce(steps_seconds, op=MPI.MAX)
    if comm.rank == 0:
        print(json.dumps({
            "case": os.path.basename(args.case), "spacing": case["particles"]["spacing"],
            "particles": sum(simulation.counts.values()), "ranks": comm.size,
            "probes": len(case["probe"]), "steps": args.steps,
            "seconds": round(steps_seconds, 3), "probe_seconds": round(probe_seconds, 4),
            "probe_percent": round(100 * probe_seconds / steps_seconds, 2)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
