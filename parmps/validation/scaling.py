"""The scaling record: per rank count, what a step sends and how the pressure solve converges::

    python -m parmps bench --scaling [--scene dam_break|dam_break_3d] [--particles N]
                           [--ranks 1 2 3 4 6 8] [--steps S] [--warmup W]
                           [--set parallel.decomposition="blocks"]

For each rank count the bench worker (:func:`parmps.validation.bench.worker`) runs the
scene twice under ``mpirun``, with W + S and W + 2S steps, with Open MPI's
monitoring component on (``pml_monitoring``, which counts every message and byte a
rank sends, PETSc's included, and writes them per rank when MPI ends). The difference
of the two runs is what S steps cost, free of the set-up, so the line gives per step
and rank:

- ``p2p_messages`` and ``p2p_bytes``: point-to-point messages and bytes a rank sends
  through MPI's ordinary calls (halo builds, ghost refreshes, migrations), the largest
  rank's and the mean (``_mean``);
- ``collective_messages``: the point-to-point messages the collectives themselves send
  (allreduces of CG and of the driver), the largest rank's;
- ``solve_messages``, ``solve_bytes``, ``solve_reductions``: what the pressure solve
  (``KSPSolve``, its preconditioner set-ups included) sends and how many reductions it
  makes, from PETSc's own log (the monitoring does not see PETSc's persistent-request
  exchanges), the largest rank's;

and, from the worker's timed steps: ``ghosts_per_owned`` (the largest rank's mean
ghost-to-owned ratio), ``neighbours`` (the most ranks one rank exchanges with),
``ksp_iterations_per_step`` and ``amg_setups`` (the solve's preconditioner set-ups in the
timed steps), plus the worker's timing line. Message counts and bytes do not depend on
the machine's load; the seconds do (oversubscribed runs, ranks > cores, are marked).

:func:`projection` turns a 1-rank cost and these measured terms into the projected
parallel efficiency at large rank counts (docs/parallel.md, "Scaling record and model").
"""

import glob
import json
import math
import os
import shutil
import sys
import tempfile

# The Open MPI MCA settings of the monitoring component: 2 separates the messages the
# collectives send internally from the program's own; output 3 writes a file per rank.
MONITORING = ("--mca", "pml_monitoring_enable", "2", "--mca", "pml_monitoring_enable_output",
              "3", "--mca", "pml_monitoring_filename")


def read_monitoring(prefix):
    """Per rank ``(p2p_messages, p2p_bytes, collective_messages)`` sent, from the files
    ``prefix.<rank>.prof`` Open MPI's monitoring writes; {} when there are none."""
    counts = {}
    for path in glob.glob(prefix + ".*.prof"):
        rank = int(path.rsplit(".", 2)[-2])
        messages = data = internal = 0
        with open(path) as handle:
            for line in handle:
                fields = line.split("\t")
                if fields[0] == "E":
                    data += int(fields[3].split()[0])
                    messages += int(fields[4].split()[0])
                elif fields[0] == "I":
                    internal += int(fields[4].split()[0])
        counts[rank] = (messages, data, internal)
    return counts


def _monitored_run(argv, ranks, directory):
    """One worker run with monitoring; returns (its JSON line as a dict, per-rank counts)."""
    from parmps.parallel.mpi import mpirun_command
    from parmps.validation import ROOT, launch
    prefix = os.path.join(directory, "traffic")
    command = mpirun_command(ranks, argv)
    command[1:1] = list(MONITORING) + [prefix]
    code, stdout, stderr, _ = launch.execute(command, timeout=None, cwd=ROOT, spin=True)
    lines = [line for line in stdout.splitlines() if line.startswith("{")]
    if code != 0 or not lines:
        return {"error": stderr.strip().splitlines()[-3:]}, {}
    return json.loads(lines[-1]), read_monitoring(prefix)


def traffic_per_step(short, long, steps):
    """Per-step traffic from two runs' per-rank counts that differ by ``steps`` steps."""
    ranks = sorted(long)
    per_rank = [[(long[r][k] - short.get(r, (0, 0, 0))[k]) / steps for k in range(3)]
                for r in ranks]
    if not per_rank:
        return {"p2p_messages": 0, "p2p_bytes": 0, "p2p_messages_mean": 0,
                "p2p_bytes_mean": 0, "collective_messages": 0}
    columns = list(zip(*per_rank))
    return {"p2p_messages": round(max(columns[0]), 1),
            "p2p_messages_mean": round(sum(columns[0]) / len(ranks), 1),
            "p2p_bytes": round(max(columns[1])),
            "p2p_bytes_mean": round(sum(columns[1]) / len(ranks)),
            "collective_messages": round(max(columns[2]), 1)}


