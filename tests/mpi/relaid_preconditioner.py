"""A preconditioner kept across a new layout of the rows (parmps.fluid.relaid), on N ranks.

Usage: mpirun -n N python tests/mpi/relaid_preconditioner.py

Rows are identified by id; the operator is the Laplacian of a chain of ids (in id order) plus
a shift. Layout A: each rank holds a block of ids in reversed order. The solver sets its
preconditioner up on layout A's matrix, then solves, reusing it:

1. layout A again, and layout B (the same rows, a few moved to the next rank and every
   rank's order shuffled): B's system is A's permuted, so CG with the kept preconditioner
   matched through the ids takes the same iterations;
2. layout C (B less one row, plus one the set-up never saw): the answer is the system's;
3. layout C twice more, the first renewing the set-up (at most three reuses): on 3 ranks
   only some ranks' rows change in number, and what every rank makes at a set-up it makes
   together (a rank left out waits for the others for ever).

Rank 0 prints one JSON line: the iterations of each solve, the set-ups, the errors.
"""

import json

import numpy as np
from mpi4py import MPI

from parmps import config, schema
from parmps.fluid import ppe

COMM = MPI.COMM_WORLD
N = 240
SHIFT = 0.05


def chain(ids):
    """The rows of the chain operator over ``ids`` (sorted by id, neighbours adjacent)."""
    order = np.sort(ids)
    neighbours = {}
    for k, i in enumerate(order):
        neighbours[i] = [order[m] for m in (k - 1, k + 1) if 0 <= m < len(order)]
    return neighbours


def system(layout):
    """This rank's two blocks, right-hand side and ids for ``layout`` (the ids of every
    rank, rank by rank, in row order), and the whole system's exact answer."""
    everything = np.concatenate(layout)
    row_of = {int(i): r for r, i in enumerate(everything)}
    first = sum(len(part) for part in layout[:COMM.rank])
    mine = layout[COMM.rank]
    neighbours = chain(everything)
    owned, other = ([0], [], []), ([0], [], [])
    for i in mine:
        columns = {row_of[int(i)] - first: 2.0 + SHIFT}
        for j in neighbours[i]:
            row = row_of[int(j)]
            if first <= row < first + len(mine):
                columns[row - first] = -1.0
            else:
                other[1].append(row)
                other[2].append(-1.0)
        for column in sorted(columns):
            owned[1].append(column)
            owned[2].append(columns[column])
        owned[0].append(len(owned[1]))
        other[0].append(len(other[1]))
    owned = tuple(np.array(part, dtype) for part, dtype in zip(owned, (np.int64, np.int32, float)))
    other = tuple(np.array(part, dtype) for part, dtype in zip(other, (np.int64, np.int32, float)))
    rhs_by_id = np.sin(0.37 * np.arange(N + 10))
    dense = np.zeros((len(everything), len(everything)))
    for i in everything:
        dense[row_of[int(i)], row_of[int(i)]] = 2.0 + SHIFT
        for j in neighbours[i]:
            dense[row_of[int(i)], row_of[int(j)]] = -1.0
    exact = np.linalg.solve(dense, rhs_by_id[everything])
    return owned, other, rhs_by_id[mine], mine, exact[first:first + len(mine)]


def layouts(size):
    rng = np.random.default_rng(7)
    blocks = np.array_split(np.arange(N), size)
    a = [block[::-1].copy() for block in blocks]
    # B: the last three ids of each block but the last go to the next rank; every rank's
    # order shuffled.
    b = [list(block[:-3]) for block in blocks[:-1]] + [list(blocks[-1])]
    for r in range(size - 1):
        b[r + 1] = list(blocks[r][-3:]) + b[r + 1]
    b = [rng.permutation(np.array(part, np.int64)) for part in b]
    # C: B less id 5, plus id N (new since the set-up) on the last rank.
    c = [part[part != 5] for part in b]
    c[-1] = np.concatenate([c[-1], [N]])
    return a, b, c


def main():
    with open("cases/hydrostatic.toml") as handle:
        case = schema.validate(config.load_text(handle.read()))
    settings = dict(case["pressure"], rtol=1e-10, reuse_preconditioner=3)
    solver = ppe.PressureSolver(COMM, settings)
    a, b, c = layouts(COMM.size)
    record = {"iterations": [], "errors": []}
    for solve, layout in enumerate((a, a, b, c, c, c)):
        owned, other, rhs, ids, exact = system(layout)
        p, iterations, _ = solver.solve(owned, other, rhs, np.zeros(len(rhs)), 0, ids)
        error = COMM.allreduce(float(np.max(np.abs(p - exact), initial=0.0)), op=MPI.MAX)
        record["iterations"].append(iterations)
        record["errors"].append(error)
        if solve == 3:
            record["setups_before_renewal"] = solver.setups
            record["relaid"] = solver.relaid is not None
            # GAMG's finest level applied the step's matrix seen in the set-up's layout.
            record["finest_on_setup_layout"] = (solver.relaid is not None
                                                and solver.relaid.operator is not None)
    record["setups"] = solver.setups
    solver.destroy()
    if COMM.rank == 0:
        print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
