"""The viscous term solved backward Euler (docs/design.md, "Implicit viscosity").

Why. The explicit term ``nu <lap u>^n`` is stable only for dt <= C l0^2 / nu
(``time.viscous_number``): at the Reynolds numbers of cells and capsules that is tens to
thousands of times below the Courant step.

What. Each moving particle's predicted velocity solves

    u*_i - dt nu <lap u*>_i = u^n_i + dt g,
    <lap u>_i = 2d/(lambda0 n0) sum_j w_ij (u_j - u_i),

the explicit term's Laplacian (its weights, radius and pair list at the start of the
step), with the unknowns the moving (fluid and inflow) particles of every rank and the
others (walls, dummies, bodies' nodes) at the values the explicit term gives them:
``2 U_j - <u>_j``, the no-slip extrapolation across the wall's surface
(:func:`parmps.fluid.viscous.no_slip_velocity`), of the unknowns themselves (taken from u^n
instead, the extrapolation converged so slowly at a thousand times the limit that a moving
wall's fluid was still 11 % off its velocity after 30 steps). A free-surface particle keeps its row with the
neighbours it has (no Dirichlet row: the stress-free surface of MPS). One matrix serves
every velocity component, ``(1/(dt nu) + 2d/(lambda0 n0) sum_j w_ij) u_i -
2d/(lambda0 n0) sum_(j moving) w_ij u_j`` plus the walls' extrapolation
``2d/(lambda0 n0) B^T S^-1 B`` (B_jk = w_jk from wall j to fluid k, S_j its row sum):
symmetric positive definite, so CG with the diagonal converges in a few tens of
iterations. It is assembled by the pressure matrix's kernel (the standard Laplacian's
rows, :class:`parmps.fluid.schemes.laplacian.StandardLaplacian`) and solved on the
pressure's distributed PETSc machinery (:class:`parmps.fluid.ppe.PressureSolver`, options
prefix ``viscous_``, case section ``[viscous]``).

When. ``mps.viscosity_scheme = "auto"``: implicit in a step longer than the viscous
limit, which then no longer limits the step; explicit otherwise, as before, so a run
the viscous limit never bound runs bit for bit as it did.
"""

import logging

import numba
import numpy as np

from parmps.core.pairs import for_each_dimension, pair_distance2, weight_of_r2

log = logging.getLogger(__name__)

VISCOSITY_SCHEMES = ("auto", "explicit", "implicit")
OPTIONS_PREFIX = "viscous_"


