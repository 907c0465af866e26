"""Domain decomposition into slabs along x: ownership, halo exchange, migration.

:class:`SlabDecomposition` implements the interface of
:class:`parmps.parallel.base.Decomposition` (``parallel.decomposition =
"slabs"``); the contract of each method is there. Slabs exchange ghosts with
two neighbours only, which is cheapest for few ranks; their ghosts grow with
the cross-section of the domain, not with N/P (blocks.py shrinks them).

Layout. Rank k owns the half-open interval ``[edges[k], edges[k+1])`` of x;
the first slab extends to -inf and the last to +inf (``edges[0]`` and
``edges[-1]`` hold the domain's x bounds for display only), so every particle,
even one exactly on an edge or outside the domain, has exactly one owner. The
ranks sit on a one-dimensional non-periodic Cartesian communicator; the
neighbours of the end slabs are ``MPI.PROC_NULL``, so exchanges need no special
cases.

Halo. Ghosts are copies of the owned particles whose distance to a slab edge is
less than ``halo_width = reach + margin`` (``reach = (re_laplacian +
halo_skin) * spacing``, ``margin`` below), sent to the neighbour across that
edge only. That is complete as long as every interior slab is at least
``min_slab_width = reach + 2 margin`` wide, which the constructor,
:meth:`distribute` and :meth:`rebalance` enforce. Ghosts come after the owned
particles: first those from the left neighbour, then those from the right, each
in the owner's order.

Lazy migration. With ``parallel.migration_margin`` m > 0 (in spacings),
particles may stray up to m past their slab before anyone migrates: while no
particle on any rank is further out, :meth:`migrate` only drops the ghosts;
once one is, every particle outside its slab moves to its owner. The ranks' row
counts then change every few steps instead of every step, so the pressure
solver can keep its AMG set-up (which cannot survive a change of layout) as
long as on one rank. The halo and the slabs widen by the margin to stay
complete. m = 0 migrates at every step.

Order. Owned particles are kept in ascending global id after every
:meth:`distribute` and :meth:`migrate`, so the local order does not depend on
the rank count or on the history of migrations.

Messages. Particle data travels as packed bytes (one row of bytes per
particle, all fields side by side) through buffer-based calls: non-blocking
sends and receives to both neighbours at once, the counts exchanged first
(``refresh`` knows them from ``build_halo`` and skips that round), and one
``Alltoallv`` when some particle has to jump more than one slab. Nothing is
pickled on the per-step path.
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.errors import CaseError
from parmps.core.particles import FIELDS, Particles
from parmps.parallel.balance import gap_quantiles, histogram_quantiles
from parmps.parallel.base import Decomposition
from parmps.parallel.exchange import (field_arrays, merge_by_id, pack, send_to_ranks,
                                      sorted_by_id, unpack_into, unpack_new)

log = logging.getLogger(__name__)

_WIDTH_RULE = ("(mps.re_laplacian + parallel.halo_skin + 2 x parallel.migration_margin) x "
               "particles.spacing")


# Message tags by the direction a message travels (towards lower or higher ranks).
_TAG_COUNT_LEFTWARD, _TAG_COUNT_RIGHTWARD, _TAG_DATA_LEFTWARD, _TAG_DATA_RIGHTWARD = range(701, 705)


# --- the decomposition -------------------------------------------------------------------------

class SlabDecomposition(Decomposition):
    """Slabs along x, one per rank of ``comm``; see the module docstring."""

    name = "slabs"

    def __init__(self, comm, domain, halo, balance):
        super().__init__(comm, domain, halo, balance)
        self.cart = comm.Create_cart([comm.size], periods=[False], reorder=False)
        self.left, self.right = self.cart.Shift(0, 1)
        self.min_slab_width = self.min_width
        self.capacity = slab_capacity(self.lower, self.upper, self.min_width)
        if comm.size > self.capacity:
            raise CaseError(too_many_slabs(comm.size, self.lower, self.upper, self.min_width))
        # Until distribute: equal widths over the domain.
        self.edges = np.linspace(self.lower[0], self.upper[0], comm.size + 1)
        self._send_left = np.empty(0, np.int64)
        self._send_right = np.empty(0, np.int64)
        self._n_from_left = 0
        self._n_from_right = 0
        self._n_owned = 0

    @property
    def neighbours(self):
        """The adjacent slabs' ranks (none past the ends)."""
        return [r for r in (self.left, self.right) if r != MPI.PROC_NULL]

    def box(self, rank):
        """(lower, upper) corners of ``rank``'s slab: x between its edges, all y (and z)."""
        lower = np.full(self.dimension, -np.inf)
        upper = np.full(self.dimension, np.inf)
        if rank > 0:
            lower[0] = self.edges[rank]
        if rank < self.size - 1:
            upper[0] = self.edges[rank + 1]
        return lower, upper

    def describe(self):
        return f"{self.size} slab{'s' if self.size > 1 else ''} along x"

    # -- layout ---------------------------------------------------------------------------------

    @property
    def interior_edges(self):
        """The size-1 edges between slabs (rank k owns [edges[k], edges[k+1]))."""
        return self.edges[1:-1]

    @property
    def slab(self):
        """This rank's half-open x interval (the end slabs are unbounded)."""
        lo = -np.inf if self.rank == 0 else self.edges[self.rank]
        hi = np.inf if self.rank == self.size - 1 else self.edges[self.rank + 1]
        return lo, hi

    def owner(self, position):
        """The rank owning each row of ``position`` ((n, d)): its x decides (half-open
        slabs; the ends extend to infinity)."""
        return self._owner_x(self._positions(position)[:, 0])

    def _owner_x(self, x):
        return np.searchsorted(self.interior_edges, np.asarray(x, dtype=np.float64),
                               side="right").astype(np.int64)

    def _thin_slab(self, edges):
        """(rank, width) of the first interior slab thinner than the halo, or None."""
        if len(edges) <= 3:
            return None
        widths = np.diff(edges[1:-1])
        thin = np.flatnonzero(~(widths >= self.min_slab_width * (1 - 1e-12)))
        if len(thin) == 0:
            return None
        return int(thin[0]) + 1, float(widths[thin[0]])

    # -- distribute -----------------------------------------------------------------------------

    def distribute(self, particles):
        """From the global scene (identical on every rank) keep this rank's particles.

        The edges go between the lattice columns nearest the quantiles of x weighted
        by work (:meth:`weights`), so the loads are even up to a column; where that
        would make a slab thinner than the halo, by count. Raises CaseError on every
        rank if an interior slab would still be thinner than the halo.
        """
        x = particles.position[:particles.n_owned, 0]
        edges = None
        if self.rank == 0:
            order = np.argsort(x, kind="stable")
            edges = self._quantile_edges(x[order], self.weights(particles)[order])
            if self._thin_slab(edges) is not None:
                # Work piles up where the fluid is: its slabs are the narrowest.
                log.info("slabs balanced by work would be thinner than the halo: balanced "
                         "by count")
                edges = self._quantile_edges(x[order], None)
        edges = self.cart.bcast(edges, root=0)
        thin = self._thin_slab(edges)
        if thin is not None:
            rank, width = thin
            raise CaseError(
                f"{self.size} ranks split the particles into slabs along x of which rank "
                f"{rank}'s is {width:g} m wide, thinner than the halo {self.min_slab_width:g} m "
                f"({_WIDTH_RULE}): run on fewer ranks")
        self.edges = edges
        mine, total, imbalance = self._keep_owned(particles, self._owner_x(x))
        log.info("distributed %d particles over %d slabs, edges %s, imbalance %.3f",
                 total, self.size, np.array2string(self.interior_edges, precision=4), imbalance)
        return mine

    def _quantile_edges(self, xs, weights):
        """Edges (size+1, the outer two the domain bounds) at the gaps nearest the quantiles
        of the sorted ``xs`` weighted by ``weights``."""
        return gap_quantiles(xs, self.size, self.lower[0], self.upper[0], weights,
                             self.extra_work)

    # -- migration ------------------------------------------------------------------------------

    def _migrate(self, particles, force=False):
        n = particles.n_owned
        if self.size == 1:
            result = particles.owned() if particles.n_ghost else particles
            self._clear_halo(result.n_owned)
            return sorted_by_id(result)
        x = particles.position[:n, 0]
        owner = self._owner_x(x)
        stay = owner == self.rank
        leaving = np.flatnonzero(~stay)
        # [farthest jump in slabs, a particle past the margin] over all ranks.
        state = np.zeros(2, np.int64)
        if len(leaving):
            state[0] = np.max(np.abs(owner[leaving] - self.rank))
            lo, hi = self.slab
            state[1] = force or self.margin == 0.0 or bool(
                np.any((x[leaving] < lo - self.margin) | (x[leaving] >= hi + self.margin)))
        self.cart.Allreduce(MPI.IN_PLACE, state, op=MPI.MAX)
        distance = int(state[0]) if state[1] else 0
        if distance:
            self.migration_count += 1
        if distance == 0:
            result = particles.owned() if particles.n_ghost else particles
        elif distance == 1:
            result = self._migrate_neighbours(particles, owner, stay)
        else:
            result = self._migrate_all(particles, owner)
        self._clear_halo(result.n_owned)
        return sorted_by_id(result)

    def _migrate_neighbours(self, particles, owner, stay):
        """Every leaving particle goes to an adjacent slab: two neighbour exchanges."""
        arrays = field_arrays(particles)
        to_left = np.flatnonzero(owner == self.rank - 1)
        to_right = np.flatnonzero(owner == self.rank + 1)
        from_left, from_right = self._exchange(pack(arrays, to_left), pack(arrays, to_right))
        incoming = unpack_new(np.concatenate([from_left, from_right]), arrays)
        return merge_by_id(particles, np.flatnonzero(stay), incoming)

    def _migrate_all(self, particles, owner):
        """Some particle jumps more than one slab: one all-to-all by owner."""
        return send_to_ranks(particles, owner, self.cart)

    def _exchange(self, to_left, to_right, counts=None):
        """Send packed rows to both neighbours; returns the rows (from_left, from_right).

        Non-blocking sends and receives, so both directions share one round of
        latency. With ``counts`` (rows expected from the left and the right) the
        count messages are skipped. Neighbours that are PROC_NULL send nothing.
        """
        cart = self.cart
        if counts is None:
            outgoing = [np.array([len(to_left)], np.int64), np.array([len(to_right)], np.int64)]
            incoming = [np.zeros(1, np.int64), np.zeros(1, np.int64)]
            MPI.Request.Waitall([
                cart.Irecv(incoming[0], source=self.left, tag=_TAG_COUNT_RIGHTWARD),
                cart.Irecv(incoming[1], source=self.right, tag=_TAG_COUNT_LEFTWARD),
                cart.Isend(outgoing[0], dest=self.left, tag=_TAG_COUNT_LEFTWARD),
                cart.Isend(outgoing[1], dest=self.right, tag=_TAG_COUNT_RIGHTWARD)])
            counts = (int(incoming[0][0]), int(incoming[1][0]))
        width = to_left.shape[1]
        from_left = np.empty((counts[0], width), np.uint8)
        from_right = np.empty((counts[1], width), np.uint8)
        MPI.Request.Waitall([
            cart.Irecv([from_left, MPI.BYTE], source=self.left, tag=_TAG_DATA_RIGHTWARD),
            cart.Irecv([from_right, MPI.BYTE], source=self.right, tag=_TAG_DATA_LEFTWARD),
            cart.Isend([to_left, MPI.BYTE], dest=self.left, tag=_TAG_DATA_LEFTWARD),
            cart.Isend([to_right, MPI.BYTE], dest=self.right, tag=_TAG_DATA_RIGHTWARD)])
        return from_left, from_right

    # -- halo -----------------------------------------------------------------------------------

    def _clear_halo(self, n_owned):
        self._send_left = np.empty(0, np.int64)
        self._send_right = np.empty(0, np.int64)
        self._n_from_left = self._n_from_right = 0
        self._n_owned = n_owned

    def _build_halo(self, particles):
        owned = particles.owned() if particles.n_ghost else particles
        n = owned.n_owned
        if self.size == 1:
            self._clear_halo(n)
            return owned
        x = owned.position[:, 0]
        lo, hi = self.slab
        self._send_left = (np.flatnonzero(x - lo < self.halo_width)
                           if self.left != MPI.PROC_NULL else np.empty(0, np.int64))
        self._send_right = (np.flatnonzero(hi - x < self.halo_width)
                            if self.right != MPI.PROC_NULL else np.empty(0, np.int64))
        arrays = field_arrays(owned)
        from_left, from_right = self._exchange(pack(arrays, self._send_left),
                                               pack(arrays, self._send_right))
        self._n_owned = n
        self._n_from_left = len(from_left)
        self._n_from_right = len(from_right)
        total = n + self._n_from_left + self._n_from_right
        combined = {}
        for name, array in zip(FIELDS, arrays):
            out = np.empty((total,) + array.shape[1:], array.dtype)
            out[:n] = array
            combined[name] = out
        out_arrays = list(combined.values())
        unpack_into(from_left, out_arrays, n)
        unpack_into(from_right, out_arrays, n + self._n_from_left)
        return Particles(combined, n_owned=n)

    @property
    def n_neighbour_ghost(self):
        """Ghosts from the adjacent slabs made by the last build_halo."""
        return self._n_from_left + self._n_from_right

    def _refresh(self, targets):
        if self.size == 1:
            return
        # The ghost counts are known since build_halo: one round of messages.
        from_left, from_right = self._exchange(pack(targets, self._send_left),
                                               pack(targets, self._send_right),
                                               (self._n_from_left, self._n_from_right))
        unpack_into(from_left, targets, self._n_owned)
        unpack_into(from_right, targets, self._n_owned + self._n_from_left)

    # -- load balance ---------------------------------------------------------------------------

    def _balanced_layout(self, particles):
        """Edges at the x quantiles of the owned work (:meth:`_histogram_edges`), or None
        when every particle has the same x."""
        return self._histogram_edges(particles.position[:particles.n_owned, 0],
                                     self.weights(particles))

    def _refusal(self, edges):
        if edges is None:
            return "every particle has the same x: keeping the slab edges"
        thin = self._thin_slab(edges)
        if thin is None:
            return None
        return (f"balancing would make rank {thin[0]}'s slab {thin[1]:.4g} m wide, thinner "
                f"than the halo {self.min_slab_width:.4g} m: keeping the slab edges")

    def _take_layout(self, edges):
        old, self.edges = self.edges, edges
        return old

    def _layout_change(self, old):
        return (f"edges {np.array2string(old[1:-1], precision=4)} -> "
                f"{np.array2string(self.interior_edges, precision=4)}")

    def _histogram_edges(self, x, weights):
        """New edges at the quantiles of x weighted by work, from allreduced histograms
        (:func:`parmps.parallel.balance.histogram_quantiles`), or None when every particle
        has the same x."""
        finite = np.isfinite(x)
        edges, cut = histogram_quantiles(self.cart, x[finite], weights[finite],
                                         np.zeros(np.count_nonzero(finite), np.int64), 1,
                                         self.size, self.edges[None, :],
                                         self.extra_work[None, :])
        return edges[0] if cut[0] else None


def slab_capacity(lower, upper, min_width):
    """How many slabs at least ``min_width`` wide the domain holds along x (at least 1)."""
    width = float(upper[0] - lower[0])
    return max(1, int(np.floor(width / min_width * (1 + 1e-12))))


def too_many_slabs(ranks, lower, upper, min_width):
    """The one-line refusal for more ranks than the domain holds slabs."""
    width = float(upper[0] - lower[0])
    capacity = slab_capacity(lower, upper, min_width)
    plural = "s" if capacity > 1 else ""
    return (f"{ranks} ranks need slabs at least {min_width:g} m wide ({_WIDTH_RULE}), but the "
            f"domain is {width:g} m wide along x and holds at most {capacity} such slab{plural}: "
            f"run on at most {capacity} rank{plural}")
