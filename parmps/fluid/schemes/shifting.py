"""Particle shifting: a small move of the fluid particles, after the correction, from where
they crowd to where they are sparse (docs/design.md §1.4).

A projection method moves the particles with a velocity whose divergence is zero only
to the solver's tolerance and the operators' truncation; over many steps they bunch
along streamlines and open gaps, and the density source then reads that disorder as
compression and answers it with pressure. Shifting keeps the arrangement near a
lattice, so the source sees the flow's compression, not the particles' disorder.

- ``none`` (default): the particles go where the velocity takes them.
- ``fickian``: Fick's law of Lind, Xu, Stansby & Rogers (2012, J. Comput. Phys.
  231:1499), ``dr_i = -D grad C_i``, with the concentration C the smooth density
  measure (Wendland's C2 on the number density's radius) over its lattice value, and
  the diffusion coefficient of Skillen, Lind, Stansby & Rogers (2013, Comput. Methods
  Appl. Mech. Eng. 265:163), ``D = A h |u_i| dt`` with h half the kernel's support:
  a particle that does not move is not shifted (a still tank keeps its lattice), and
  the shift is a fraction of the step's own travel. Near the free surface (a
  free-surface particle within the Laplacian's radius) only the component along the
  surface is kept, with the surface's fitted normal (Lind et al. 2012): the
  concentration falls across the surface because the water ends there, not because
  the particles are disordered. Each shift is capped at ``max_shift`` l0.
  Velocities are not interpolated to the shifted position: the next step's pressure
  is solved afresh, and the velocity differs across a shift by O(|dr| |grad u|).
- ``dynamic_stabilisation``: the other particle regularisation Khayyer, Gotoh & Shimizu
  (2017, J. Comput. Phys. 332:236) set beside shifting, the dynamic stabilisation of
  Tsuruta, Khayyer & Gotoh (2013, Comput. Fluids 82:158): a pairwise velocity change,
  not a move, for the pairs closer than ``distance`` l0 after the correction, which gives
  each such pair the separation speed that takes it ``separation`` of the way back to
  that distance in one step (``stabilisation_change``; the form here is this
  solver's reading of the idea, not the paper's formula, which was not at hand). Two
  fluid particles share it equally, so momentum is kept; a particle takes the whole of
  it from a wall (bodies' nodes are left out). The position follows the velocity (``dt``
  times the change), as the correction's does. With ``separation`` = 0 (the default) it
  only stops the approach of such pairs: each pair's exchange alone takes kinetic
  energy and never gives it.

Every scheme answers ``regularise(...)``: the position and velocity changes of the owned
rows (None: no change).
"""

import numpy as np

from parmps.config import Key
from parmps.core.pairs import for_each_dimension, pair_component, pair_distance2
from parmps.core import lattice
from parmps.core.particles import DUMMY, FLUID, INFLOW, WALL
from parmps.fluid.schemes.surface import surface_fitted_normals, surface_normals


class NoShifting:
    KEYS = {}
    active = False

    def __init__(self, settings, constants):
        self.constants = constants

    def regularise(self, indptr, cols, position, velocity, on_surface, rows, kind, dt,
                   n_rows):
        """(position change, velocity change) of the owned rows, (n_rows, d) or None.
        ``position``, ``velocity``: every local particle after the correction (ghosts
        current); ``on_surface``: every local particle on the water's free surface;
        ``rows``: the owned fluid particles; ``kind``: every local particle's kind."""
        return None, None


class FickianShifting(NoShifting):
    KEYS = {
        "coefficient": Key("float", 2.0, gt=0.0, le=10.0,
                           doc="A of D = A h |u| dt (Skillen et al. 2013 use 1-6; 2 as "
                               "DualSPHysics's default)"),
        "max_shift": Key("float", 0.2, gt=0.0, le=0.5,
                         doc="the largest shift of a particle in one step, in l0"),
    }
    active = True

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.coefficient = settings["coefficient"]
        self.max_shift = settings["max_shift"] * constants.spacing
        self.smooth0 = lattice.smooth_reference(constants.spacing, constants.re_number_density,
                                                constants.dimension)

    def regularise(self, indptr, cols, position, velocity, on_surface, rows, kind, dt,
                   n_rows):
        return self.shift(indptr, cols, position, velocity, on_surface, rows, dt, n_rows), \
            None

    def shift(self, indptr, cols, position, velocity, on_surface, rows, dt, n_rows):
        """(n_rows, d) shift of the owned rows in ``rows`` (0 elsewhere). ``position`` and
        ``velocity``: every local particle after the correction (ghosts current);
        ``on_surface``: every local particle that is on the water's free surface."""
        c = self.constants
        support = c.re_number_density
        gradient = concentration_gradient(indptr, cols, position, support, rows,
                                          n_rows) / self.smooth0
        speed = np.sqrt((velocity[:n_rows] ** 2).sum(axis=1))
        diffusion = self.coefficient * 0.5 * support * speed * dt
        shift = -diffusion[:, None] * gradient
        raw = surface_normals(indptr, cols, position, on_surface, c.re_laplacian,
                              n_rows)
        normal = surface_fitted_normals(indptr, cols, position, raw, on_surface,
                                        c.re_laplacian, n_rows)
        shift -= (shift * normal).sum(axis=1)[:, None] * normal
        length = np.sqrt((shift ** 2).sum(axis=1))
        too_far = length > self.max_shift
        shift[too_far] *= (self.max_shift / length[too_far])[:, None]
        shift[~rows] = 0.0
        return shift


