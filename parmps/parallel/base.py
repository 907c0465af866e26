"""The decomposition interface: what the solver asks of any way of cutting the domain.

A decomposition assigns every particle to exactly one rank (its owner) by
position, copies the particles near a rank's region to it as ghosts, moves
particles to their new owners after they moved, and moves the region
boundaries when the load drifts. The solver, the coupling, the open boundaries
and the output talk to it only through this interface; which decomposition runs
is the case's ``parallel.decomposition`` (see :mod:`parmps.parallel`). All
methods are collective over ``comm`` unless they say otherwise, and run on
every rank, including ranks that hold no particles.

Contract shared by every implementation:

- ``distribute(particles)``: from the global scene (the same on every rank)
  keep the particles this rank owns; raises CaseError on every rank for a
  layout too fine for the halo.
- ``migrate(particles, eager=False)``: drop ghosts, send owned particles that
  left this rank's region to their owners (lazily: see
  ``parallel.migration_margin``; ``eager`` moves every one outside its region at
  once); returns owned-only Particles in ascending global id.
- ``build_halo(particles)``: owned particles followed by ghosts (copies of the
  particles of other ranks within the halo width of this rank's region); it
  remembers what it sent, so ``refresh`` updates the same ghosts.
- ``refresh(arrays, positions=())``: the owners' current values of per-particle arrays
  (length n_owned + n_ghost) copied into the ghost slots, in place; the arrays
  ``positions`` (indices into ``arrays``) hold positions, which a periodic image gets
  shifted by the period.
- ``rebalance(particles, step)``: move region boundaries when the load is
  uneven (or heading there); returns owned-only Particles.
- ``owner(position)``: the owning rank of each row of an (n, d) array of
  positions (local, not collective; every position has exactly one owner).
- ``box(rank)``: the region a rank owns, as a box (local).
- ``neighbours``: the ranks this rank exchanges ghosts with (local).
- ``update(particles, step, eager=False)``: migrate, rebalance, build the halo, in
  that order.

Along the domain's periodic axes (``domain.periodic``) the base class wraps the particles
that left through a face (in ``migrate``) and appends, after the decomposition's own
ghosts, the periodic images (:mod:`parmps.parallel.periodic`): an implementation knows
nothing of periodicity beyond its boxes, which tile all of space.

Global ids never change and owned particles are kept in ascending id, so the
results do not depend on the decomposition or the rank count beyond round-off.
"""

import abc
import collections
import logging
import time

import numpy as np
from mpi4py import MPI

from parmps.core.particles import DUMMY, KIND_NAMES, WALL
from parmps.core.particles import FIELDS, Particles
from parmps.core.settings import search_radius
from parmps.parallel.exchange import field_arrays, imbalance_of, sorted_by_id
from parmps.parallel.periodic import PeriodicImages

# The package's logger: rank 0's line says which decomposition runs.
log = logging.getLogger("parmps.parallel")

# The load above which the first check after the scene's cut rebalances. The cut (on every
# rank's copy of the scene, before any halo) weighs every wall as a wall; once the dry walls
# weigh as dummies the SPHERIC tank's ranks were up to 1.093 apart (2.93M particles, 2
# ranks), under the tolerance, and the slower rank did 29 % more pairs' work every step.
FIRST_CUT_TOLERANCE = 1.02


Halo = collections.namedtuple("Halo", "reach margin width min_width")

#: How a decomposition weighs and rebalances its load: a wall's and a dummy's work in
#: fluid particles', the steps between load checks, the imbalance (max / mean) it accepts.
Balance = collections.namedtuple(
    "Balance", "wall_weight dummy_weight rebalance_interval imbalance_tolerance")


def balance_settings(parallel):
    """The :class:`Balance` of a case's ``[parallel]`` section."""
    return Balance(float(parallel["wall_weight"]), float(parallel["dummy_weight"]),
                   int(parallel["rebalance_interval"]), float(parallel["imbalance_tolerance"]))


def halo_widths(case):
    """The case's :class:`Halo`: ``reach``, the pair search's radius; ``margin``, how far
    an owned particle strays out of its region before it migrates
    (``parallel.migration_margin`` spacings); ``width``, reach + margin, from within which
    of a region its ghosts come (an owned particle strays up to the margin and sees up to
    the reach); ``min_width``, reach + 2 margin, the narrowest region whose ghosts all come
    from the regions beside it."""
    reach = search_radius(case)
    margin = float(case["parallel"].get("migration_margin", 0.0)) * float(
        case["particles"]["spacing"])
    return Halo(reach, margin, reach + margin, reach + 2.0 * margin)


