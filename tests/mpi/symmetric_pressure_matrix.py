"""Run the parmps command line, checking every step's pressure matrix against its transpose.

Usage: mpirun -n N python tests/mpi/symmetric_pressure_matrix.py CASE.toml [parmps arguments]

The pressure matrix is marked symmetric (parmps.fluid.ppe.pressure_matrix), so GAMG builds
its graph from it without symmetrising it. This checks the claim: every matrix the run
assembles, taken whole across the ranks, less its transpose, in the infinity norm. After
the run rank 0 prints one JSON line: the matrices checked and the largest such norm
relative to the matrix's own (0 when every matrix is exactly symmetric).
"""

import json
import sys

from mpi4py import MPI

from parmps import cli
from parmps.fluid import ppe

_assembled = ppe.pressure_matrix
record = {"matrices": 0, "asymmetry": 0.0}


def checked_matrix(PETSc, comm, *args):
    matrix, csr = _assembled(PETSc, comm, *args)
    difference = matrix.duplicate(copy=True)
    # Known symmetric, the copy would be transposed in place by doing nothing.
    difference.setOption(PETSc.Mat.Option.SYMMETRIC, False)
    difference.transpose()
    difference.axpy(-1.0, matrix)
    norm = PETSc.NormType.INFINITY
    asymmetry = difference.norm(norm) / max(matrix.norm(norm), 1e-300)
    difference.destroy()
    record["matrices"] += 1
    record["asymmetry"] = max(record["asymmetry"], asymmetry)
    return matrix, csr


ppe.pressure_matrix = checked_matrix
status = cli.main(sys.argv[1:])
if MPI.COMM_WORLD.rank == 0:
    print(json.dumps(record), flush=True)
sys.exit(status)