def record(args, spacing):
    """The scaling lines of ``args.ranks`` at ``spacing``, printed as they come; returns the
    exit status."""
    status = 0
    for ranks in args.ranks or [1, 2, 3, 4, 6, 8]:
        directory = tempfile.mkdtemp(prefix="parmps-scaling-")
        try:
            runs = []
            for steps in (args.steps, 2 * args.steps):
                argv = [sys.executable, "-m", "parmps.validation.bench", "--worker",
                        "--spacing", repr(spacing), "--steps", str(steps),
                        "--warmup", str(args.warmup), "--scene", args.scene]
                argv += [word for override in args.overrides for word in ("--set", override)]
                run_directory = os.path.join(directory, str(steps))
                os.mkdir(run_directory)
                runs.append(_monitored_run(argv, ranks, run_directory))
            (_, short), (line, long) = runs
            if "error" in line or (ranks > 1 and not long):
                line = dict(line, ranks=ranks, error=line.get("error", "no monitoring files: "
                                                              "Open MPI's pml_monitoring?"))
                status = 1
            else:
                line.update(traffic_per_step(short, long, args.steps))
            print(json.dumps(line), flush=True)
        finally:
            shutil.rmtree(directory, ignore_errors=True)
    return status


def terms_from_record(lines):
    """The model's measured terms from a ``--scaling`` record of one scene: the cost per
    particle-step on one rank, and from the multi-rank lines the messages per neighbour and
    step (the program's and the solve's), the bytes per ghost and step and the reductions
    per step (each rank count's own, their median over the rank counts)."""
    import statistics
    one = [line for line in lines if line["ranks"] == 1]
    many = [line for line in lines if line["ranks"] > 1 and line.get("neighbours")]
    if not one or not many:
        raise ValueError("the record needs a 1-rank line and a line with neighbours")
    ghosts = [line["ghosts_per_owned"] * line["particles"] / line["ranks"] for line in many]
    return {
        "cost": 1e-6 * one[0]["us_per_particle_step"],
        "messages": statistics.median(
            (line["p2p_messages"] + line["solve_messages"]) / line["neighbours"]
            for line in many),
        "message_bytes": statistics.median(
            (line["p2p_bytes"] + line["solve_bytes"]) / g for line, g in zip(many, ghosts)),
        # An allreduce over P ranks sends log2 P messages from each rank (recursive
        # doubling); the collectives' own messages count PETSc's reductions too.
        "reductions": statistics.median(
            line["collective_messages"] / max(math.log2(line["ranks"]), 1.0)
            for line in many),
    }


def project(lines, halo_width, particles=(1e7, 1e8), ranks=(100, 1000, 10000),
            ghost_shares=(0.25, 1.0), cost=None):
    """Projection lines (dicts) for ``particles`` x ``ranks``, a ghost costing each of
    ``ghost_shares`` of an owned particle-step; ``cost`` [s per particle-step] replaces the
    record's 1-rank figure (a record taken on a busy machine overstates it)."""
    terms = terms_from_record(lines)
    if cost is not None:
        terms["cost"] = cost
    out = []
    for n in particles:
        for p in ranks:
            line = {"particles": n, "ranks": p, "owned_per_rank": round(n / p)}
            for share in ghost_shares:
                efficiency, ghosts, shares = projection(
                    terms["cost"], share * terms["cost"], halo_width, terms["messages"],
                    terms["message_bytes"], terms["reductions"], n, p)
                line["ghosts_per_owned"] = round(ghosts, 3)
                line[f"efficiency_ghost_{share:g}"] = round(efficiency, 3)
                line[f"largest_loss_ghost_{share:g}"] = max(
                    (name for name in shares if name != "compute"), key=shares.get)
            out.append(line)
    return terms, out


def projection(cost, ghost_cost, halo_width, messages, message_bytes, reductions,
               particles, ranks, dimension=3, latency=2e-6, bandwidth=5e9,
               reduction_latency=3e-6):
    """Projected parallel efficiency of ``particles`` on ``ranks`` cubic blocks.

    ``cost``: seconds per owned particle-step on one rank; ``ghost_cost``: seconds per
    ghost-step (ghosts enter the pair search and the operators, not the matrix);
    ``halo_width`` in spacings; ``messages`` per step and neighbour; ``message_bytes`` per
    ghost and step; ``reductions`` per step (each costs ``reduction_latency`` x log2 P).
    Returns (efficiency, ghosts per owned particle, the share of the step each term
    takes as a dict).
    """
    owned = particles / ranks
    side = owned ** (1.0 / dimension)
    ghosts = ((side + 2.0 * halo_width) ** dimension - side ** dimension) if ranks > 1 else 0.0
    neighbours = 3 ** dimension - 1 if ranks > 1 else 0
    terms = {
        "compute": cost * owned,
        "ghosts": ghost_cost * ghosts,
        "latency": latency * messages * neighbours,
        "bandwidth": message_bytes * ghosts / bandwidth,
        "reductions": reduction_latency * reductions * math.log2(max(ranks, 1)),
    }
    total = sum(terms.values())
    return (cost * owned / total, ghosts / owned,
            {name: value / total for name, value in terms.items()})
