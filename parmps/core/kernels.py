"""Compiled pair loops for the fluid step.

The same sums as :mod:`parmps.core.operators`, computed row by row over the CSR
neighbour lists with distances evaluated on the fly. In numpy each operator
gathers and masks every pair (about 1.7 M at 40k particles) several times; here
each pair is visited once per operator and nothing is allocated per pair. The
numpy operators stay as the reference the tests compare these against.
"""

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _weight(distance, radius):
    if distance <= 0.0 or distance >= radius:
        return 0.0
    return radius / distance - 1.0


@numba.njit(cache=True)
def number_density(indptr, cols, position, radius, n_rows):
    """n_i = sum_j w(r_ij) and the count of neighbours within ``radius``."""
    density = np.zeros(n_rows)
    count = np.zeros(n_rows, np.int64)
    for i in range(n_rows):
        xi, yi = position[i, 0], position[i, 1]
        total = 0.0
        within = 0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            w = _weight(np.sqrt(dx * dx + dy * dy), radius)
            if w > 0.0:
                total += w
                within += 1
        density[i] = total
        count[i] = within
    return density, count


@numba.njit(cache=True)
def vector_laplacian_sum(indptr, cols, position, field, radius, n_rows):
    """sum_j (u_j - u_i) w(r_ij) for an N×2 field (times 2d/(lambda0 n0) gives the Laplacian)."""
    out = np.zeros((n_rows, 2))
    for i in range(n_rows):
        xi, yi = position[i, 0], position[i, 1]
        sx = 0.0
        sy = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            w = _weight(np.sqrt(dx * dx + dy * dy), radius)
            if w > 0.0:
                sx += (field[j, 0] - field[i, 0]) * w
                sy += (field[j, 1] - field[i, 1]) * w
        out[i, 0] = sx
        out[i, 1] = sy
    return out


@numba.njit(cache=True)
def divergence_sum(indptr, cols, position, field, radius, n_rows):
    """sum_j (u_j - u_i) . r_ij w / |r_ij|^2 (times d/n0 gives the divergence)."""
    out = np.zeros(n_rows)
    for i in range(n_rows):
        xi, yi = position[i, 0], position[i, 1]
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            r2 = dx * dx + dy * dy
            w = _weight(np.sqrt(r2), radius)
            if w > 0.0:
                total += ((field[j, 0] - field[i, 0]) * dx +
                          (field[j, 1] - field[i, 1]) * dy) * w / r2
        out[i] = total
    return out


@numba.njit(cache=True)
def pressure_gradient_sum(indptr, cols, position, pressure, has_pressure, radius, n_rows):
    """sum_j (P_j - Pmin_i) r_ij w / |r_ij|^2 over neighbours that carry a pressure.

    Pmin_i is the minimum of P over i and those neighbours (times d/n0 gives the
    MPS pressure gradient).
    """
    out = np.zeros((n_rows, 2))
    for i in range(n_rows):
        xi, yi = position[i, 0], position[i, 1]
        minimum = pressure[i]
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not has_pressure[j]:
                continue
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            if dx * dx + dy * dy < radius * radius and pressure[j] < minimum:
                minimum = pressure[j]
        sx = 0.0
        sy = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not has_pressure[j]:
                continue
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            r2 = dx * dx + dy * dy
            w = _weight(np.sqrt(r2), radius)
            if w > 0.0:
                factor = (pressure[j] - minimum) * w / r2
                sx += factor * dx
                sy += factor * dy
        out[i, 0] = sx
        out[i, 1] = sy
    return out


@numba.njit(cache=True)
def correct_gradient(indptr, cols, position, has_pressure, radius, scale, gradient,
                     min_eigenvalue):
    """Apply the corrective matrix to MPS pressure gradients, in place.

    ``gradient`` holds d/n0 sum_j (P_j - Pmin_i) r_ij w / r^2 per row and
    ``scale`` is d/n0. With A_i = d/n0 sum_j r_ij (x) r_ij w / r^2 over the same
    neighbours (those that carry a pressure), which is the identity on the full
    initial lattice, the row becomes A_i^-1 times itself (Khayyer & Gotoh 2011's
    gradient correction): exact for a linear field on any particle arrangement
    for the sum over P_j - P_i; the Pmin shift's part (P_i - Pmin_i) d/n0
    sum_j r_ij w / r^2 is only rescaled. Rows whose A_i has an eigenvalue below ``min_eigenvalue`` (a
    truncated neighbourhood at a free surface or in a splash) are left as they
    are. Returns how many rows were corrected.
    """
    n_rows = gradient.shape[0]
    corrected = 0
    for i in range(n_rows):
        xi, yi = position[i, 0], position[i, 1]
        axx = 0.0
        axy = 0.0
        ayy = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not has_pressure[j]:
                continue
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            r2 = dx * dx + dy * dy
            w = _weight(np.sqrt(r2), radius)
            if w > 0.0:
                axx += dx * dx * w / r2
                axy += dx * dy * w / r2
                ayy += dy * dy * w / r2
        axx *= scale
        axy *= scale
        ayy *= scale
        trace = axx + ayy
        det = axx * ayy - axy * axy
        smallest = 0.5 * trace - np.sqrt(max(0.25 * trace * trace - det, 0.0))
        if smallest < min_eigenvalue:
            continue
        gx = gradient[i, 0]
        gy = gradient[i, 1]
        gradient[i, 0] = (ayy * gx - axy * gy) / det
        gradient[i, 1] = (axx * gy - axy * gx) / det
        corrected += 1
    return corrected


