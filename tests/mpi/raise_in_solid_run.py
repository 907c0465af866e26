"""Run a solid-only case through the command line with a fault on the last rank only.

Usage: mpirun -n N python tests/mpi/raise_in_solid_run.py CASE.toml [parmps arguments]

At the third solid step the last rank raises while the others go on to the
collective frame write: the job must end (COMM_WORLD.Abort), not hang.
"""

import sys

from mpi4py import MPI

from parmps import cli
from parmps.solids.mass_spring import model as solid

_advance = solid.MassSpringModel.advance
_calls = {"count": 0}


def faulty_advance(self, *args, **kwargs):
    comm = MPI.COMM_WORLD
    _calls["count"] += 1
    if _calls["count"] == 3 and comm.rank == comm.size - 1:
        raise ZeroDivisionError(f"injected fault on rank {comm.rank}")
    return _advance(self, *args, **kwargs)


solid.MassSpringModel.advance = faulty_advance
sys.exit(cli.main(sys.argv[1:]))
