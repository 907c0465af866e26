"""The particles' number density: the MPS number density n_i = sum_j w(r_ij), the smooth
density measure of Wendland's C2 function, and the rows beside a set of particles, in
compiled pair loops (:mod:`parmps.core.pairs`)."""

import numba
import numpy as np

from parmps.core.pairs import for_each_dimension, pair_distance2, weight_of_r2, wendland


@for_each_dimension
def number_density(d, indptr, cols, position, radius, n_rows):
    """n_i = sum_j w(r_ij) and the count of neighbours within ``radius``."""
    density = np.zeros(n_rows)
    count = np.zeros(n_rows, np.int64)
    for i in range(n_rows):
        total = 0.0
        within = 0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                total += w
                within += 1
        density[i] = total
        count[i] = within
    return density, count


@numba.njit(cache=True, inline="always")
def _smooth_weight_of_r2(r2, support):
    if r2 >= support * support:
        return 0.0
    return wendland(np.sqrt(r2) / support)


@for_each_dimension
def smooth_density(d, indptr, cols, position, support, n_rows):
    """sum_j W(r_ij) over j and i itself, W Wendland's C2 function of radius ``support``."""
    density = np.ones(n_rows)  # each particle's own weight, W(0) = 1
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += _smooth_weight_of_r2(pair_distance2(position, i, cols[p], d), support)
        density[i] += total
    return density


@numba.njit(cache=True)
def rows_beside(indptr, cols, is_target, n_rows):
    """The rows [0, n_rows) of the pair list with a neighbour in ``is_target`` (every local
    particle), or one themselves."""
    found = np.zeros(n_rows, np.bool_)
    for i in range(n_rows):
        if is_target[i]:
            found[i] = True
            continue
        for p in range(indptr[i], indptr[i + 1]):
            if is_target[cols[p]]:
                found[i] = True
                break
    return found

