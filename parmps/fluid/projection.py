"""One MPS fluid step: prediction, pressure, correction (docs/design.md §1.3).

The step works on one rank's particles (owned, then ghosts) and a communicator;
the decomposition keeps the ghosts current after every change of positions.
One neighbour search per step, at the start, with a skin: the pair list stays
valid for the predicted and corrected positions because no particle moves more
than a fraction of the skin in one step (the Courant limit).
"""

import logging
import time
from dataclasses import dataclass

import numba
import numpy as np

from parmps.core.density import number_density
from parmps.core.neighbours import pair_list, pairs_within, rows_near
from parmps.core.particles import DUMMY, FLUID, INFLOW, WALL
from parmps.errors import RunFailure
from parmps.fluid.collisions import collision_change
from parmps.fluid.constants import MPSConstants
from parmps.geometry.domain import Domain
from parmps.fluid.schemes import (GRADIENTS, LAPLACIANS, SHIFTINGS, SOURCES, SURFACES,
                                  scheme_class)
from parmps.fluid.schemes.laplacian import SURFACE_ROW
from parmps.fluid.viscous import ImplicitViscosity, no_slip_velocity, vector_laplacian_sum

log = logging.getLogger(__name__)


class Timers:
    """Seconds spent in each part of the step, for the benchmark breakdown."""

    PARTS = ("neighbours", "operators", "viscous", "assembly", "solve", "halo", "output")

    def __init__(self):
        self.seconds = dict.fromkeys(self.PARTS, 0.0)
        self._part = None
        self._start = 0.0

    def start(self, part):
        now = time.perf_counter()
        if self._part is not None:
            self.seconds[self._part] += now - self._start
        self._part, self._start = part, now

    def stop(self):
        self.start(None)


@dataclass
class PressureStep:
    """What a source scheme may read to make the PPE's right-hand side.

    ``position`` and ``velocity`` are the start of the step (owned, then
    ghosts), ``position_star`` and ``velocity_star`` the prediction; ``number_density``
    is n* of the owned particles and ``unknown_index`` the owned particles whose rows
    are unknowns.
    ``indptr``/``cols`` is the step's pair list (the search radius, which covers
    any position in the step); ``near_indptr``/``near_cols`` its pairs within the
    number density's radius at ``position_star``, for the sums there.
    ``kind``: every local particle's kind (owned, then ghosts).
    ``gravity``: the body force per unit mass the prediction added (``dt gravity`` is in
    ``velocity_star`` of the moving particles); ``laplacian``: the Laplacian scheme the
    matrix was assembled with.
    """

    dt: float
    n_owned: int
    indptr: np.ndarray
    cols: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    position_star: np.ndarray
    velocity_star: np.ndarray
    number_density: np.ndarray
    unknown_index: np.ndarray
    near_indptr: np.ndarray
    near_cols: np.ndarray
    kind: np.ndarray
    gravity: np.ndarray
    laplacian: object

    def number_density_at(self, position, radius):
        """The number density of the owned rows with the particles at ``position``
        (owned, then ghosts; e.g. the start of the step), over this step's pair list."""
        density, _ = number_density(self.indptr, self.cols, position, radius,
                                    self.n_owned)
        return density


@dataclass
class PressureSystem:
    """One step's pressure equation on one rank: its ``rows`` (the matrix's two blocks,
    :class:`parmps.fluid.schemes.laplacian.PressureRows`), ``rhs``; ``pressure_index``: the
    owned particles with a row, in row order; ``in_rows``: which of those rows are unknowns
    (the rest are held at P = 0); ``has_pressure``: every local particle that carries a
    pressure; ``surface_gradient``: the free-surface scheme's terms for the gradient."""

    rows: object
    rhs: np.ndarray
    pressure_index: np.ndarray
    in_rows: np.ndarray
    has_pressure: np.ndarray
    surface_gradient: object


