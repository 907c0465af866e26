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
    d = position.shape[1]
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
def held_force_substeps(position, velocity, acceleration, inverse_mass, springs, rest_length,
                        stiffness, damping, axial_damping, external, h, count):
    """``count`` velocity-Verlet substeps of length h with the external force held.

    The body's own scheme (body.py): v += h/2 a; x += h v; a = M^-1 F(x, v_half); v += h/2 a,
    in place on ``position``, ``velocity`` and ``acceleration`` (n, d). For bodies without a
    volume constraint and without time-windowed loads, whose force depends on nothing else.
    """
    n, d = position.shape
    force = np.empty((n, d))
    for _ in range(count):
        for k in range(n):
            for axis in range(d):
                velocity[k, axis] += 0.5 * h * acceleration[k, axis]
                position[k, axis] += h * velocity[k, axis]
        force[:, :] = 0.0
        network_forces(position, velocity, springs, rest_length, stiffness, damping,
                       axial_damping, force)
        for k in range(n):
            for axis in range(d):
                acceleration[k, axis] = (force[k, axis] + external[k, axis]) * inverse_mass[k]
                velocity[k, axis] += 0.5 * h * acceleration[k, axis]
