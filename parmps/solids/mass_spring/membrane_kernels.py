"""Compiled loops of the cell membrane (:mod:`parmps.solids.mass_spring.membrane`).

Every loop runs over edges, dihedrals or triangles and scatters into per-node arrays;
the formulas, their sources and their tests: membrane.py, docs/shells.md (Cell
membranes), tests/test_membrane.py.
"""

import numba
import numpy as np

from parmps.solids.mass_spring.kernels import drag_kick, drag_prediction


@numba.njit(cache=True)
def wlc_pow_tension(length, max_length, kbt_over_p, kp, exponent):
    """dU/dl of one worm-like-chain spring with a repulsive power term (Fedosov et al.
    2010): kBT/(4p) (1/(1-x)^2 - 1 + 4x) - kp/l^m, x = l/l_max (> 0: it pulls)."""
    x = length / max_length
    slack = 1.0 - x
    repulsion = kp / (length * length) if exponent == 2.0 else kp / length ** exponent
    return 0.25 * kbt_over_p * (1.0 / (slack * slack) - 1.0 + 4.0 * x) - repulsion


@numba.njit(cache=True)
def edge_forces(position, velocity, edges, max_length, kp, kbt_over_p, exponent, damping,
                limit, force):
    """WLC-POW tensions and dashpots -b (v_i - v_j) of every edge, added into ``force``;
    returns the largest extension l/l_max met and its edge. An edge at or beyond ``limit``
    l_max is held at the tension of ``limit`` (the caller stops the run on it)."""
    most = 0.0
    worst = 0
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        dx = position[i, 0] - position[j, 0]
        dy = position[i, 1] - position[j, 1]
        dz = position[i, 2] - position[j, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length <= 0.0:
            continue
        x = length / max_length[e]
        if x > most:
            most, worst = x, e
        tension = wlc_pow_tension(min(length, limit * max_length[e]), max_length[e],
                                  kbt_over_p, kp[e], exponent)
        scale = tension / length
        fx, fy, fz = -scale * dx, -scale * dy, -scale * dz
        if damping != 0.0:
            fx -= damping * (velocity[i, 0] - velocity[j, 0])
            fy -= damping * (velocity[i, 1] - velocity[j, 1])
            fz -= damping * (velocity[i, 2] - velocity[j, 2])
        force[i, 0] += fx
        force[i, 1] += fy
        force[i, 2] += fz
        force[j, 0] -= fx
        force[j, 1] -= fy
        force[j, 2] -= fz
    return most, worst


@numba.njit(cache=True, inline="always")
def _cross(ux, uy, uz, vx, vy, vz):
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@numba.njit(cache=True, inline="always")
def _corner(position, i, j):
    """position[i] - position[j] as three scalars (no array allocated)."""
    return (position[i, 0] - position[j, 0], position[i, 1] - position[j, 1],
            position[i, 2] - position[j, 2])


@numba.njit(cache=True)
def bending_forces(position, quads, rest_cosine, rest_sine, kb, force):
    """Forces of U = kb sum (1 - cos(theta - theta0)) over the dihedrals ``quads`` (a, b,
    c, d) (membrane.dihedral_angles: the signed angle between the outward normals of
    (a, b, c) and (b, a, d)), theta0 given by its cosine and sine, added into ``force``.
    The angle's gradient: c and d move it by -|e| N/|N|^2 along their triangle's normal N,
    a and b by the opposite of those shares weighted by where c and d project on the edge
    e = b - a."""
    for q in range(quads.shape[0]):
        ia, ib, ic, id_ = quads[q, 0], quads[q, 1], quads[q, 2], quads[q, 3]
        ex, ey, ez = _corner(position, ib, ia)
        cx, cy, cz = _corner(position, ic, ia)
        dx, dy, dz = _corner(position, id_, ib)
        n1x, n1y, n1z = _cross(ex, ey, ez, cx, cy, cz)
        n2x, n2y, n2z = _cross(-ex, -ey, -ez, dx, dy, dz)
        s1 = n1x * n1x + n1y * n1y + n1z * n1z
        s2 = n2x * n2x + n2y * n2y + n2z * n2z
        ee = ex * ex + ey * ey + ez * ez
        if s1 <= 0.0 or s2 <= 0.0 or ee <= 0.0:
            continue
        length = np.sqrt(ee)
        mx, my, mz = _cross(n1x, n1y, n1z, n2x, n2y, n2z)
        # dU/dtheta = kb sin(theta - theta0), from the angle's sine and cosine.
        norm = np.sqrt(s1 * s2)
        sine = (mx * ex + my * ey + mz * ez) / (length * norm)
        cosine = (n1x * n2x + n1y * n2y + n1z * n2z) / norm
        slope = kb * (sine * rest_cosine[q] - cosine * rest_sine[q])
        # c - a and d - a projected on the edge, as shares of it.
        tc = (cx * ex + cy * ey + cz * ez) / ee
        td = ((dx + ex) * ex + (dy + ey) * ey + (dz + ez) * ez) / ee
        w1, w2 = -length / s1, -length / s2
        gc = (w1 * n1x, w1 * n1y, w1 * n1z)
        gd = (w2 * n2x, w2 * n2y, w2 * n2z)
        for k in range(3):
            ga = -(1.0 - tc) * gc[k] - (1.0 - td) * gd[k]
            gb = -tc * gc[k] - td * gd[k]
            force[ia, k] -= slope * ga
            force[ib, k] -= slope * gb
            force[ic, k] -= slope * gc[k]
            force[id_, k] -= slope * gd[k]


@numba.njit(cache=True)
def local_area_forces(position, triangles, rest_area, modulus, force):
    """Forces of U = K sum (A_t - A0_t)^2 / (2 A0_t) over the triangles (Fedosov et al.
    2010's local area term), added into ``force``; dA/da = (b - c) x n/2, and cyclically."""
    for t in range(triangles.shape[0]):
        i, j, k = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        bx, by, bz = _corner(position, j, i)
        cx, cy, cz = _corner(position, k, i)
        nx, ny, nz = _cross(bx, by, bz, cx, cy, cz)
        size = np.sqrt(nx * nx + ny * ny + nz * nz)
        if size <= 0.0:
            continue
        # dU/dA over |n|, with the 1/2 of dA/dx: the scale of the cross products below.
        scale = 0.5 * modulus * (0.5 * size - rest_area[t]) / (rest_area[t] * size)
        g = _cross(bx - cx, by - cy, bz - cz, nx, ny, nz)
        h = _cross(cx, cy, cz, nx, ny, nz)
        f = _cross(-bx, -by, -bz, nx, ny, nz)
        for m in range(3):
            force[i, m] -= scale * g[m]
            force[j, m] -= scale * h[m]
            force[k, m] -= scale * f[m]


@numba.njit(cache=True)
def area_volume(position, triangles, gradients, with_gradient):
    """(A, V) of a closed outward triangle mesh, and with ``with_gradient`` dA/dx and
    dV/dx into ``gradients`` (2, n, 3); V about the first triangle's first node."""
    o = triangles[0, 0]
    if with_gradient:
        gradients[:, :, :] = 0.0
    area = 0.0
    volume = 0.0
    for t in range(triangles.shape[0]):
        i, j, k = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        ax, ay, az = _corner(position, i, o)
        bx, by, bz = _corner(position, j, o)
        cx, cy, cz = _corner(position, k, o)
        nx, ny, nz = _cross(bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az)
        size = np.sqrt(nx * nx + ny * ny + nz * nz)
        area += 0.5 * size
        vx, vy, vz = _cross(bx, by, bz, cx, cy, cz)      # b x c: 6 dV/da
        volume += (ax * vx + ay * vy + az * vz) / 6.0
        if with_gradient:
            if size > 0.0:
                nx, ny, nz = 0.5 * nx / size, 0.5 * ny / size, 0.5 * nz / size
            # dA/da = (b - c) x n/2, and cyclically; dV/da = b x c/6, and cyclically.
            g = _cross(bx - cx, by - cy, bz - cz, nx, ny, nz)
            h = _cross(cx - ax, cy - ay, cz - az, nx, ny, nz)
            f = _cross(ax - bx, ay - by, az - bz, nx, ny, nz)
            u = _cross(cx, cy, cz, ax, ay, az)
            w = _cross(ax, ay, az, bx, by, bz)
            v = (vx, vy, vz)
            for m in range(3):
                gradients[0, i, m] += g[m]
                gradients[0, j, m] += h[m]
                gradients[0, k, m] += f[m]
                gradients[1, i, m] += v[m] / 6.0
                gradients[1, j, m] += u[m] / 6.0
                gradients[1, k, m] += w[m] / 6.0
    return area, volume


@numba.njit(cache=True)
def _solve(matrix, rhs, active):
    """The 2x2 system on the active constraints (an inactive one's multiplier is 0)."""
    out = np.zeros(2)
    if active[0] and active[1]:
        det = matrix[0, 0] * matrix[1, 1] - matrix[0, 1] * matrix[1, 0]
        out[0] = (matrix[1, 1] * rhs[0] - matrix[0, 1] * rhs[1]) / det
        out[1] = (matrix[0, 0] * rhs[1] - matrix[1, 0] * rhs[0]) / det
    elif active[0]:
        out[0] = rhs[0] / matrix[0, 0]
    elif active[1]:
        out[1] = rhs[1] / matrix[1, 1]
    return out


@numba.njit(cache=True)
def constrain(position, velocity, inverse_mass, force, triangles, rest, active, dt,
              tolerance, iterations, gradients):
    """The area and volume multipliers of the next substep, subtracted from ``force``.

    Hong et al.'s multiplier for two constraints (docs/shells.md): with g_k = dPhi_k/dx at
    x, G_kj = g_k.M^-1 g_j, lambda = G^-1 [Phi/dt^2 + g.v/dt + g.M^-1 F] zeroes both to first
    order in the predicted x + dt v + dt^2 M^-1 (F - g lambda); Newton steps with G held
    then take both true values to within ``tolerance`` of ``rest`` (A0, V0). Returns
    (lambda (2,), the Newton steps taken)."""
    n = position.shape[0]
    area, volume = area_volume(position, triangles, gradients, True)
    phi = np.array([area - rest[0], volume - rest[1]])
    matrix = np.zeros((2, 2))
    rhs = np.zeros(2)
    for k in range(2):
        rhs[k] = phi[k] / dt ** 2
        for p in range(n):
            w = inverse_mass[p]
            for m in range(3):
                g = gradients[k, p, m]
                rhs[k] += g * velocity[p, m] / dt + w * g * force[p, m]
                for j in range(2):
                    matrix[k, j] += w * g * gradients[j, p, m]
    for k in range(2):
        if not active[k]:
            matrix[k, :] = 0.0
            matrix[:, k] = 0.0
            matrix[k, k] = 1.0
            rhs[k] = 0.0
    if matrix[0, 0] <= 0.0 or matrix[1, 1] <= 0.0:
        return np.zeros(2), 0
    multiplier = _solve(matrix, rhs, active)
    steps = 0
    if iterations > 0:
        free = np.empty((n, 3))
        predicted = np.empty((n, 3))
        for p in range(n):
            for m in range(3):
                free[p, m] = (position[p, m] + dt * velocity[p, m]
                              + dt ** 2 * inverse_mass[p] * force[p, m])
        none = np.empty((2, 0, 3))
        residual = np.zeros(2)
        while steps < iterations:
            for p in range(n):
                w = dt ** 2 * inverse_mass[p]
                for m in range(3):
                    predicted[p, m] = free[p, m] - w * (gradients[0, p, m] * multiplier[0]
                                                        + gradients[1, p, m] * multiplier[1])
            a, v = area_volume(predicted, triangles, none, False)
            residual[0] = a - rest[0] if active[0] else 0.0
            residual[1] = v - rest[1] if active[1] else 0.0
            if (abs(residual[0]) <= tolerance * rest[0]
                    and abs(residual[1]) <= tolerance * abs(rest[1])):
                break
            multiplier += _solve(matrix, residual / dt ** 2, active)
            steps += 1
    for p in range(n):
        for m in range(3):
            force[p, m] -= (gradients[0, p, m] * multiplier[0]
                            + gradients[1, p, m] * multiplier[1])
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
def membrane_force(position, velocity, mass, held, load_field, load_start, load_end,
                   load_ramp, now, edges, max_length, kp, kbt_over_p, exponent, damping,
                   limit, quads, rest_cosine, rest_sine, kb, triangles, rest_area,
                   local_modulus, drag, triangle_law, force):
    """Every force on the nodes but the constraints', into ``force``: ``held`` (gravity,
    fluid), the windowed loads at ``now``, the edges, the dihedrals, the triangles' local
    area term, their in-plane law if ``triangle_law`` = (law, Dm^-1, G, C) names one
    (:func:`triangle_forces`; law 0: none) and the drag -drag m v. Returns the largest
    edge extension l/l_max and its edge."""
    n = position.shape[0]
    force[:, :] = held
    for load in range(load_field.shape[0]):
        factor = load_factor(now, load_start[load], load_end[load], load_ramp[load])
        if factor != 0.0:
            for p in range(n):
                for m in range(3):
                    force[p, m] += factor * load_field[load, p, m]
    most, worst = edge_forces(position, velocity, edges, max_length, kp, kbt_over_p,
                              exponent, damping, limit, force)
    if kb != 0.0:
        bending_forces(position, quads, rest_cosine, rest_sine, kb, force)
    if local_modulus != 0.0:
        local_area_forces(position, triangles, rest_area, local_modulus, force)
    law, rest_inverse, modulus, dilation = triangle_law
    if law != 0:
        triangle_forces(position, triangles, rest_inverse, rest_area, law, modulus, dilation,
                        force)
    if drag != 0.0:
        for p in range(n):
            for m in range(3):
                force[p, m] -= drag * mass[p] * velocity[p, m]
    return most, worst


@numba.njit(cache=True)
def membrane_substeps(position, velocity, acceleration, mass, inverse_mass, held, load_field,
                      load_start, load_end, load_ramp, time, h, count, edges, max_length, kp,
                      kbt_over_p, exponent, damping, limit, quads, rest_cosine, rest_sine, kb,
                      rest_area, local_modulus, drag, triangle_law, triangles, rest, active,
                      tolerance, iterations, rate, target):
    """``count`` velocity-Verlet substeps of a membrane body (body.Body.advance's scheme),
    each half kick with the fluid's drag ``rate`` towards ``target`` (kernels.drag_kick).
    Returns (the last multipliers (2,), the most Newton steps, the largest extension and
    its edge). A substep that takes an edge to ``limit`` ends the loop: the caller stops
    the run on it."""
    n = position.shape[0]
    force = np.empty((n, 3))
    gradients = np.empty((2, n, 3))
    multiplier = np.zeros(2)
    most_steps = 0
    most_extension = 0.0
    worst_edge = 0
    constrained = active[0] or active[1]
    dragged = n > 0 and rate.max() > 0.0
    seen_velocity = np.empty((n, 3))
    seen_inverse_mass = np.empty(n)
    for step in range(count):
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)
        for p in range(n):
            for m in range(3):
                position[p, m] += h * velocity[p, m]
        extension, edge = membrane_force(position, velocity, mass, held, load_field, load_start,
                                   load_end, load_ramp, time + (step + 1) * h, edges,
                                   max_length, kp, kbt_over_p, exponent, damping, limit,
                                   quads, rest_cosine, rest_sine, kb, triangles, rest_area,
                                   local_modulus, drag, triangle_law, force)
        if extension > most_extension:
            most_extension, worst_edge = extension, edge
        if extension >= limit:
            break
        if constrained:
            if dragged:
                # The multipliers predict where the drag's kicks will put the nodes.
                drag_prediction(velocity, inverse_mass, rate, target, h, 2, seen_velocity,
                                seen_inverse_mass)
                multiplier, steps = constrain(position, seen_velocity, seen_inverse_mass,
                                              force, triangles, rest, active, h, tolerance,
                                              iterations, gradients)
            else:
                multiplier, steps = constrain(position, velocity, inverse_mass, force,
                                              triangles, rest, active, h, tolerance,
                                              iterations, gradients)
            most_steps = max(most_steps, steps)
        for p in range(n):
            for m in range(3):
                acceleration[p, m] = force[p, m] * inverse_mass[p]
        drag_kick(velocity, acceleration, rate, target, 0.5 * h)
    return multiplier, most_steps, most_extension, worst_edge