class RowOrder:
    """The order of the pressure rows on this rank: the neighbour search's cell order of
    the owned particles with a pressure, taken afresh when the preconditioner is set up,
    and kept while it is reused.

    Numbered in the search's cell order, each row lists its columns in ascending order
    (the search visits the cells in ascending order), so the rows need no sort before
    PETSc takes them: numbered by index, sorting them took a sixth of a 3D step at
    3.1 l0. A kept preconditioner, though, was set up on the rows in their order then:
    renumbered every step, it preconditions a permuted matrix (27 CG iterations a step
    instead of 4 in 3D). Kept, the order drifts from the cells' as particles move, and
    the rows come out nearly ascending.
    """

    def __init__(self):
        self.ids = None
        self.order = None

    def rows(self, cell_order, has_pressure, ids, n, renumber):
        """The owned particles with a pressure, in row order. ``cell_order``: the local
        particles in the search's cell order; ``ids``: their global ids; ``renumber``:
        whether to take the cell order afresh (the next solve sets its preconditioner
        up). The order is taken afresh, too, when the owned particles changed."""
        kept = (not renumber and self.ids is not None and len(self.ids) == n
                and np.array_equal(self.ids, ids[:n])
                and len(self.order) == np.count_nonzero(has_pressure[:n]))
        if not kept:
            owned = cell_order[cell_order < n]
            self.order = owned[has_pressure[owned]]
            self.ids = ids[:n].copy()
        return self.order


class _Step:
    """What the phases of one step hand on to each other: the particles (owned, then
    ghosts), dt and the moving owned particles, then what each phase adds (the pair list,
    the prediction, n* and the free surface)."""

    def __init__(self, particles, dt, moving):
        self.particles = particles
        self.n = particles.n_owned
        self.dt = dt
        self.moving = moving


