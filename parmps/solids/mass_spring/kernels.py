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
    """Spring and dashpot forces of every spring, added into ``force`` (n, 2).

    Hooke ``-k (|l| - l0) l/|l|`` with l = x_i - x_j (a collapsed spring exerts none);
    dashpots ``-b ((v_i - v_j).e) e`` along e = l/|l| when ``axial_damping``, else
    ``-b (v_i - v_j)``.
    """
    for s in range(springs.shape[0]):
        i, j = springs[s, 0], springs[s, 1]
        dx = position[i, 0] - position[j, 0]
        dy = position[i, 1] - position[j, 1]
        length = np.sqrt(dx * dx + dy * dy)
        fx = 0.0
        fy = 0.0
        if length > 0.0:
            scale = stiffness[s] * (length - rest_length[s]) / length
            fx = -scale * dx
            fy = -scale * dy
        b = damping[s]
        if b != 0.0:
            rx = velocity[i, 0] - velocity[j, 0]
            ry = velocity[i, 1] - velocity[j, 1]
            if axial_damping:
                if length > 0.0:
                    rate = b * (rx * dx + ry * dy) / (length * length)
                    fx -= rate * dx
                    fy -= rate * dy
            else:
                fx -= b * rx
                fy -= b * ry
        force[i, 0] += fx
        force[i, 1] += fy
        force[j, 0] -= fx
        force[j, 1] -= fy


@numba.njit(cache=True)
def held_force_substeps(position, velocity, acceleration, inverse_mass, springs, rest_length,
                        stiffness, damping, axial_damping, external, h, count):
    """``count`` velocity-Verlet substeps of length h with the external force held.

    The body's own scheme (body.py): v += h/2 a; x += h v; a = M^-1 F(x, v_half); v += h/2 a,
    in place on ``position``, ``velocity`` and ``acceleration``. For bodies without an area
    constraint and without time-windowed loads, whose force depends on nothing else.
    """
    n = position.shape[0]
    force = np.empty((n, 2))
    for _ in range(count):
        for k in range(n):
            for axis in range(2):
                velocity[k, axis] += 0.5 * h * acceleration[k, axis]
                position[k, axis] += h * velocity[k, axis]
        for k in range(n):
            force[k, 0] = 0.0
            force[k, 1] = 0.0
        network_forces(position, velocity, springs, rest_length, stiffness, damping,
                       axial_damping, force)
        for k in range(n):
            for axis in range(2):
                acceleration[k, axis] = (force[k, axis] + external[k, axis]) * inverse_mass[k]
                velocity[k, axis] += 0.5 * h * acceleration[k, axis]