@numba.njit(cache=True, inline="always")
def _segment_hits_triangle(position, a, b, i, j, k):
    """Whether the segment a-b passes through the triangle (i, j, k) (Moller & Trumbore
    1997); a segment in the triangle's plane counts as missing it."""
    dx, dy, dz = _corner(position, b, a)
    e1x, e1y, e1z = _corner(position, j, i)
    e2x, e2y, e2z = _corner(position, k, i)
    px, py, pz = _cross(dx, dy, dz, e2x, e2y, e2z)
    det = e1x * px + e1y * py + e1z * pz
    scale = (np.sqrt(dx * dx + dy * dy + dz * dz)
             * np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
             * np.sqrt(e2x * e2x + e2y * e2y + e2z * e2z))
    if abs(det) <= 1e-12 * scale:
        return False
    sx, sy, sz = _corner(position, a, i)
    u = (sx * px + sy * py + sz * pz) / det
    if u < 0.0 or u > 1.0:
        return False
    qx, qy, qz = _cross(sx, sy, sz, e1x, e1y, e1z)
    v = (dx * qx + dy * qy + dz * qz) / det
    if v < 0.0 or u + v > 1.0:
        return False
    t = (e2x * qx + e2y * qy + e2z * qz) / det
    return 0.0 < t < 1.0