class Decomposition(abc.ABC):
    """Common state (halo widths, load-balance settings, timers) and the shared logic."""

    #: the name the case chooses it by (``parallel.decomposition``)
    name = None

    #: the ``[parallel]`` keys beyond the balance's that its constructor takes
    options = ()

    def __init__(self, comm, domain, halo, balance):
        """On ``comm``, over ``domain`` (a :class:`parmps.geometry.domain.Domain`), with
        ``halo`` (:class:`Halo`) and ``balance`` (:class:`Balance`) as given: a
        decomposition reads no case."""
        self.comm = comm
        self.size = comm.size
        self.rank = comm.rank
        self.domain = domain
        self.lower, self.upper = self.domain.lower, self.domain.upper
        self.dimension = self.domain.dimension
        self.reach, self.margin, self.halo_width, self.min_width = halo
        self.images = None
        if self.domain.is_periodic:
            self.images = PeriodicImages(comm, self.domain, self.halo_width)
        # Balance is by work, not count: each particle weighs its kind's cost.
        self.kind_weight = np.ones(max(KIND_NAMES) + 1)
        self.kind_weight[WALL] = balance.wall_weight
        self.kind_weight[DUMMY] = balance.dummy_weight
        # Work a rank carries beyond its particles, in particle weights (set_extra_work).
        self.extra_work = np.zeros(self.size)
        self.rebalance_interval = balance.rebalance_interval
        self.imbalance_tolerance = balance.imbalance_tolerance
        self.halo_seconds = 0.0
        self.migration_seconds = 0.0
        self.rebalance_count = 0
        self.migration_count = 0  # migrations that moved particles
        self._reference = (0, 1.0)  # (step, imbalance) the load drift is measured from
        self._refused = False  # the last rebalance was refused (too thin)
        self._first_check = True  # the next check is the first after a cut blind to dry walls

    # -- the interface ------------------------------------------------------------------------

    @abc.abstractmethod
    def distribute(self, particles):
        """Keep this rank's particles of the global scene (identical on every rank)."""

    def migrate(self, particles, eager=False):
        """Drop ghosts, send owned particles that left to their owners; owned-only, by id.
        Lazily, once one is past the margin; ``eager``: now (collective, so any rank's
        ``eager`` moves them on every rank). Along a periodic axis a particle more than
        the margin past a face (any past it, when ``eager``) is first wrapped."""
        if self.images is not None:
            self.images.clear()
            self.domain.wrap(particles.position[:particles.n_owned],
                             0.0 if eager else self.margin)
        return self._timed("migration_seconds", self._migrate, particles, eager)

    def build_halo(self, particles):
        """Owned particles followed by the ghosts this rank needs: the decomposition's,
        then the periodic images. Remembers what it sent, for refresh."""
        return self._timed("halo_seconds", self._halo_with_images, particles)

    def _halo_with_images(self, particles):
        halo = self._build_halo(particles)
        if self.images is None:
            return halo
        boxes = [self.box(rank) for rank in range(self.size)]
        return self.images.build(halo, halo.n_owned, boxes)

    def refresh(self, arrays, positions=()):
        """Copy the owners' values into the ghost slots of ``arrays``, in place: a
        Particles (all its fields), one array, or a list of arrays, each of length
        n_owned + n_ghost of the last build_halo. ``positions``: the indices of the
        arrays that hold positions (a Particles' position field is one), which a periodic
        image gets shifted. Returns ``arrays``."""
        if isinstance(arrays, Particles):
            targets = field_arrays(arrays)
            positions = (list(FIELDS).index("position"),)
        elif isinstance(arrays, np.ndarray):
            targets = [arrays]
        else:
            targets = list(arrays)
        self._timed("halo_seconds", self._refresh_with_images, targets, positions)
        return arrays

    def _refresh_with_images(self, targets, positions):
        expected = self._n_owned + self.n_ghost
        for array in targets:
            if len(array) != expected:
                raise ValueError(f"refresh: array of length {len(array)}, expected n_owned + "
                                 f"n_ghost = {self._n_owned} + {self.n_ghost} = {expected}")
        if not targets:
            return
        self._refresh(targets)
        if self.images is not None:
            self.images.refresh(targets, positions)

    @property
    def n_ghost(self):
        """Ghosts made by the last build_halo: the decomposition's and the images."""
        images = self.images.count if self.images is not None else 0
        return self.n_neighbour_ghost + images

    @abc.abstractmethod
    def _migrate(self, particles, force=False):
        """migrate's work (untimed, no wrap): owned-only in ascending id."""

    @abc.abstractmethod
    def _build_halo(self, particles):
        """Owned particles followed by the ghosts from the neighbouring regions."""

    @abc.abstractmethod
    def _refresh(self, targets):
        """The owners' values into the neighbouring regions' ghost slots (lengths checked)."""

    @abc.abstractmethod
    def _balanced_layout(self, particles):
        """The region boundaries that balance the owned ``particles``' work (collective; the
        same on every rank), in the implementation's own form (slabs' edges, blocks' cuts)."""

    @abc.abstractmethod
    def _refusal(self, layout):
        """Why ``layout`` cannot be taken (it would make a region thinner than the halo), a
        phrase for the log, or None."""

    @abc.abstractmethod
    def _take_layout(self, layout):
        """Make ``layout`` this decomposition's (before the particles migrate to it); returns
        what the log's line needs of the old one."""

    @abc.abstractmethod
    def _layout_change(self, old):
        """The log's account of the new layout against ``old`` (after the migration)."""

    @abc.abstractmethod
    def owner(self, position):
        """The rank owning each row of ``position`` ((n, d)); local."""

    @abc.abstractmethod
    def box(self, rank):
        """(lower, upper) corners ((d,) arrays) of ``rank``'s region, +-inf where it is
        open; regions tile space, half-open [lower, upper). Local."""

    @property
    @abc.abstractmethod
    def neighbours(self):
        """The ranks this rank exchanges ghosts with (a sorted list; local)."""

    @property
    @abc.abstractmethod
    def n_neighbour_ghost(self):
        """Ghosts from the neighbouring regions made by the last build_halo."""

    # (name, why) of the choice, set by parallel.create_decomposition.
    choice = None

    def log_choice(self):
        """Rank 0 logs which decomposition runs and why (after the scene is distributed)."""
        if self.choice is not None and self.comm.rank == 0:
            name, why = self.choice
            log.info("decomposition: %s, %s (%s)", name, self.describe(), why)

    @abc.abstractmethod
    def describe(self):
        """One line for the log: the layout."""

    # -- shared -------------------------------------------------------------------------------

    def update(self, particles, step, eager=False):
        """Everything positions changed since the last step: migrate, rebalance when due,
        then rebuild the halo. Returns owned particles followed by current ghosts.

        ``eager``: migrate every particle outside its region, not only once one is past
        the margin. The caller says when a new layout of its rows costs nothing extra
        (the pressure preconditioner is set up afresh this step anyway), so the migrations
        the margin would force later, each with a set-up of its own, come less often."""
        particles = self.migrate(particles, eager)
        particles = self.rebalance(particles, step)
        return self.build_halo(particles)

    def rebalance(self, particles, step):
        """Move the region boundaries when the load is uneven (the triggers of
        :meth:`_rebalance_reason`), to the layout that balances the work
        (:meth:`_balanced_layout`), then migrate the particles to it; returns owned-only.
        A layout that would make a region thinner than the halo is not taken (a warning,
        repeated at most once per interval) and the run goes on unbalanced. Timed as a
        migration."""
        owned = particles.owned() if particles.n_ghost else particles
        if self.size == 1:
            return owned
        return self._timed("migration_seconds", self._rebalance, owned, step)

    def _rebalance(self, particles, step):
        loads = self.loads(particles)
        before = imbalance_of(loads)
        periodic = step % self.rebalance_interval == 0
        reason = self._rebalance_reason(loads, step)
        if reason is None:
            return particles
        # Logged under the implementation's module, as each logged its own before.
        logger = logging.getLogger(type(self).__module__)
        layout = self._balanced_layout(particles)
        refusal = self._refusal(layout)
        if refusal is not None:
            if self.rank == 0 and (periodic or not self._refused):
                logger.warning("step %d: load imbalance %.3f, but %s", step, before, refusal)
            self._refused = True
            return particles
        self._refused = False
        old = self._take_layout(layout)
        result = self._migrate(particles, force=True)
        after = self.imbalance(result)
        self._reference = (step, after)
        self.rebalance_count += 1
        logger.info("step %d: rebalanced %s (imbalance %.3f, %s) -> %.3f, %s", step, self.name,
                    before, reason, after, self._layout_change(old))
        return result

    def counts(self, particles):
        """Owned counts of every rank (int64 array, the same on every rank)."""
        counts = np.empty(self.size, np.int64)
        self.comm.Allgather(np.array([particles.n_owned], np.int64), counts)
        return counts

    def weights(self, particles):
        """The load-balance weight of each owned particle (local): its kind's, and a dry
        wall's a dummy's (it is in no sum either, bar its one-entry row of P = 0)."""
        n = particles.n_owned
        return np.where(particles.dry[:n] != 0, self.kind_weight[DUMMY],
                        self.kind_weight[particles.kind[:n]])

    def set_extra_work(self, work):
        """Each rank's work beyond its particles (an array over the ranks, the same on every
        rank), in the particles' weights: a body's substeps on the rank that runs them.
        The balance gives a rank that much less particle work from its next rebalance."""
        self.extra_work = np.asarray(work, dtype=np.float64).reshape(self.size)

    def loads(self, particles):
        """Owned work of every rank, the particles weighted by kind, plus its extra work
        (the same on every rank)."""
        loads = np.empty(self.size)
        self.comm.Allgather(np.array([self.weights(particles).sum()]), loads)
        return loads + self.extra_work

    def imbalance(self, particles):
        """Largest rank's owned work over the mean (1.0 is perfect balance)."""
        return imbalance_of(self.loads(particles))

    def _keep_owned(self, particles, owner_rank):
        """The scene's particles whose ``owner_rank`` is this rank, in ascending id, with the
        halo cleared and the load's drift reference reset; collective. Returns them, the total
        over the ranks and the imbalance. A total that is not the scene's means the ranks built
        different scenes, which is a bug, not a case error."""
        mine = sorted_by_id(particles.select(np.flatnonzero(owner_rank == self.rank)))
        total = self.comm.allreduce(mine.n_owned, op=MPI.SUM)
        if total != particles.n_owned:
            raise RuntimeError(f"distribute: ranks hold {total} particles of "
                               f"{particles.n_owned} (the scenes differ between ranks?)")
        imbalance = self.imbalance(mine)
        self._reference = (0, imbalance)
        # A scene knows no dry walls yet; a checkpoint keeps them, and its cut weighed them
        # as the step will (the same answer on every rank: the same particles).
        self._first_check = not np.any(particles.dry[:particles.n_owned])
        self._clear_halo(mine.n_owned)
        if self.images is not None:
            self.images.clear()
        return mine, total, imbalance

    def _positions(self, position):
        position = np.asarray(position, dtype=np.float64)
        if position.ndim != 2 or position.shape[1] != self.dimension:
            raise ValueError(f"owner: positions of shape (n, {self.dimension}) expected, "
                             f"got {position.shape}")
        return position

    def _rebalance_reason(self, loads, step):
        """Why to rebalance now (a phrase for the log), or None; updates the drift reference.

        The first check after the scene's cut rebalances above ``FIRST_CUT_TOLERANCE``:
        that cut weighed every wall as a wall, and the walls away from the water, known
        only once the halo is built, weigh as dummies from the first step on (a
        checkpoint's cut knew them: after it the first check is like any other). Then the
        load (max/mean owned work) is checked at every step: above
        ``imbalance_tolerance`` the regions are rebalanced at once (unless the
        last attempt was refused, then only every interval). Every
        ``rebalance_interval`` steps the drift of the load is also projected one
        interval ahead, and a load heading past the tolerance is rebalanced
        before it gets there.
        """
        tolerance = self.imbalance_tolerance
        before = imbalance_of(loads)
        periodic = step % self.rebalance_interval == 0
        reason = None
        first, self._first_check = self._first_check, False
        if first and before > FIRST_CUT_TOLERANCE:
            reason = "the scene's cut weighed the walls before they were known dry"
        elif before > tolerance and (periodic or not self._refused):
            reason = "over the tolerance"
        elif periodic:
            last_step, last_imbalance = self._reference
            rate = max(0.0, before - last_imbalance) / max(step - last_step, 1)
            projected = before + rate * self.rebalance_interval
            if projected > tolerance:
                reason = f"heading for {projected:.3f} by step {step + self.rebalance_interval}"
        if periodic:
            self._reference = (step, before)
        return reason

    def _timed(self, counter, function, *args):
        """``function(*args)``, its wall time added to the counter named ``counter``."""
        start = time.perf_counter()
        try:
            return function(*args)
        finally:
            setattr(self, counter, getattr(self, counter) + time.perf_counter() - start)