class FluidSolver:
    """The MPS projection step for a case: its constants, its schemes, its pressure solver.

    ``source`` and ``gradient`` are the registered schemes the case chose
    (:mod:`parmps.fluid.schemes`); the coupling takes its pressure gradient from
    ``gradient`` too, so the fluid and the bodies feel the same one.
    """

    def __init__(self, case, comm, decomposition, pressure_solver=None):
        self.comm = comm
        self.decomposition = decomposition
        constants = MPSConstants.from_case(case)
        self.constants = constants
        mps = case["mps"]
        self.source = scheme_class(SOURCES, mps["source"])(mps[mps["source"]], constants)
        self.laplacian = scheme_class(LAPLACIANS, mps["laplacian"])(mps[mps["laplacian"]],
                                                                    constants)
        self.gradient = scheme_class(GRADIENTS, mps["gradient"])(mps[mps["gradient"]],
                                                                 constants)
        self.free_surface = scheme_class(SURFACES, mps["free_surface"])(
            mps[mps["free_surface"]], constants)
        self.shifting = scheme_class(SHIFTINGS, mps["shifting"])(mps[mps["shifting"]],
                                                                 constants)
        self.gravity = np.asarray(case["physics"]["gravity"], dtype=float)
        # The domain (its periodic axes), for those that measure across a seam.
        self.domain = Domain.from_case(case)
        self.surface_threshold = mps["surface_threshold"]
        self.neighbour_threshold = mps["neighbour_threshold"]
        self.compressibility = mps["compressibility"]
        self.clamp = mps["clamp_negative_pressure"]
        self.collision = mps["collision"]
        self.collision_distance = mps["collision_distance"] * constants.spacing
        self.restitution = mps["restitution"]
        self.pressure_solver = pressure_solver
        self.timers = Timers()
        self.last_iterations = 0
        self.last_residual = 0.0
        self.expected_pairs = 0
        self.expected_cut = {"wide": 0, "narrow": 0}
        self.row_order = RowOrder()
        self.viscosity_scheme = mps["viscosity_scheme"]
        # dt <= viscous_number l0^2 / nu keeps the explicit term stable.
        self.viscous_limit = (case["time"]["viscous_number"] * constants.spacing ** 2
                              / constants.viscosity if constants.viscosity > 0.0 else np.inf)
        self.implicit_viscosity = ImplicitViscosity(constants, case["viscous"], comm)
        # The schemes this run has used so far (each is logged at its first step).
        self.viscosity_used = set()
        # Every local particle's velocity the last step's viscous term took, when that was
        # implicit (u* of the moving particles): the viscous force on the bodies reads it.
        self.viscous_velocity = None
        self.viscous_iterations = 0

    def viscosity_implicit(self, dt):
        """Whether a step of ``dt`` takes the viscous term implicitly: always or never as
        mps.viscosity_scheme says, or under "auto" where dt is beyond the viscous limit."""
        if self.constants.viscosity <= 0.0 or self.viscosity_scheme == "explicit":
            return False
        return self.viscosity_scheme == "implicit" or dt > self.viscous_limit

    def _note_viscosity(self, implicit, dt, step_number):
        """Log each viscous scheme at the first step that uses it, with the reason."""
        scheme = "implicit" if implicit else "explicit"
        if scheme in self.viscosity_used or self.constants.viscosity <= 0.0:
            return
        self.viscosity_used.add(scheme)
        if self.comm.rank != 0:
            return
        if self.viscosity_scheme != "auto":
            why = f"mps.viscosity_scheme = \"{self.viscosity_scheme}\""
        elif implicit:
            why = (f"the step the other limits allow, {dt:.4g} s, is beyond the viscous limit "
                   f"time.viscous_number l0^2/nu = {self.viscous_limit:.4g} s, which then no "
                   f"longer limits the step")
        else:
            why = f"the step {dt:.4g} s is within the viscous limit {self.viscous_limit:.4g} s"
        log.info("viscosity: %s from step %d (%s)", "backward Euler" if implicit else "explicit",
                 step_number, why)

    def rows_may_move(self):
        """Whether this step's pressure rows may change ranks at no extra cost: the solve
        sets its preconditioner up afresh anyway (a new row layout forces a set-up)."""
        return self.pressure_solver is not None and self.pressure_solver.setup_due()

    # The explicit part and the correction move fluid particles only.
    @staticmethod
    def moving(kind):
        return (kind == FLUID) | (kind == INFLOW)

    def step(self, particles, dt, step_number, dirichlet=None, mobility=None):
        """Advance the particles (with current ghosts) by dt; returns step statistics.

        ``dirichlet``: optional owned-length mask of particles held at P = 0
        besides the free surface (an outlet's pressure reference).
        ``mobility``: optional rho/rho_i of every local particle (owned and
        ghosts): the pressure equation becomes ``div (1/rho_i grad P)`` (bodies'
        nodes as particles of their own density); None: one density.
        """
        s = _Step(particles, dt, self.moving(particles.kind[:particles.n_owned]))
        s.step_number = step_number
        s.implicit_viscosity = self.viscosity_implicit(dt)
        self._note_viscosity(s.implicit_viscosity, dt, step_number)
        self._search(s)
        self._predict(s)
        self._number_density(s)
        system = self._pressure_system(s, dirichlet, mobility)
        pressure = self._solve(s, system, step_number)
        self._correct(s, pressure, system)
        self.timers.stop()
        return {"ksp_iterations": self.last_iterations, "ksp_residual": self.last_residual,
                "viscous_iterations": self.viscous_iterations,
                "n_surface": int(np.count_nonzero(s.surface & s.moving))}

    def _search(self, s):
        """The step's pair list within the search radius (rows: the owned particles that
        take part); flags the owned dry walls."""
        self.timers.start("neighbours")
        particles, n = s.particles, s.n
        kind, position = particles.kind, particles.position
        # Dummies need no sums of their own: they carry no pressure and do not move; they
        # count only as the neighbours of others. Nor do the walls away from the water.
        wetting = self._wetting(position, kind, n)
        s.indptr, s.cols, s.cell_order = pair_list(
            position, self.constants.search_radius, n_rows=n, rows=kind[:n] != DUMMY,
            expected_pairs=self.expected_pairs, only_near=kind[:n] == WALL, near=wetting,
            cell_order=True)
        s.dry = (kind[:n] == WALL) & (s.indptr[1:] == s.indptr[:-1])
        particles.dry[:n] = s.dry
        # Room for the next step's search in one pass: the count changes by well under
        # a few percent from one step to the next.
        self.expected_pairs = int(1.05 * len(s.cols)) + 64

    def _predict(self, s):
        """The explicit part: viscosity and the body force, then the collisions, into
        ``s.position_star`` and ``s.velocity_star`` (ghosts refreshed)."""
        timers, c, n, moving, dt = self.timers, self.constants, s.n, s.moving, s.dt
        particles = s.particles
        timers.start("operators")
        velocity_star = particles.velocity.copy()
        position_star = particles.position.copy()
        acceleration = np.broadcast_to(self.gravity, (n, c.dimension)).copy()
        self.viscous_velocity, self.viscous_iterations = None, 0
        if c.viscosity > 0.0 and not s.implicit_viscosity:
            acceleration += (c.viscosity * c.laplacian_coefficient) * \
                vector_laplacian_sum(s.indptr, s.cols, particles.position,
                                     self._wall_velocity(s), c.re_laplacian, n,
                                     moving)
        velocity_star[:n][moving] += dt * acceleration[moving]
        if s.implicit_viscosity:
            self._viscous_solve(s, velocity_star)
        position_star[:n][moving] += dt * velocity_star[:n][moving]
        timers.start("halo")
        self.decomposition.refresh([position_star, velocity_star], positions=(0,))
        if self.collision:
            timers.start("operators")
            change = collision_change(s.indptr, s.cols, position_star, velocity_star,
                                      self.moving(particles.kind),
                                      self.collision_distance, self.restitution, n,
                                      particles.position)
            velocity_star[:n] += change
            position_star[:n] += dt * change
            timers.start("halo")
            self.decomposition.refresh([position_star, velocity_star], positions=(0,))
        s.position_star, s.velocity_star = position_star, velocity_star

    def _viscous_solve(self, s, velocity_star):
        """u* of the moving particles by the backward-Euler viscous term, in place in
        ``velocity_star`` (which holds u^n + dt g); kept for the bodies' viscous force."""
        timers, particles = self.timers, s.particles
        timers.start("viscous")
        moving_local = self.moving(particles.kind)

        def refresh(arrays):
            timers.start("halo")
            self.decomposition.refresh(arrays)
            timers.start("viscous")

        self.implicit_viscosity.predict(particles, s.indptr, s.cols, s.cell_order,
                                        moving_local, velocity_star, s.dt, s.step_number,
                                        refresh)
        self.viscous_iterations = self.implicit_viscosity.last_iterations
        self.viscous_velocity = velocity_star.copy()
        timers.start("operators")

    def _wall_velocity(self, s):
        """Every local particle's velocity as the viscous term sees it: the walls', dummies'
        and nodes' extrapolated so the fluid's velocity meets theirs at the wall's surface
        (no slip), ghosts refreshed."""
        particles, c = s.particles, self.constants
        velocity = np.empty_like(particles.velocity)
        velocity[:s.n] = no_slip_velocity(
            s.indptr, s.cols, particles.position, particles.velocity, c.re_laplacian, s.n,
            self.moving(particles.kind))
        self.timers.start("halo")
        self.decomposition.refresh([velocity])
        self.timers.start("operators")
        return velocity

    def _number_density(self, s):
        """n* at the predicted positions and the free surface it marks."""
        self.timers.start("operators")
        c = self.constants
        self._cut_sub_lists(s)
        s.number_density, neighbour_count = number_density(
            s.near_indptr, s.near_cols, s.position_star, c.re_number_density, s.n)
        s.surface = s.number_density < self.surface_threshold * c.n0
        if self.neighbour_threshold > 0.0:
            s.surface |= neighbour_count < self.neighbour_threshold * c.neighbour_count0

    def _cut_sub_lists(self, s):
        """The pairs within the number density's radius (n*, the sources' divergence, the
        gradient: ``s.near_*``) and within the Laplacian's (the matrix and the free
        surface's terms: ``s.laplacian_*``) at the predicted positions. The wider is cut
        from the search's list, the narrower from it; one list serves both when the radii
        are the same (3D's defaults). Each sum over a sub-list is bit for bit the sum over
        the search's list, whose skin holds the pairs a step may bring within a radius."""
        c = self.constants
        wide, narrow = max(c.re_number_density, c.re_laplacian), \
            min(c.re_number_density, c.re_laplacian)
        cut = {wide: self._cut(s.indptr, s.cols, s.position_star, wide, s.n, "wide")}
        if narrow < wide:
            cut[narrow] = self._cut(*cut[wide], s.position_star, narrow, s.n, "narrow")
        s.near_indptr, s.near_cols = cut[c.re_number_density]
        s.laplacian_indptr, s.laplacian_cols = cut[c.re_laplacian]
        s.wide_indptr, s.wide_cols = cut[wide]

    def _cut(self, indptr, cols, position, radius, n, name):
        # 32-bit indices where a rank's particles allow (always, in practice): the sub-list
        # is alive at the step's peak, the solver's set-up (docs/performance.md).
        dtype = np.int32 if len(position) < 2 ** 31 else np.int64
        sub = pairs_within(indptr, cols, position, radius, n,
                           expected_pairs=self.expected_cut[name], dtype=dtype)
        # Room for the next step's cut in one pass, as for the search.
        self.expected_cut[name] = int(1.05 * len(sub[1])) + 64
        return sub

    def _pressure_system(self, s, dirichlet, mobility):
        """The pressure equation's rows on this rank: which particles are unknowns, the
        matrix in global row numbers, and the source scheme's right-hand side."""
        c, n, particles = self.constants, s.n, s.particles
        kind = particles.kind
        has_pressure = kind != DUMMY
        unknown, surface_unknown = self.free_surface.unknowns(
            has_pressure[:n], s.surface, (kind[:n] == FLUID) | (kind[:n] == WALL))
        unknown &= ~s.dry
        surface_unknown &= ~s.dry
        if dirichlet is not None:
            # Open boundaries: a closed channel otherwise has no pressure level.
            unknown &= ~dirichlet
            surface_unknown &= ~dirichlet
        pressure_index = self.row_order.rows(
            s.cell_order, has_pressure, particles.id, n,
            renumber=self.pressure_solver.setup_due())
        first_row = self.comm.exscan(len(pressure_index)) or 0
        row_number = np.full(len(particles), -1, np.int64)
        row_number[pressure_index] = first_row + np.arange(len(pressure_index))
        is_unknown = np.zeros(len(particles), np.int8)
        is_unknown[:n] = np.where(surface_unknown, SURFACE_ROW, unknown)
        self.timers.start("halo")
        self.decomposition.refresh([row_number, is_unknown])

        self.timers.start("assembly")
        with_source = unknown[pressure_index]
        rhs = np.zeros(len(pressure_index))
        rhs[with_source] = self.source.rhs(PressureStep(
            dt=s.dt, n_owned=n, indptr=s.indptr, cols=s.cols, position=particles.position,
            velocity=particles.velocity, position_star=s.position_star,
            velocity_star=s.velocity_star, number_density=s.number_density,
            unknown_index=pressure_index[with_source], near_indptr=s.near_indptr,
            near_cols=s.near_cols, kind=kind, gravity=self.gravity, laplacian=self.laplacian))
        self._let_search_list_go(s)
        rows = self.laplacian.rows(
            s.laplacian_indptr, s.laplacian_cols, s.position_star, row_number, is_unknown,
            c.density * self.compressibility / s.dt ** 2, pressure_index, mobility,
            index_dtype=self.pressure_solver.index_dtype)
        extra_diagonal, surface_gradient = self.free_surface.terms(
            s.laplacian_indptr, s.laplacian_cols, s.position_star, is_unknown,
            self.moving(kind), self.laplacian, n)
        if extra_diagonal is not None:
            if mobility is not None:
                extra_diagonal *= mobility[:n]
            rows.owned[2][rows.diagonal_at] += extra_diagonal[pressure_index]
        return PressureSystem(rows, rhs, pressure_index,
                              (unknown | surface_unknown)[pressure_index], has_pressure,
                              surface_gradient)

    def _let_search_list_go(self, s):
        """Drop the search's pair list once the source has read it (at the start of the
        step's positions): the sub-lists cut from it serve the rest, the shift included,
        and without it the matrix, the step's largest allocation, is assembled beside
        about half the pairs in 3D (docs/performance.md)."""
        s.indptr = s.cols = None

    def _solve(self, s, system, step_number):
        """The pressure of every local particle (0 off the rows; ghosts refreshed)."""
        self.timers.start("solve")
        particles = s.particles
        guess = np.where(system.in_rows, particles.pressure[:s.n][system.pressure_index], 0.0)
        solution, iterations, residual = self.pressure_solver.solve(
            system.rows.owned, system.rows.other, system.rhs, guess, step_number,
            particles.id[system.pressure_index])
        self.last_iterations, self.last_residual = iterations, residual

        self.timers.start("operators")
        pressure = np.zeros(len(particles))
        pressure[system.pressure_index] = np.where(system.in_rows, solution, 0.0)
        if self.clamp:
            np.maximum(pressure, 0.0, out=pressure)
        self.timers.start("halo")
        self.decomposition.refresh([pressure])
        return pressure

    def _correct(self, s, pressure, system):
        """The projection: the pressure gradient corrects the prediction of the moving
        particles; then the shift, if any; the owned particles take the result."""
        self.timers.start("operators")
        n, moving, dt, particles = s.n, s.moving, s.dt, s.particles
        position_star, velocity_star = s.position_star, s.velocity_star
        # Only the particles the correction moves need the gradient.
        pressure_gradient = self.gradient.gradient(
            s.near_indptr, s.near_cols, position_star, pressure, system.has_pressure, n,
            moving, surface=system.surface_gradient)
        correction = pressure_gradient[moving] / self.constants.density
        velocity_star[:n][moving] -= dt * correction
        position_star[:n][moving] -= dt * dt * correction
        if self.shifting.active:
            # The wider sub-list, cut at the predicted positions: the correction moves a
            # particle a fraction of a spacing, and a pair it brings within either radius
            # enters at the edge, where the shift's weights vanish.
            self._shift(particles, s.wide_indptr, s.wide_cols, position_star, velocity_star,
                        s.surface, dt)
        particles.position[:n] = position_star[:n]
        particles.velocity[:n] = velocity_star[:n]
        particles.pressure[:n] = pressure[:n]
        particles.number_density[:n] = s.number_density

    def mark_dry(self, particles):
        """Flag the owned dry walls of ``particles`` (owned and current ghosts) as the step
        would, before any step has run (collective): the load balance's first cut then
        weighs them as it will from the first step on."""
        self.timers.start("neighbours")
        n = particles.n_owned
        kind, position = particles.kind, particles.position
        wall = kind[:n] == WALL
        taking_part = rows_near(position, self.constants.search_radius, wall,
                                self._wetting(position, kind, n))
        particles.dry[:n] = wall & ~taking_part
        self.timers.stop()

    def _wetting(self, position, kind, n):
        """The local particles that make the walls within the search radius of them take
        part in the step (collective: one halo refresh): those that carry the water's
        pressure (fluid, buffers, bodies' nodes), and the walls within the search radius
        of one of those (wet walls).

        A wall beyond, two search radii from the water, is dry: no row that moves reads it,
        and it is held at P = 0, which is what the solve gave such walls when they were
        unknowns (their sources' negative pressures, clamped; docs/performance.md). The
        ring beside the wet walls keeps the pressure the solve gives it: with one radius
        only, the walls there were pulled to zero, and the SPHERIC box's sensor P3 read
        the impact 6 ms later on 1 and 2 ranks."""
        bearing = (kind != WALL) & (kind != DUMMY)
        wet = np.zeros(len(kind), np.int8)
        wet[:n] = rows_near(position, self.constants.search_radius, kind[:n] == WALL, bearing)
        self.timers.start("halo")
        self.decomposition.refresh([wet])
        self.timers.start("neighbours")
        return bearing | wet.view(bool)

    def _shift(self, particles, indptr, cols, position, velocity, surface, dt):
        """Move the owned fluid particles by the shifting scheme's regularisation (in
        place), from the corrected positions and velocities; ``surface``: the owned
        free-surface particles of the step."""
        timers = self.timers
        n = particles.n_owned
        fluid = particles.kind == FLUID
        on_surface = np.zeros(len(particles), np.int8)
        on_surface[:n] = surface & fluid[:n]
        timers.start("halo")
        self.decomposition.refresh([position, velocity, on_surface], positions=(0,))
        timers.start("operators")
        shift, change = self.shifting.regularise(
            indptr, cols, position, velocity, on_surface.view(bool), fluid[:n],
            particles.kind, dt, n)
        if shift is not None:
            position[:n] += shift
        if change is not None:
            velocity[:n] += change