@numba.njit(cache=True)
def _cell_range(low, high, origin, cell, shape):
    """The grid cells [lo, hi] per axis that the box [low, high] overlaps."""
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for m in range(3):
        lo[m] = min(max(int((low[m] - origin[m]) / cell), 0), shape[m] - 1)
        hi[m] = min(max(int((high[m] - origin[m]) / cell), 0), shape[m] - 1)
    return lo, hi


@numba.njit(cache=True)
def _triangle_box(position, triangles, t):
    low = np.full(3, np.inf)
    high = np.full(3, -np.inf)
    for c in range(3):
        for m in range(3):
            x = position[triangles[t, c], m]
            low[m], high[m] = min(low[m], x), max(high[m], x)
    return low, high


@numba.njit(cache=True)
def _bin_triangles(position, triangles, origin, cell, shape):
    """(start, members) of a grid of cells of size ``cell``: the triangles whose bounding
    box overlaps cell c are members[start[c]:start[c + 1]]."""
    count = np.zeros(shape[0] * shape[1] * shape[2] + 1, np.int64)
    for rounds in range(2):
        if rounds == 1:
            start = np.cumsum(count)
            members = np.empty(start[-1], np.int64)
            fill = start.copy()
        for t in range(triangles.shape[0]):
            low, high = _triangle_box(position, triangles, t)
            lo, hi = _cell_range(low, high, origin, cell, shape)
            for x in range(lo[0], hi[0] + 1):
                for y in range(lo[1], hi[1] + 1):
                    for z in range(lo[2], hi[2] + 1):
                        c = (x * shape[1] + y) * shape[2] + z
                        if rounds == 0:
                            count[c + 1] += 1
                        else:
                            members[fill[c]] = t
                            fill[c] += 1
    return start, members


