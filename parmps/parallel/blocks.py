"""Domain decomposition into blocks of a px x py (x pz) rank grid, for any dimension d.

:class:`BlockDecomposition` implements :class:`parmps.parallel.base.Decomposition`
(``parallel.decomposition = "blocks"``); the contract of each method is there.

Grid. The rank grid (g_0, ..., g_{d-1}) is ``parallel.grid`` when the case
sets it, else the factorisation of the rank count with the fewest modelled
ghosts (:mod:`parmps.parallel.grid`): for the domain's extent when the
decomposition is made, then for the particles' bounding box in
:meth:`distribute` (a 3D tank's headroom holds no particles: on 8 ranks, for the 3D dam break
at l0 = 3 cm, the domain favours 4 x 1 x 2, the particles 4 x 2 x 1, which has a quarter fewer
ghosts on the largest rank). Rank r sits at the grid coordinates
``np.unravel_index(r, grid)``.

Cuts, balanced by particle count (multi-jagged). The domain is cut along x
into g_0 columns at the quantiles of x; each column is cut along y into g_1
at the quantiles of y of its own particles; in 3D each of those along z into
g_2. So every block holds the same count up to a lattice column, whatever the
distribution; one set of cuts per axis (a tensor grid, balanced by the counts
along each axis) does not: on the dam break at 42k particles its largest block
holds 5.5 % (2 x 2) and 14 % (4 x 2) more than the mean, the nested cuts'
0.5 % and 2.1 %; on the 3D dam break at l0 = 3 cm, 2 x 2 x 2, 7.5 % against
2.7 % (the ghosts are the same to 0.1 %). The price: a block's neighbours across a
column boundary are those
whose y range overlaps its own, not a fixed set of 3^d - 1, which the halo
below finds from the boxes. ``cuts[k]`` has one row per group of the first k
coordinates and g_k + 1 columns; the outer ones hold the domain's bounds for
display only: the blocks at the grid's faces extend to infinity, so every
position has exactly one owner.

Halo. Ghosts are copies of the particles within ``halo_width`` of a block
(its box grown by the halo width along every axis), so the neighbours across
faces, edges and corners all send theirs. Neighbours are the ranks whose box
is nearer than ``min_width`` along every axis (their strays come within the
halo); blocks at least ``min_width`` wide along each cut axis, which the
constructor, :meth:`distribute` and :meth:`rebalance` enforce as the slabs do,
keep them adjacent. Ghosts come after the owned particles by neighbour rank,
each neighbour's in its owned (ascending id) order.

Migration and rebalancing are the slabs' (lazy by ``parallel.migration_margin``,
the same load triggers), with one neighbour exchange when every particle that
leaves goes to a neighbour and one ``Alltoallv`` otherwise; a rebalance moves
the cuts to the quantiles of nested parallel histograms.
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.core.particles import FIELDS, Particles
from parmps.errors import CaseError
from parmps.parallel.balance import gap_quantiles, histogram_quantiles
from parmps.parallel.base import Decomposition
from parmps.parallel.exchange import (exchange, field_arrays, merge_by_id, pack,
                                      send_to_ranks, sorted_by_id, unpack_into, unpack_new)
from parmps.parallel.grid import capacities, choose_grid, describe_grid

log = logging.getLogger(__name__)

_WIDTH_RULE = ("(mps.re_laplacian + parallel.halo_skin + 2 x parallel.migration_margin) x "
               "particles.spacing")
_AXES = "xyz"


class BlockDecomposition(Decomposition):
    """Blocks of a Cartesian rank grid with count-balanced nested cuts; see the module."""

    name = "blocks"

    options = ("grid",)

    def __init__(self, comm, domain, halo, balance, grid=None):
        """``grid``: the rank grid (``parallel.grid``), or None to choose one."""
        super().__init__(comm, domain, halo, balance)
        grid = grid or None
        self.fixed_grid = grid is not None
        if grid is not None:
            self._check_grid(grid)
        else:
            grid = choose_grid(comm.size, self.lower, self.upper, self.min_width,
                               self.halo_width)
        if grid is None:
            raise CaseError(self._too_many_ranks())
        self._set_grid(grid)
        # Until distribute: equal widths over the domain.
        self.cuts = [np.tile(np.linspace(self.lower[k], self.upper[k], g + 1),
                             (int(np.prod(self.grid[:k], dtype=np.int64)), 1))
                     for k, g in enumerate(self.grid)]
        self._set_boxes()
        self._clear_halo(0)

    def _set_grid(self, grid):
        self.grid = tuple(int(g) for g in grid)
        self.coords = tuple(int(c) for c in np.unravel_index(self.rank, self.grid))

    def _scene_grid(self, position):
        """The grid with the fewest modelled ghosts for the particles' bounding box, which
        fits a scene better than the domain does (a tank's headroom holds no particles);
        the constructor's grid when the case set one or none fits the particles."""
        if self.fixed_grid or len(position) == 0:
            return self.grid
        lower, upper = np.min(position, axis=0), np.max(position, axis=0)
        grid = choose_grid(self.size, lower, upper, self.min_width, self.halo_width)
        return self.grid if grid is None else tuple(int(g) for g in grid)

    def _check_grid(self, grid):
        """A grid the case chose: one factor per axis, the rank count, room for the halo."""
        if int(np.prod(grid)) != self.size:
            raise CaseError(f"parallel.grid = {list(grid)} has {int(np.prod(grid))} blocks for "
                            f"{self.size} ranks: their product must be the rank count")
        caps = capacities(self.lower, self.upper, self.min_width)
        for k, (g, cap) in enumerate(zip(grid, caps)):
            if g > cap:
                raise CaseError(
                    f"parallel.grid = {list(grid)} cuts {_AXES[k]} into {g} blocks, but they "
                    f"must be at least {self.min_width:g} m wide ({_WIDTH_RULE}) and the "
                    f"domain holds at most {cap} along {_AXES[k]}")

    def _too_many_ranks(self):
        caps = capacities(self.lower, self.upper, self.min_width)
        extent = " x ".join(f"{u - l:g}" for l, u in zip(self.lower, self.upper))
        total = int(np.prod(caps))
        return (f"{self.size} ranks need blocks at least {self.min_width:g} m wide along every "
                f"cut axis ({_WIDTH_RULE}), but no grid of {self.size} ranks fits the "
                f"{extent} m domain, which holds at most {describe_grid(caps)} = {total} "
                f"such blocks: run on at most {total} rank{'s' if total > 1 else ''}")

    def describe(self):
        return f"{describe_grid(self.grid)} blocks"

    # -- layout ---------------------------------------------------------------------------------

    def box(self, rank):
        """(lower, upper) corners of ``rank``'s block; +-inf at the grid's faces."""
        return self.boxes[0][rank], self.boxes[1][rank]

    def _set_boxes(self):
        """Every rank's box from the cuts, and this rank's neighbours."""
        ranks = np.arange(self.size)
        coords = np.column_stack(np.unravel_index(ranks, self.grid))
        lower = np.empty((self.size, self.dimension))
        upper = np.empty((self.size, self.dimension))
        group = np.zeros(self.size, np.int64)
        for k, g in enumerate(self.grid):
            column = coords[:, k]
            lower[:, k] = np.where(column == 0, -np.inf, self.cuts[k][group, column])
            upper[:, k] = np.where(column == g - 1, np.inf, self.cuts[k][group, column + 1])
            group = group * g + column
        self.boxes = (lower, upper)
        gap = np.maximum(np.maximum(lower - upper[self.rank], lower[self.rank] - upper), 0.0)
        near = np.all(gap < self.min_width, axis=1) & (ranks != self.rank)
        self._neighbours = [int(r) for r in np.flatnonzero(near)]

    @property
    def neighbours(self):
        return list(self._neighbours)

    def owner(self, position):
        """The rank owning each row of ``position`` ((n, d)): half-open [lower, upper) boxes."""
        return self._owner(self._positions(position), self.cuts)

    def _owner(self, position, cuts):
        group = np.zeros(len(position), np.int64)
        for k, g in enumerate(self.grid):
            # The count of interior cuts at or below x is the index along axis k.
            interior = cuts[k][group][:, 1:-1]
            group = group * g + np.count_nonzero(position[:, k:k + 1] >= interior, axis=1)
        return group

    def _thin_block(self, cuts):
        """(rank, axis, width) of the first block narrower than the halo along a cut, or None."""
        for k, g in enumerate(self.grid):
            if g < 3:
                continue  # no interior block along this axis
            widths = np.diff(cuts[k][:, 1:-1], axis=1)
            thin = np.argwhere(~(widths >= self.min_width * (1 - 1e-12)))
            if len(thin):
                group, j = (int(i) for i in thin[0])
                head = np.unravel_index(group, self.grid[:k]) if k else ()
                coords = tuple(int(c) for c in head) + (j + 1,) + (0,) * (len(self.grid) - k - 1)
                return int(np.ravel_multi_index(coords, self.grid)), k, float(widths[group, j])
        return None

    # -- distribute -----------------------------------------------------------------------------

    def distribute(self, particles):
        """From the global scene (identical on every rank) keep this rank's particles.

        The grid is chosen again for the particles' bounding box (unless the case
        set it); the cuts go between the lattice columns nearest the quantiles of work
        (by count where work would make a block narrower than the halo), column by
        column. Raises CaseError on every rank if a block would still be narrower than
        the halo along a cut axis.
        """
        position = particles.position[:particles.n_owned]
        layout = None
        if self.rank == 0:
            grid = self._scene_grid(position)
            layout = grid, self._exact_cuts(position, self.weights(particles), grid)
        grid, cuts = self.comm.bcast(layout, root=0)
        self._set_grid(grid)
        if self._thin_block(cuts) is not None:
            # Work piles up where the fluid is: its blocks are the narrowest. The same
            # branch on every rank (the same cuts).
            if self.rank == 0:
                log.info("blocks balanced by work would be thinner than the halo: balanced "
                         "by count")
                cuts = self._exact_cuts(position, np.ones(len(position)), grid)
            cuts = self.comm.bcast(cuts, root=0)
        thin = self._thin_block(cuts)
        if thin is not None:
            rank, axis, width = thin
            raise CaseError(
                f"{self.size} ranks split the particles into a {describe_grid(self.grid)} grid "
                f"of blocks of which rank {rank}'s is {width:g} m wide along {_AXES[axis]}, "
                f"thinner than the halo {self.min_width:g} m ({_WIDTH_RULE}): run on fewer "
                f"ranks")
        self.cuts = cuts
        self._set_boxes()
        mine, total, imbalance = self._keep_owned(particles, self._owner(position, cuts))
        log.info("distributed %d particles over %s blocks, %d neighbours on rank %d, "
                 "imbalance %.3f", total, describe_grid(self.grid), len(self._neighbours),
                 self.rank, imbalance)
        return mine

    def _exact_cuts(self, position, weights, grid):
        """Nested cuts at the gaps nearest the quantiles of each group's sorted coordinates,
        weighted by work."""
        cuts = []
        group = np.zeros(len(position), np.int64)
        for k, g in enumerate(grid):
            groups = int(np.prod(grid[:k], dtype=np.int64))
            level = np.empty((groups, g + 1))
            extra = self._extra_of_parts(grid, k)
            for index in range(groups):
                values = position[group == index, k]
                order = np.argsort(values, kind="stable")
                level[index] = gap_quantiles(values[order], g, self.lower[k], self.upper[k],
                                             weights[group == index][order], extra[index])
            cuts.append(level)
            interior = level[group][:, 1:-1]
            group = group * g + np.count_nonzero(position[:, k:k + 1] >= interior, axis=1)
        return cuts

    # -- migration ------------------------------------------------------------------------------

    def _migrate(self, particles, force=False):
        n = particles.n_owned
        if self.size == 1:
            result = particles.owned() if particles.n_ghost else particles
            self._clear_halo(result.n_owned)
            return sorted_by_id(result)
        position = particles.position[:n]
        owner = self._owner(position, self.cuts)
        stay = owner == self.rank
        leaving = np.flatnonzero(~stay)
        # [some particle goes past the neighbours, some particle is past the margin].
        state = np.zeros(2, np.int64)
        if len(leaving):
            state[0] = not np.all(np.isin(owner[leaving], self._neighbours))
            lo, hi = self.box(self.rank)
            out = position[leaving]
            state[1] = force or self.margin == 0.0 or bool(
                np.any((out < lo - self.margin) | (out >= hi + self.margin)))
        self.comm.Allreduce(MPI.IN_PLACE, state, op=MPI.MAX)
        if not state[1]:
            result = particles.owned() if particles.n_ghost else particles
        else:
            self.migration_count += 1
            if state[0]:  # some particle jumps past the neighbours: one all-to-all
                owned = particles.owned() if particles.n_ghost else particles
                result = send_to_ranks(owned, owner, self.comm)
            else:
                arrays = field_arrays(particles)
                outgoing = [pack(arrays, np.flatnonzero(owner == r)) for r in self._neighbours]
                incoming = exchange(self.comm, self._neighbours, outgoing)
                rows = np.concatenate([pack(arrays, leaving[:0])] + incoming)
                result = merge_by_id(particles, np.flatnonzero(stay), unpack_new(rows, arrays))
        self._clear_halo(result.n_owned)
        return sorted_by_id(result)

    # -- halo -----------------------------------------------------------------------------------

    def _clear_halo(self, n_owned):
        self._send = [np.empty(0, np.int64) for _ in self._neighbours]
        self._received = [0 for _ in self._neighbours]
        self._n_owned = n_owned

    @property
    def n_neighbour_ghost(self):
        return int(sum(self._received))

    def _build_halo(self, particles):
        owned = particles.owned() if particles.n_ghost else particles
        n = owned.n_owned
        self._clear_halo(n)
        if self.size == 1 or not self._neighbours:
            return owned
        position = owned.position[:n]
        lo, hi = self.box(self.rank)
        h = self.halo_width
        # Only particles within the halo width of this block's faces can be near another.
        candidates = np.flatnonzero(~np.all((position - lo >= h) & (hi - position >= h), axis=1))
        near = position[candidates]
        lower, upper = self.boxes
        for slot, r in enumerate(self._neighbours):
            inside = np.all((near > lower[r] - h) & (near < upper[r] + h), axis=1)
            self._send[slot] = candidates[inside]
        arrays = field_arrays(owned)
        incoming = exchange(self.comm, self._neighbours, [pack(arrays, s) for s in self._send])
        self._received = [len(rows) for rows in incoming]
        total = n + self.n_neighbour_ghost
        combined = {}
        for name, array in zip(FIELDS, arrays):
            out = np.empty((total,) + array.shape[1:], array.dtype)
            out[:n] = array
            combined[name] = out
        self._unpack_ghosts(incoming, list(combined.values()))
        return Particles(combined, n_owned=n)

    def _unpack_ghosts(self, incoming, targets):
        start = self._n_owned
        for rows in incoming:
            unpack_into(rows, targets, start)
            start += len(rows)

    def _refresh(self, targets):
        if self.size == 1 or not self._neighbours:
            return
        # The ghost counts are known since build_halo: one round of messages.
        incoming = exchange(self.comm, self._neighbours, [pack(targets, s) for s in self._send],
                            self._received)
        self._unpack_ghosts(incoming, targets)

    # -- load balance ---------------------------------------------------------------------------

    def _balanced_layout(self, particles):
        """Nested cuts at the quantiles of the owned work (:meth:`_histogram_cuts`)."""
        return self._histogram_cuts(particles.position[:particles.n_owned],
                                    self.weights(particles))

    def _refusal(self, cuts):
        thin = self._thin_block(cuts)
        if thin is None:
            return None
        return (f"balancing would make rank {thin[0]}'s block {thin[2]:.4g} m wide along "
                f"{_AXES[thin[1]]}, thinner than the halo {self.min_width:.4g} m: keeping the "
                f"blocks")

    def _take_layout(self, cuts):
        self.cuts = cuts
        self._set_boxes()

    def _layout_change(self, old):
        return f"{len(self._neighbours)} neighbours on rank {self.rank}"

    def _extra_of_parts(self, grid, k):
        """The extra work of each part of each group cut along axis k, (groups, grid[k]):
        the ranks are the grid's cells in row-major order, a part along axis k holds those
        that share its first k + 1 coordinates."""
        per_rank = self.extra_work.reshape(grid)
        return per_rank.sum(axis=tuple(range(k + 1, len(grid)))).reshape(-1, grid[k])

    def _histogram_cuts(self, position, weights):
        """New nested cuts, axis by axis: per group, the quantiles of work over an allreduced
        coarse histogram refined by a second one (collective; the same cuts on every rank)."""
        finite = np.all(np.isfinite(position), axis=1)
        position, weights = position[finite], weights[finite]
        cuts = []
        group = np.zeros(len(position), np.int64)
        for k, g in enumerate(self.grid):
            groups = int(np.prod(self.grid[:k], dtype=np.int64))
            level, _ = histogram_quantiles(self.comm, position[:, k], weights, group, groups,
                                           g, self.cuts[k], self._extra_of_parts(self.grid, k))
            cuts.append(level)
            interior = level[group][:, 1:-1]
            group = group * g + np.count_nonzero(position[:, k:k + 1] >= interior, axis=1)
        return cuts