@numba.njit(cache=True)
def collision_change(indptr, cols, position, velocity, moving, distance_limit, restitution,
                     n_rows):
    """Velocity changes of moving particles from collisions closer than ``distance_limit``.

    Uses pre-collision velocities only, so the result is independent of pair order:
    two moving particles share the impulse; a fixed partner is infinitely heavy.
    """
    out = np.zeros((n_rows, 2))
    limit2 = distance_limit * distance_limit
    for i in range(n_rows):
        if not moving[i]:
            continue
        xi, yi = position[i, 0], position[i, 1]
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            r2 = dx * dx + dy * dy
            if r2 >= limit2 or r2 <= 0.0:
                continue
            r = np.sqrt(r2)
            nx = dx / r
            ny = dy / r
            approach = (velocity[i, 0] - velocity[j, 0]) * nx + \
                (velocity[i, 1] - velocity[j, 1]) * ny
            if approach <= 0.0:
                continue
            share = 0.5 if moving[j] else 1.0
            impulse = (1.0 + restitution) * share * approach
            out[i, 0] -= impulse * nx
            out[i, 1] -= impulse * ny
    return out


@numba.njit(cache=True)
def poisson_rows(indptr, cols, position, radius, row_number, is_unknown, coefficient,
                 diagonal_shift, dirichlet_diagonal):
    """CSR rows of the pressure Poisson matrix, one per owned particle with a pressure.

    ``row_number`` is the global row of every local particle (-1 for dummies,
    which carry no pressure); ``is_unknown`` is false for free-surface
    (Dirichlet) particles. An unknown row i has the diagonal a sum_j w_ij + shift
    over neighbours j with a pressure, and -a w_ij where j is an unknown too: a
    Dirichlet neighbour has P_j = 0 and adds to the diagonal only. A Dirichlet
    row is ``dirichlet_diagonal`` * P_i = 0, decoupled, so the matrix keeps one
    size while particles reach and leave the surface and a preconditioner can
    be reused across steps. Diagonal first in each row.
    """
    n_owned = indptr.shape[0] - 1
    n_rows = 0
    for i in range(n_owned):
        if row_number[i] >= 0:
            n_rows += 1
    row_ptr = np.zeros(n_rows + 1, np.int64)
    k = 0
    for i in range(n_owned):
        if row_number[i] < 0:
            continue
        length = 1
        if is_unknown[i]:
            xi, yi = position[i, 0], position[i, 1]
            for p in range(indptr[i], indptr[i + 1]):
                j = cols[p]
                if row_number[j] < 0 or not is_unknown[j]:
                    continue
                dx = position[j, 0] - xi
                dy = position[j, 1] - yi
                if _weight(np.sqrt(dx * dx + dy * dy), radius) > 0.0:
                    length += 1
        row_ptr[k + 1] = row_ptr[k] + length
        k += 1
    columns = np.empty(row_ptr[n_rows], np.int64)
    values = np.empty(row_ptr[n_rows])
    k = 0
    for i in range(n_owned):
        if row_number[i] < 0:
            continue
        columns[row_ptr[k]] = row_number[i]
        if not is_unknown[i]:
            values[row_ptr[k]] = dirichlet_diagonal
            k += 1
            continue
        xi, yi = position[i, 0], position[i, 1]
        place = row_ptr[k] + 1
        diagonal = diagonal_shift
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if row_number[j] < 0:
                continue
            dx = position[j, 0] - xi
            dy = position[j, 1] - yi
            w = _weight(np.sqrt(dx * dx + dy * dy), radius)
            if w <= 0.0:
                continue
            diagonal += coefficient * w
            if is_unknown[j]:
                columns[place] = row_number[j]
                values[place] = -coefficient * w
                place += 1
        values[row_ptr[k]] = diagonal
        k += 1
    return row_ptr, columns, values