@numba.njit(cache=True)
def first_crossing(position, edges, triangles, cell):
    """(edge, triangle) of the first edge found passing through a triangle it does not
    touch, or (-1, -1): a closed surface whose edge pierces one of its own triangles has
    passed through itself. Triangles are binned on a grid of cells of size ``cell`` (at
    least the longest edge, so a triangle's box spans at most two cells an axis) and each
    edge is tested against the triangles of the cells its box overlaps."""
    origin = np.empty(3)
    shape = np.empty(3, np.int64)
    for m in range(3):
        origin[m] = position[:, m].min()
        shape[m] = int((position[:, m].max() - origin[m]) / cell) + 1
    start, members = _bin_triangles(position, triangles, origin, cell, shape)
    low = np.empty(3)
    high = np.empty(3)
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        for m in range(3):
            low[m] = min(position[a, m], position[b, m])
            high[m] = max(position[a, m], position[b, m])
        lo, hi = _cell_range(low, high, origin, cell, shape)
        for x in range(lo[0], hi[0] + 1):
            for y in range(lo[1], hi[1] + 1):
                for z in range(lo[2], hi[2] + 1):
                    c = (x * shape[1] + y) * shape[2] + z
                    for s in range(start[c], start[c + 1]):
                        t = members[s]
                        i, j, k = triangles[t, 0], triangles[t, 1], triangles[t, 2]
                        if a == i or a == j or a == k or b == i or b == j or b == k:
                            continue
                        if _segment_hits_triangle(position, a, b, i, j, k):
                            return e, t
    return -1, -1


