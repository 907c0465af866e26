"""The fluid's force on particles that the fluid step does not move (bodies' nodes, moving
walls): ``-V <grad P> + V mu <lap u>``, ``V = l0^d``, with the fluid's own gradient scheme."""

import numpy as np

from parmps.core.lattice import neighbour_count_reference
from parmps.core.neighbours import pair_list
from parmps.core.particles import DUMMY, FLUID, INFLOW
from parmps.fluid.schemes.gradient import pressure_share_sum
from parmps.fluid.viscous import fluid_drag_sum


def fluid_forces(particles, rows, constants, gradient, velocity=None):
    """Fluid force on the particles ``rows`` (owned): ``-V grad P + V mu lap u``.

    ``particles`` must have current ghosts (positions, velocities, pressures);
    ``constants`` are the fluid's MPS constants and ``gradient`` its pressure
    gradient scheme, so a body feels the gradient that moves the fluid.
    ``velocity``: see :func:`fluid_force_parts`. Returns (len(rows), d).
    """
    pressure_force, viscous_force, _ = fluid_force_parts(particles, rows, constants, gradient,
                                                         velocity)
    return pressure_force + viscous_force


def fluid_force_parts(particles, rows, constants, gradient, velocity=None):
    """The pressure force ``-V grad P`` and the viscous force ``V mu lap u`` on ``rows``,
    and each row's viscous relaxation rate for a particle of the fluid's density.

    ``velocity``: every local particle's velocity for the viscous force (ghosts current),
    or None for ``particles.velocity``. A step that took the viscous term implicitly gives
    the fluid's u* there (:attr:`parmps.fluid.projection.FluidSolver.viscous_velocity`):
    the fluid felt the nodes through u*, and the nodes feel the fluid through it, so the
    pairs' viscous forces are equal and opposite.

    The viscous force is the reaction to the fluid's own viscous term beside a no-slip
    wall, in which particle i carries ``2 u_i - <u>_i`` (:func:`parmps.fluid.viscous.no_slip_velocity`):
    summed over its fluid neighbours j, ``V mu c w_ij (u_j - (2 u_i - <u>_i))`` is
    ``2 V mu c sum_j w_ij (u_j - u_i)``, c = 2d/(lambda0 n0): ``k_i (u_bar_i - u_i)`` with
    u_bar the weighted mean of the fluid neighbours' velocities. The rate returned is
    k_i / (rho V) = ``2 nu c sum_j w_ij`` [1/s] (how fast that force would relax the velocity
    of a particle of the fluid's density). Returns ((n, d), (n, d), (n,)).
    """
    dimension = particles.position.shape[1]
    n = len(rows)
    if n == 0:
        return np.empty((0, dimension)), np.empty((0, dimension)), np.empty(0)
    order, position, indptr, cols = _rows_first_pairs(particles.position, rows, constants)
    pressure = particles.pressure[order]
    has_pressure = particles.kind[order] != DUMMY
    volume = constants.spacing ** dimension
    pressure_force = -volume * gradient.gradient(indptr, cols, position, pressure,
                                                 has_pressure, n)
    viscous_force = np.zeros((n, dimension))
    viscous_rate = np.zeros(n)
    if constants.viscosity > 0.0:
        # The compiled sums the fluid's own viscous term uses (numpy over the pairs cost
        # most of this function on a 10k-node body).
        coefficient = 2.0 * dimension / (constants.lambda0 * constants.n0_laplacian)
        velocity = np.ascontiguousarray((particles.velocity if velocity is None
                                         else velocity)[order])
        kind = particles.kind[order]
        drag, weight = fluid_drag_sum(indptr, cols, position, velocity,
                                      constants.re_laplacian, n,
                                      (kind == FLUID) | (kind == INFLOW))
        viscous_force = 2.0 * volume * constants.density * constants.viscosity * \
            coefficient * drag
        viscous_rate = 2.0 * constants.viscosity * coefficient * weight
    return pressure_force, viscous_force, viscous_rate


def _rows_first_pairs(position, rows, constants):
    """The order that puts ``rows`` first, followed by the particles within the Laplacian's
    radius of their bounding box, the positions in that order and the rows' pair lists."""
    n = len(rows)
    dimension = position.shape[1]
    # Put the rows first so the pair search produces exactly their lists; only particles
    # within the rows' reach can be their neighbours, so the search sees no others (a
    # body's nodes are a few percent of a tank's particles).
    reach = constants.re_laplacian
    at_rows = position[rows]
    others = np.all((position >= at_rows.min(axis=0) - reach)
                    & (position <= at_rows.max(axis=0) + reach), axis=1)
    others[rows] = False
    order = np.concatenate([rows, np.flatnonzero(others)])
    ordered = np.ascontiguousarray(position[order])
    # Room for a lattice's neighbours and a little more, so the search runs once (a 3D
    # search costs as much as the rest of this function).
    room = int(1.2 * n * neighbour_count_reference(constants.spacing, reach, dimension)) + 64
    indptr, cols = pair_list(ordered, reach, n_rows=n, expected_pairs=room)
    return order, ordered, indptr, cols


def pressure_force_from(particles, rows, constants, sources):
    """The pressure force ``-V <grad P>`` that the particles ``sources`` (a mask over every
    local particle) exert on the owned particles ``rows``: the plain gradient's terms of those
    neighbours, with their absolute pressure (:func:`parmps.fluid.schemes.gradient.pressure_share_sum`). Summed over the fluid's rows and with
    the sign turned, the force of the fluid on a wall. Returns (len(rows), d)."""
    dimension = particles.position.shape[1]
    if len(rows) == 0:
        return np.empty((0, dimension))
    order, position, indptr, cols = _rows_first_pairs(particles.position, rows, constants)
    share = pressure_share_sum(indptr, cols, position, particles.pressure[order],
                               sources[order] & (particles.kind[order] != DUMMY),
                               constants.re_number_density, len(rows))
    return -(constants.spacing ** dimension * constants.dimension / constants.n0) * share
