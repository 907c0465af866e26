"""Collisions of particles closer than a distance limit: the velocity changes that stop
the approach of close pairs, moving pairs sharing the impulse and the fixed partners
acting as one wall (the projection's collision step, :mod:`parmps.fluid.projection`), in
a compiled pair loop (:mod:`parmps.core.pairs`)."""

import numba
import numpy as np

from parmps.core.pairs import for_each_dimension, pair_component, pair_distance2


# How far above a wall layer's plane its gaps close, in collision distances: a quarter of
# a spacing at the default 0.5 l0, a margin a step's overshoot does not cross.
WALL_GAP_CLOSURE = 0.5


# The support of a wall's contact normal, in fixed-partner reaches: twice it (1.1 l0 in
# 2D, 1.5 l0 in 3D at the default collision distance) spans a wall layer's gap from half
# a spacing in front of it.
WALL_NORMAL_REACH = 2.0


@numba.njit(cache=True, inline="always")
def _length(vector, d):
    total = 0.0
    for k in range(d):
        total += vector[k] * vector[k]
    return np.sqrt(total)


@numba.njit(cache=True, inline="always")
def _wall_contact(indptr, cols, moving, start, velocity, i, d, normal_reach, normal_reach2,
                  normal, contact, wall_velocity, weight_sum, restitution, out):
    """The fixed partners' impulse on particle i in contact with them (into ``out[i]``):
    along the wall's normal, from a second pass over them at the start of the step (only a
    particle in contact needs it), against the partners' weighted mean velocity."""
    for p in range(indptr[i], indptr[i + 1]):
        j = cols[p]
        if moving[j]:
            continue
        s2 = pair_distance2(start, i, j, d)
        if 0.0 < s2 < normal_reach2:
            r_start = np.sqrt(s2)
            weight = (1.0 - r_start / normal_reach) ** 2
            for k in range(d):
                normal[k] += weight * (pair_component(start, i, j, k) / r_start)
    length = _length(normal, d)
    if length <= 1e-12:
        # No fixed partner around where the particle started (a step longer than the
        # support): the contacts' own directions, overlap-weighted.
        for k in range(d):
            normal[k] = contact[k]
        length = _length(normal, d)
        if length <= 1e-12 * weight_sum:
            return
    approach = 0.0
    for k in range(d):
        approach += (velocity[i, k] - wall_velocity[k] / weight_sum) * (normal[k] / length)
    if approach <= 0.0:
        return
    impulse = (1.0 + restitution) * approach
    for k in range(d):
        out[i, k] -= impulse * (normal[k] / length)


@for_each_dimension
def collision_change(d, indptr, cols, position, velocity, moving, distance_limit, restitution,
                     n_rows, start):
    """Velocity changes of moving particles from collisions closer than ``distance_limit``
    at ``position`` (the predicted positions).

    Uses pre-collision velocities only, so the result is independent of pair order:
    two moving particles share the impulse; the fixed partners within reach act as one
    infinitely heavy wall along the normal of the fixed partners around the particle at
    ``start`` (the positions at the start of the step; ``position`` again for a static
    check).
    """
    out = np.zeros((n_rows, d))
    limit2 = distance_limit * distance_limit
    # A wall layer is a (d-1)-dimensional square lattice: the centre of its widest gap lies
    # sqrt(d-1)/2 spacings from the particles around it (half a spacing in 2D, 0.71 in
    # 3D), so a fixed partner reaches far enough that the gaps close above the layer's
    # plane, by WALL_GAP_CLOSURE collision distances: a droplet that rests on a wall (no
    # pressure holds it) otherwise sinks down the lattice's gaps, which gravity and the
    # collisions themselves steer it into.
    fixed_limit2 = limit2 * ((d - 1) + WALL_GAP_CLOSURE * WALL_GAP_CLOSURE)
    fixed_limit = np.sqrt(fixed_limit2)
    normal_reach = WALL_NORMAL_REACH * fixed_limit
    normal_reach2 = normal_reach * normal_reach
    normal = np.zeros(d)
    contact = np.zeros(d)
    wall_velocity = np.zeros(d)
    for i in range(n_rows):
        if not moving[i]:
            continue
        # Fixed partners act together, as one wall: any within reach at the predicted
        # position makes a contact, and the wall's normal is the weighted sum of the
        # directions to every fixed partner within twice that reach at the start of the
        # step. Pair by pair, the partners around a gap each see a glancing approach and
        # together do not stop the particle; and a fast particle predicted to land in a
        # wall layer's plane, between two of its particles, sees them only sideways there:
        # from where it came, and over a support that spans the gap, the wall lies ahead.
        weight_sum = 0.0
        for k in range(d):
            normal[k] = 0.0
            contact[k] = 0.0
            wall_velocity[k] = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            if r2 >= (limit2 if moving[j] else fixed_limit2) or r2 <= 0.0:
                continue
            r = np.sqrt(r2)
            if not moving[j]:
                weight = 1.0 - r / fixed_limit
                weight_sum += weight
                for k in range(d):
                    contact[k] += weight * (pair_component(position, i, j, k) / r)
                    wall_velocity[k] += weight * velocity[j, k]
                continue
            # The unit vector r_ij / r, component by component.
            approach = 0.0
            for k in range(d):
                approach += (velocity[i, k] - velocity[j, k]) * \
                    (pair_component(position, i, j, k) / r)
            if approach <= 0.0:
                continue
            impulse = (1.0 + restitution) * 0.5 * approach
            for k in range(d):
                out[i, k] -= impulse * (pair_component(position, i, j, k) / r)
        if weight_sum <= 0.0:
            continue
        _wall_contact(indptr, cols, moving, start, velocity, i, d, normal_reach, normal_reach2,
                      normal, contact, wall_velocity, weight_sum, restitution, out)
    return out