# The in-plane laws of a triangle (membrane.TRIANGLE_LAWS).
SKALAK = 1
NEO_HOOKEAN = 2


@numba.njit(cache=True)
def triangle_forces(position, triangles, rest_inverse, rest_area, law, modulus, dilation,
                    force):
    """Forces of the triangles' hyperelastic energy A0 W(C), C = F^T F the right
    Cauchy-Green tensor of each triangle's (constant) deformation gradient F = [x1 - x0,
    x2 - x0] Dm^-1 (3x2; ``rest_inverse`` Dm^-1 from the rest triangle in its own plane),
    added into ``force``. With I1 = tr C - 2 and I2 = det C - 1:
    Skalak et al. (1973), W = G/4 (I1^2 + 2 I1 - 2 I2 + C I2^2) (``dilation`` C);
    neo-Hookean (a thin sheet of incompressible material), W = G/2 (tr C + 1/det C - 3).
    dW/dF = 2 W_I1 F + 2 W_I2 F adj(C); the nodes get -A0 dW/dF Dm^-T (1 and 2) and minus
    their sum (0). A triangle collapsed to det C <= 0 is skipped (the fold check stops
    the run on it)."""
    for t in range(triangles.shape[0]):
        i, j, k = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        d1 = _corner(position, j, i)
        d2 = _corner(position, k, i)
        f0 = np.empty(3)
        f1 = np.empty(3)
        for m in range(3):
            f0[m] = d1[m] * rest_inverse[t, 0, 0] + d2[m] * rest_inverse[t, 1, 0]
            f1[m] = d1[m] * rest_inverse[t, 0, 1] + d2[m] * rest_inverse[t, 1, 1]
        c11 = f0[0] * f0[0] + f0[1] * f0[1] + f0[2] * f0[2]
        c12 = f0[0] * f1[0] + f0[1] * f1[1] + f0[2] * f1[2]
        c22 = f1[0] * f1[0] + f1[1] * f1[1] + f1[2] * f1[2]
        det = c11 * c22 - c12 * c12
        if det <= 0.0:
            continue
        if law == SKALAK:
            w1 = 0.5 * modulus * (c11 + c22 - 1.0)
            w2 = 0.5 * modulus * (dilation * (det - 1.0) - 1.0)
        else:
            w1 = 0.5 * modulus
            w2 = -0.5 * modulus / (det * det)
        a = -rest_area[t]
        for m in range(3):
            # dW/dF's two columns, then -A0 dW/dF Dm^-T.
            p0 = 2.0 * w1 * f0[m] + 2.0 * w2 * (f0[m] * c22 - f1[m] * c12)
            p1 = 2.0 * w1 * f1[m] + 2.0 * w2 * (f1[m] * c11 - f0[m] * c12)
            h1 = a * (p0 * rest_inverse[t, 0, 0] + p1 * rest_inverse[t, 0, 1])
            h2 = a * (p0 * rest_inverse[t, 1, 0] + p1 * rest_inverse[t, 1, 1])
            force[j, m] += h1
            force[k, m] += h2
            force[i, m] -= h1 + h2