class ImplicitViscosity:
    """The backward-Euler viscous prediction of one rank, and its KSP (made at its first
    solve). ``command_line``: the ``viscous_`` options from the command line, name (no
    prefix) -> value; set before the first solve."""

    def __init__(self, constants, settings, comm):
        from parmps.fluid.schemes.laplacian import StandardLaplacian
        self.constants = constants
        self.comm = comm
        # Set up every solve: the diagonal costs nothing to take afresh.
        self.settings = dict(settings, reuse_preconditioner=0, setup_cost=0.0)
        self.rows = StandardLaplacian({}, constants)
        self.command_line = {}
        self.solver = None
        self.last_iterations = 0
        self.last_residual = 0.0

    def _solver(self):
        if self.solver is None:
            from parmps.fluid.ppe import PressureSolver
            self.solver = PressureSolver(self.comm, self.settings, self.command_line,
                                         dimension=self.constants.dimension,
                                         re_laplacian=(self.constants.re_laplacian
                                                       / self.constants.spacing),
                                         prefix=OPTIONS_PREFIX, name="viscous")
            if self.comm.rank == 0:
                log.info("viscous solver: %s", self.solver.describe())
        return self.solver

    def predict(self, particles, indptr, cols, cell_order, moving_local, explicit_velocity,
                dt, step, refresh, no_slip=True):
        """The owned moving particles' u* in place in ``explicit_velocity`` (every local
        particle's; the moving ones hold u^n + dt g, the others their velocity), then the
        ghosts refreshed (``refresh``: the decomposition's). ``indptr``/``cols``: the step's
        pair list at ``particles.position``; ``cell_order``: its cell order of the local
        particles; ``moving_local``: every local particle that moves. ``no_slip``: the walls
        extrapolated (the step's viscous term), or taken at their own velocity (False)."""
        c, n = self.constants, particles.n_owned
        solver = self._solver()
        # The rows: the owned moving particles, in the search's cell order (their columns
        # nearly ascending). Every other particle is a known neighbour with the rank's first
        # row as its number: a row number >= 0 puts its weight on the diagonal, only unknowns
        # are columns, and the rank's row numbers keep their range (the rows' room).
        owned = cell_order[cell_order < n]
        order = owned[moving_local[owned]]
        first = self.comm.exscan(len(order)) or 0
        row_number = np.full(len(particles), first, np.int64)
        row_number[order] = first + np.arange(len(order))
        is_unknown = moving_local.astype(np.int8)
        refresh([row_number, is_unknown])
        rows = self.rows.rows(indptr, cols, particles.position, row_number, is_unknown,
                              1.0 / (dt * c.viscosity), order, index_dtype=solver.index_dtype)
        known, coupling = particles.velocity.copy(), None
        if no_slip:
            known[:n], coupling = self._walls(particles, indptr, cols, moving_local,
                                              row_number, len(order), solver.PETSc)
            refresh([known])
        # The known neighbours' share of the Laplacian goes to the right-hand side: the sum
        # over a field that is 0 on the moving particles is sum_(j known) w_ij u_j.
        known[moving_local] = 0.0
        known_sum = vector_laplacian_sum(indptr, cols, particles.position, known,
                                         c.re_laplacian, n, moving_local[:n])
        guess = explicit_velocity[order]
        rhs = guess / (dt * c.viscosity) + c.laplacian_coefficient * known_sum[order]
        try:
            solution, self.last_iterations, self.last_residual = solver.solve(
                rows.owned, rows.other, rhs, guess, step, particles.id[order], extra=coupling)
        finally:
            if coupling is not None:
                coupling.destroy()
        explicit_velocity[order] = solution
        refresh([explicit_velocity])

    def _walls(self, particles, indptr, cols, moving_local, row_number, n_rows, PETSc):
        """The no-slip walls, implicit: a wall, dummy or node j with fluid neighbours carries
        ``2 U_j - sum_k w_jk u_k / S_j`` (S_j = sum_k w_jk over its fluid neighbours k), the
        explicit term's extrapolation (:func:`parmps.fluid.viscous.no_slip_velocity`) of the
        unknowns themselves. Returns (the owned particles' known part, 2 U_j there and U_j
        elsewhere; the matrix ``2d/(lambda0 n0) B^T S^-1 B`` the rows gain, B_jk = w_jk:
        symmetric positive semi-definite, so the system stays symmetric positive definite)."""
        c, n = self.constants, particles.n_owned
        i = np.repeat(np.arange(n), np.diff(indptr[:n + 1]))
        j = np.asarray(cols[:indptr[n]])
        wall_pair = ~moving_local[i] & moving_local[j]
        i, j = i[wall_pair], j[wall_pair]
        distance = np.linalg.norm(particles.position[i] - particles.position[j], axis=1)
        inside = (distance > 0.0) & (distance < c.re_laplacian)
        i, j = i[inside], j[inside]
        w = c.re_laplacian / distance[inside] - 1.0
        total = np.bincount(i, weights=w, minlength=n)
        known = particles.velocity[:n].copy()
        walls = total > 0.0
        known[walls] *= 2.0
        # B: one row for each owned wall with fluid neighbours, the fluid's global rows as
        # columns, ascending in each row (PETSc's CSR on several ranks needs them so).
        wall_row = np.cumsum(walls) - 1
        column = row_number[j]
        ordered = np.lexsort((column, wall_row[i]))
        i, column, w = i[ordered], column[ordered], w[ordered]
        row_ptr = np.concatenate([[0], np.cumsum(np.bincount(wall_row[i],
                                                             minlength=int(walls.sum())))])
        index = PETSc.IntType
        B = PETSc.Mat().createAIJ(
            size=((int(walls.sum()), PETSc.DETERMINE), (n_rows, PETSc.DETERMINE)),
            csr=(row_ptr.astype(index), column.astype(index), w), comm=self.comm)
        B.assemble()
        scaled = B.duplicate(copy=True)
        scale = scaled.createVecLeft()
        scale.getArray()[:] = c.laplacian_coefficient / total[walls]
        scaled.diagonalScale(L=scale)
        coupling = B.transposeMatMult(scaled)
        for item in (B, scaled, scale):
            item.destroy()
        return known, coupling

    def destroy(self):
        if self.solver is not None:
            self.solver.destroy()
            self.solver = None


@for_each_dimension
def vector_laplacian_sum(d, indptr, cols, position, field, radius, n_rows, rows=None):
    """sum_j (u_j - u_i) w(r_ij) for an N×d field (times 2d/(lambda0 n0) gives the Laplacian).

    ``rows``: optional mask of the rows wanted; the others are left 0 (walls do not move).
    """
    out = np.zeros((n_rows, d))
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                for k in range(d):
                    out[i, k] += (field[j, k] - field[i, k]) * w
    return out


@for_each_dimension
def fluid_drag_sum(d, indptr, cols, position, velocity, radius, n_rows, is_fluid, rows=None):
    """``(sum_j (u_j - u_i) w_ij, sum_j w_ij)`` over the fluid neighbours j of the rows
    ``n_rows`` (those ``rows`` selects; the others 0): what the no-slip wall's viscous force
    on a wall, body or node particle is made of (:func:`no_slip_velocity`)."""
    out = np.zeros((n_rows, d))
    weights = np.zeros(n_rows)
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not is_fluid[j]:
                continue
            w = weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                weights[i] += w
                for k in range(d):
                    out[i, k] += (velocity[j, k] - velocity[i, k]) * w
    return out, weights


@numba.njit(cache=True)
def no_slip_velocity(indptr, cols, position, velocity, radius, n_rows, is_fluid):
    """The velocity the viscous term sees at the rows ``n_rows``: a fluid particle's own; a
    wall's, dummy's or body node's ``2 u_i - <u>_i``, ``<u>_i`` the mean of its fluid
    neighbours' velocities weighted by w(r) (its own where it has none), so that the
    velocity extrapolated across the wall's surface meets the wall's there (Adami, Hu &
    Adams 2012's no-slip wall). From :func:`fluid_drag_sum`: ``2 u_i - <u>_i = u_i -
    sum_j w_ij (u_j - u_i) / sum_j w_ij``."""
    drag, weight = fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid,
                                  ~is_fluid[:n_rows])
    out = velocity[:n_rows].copy()
    for i in range(n_rows):
        if weight[i] > 0.0:
            for k in range(out.shape[1]):
                out[i, k] -= drag[i, k] / weight[i]
    return out

