"""The viscous term solved backward Euler (docs/design.md, "Implicit viscosity").

Why. The explicit term ``nu <lap u>^n`` is stable only for dt <= C l0^2 / nu
(``time.viscous_number``): at the Reynolds numbers of cells and capsules that is tens to
thousands of times below the Courant step.

What. Each moving particle's predicted velocity solves

    u*_i - dt nu <lap u*>_i = u^n_i + dt g,
    <lap u>_i = 2d/(lambda0 n0) sum_j w_ij (u_j - u_i),

the explicit term's Laplacian (its weights, radius and pair list at the start of the
step), with the unknowns the moving (fluid and inflow) particles of every rank and the
others (walls, dummies, bodies' nodes) known at the values the explicit term gives them:
``2 u_i - <u>_i``, the no-slip extrapolation across the wall's surface
(:func:`parmps.core.kernels.no_slip_velocity`), taken from u^n (lagged: with the walls moving
together it can make no velocity grow, as the matrix is an M-matrix and the extrapolation
of u - U_w is at most its largest value). A free-surface particle keeps its row with the
neighbours it has (no Dirichlet row: the stress-free surface of MPS). One matrix serves
every velocity component, ``(1/(dt nu) + 2d/(lambda0 n0) sum_j w_ij) u_i -
2d/(lambda0 n0) sum_(j moving) w_ij u_j``: symmetric, strictly diagonally dominant
(a positive definite M-matrix), so CG with the diagonal converges in a few tens of
iterations. It is assembled by the pressure matrix's kernel (the standard Laplacian's
rows, :class:`parmps.fluid.schemes.laplacian.StandardLaplacian`) and solved on the
pressure's distributed PETSc machinery (:class:`parmps.fluid.ppe.PressureSolver`, options
prefix ``viscous_``, case section ``[viscous]``).

When. ``mps.viscosity_scheme = "auto"``: implicit in a step longer than the viscous
limit, which then no longer limits the step; explicit otherwise, as before, so a run
the viscous limit never bound runs bit for bit as it did.
"""

import logging

import numpy as np

from parmps.core import kernels

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
                known_velocity, dt, step, refresh):
        """The owned moving particles' u* in place in ``explicit_velocity`` (every local
        particle's; the moving ones hold u^n + dt g, the others their velocity), then the
        ghosts refreshed (``refresh``: the decomposition's). ``indptr``/``cols``: the step's
        pair list at ``particles.position``; ``cell_order``: its cell order of the local
        particles; ``moving_local``: every local particle that moves; ``known_velocity``:
        every local particle's velocity as the viscous term sees it (only the particles that
        do not move are read: the walls' no-slip values)."""
        c, n = self.constants, particles.n_owned
        solver = self._solver()
        # The rows: the owned moving particles, in the search's cell order (their columns
        # nearly ascending). Every other particle is a known neighbour, row number 0 (a
        # row number >= 0 puts its weight on the diagonal; only unknowns are columns).
        owned = cell_order[cell_order < n]
        order = owned[moving_local[owned]]
        row_number = np.zeros(len(particles), np.int64)
        row_number[order] = (self.comm.exscan(len(order)) or 0) + np.arange(len(order))
        is_unknown = moving_local.astype(np.int8)
        refresh([row_number, is_unknown])
        rows = self.rows.rows(indptr, cols, particles.position, row_number, is_unknown,
                              1.0 / (dt * c.viscosity), order, index_dtype=solver.index_dtype)
        # The known neighbours' share of the Laplacian goes to the right-hand side: the sum
        # over a field that is 0 on the moving particles is sum_(j known) w_ij u_j.
        known = np.where(moving_local[:, None], 0.0, known_velocity)
        known_sum = kernels.vector_laplacian_sum(indptr, cols, particles.position, known,
                                                 c.re_laplacian, n, moving_local[:n])
        guess = explicit_velocity[order]
        rhs = guess / (dt * c.viscosity) + c.laplacian_coefficient * known_sum[order]
        solution, self.last_iterations, self.last_residual = solver.solve(
            rows.owned, rows.other, rhs, guess, step, particles.id[order])
        explicit_velocity[order] = solution
        refresh([explicit_velocity])

    def destroy(self):
        if self.solver is not None:
            self.solver.destroy()
            self.solver = None
