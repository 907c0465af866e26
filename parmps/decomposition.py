"""Domain decomposition into slabs along x: ownership, halo exchange, migration.

The interface the solver uses (all methods are collective over ``comm``):

- ``SlabDecomposition(comm, case)``: the slab layout for a case.
- ``distribute(particles)``: from the global scene (the same on every rank) keep
  the particles this rank owns.
- ``migrate(particles)``: drop ghosts, send owned particles that left the slab to
  their new owner; returns owned-only Particles.
- ``build_halo(particles)``: append ghosts (copies of neighbours' particles within
  the halo width of this slab's edges) after the owned ones; remembers what was
  sent so ``refresh`` can update the same ghosts.
- ``refresh(particles_or_arrays)``: copy the owners' current values of
  per-particle arrays (length n_owned + n_ghost) into the ghost slots, in place.
- ``rebalance(particles, step)``: every few steps move slab edges to the
  quantiles of x if the load is uneven; returns owned-only Particles.

This version holds one slab: the whole domain on one rank.
"""

import logging

import numpy as np

from parmps.errors import CaseError

log = logging.getLogger(__name__)


class SlabDecomposition:
    def __init__(self, comm, case):
        self.comm = comm
        spacing = case["particles"]["spacing"]
        self.halo_width = (case["mps"]["re_laplacian"] + case["parallel"]["halo_skin"]) * spacing
        self.lower = float(case["domain"]["lower"][0])
        self.upper = float(case["domain"]["upper"][0])
        if comm.size > 1:
            raise CaseError(f"this build of parmps runs on one rank only; got {comm.size} ranks "
                            f"(domain decomposition is not available yet)")
        self.edges = np.array([self.lower, self.upper])
        self.halo_seconds = 0.0
        self.migration_seconds = 0.0

    def distribute(self, particles):
        return particles.owned()

    def migrate(self, particles):
        return particles.owned()

    def build_halo(self, particles):
        return particles.owned()

    def refresh(self, arrays):
        return arrays

    def rebalance(self, particles, step):
        return particles.owned()

    def imbalance(self, particles):
        """Largest rank's owned count over the mean (1.0 is perfect balance)."""
        counts = self.comm.allgather(particles.n_owned)
        mean = sum(counts) / len(counts)
        return max(counts) / mean if mean > 0 else 1.0
