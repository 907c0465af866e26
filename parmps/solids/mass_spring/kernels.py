"""numba kernels of the mass-spring substep: the spring network's forces and, for a body
whose external force is held over the step, the whole Verlet substep loop.

A stiff body takes hundreds to thousands of substeps per fluid step (an aluminium plate at
l0 = 1/60 m: about 1000 of 1e-6 s), so the per-substep cost of numpy calls on a few
hundred springs, not the arithmetic, would dominate the run. The numpy forms in
``body.py`` and ``elastic.py`` state the same physics and are the reference the tests
compare these with.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def network_forces(position, velocity, springs, rest_length, stiffness, damping,
                   axial_damping, force):
    """Spring and dashpot forces of every spring, added into ``force`` (n, d).

    Hooke ``-k (|l| - l0) l/|l|`` with l = x_i - x_j (a collapsed spring exerts none);
    dashpots ``-b ((v_i - v_j).e) e`` along e = l/|l| when ``axial_damping``, else
    ``-b (v_i - v_j)``. Any number of components d; in 2D the arithmetic is the
    same, operation for operation, as the 2D kernel this replaced.
    """
    # d as a literal, so the component loops unroll (as parmps.core.pairs does): a 10k-node
    # 3D body's spring forces took 1.7 times as long with d read from the array.
    if position.shape[1] == 2:
        _network_forces(position, velocity, springs, rest_length, stiffness, damping,
                        axial_damping, force, 2)
    elif position.shape[1] == 3:
        _network_forces(position, velocity, springs, rest_length, stiffness, damping,
                        axial_damping, force, 3)
    else:
        _network_forces(position, velocity, springs, rest_length, stiffness, damping,
                        axial_damping, force, position.shape[1])


@numba.njit(cache=True, inline="always")
def _network_forces(position, velocity, springs, rest_length, stiffness, damping,
                    axial_damping, force, d):
    """network_forces with the number of components d a compile-time constant."""
    for s in range(springs.shape[0]):
        i, j = springs[s, 0], springs[s, 1]
        squared = 0.0
        for a in range(d):
            delta = position[i, a] - position[j, a]
            squared += delta * delta
        length = np.sqrt(squared)
        scale = 0.0
        if length > 0.0:
            scale = stiffness[s] * (length - rest_length[s]) / length
        b = damping[s]
        # Axial dashpots: the rate of stretch, b (v_i - v_j).l / |l|^2.
        rate = 0.0
        if b != 0.0 and axial_damping and length > 0.0:
            closing = 0.0
            for a in range(d):
                closing += ((velocity[i, a] - velocity[j, a])
                            * (position[i, a] - position[j, a]))
            rate = b * closing / (length * length)
        for a in range(d):
            delta = position[i, a] - position[j, a]
            f = -scale * delta
            if b != 0.0:
                if axial_damping:
                    f -= rate * delta
                else:
                    f -= b * (velocity[i, a] - velocity[j, a])
            force[i, a] += f
            force[j, a] -= f


@numba.njit(cache=True)
def drag_kick(velocity, acceleration, rate, target, half):
    """A half kick ``v += half a`` with a drag ``rate (target - v)`` [1/s] on top, taken
    backward Euler in v: ``v <- (v + half (a + rate target)) / (1 + half rate)``.

    The drag is a node's viscous force towards its fluid neighbours' mean velocity (the
    coupling's, :meth:`parmps.coupling.weak.WeakCoupling.node_forces`): it relaxes a node
    far faster than a substep (``half rate`` of 3 or more), where an explicit drag would be
    unstable; backward Euler damps that mode for any rate and keeps the steady slip
    ``v - target = a / rate`` exact. A node of rate 0 gets the plain kick, bit for bit."""
    n, d = velocity.shape
    for k in range(n):
        r = rate[k]
        if r == 0.0:
            for a in range(d):
                velocity[k, a] += half * acceleration[k, a]
        else:
            scale = 1.0 / (1.0 + half * r)
            for a in range(d):
                velocity[k, a] = (velocity[k, a]
                                  + half * (acceleration[k, a] + r * target[k, a])) * scale


@numba.njit(cache=True)
def drag_prediction(velocity, inverse_mass, rate, target, h, kicks, predicted_velocity,
                    predicted_inverse_mass):
    """The velocity and inverse mass with which ``x + h v' + h^2 w' F`` is the next
    position under ``kicks`` (1 or 2) of :func:`drag_kick`'s half kicks, s = 1/(1 + h
    rate/2): two (a substep's second and the next one's first) give v' = s^2 v + h (s^2 +
    s)/2 rate target, w' = (s^2 + s)/2 w; one (a step's first substep, from the full-step
    velocity) v' = s v + h s/2 rate target, w' = s/2 w. A constraint's multiplier predicts
    from them (it zeroes the volume where the node will be)."""
    n, d = velocity.shape
    for k in range(n):
        r = rate[k]
        s = 1.0 / (1.0 + 0.5 * h * r)
        grow = s * s if kicks == 2 else s
        both = 0.5 * (s * s + s) if kicks == 2 else 0.5 * s
        predicted_inverse_mass[k] = both * inverse_mass[k]
        for a in range(d):
            predicted_velocity[k, a] = grow * velocity[k, a] + h * both * r * target[k, a]


@numba.njit(cache=True)
def held_force_substeps(position, velocity, acceleration, inverse_mass, springs, rest_length,
                        stiffness, damping, axial_damping, external, h, count, rate, target):
    """``count`` velocity-Verlet substeps of length h with the external force held.

    The body's own scheme (body.py): v += h/2 a; x += h v; a = M^-1 F(x, v_half); v += h/2 a,
    in place on ``position``, ``velocity`` and ``acceleration`` (n, d), each half kick with
    the drag ``rate`` (n,) towards ``target`` (n, d) (:func:`drag_kick`). For bodies without
    a volume constraint and without time-windowed loads, whose force depends on nothing else.
    """
    n, d = position.shape
    force = np.empty((n, d))
    for _ in range(count):
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)
        for k in range(n):
            for axis in range(d):
                position[k, axis] += h * velocity[k, axis]
        force[:, :] = 0.0
        network_forces(position, velocity, springs, rest_length, stiffness, damping,
                       axial_damping, force)
        for k in range(n):
            for axis in range(d):
                acceleration[k, axis] = (force[k, axis] + external[k, axis]) * inverse_mass[k]
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)


# --------------------------------------------------------------------------
# The volume constraint and the general substep loop (loads and constraint)


@numba.njit(cache=True)
def facet_volume(x, facets, permutations, signs, gradient, with_gradient):
    """d! V of the facets over the positions ``x`` (s, d) (surface.enclosed_volume), about
    the first facet's first node; with ``with_gradient``, d! dV/dx into ``gradient`` (s, d).

    ``permutations`` (d!, d) and ``signs`` (d!,): the terms of a d x d determinant.
    """
    # d as a literal, as in network_forces: the substeps evaluate this once or more each.
    if x.shape[1] == 2:
        return _facet_volume(x, facets, permutations, signs, gradient, with_gradient, 2)
    if x.shape[1] == 3:
        return _facet_volume(x, facets, permutations, signs, gradient, with_gradient, 3)
    return _facet_volume(x, facets, permutations, signs, gradient, with_gradient, x.shape[1])


@numba.njit(cache=True, inline="always")
def _facet_volume(x, facets, permutations, signs, gradient, with_gradient, d):
    apex = np.empty(d)
    for a in range(d):
        apex[a] = x[facets[0, 0], a]
    if with_gradient:
        gradient[:, :] = 0.0
    corner = np.empty((d, d))
    factor = np.empty(d)
    before = np.empty(d + 1)
    total = 0.0
    for f in range(facets.shape[0]):
        for r in range(d):
            for a in range(d):
                corner[r, a] = x[facets[f, r], a] - apex[a]
        for p in range(permutations.shape[0]):
            # before[r]: the sign times the factors of rows 0..r-1.
            before[0] = signs[p]
            for r in range(d):
                factor[r] = corner[r, permutations[p, r]]
                before[r + 1] = before[r] * factor[r]
            total += before[d]
            if with_gradient:
                # The cofactor of row r: the term without its factor from row r,
                # the factors before r times those after it.
                after = 1.0
                for r in range(d - 1, -1, -1):
                    gradient[facets[f, r], permutations[p, r]] += before[r] * after
                    after *= factor[r]
    return total


@numba.njit(cache=True)
def _newton(x, velocity, inverse_mass, force, nodes, facets, rest_volume, dt, tolerance,
            iterations, permutations, signs, factorial, gradient, multiplier, slope):
    """Newton steps on lambda alone, on the true volume of the predicted next position
    x + dt v + dt^2 M^-1 (F - gradV lambda), gradV and the slope ``slope`` =
    dt^2 gradV.M^-1 gradV held at x (body.volume_multiplier)."""
    s, d = x.shape
    free = np.empty((s, d))
    push = np.empty((s, d))
    predicted = np.empty((s, d))
    no_gradient = np.empty((0, d))
    for k in range(s):
        w = inverse_mass[nodes[k]]
        for a in range(d):
            free[k, a] = (x[k, a] + dt * velocity[nodes[k], a]
                          + dt ** 2 * w * force[nodes[k], a])
            push[k, a] = dt ** 2 * w * gradient[k, a]
    limit = tolerance * abs(rest_volume)
    for step in range(iterations):
        for k in range(s):
            for a in range(d):
                predicted[k, a] = free[k, a] - push[k, a] * multiplier
        residual = (facet_volume(predicted, facets, permutations, signs, no_gradient, False)
                    / factorial - rest_volume)
        if abs(residual) <= limit:
            return multiplier, step
        multiplier += residual / slope
    return multiplier, iterations


@numba.njit(cache=True)
def constrain(position, velocity, inverse_mass, force, nodes, facets, rest_volume, dt,
              tolerance, iterations, permutations, signs, factorial):
    """body.volume_multiplier compiled, on the surface ``nodes`` (``facets`` index them):
    subtracts gradV lambda from ``force``; returns (lambda, Newton steps taken)."""
    s, d = nodes.shape[0], position.shape[1]
    x = np.empty((s, d))
    gradient = np.empty((s, d))
    for k in range(s):
        for a in range(d):
            x[k, a] = position[nodes[k], a]
    phi = facet_volume(x, facets, permutations, signs, gradient, True) / factorial - rest_volume
    # Seed eq. (12): body.area_multiplier.
    denominator = 0.0
    along_velocity = 0.0
    along_force = 0.0
    for k in range(s):
        w = inverse_mass[nodes[k]]
        for a in range(d):
            gradient[k, a] /= factorial
            denominator += w * gradient[k, a] * gradient[k, a]
            along_velocity += gradient[k, a] * velocity[nodes[k], a]
            along_force += w * gradient[k, a] * force[nodes[k], a]
    if denominator <= 0.0:
        return 0.0, 0
    multiplier = (phi / dt ** 2 + along_velocity / dt + along_force) / denominator
    steps = 0
    if iterations > 0 and multiplier != 0.0:
        multiplier, steps = _newton(x, velocity, inverse_mass, force, nodes, facets,
                                    rest_volume, dt, tolerance, iterations, permutations,
                                    signs, factorial, gradient, multiplier,
                                    dt ** 2 * denominator)
    for k in range(s):
        for a in range(d):
            force[nodes[k], a] -= gradient[k, a] * multiplier
    return multiplier, steps


@numba.njit(cache=True)
def load_factor(time, start, end, ramp):
    """body.load_factor for one window, scalar."""
    if not (time >= start and time < end):
        return 0.0
    rise = (time - start) / ramp if ramp > 0 else 1.0
    fall = (end - time) / ramp if ramp > 0 else 1.0
    return min(max(min(rise, fall), 0.0), 1.0)


@numba.njit(cache=True)
def body_substeps(position, velocity, acceleration, inverse_mass, springs, rest_length,
                  stiffness, damping, axial_damping, held, load_field, load_start, load_end,
                  load_ramp, time, h, count, constrained, nodes, facets, rest_volume,
                  tolerance, iterations, permutations, signs, factorial, rate, target):
    """``count`` velocity-Verlet substeps from ``time`` of a body with windowed loads and/or
    the volume constraint: body.Body.acceleration_at's force (``held`` = gravity + fluid
    force, plus the loads at the substep's end, plus the springs, minus gradV lambda),
    compiled, each half kick with the drag ``rate`` towards ``target`` (:func:`drag_kick`).
    Returns (the last lambda, the most Newton steps of any substep)."""
    n, d = position.shape
    force = np.empty((n, d))
    multiplier = 0.0
    most = 0
    dragged = rate.shape[0] > 0 and rate.max() > 0.0
    seen_velocity = np.empty((n, d))
    seen_inverse_mass = np.empty(n)
    for step in range(count):
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)
        for k in range(n):
            for a in range(d):
                position[k, a] += h * velocity[k, a]
        now = time + (step + 1) * h
        force[:, :] = held
        for load in range(load_field.shape[0]):
            factor = load_factor(now, load_start[load], load_end[load], load_ramp[load])
            if factor != 0.0:
                for k in range(n):
                    for a in range(d):
                        force[k, a] += factor * load_field[load, k, a]
        network_forces(position, velocity, springs, rest_length, stiffness, damping,
                       axial_damping, force)
        if constrained:
            if dragged:
                drag_prediction(velocity, inverse_mass, rate, target, h, 2, seen_velocity,
                                seen_inverse_mass)
                multiplier, steps = constrain(position, seen_velocity, seen_inverse_mass,
                                              force, nodes, facets, rest_volume, h, tolerance,
                                              iterations, permutations, signs, factorial)
            else:
                multiplier, steps = constrain(position, velocity, inverse_mass, force, nodes,
                                              facets, rest_volume, h, tolerance, iterations,
                                              permutations, signs, factorial)
            most = max(most, steps)
        for k in range(n):
            for a in range(d):
                acceleration[k, a] = force[k, a] * inverse_mass[k]
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)
    return multiplier, most