class DynamicStabilisation(NoShifting):
    KEYS = {
        "distance": Key("float", 0.8, gt=0.0, lt=1.0,
                        doc="pairs closer than this, in l0, are stabilised"),
        # 1 (a pair given the speed to be back at the distance after one step) let the
        # 1 cm dam break's energy rise by 2.9 % between frames; 0 by 0.02 % (docs/history.md).
        "separation": Key("float", 0.0, ge=0.0, le=1.0,
                          doc="the fraction of the way back to the distance a pair is "
                              "given the speed to cover in one step (0: its approach is "
                              "only stopped)"),
    }
    active = True

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.distance = settings["distance"] * constants.spacing
        self.separation = settings["separation"]

    def regularise(self, indptr, cols, position, velocity, on_surface, rows, kind, dt,
                   n_rows):
        moving = (kind == FLUID) | (kind == INFLOW)
        # The walls, not the bodies' nodes: the change would push a body without its
        # reaction on it (the coupling moves the bodies by the fluid's pressure).
        fixed = (kind == WALL) | (kind == DUMMY)
        change = stabilisation_change(indptr, cols, position, velocity, moving, fixed,
                                      self.distance, self.separation, dt, n_rows)
        return dt * change, change


@for_each_dimension
def concentration_gradient(d, indptr, cols, position, support, rows, n_rows):
    """``grad_i sum_j W(r_ij)`` of the rows in ``rows`` (0 for the others), W Wendland's C2
    function of radius ``support``: the gradient of :func:`smooth_density`, which points
    to where the neighbours crowd."""
    gradient = np.zeros((n_rows, d))
    inverse_square = 1.0 / (support * support)
    for i in range(n_rows):
        if not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            if r2 >= support * support:
                continue
            # grad_i W(|x_i - x_j| / s) = 20 (1 - q)^3 r_ij / s^2 for Wendland's C2
            # function (r_ij = x_j - x_i): no 1/r, so coincident pairs are harmless.
            a = 1.0 - np.sqrt(r2) / support
            factor = 20.0 * a * a * a * inverse_square
            for k in range(d):
                gradient[i, k] += factor * pair_component(position, i, j, k)
    return gradient


@for_each_dimension
def stabilisation_change(d, indptr, cols, position, velocity, moving, fixed, distance,
                         separation, dt, n_rows):
    """Velocity changes of the moving rows [0, n_rows) from the pairs closer than
    ``distance`` at ``position`` with a moving or a ``fixed`` partner (others are left
    out): each such pair whose separation speed along its line is
    below ``separation (distance - r) / dt`` is given that speed, shared equally between two
    moving particles (their momentum is kept), taken whole by a moving particle from a fixed
    partner. ``separation`` = 0 only stops the approach (no pair gains kinetic energy).
    Uses the velocities before any change, so the result is independent of pair order."""
    out = np.zeros((n_rows, d))
    limit2 = distance * distance
    for i in range(n_rows):
        if not moving[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not (moving[j] or fixed[j]):
                continue
            r2 = pair_distance2(position, i, j, d)
            if r2 >= limit2 or r2 <= 0.0:
                continue
            r = np.sqrt(r2)
            # w: the pair's separation speed along e = r_ij / r; wanted: enough to be
            # ``separation`` of the way back to ``distance`` by the end of the next step.
            w = 0.0
            for k in range(d):
                w += (velocity[j, k] - velocity[i, k]) * (pair_component(position, i, j, k) / r)
            change = separation * (distance - r) / dt - w
            if change <= 0.0:
                continue
            # Two moving particles share the change (equal masses: momentum kept); a
            # fixed partner is infinitely heavy and i takes all of it.
            share = 0.5 if moving[j] else 1.0
            for k in range(d):
                out[i, k] -= share * change * (pair_component(position, i, j, k) / r)
    return out

