"""Run the parmps command line with a fault injected on the last rank only.

Usage: mpirun -n N python tests/mpi/raise_on_one_rank.py CASE.toml [parmps arguments]

At step 3 the last rank's fluid step raises while the others go on into the
step's collective calls: the job must end (COMM_WORLD.Abort), not hang.
"""

import sys

from mpi4py import MPI

from parmps import cli
from parmps.fluid import projection as fluid

_step = fluid.FluidSolver.step


def faulty_step(self, particles, dt, step_number, *args, **kwargs):
    comm = MPI.COMM_WORLD
    if step_number == 3 and comm.rank == comm.size - 1:
        raise ZeroDivisionError(f"injected fault on rank {comm.rank}")
    return _step(self, particles, dt, step_number, *args, **kwargs)


fluid.FluidSolver.step = faulty_step
sys.exit(cli.main(sys.argv[1:]))