def max_speed(particles, comm):
    """Largest fluid speed over all ranks."""
    n = particles.n_owned
    moving = FluidSolver.moving(particles.kind[:n])
    local = float(np.sqrt(largest_norm2(particles.velocity[:n], moving)))
    return comm.allreduce(local, op=_max_op())


def _max_op():
    from mpi4py import MPI
    return MPI.MAX


def check_finite(particles, comm, step):
    """Stop loudly if any owned particle has a NaN or infinite position or velocity."""
    n = particles.n_owned
    first = int(lowest_id_not_finite(particles.position[:n], particles.velocity[:n],
                                     particles.id[:n]))
    worst = comm.allreduce(first if first >= 0 else np.iinfo(np.int64).max, op=_min_op())
    if worst != np.iinfo(np.int64).max:
        raise RunFailure(f"step {step}: particle {worst} has a non-finite position or velocity "
                         f"(the run went unstable; reduce time.dt_max or time.cfl)")


def _min_op():
    from mpi4py import MPI
    return MPI.MIN


@numba.njit(cache=True)
def largest_norm2(vectors, mask):
    """The largest |v|^2 over the rows of ``vectors`` that ``mask`` selects (0 if none);
    each row's squares summed in component order, as numpy's row sums add them."""
    largest = 0.0
    for i in range(vectors.shape[0]):
        if mask[i]:
            norm2 = 0.0
            for k in range(vectors.shape[1]):
                norm2 += vectors[i, k] * vectors[i, k]
            if norm2 > largest:
                largest = norm2
    return largest


@numba.njit(cache=True)
def lowest_id_not_finite(position, velocity, ids):
    """The lowest id among the rows with a NaN or infinite position or velocity, or -1."""
    lowest = -1
    for i in range(position.shape[0]):
        finite = True
        for k in range(position.shape[1]):
            if not (np.isfinite(position[i, k]) and np.isfinite(velocity[i, k])):
                finite = False
        if not finite and (lowest < 0 or ids[i] < lowest):
            lowest = ids[i]
    return lowest

