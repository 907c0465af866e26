"""MPS operators on a pair list (docs/design.md §1.1), in d dimensions.

Each operator takes the pair rows ``i`` (grouped, owned particles), the pair
columns ``j`` (owned or ghost), the pair geometry and per-particle arrays, and
returns one value per row. Weighted sums use ``np.bincount``. The dimension d
is that of the positions the pair geometry was made from (``pairs.dimension``);
the reference values n0 and lambda0 come from :mod:`parmps.core.lattice`.
"""

import numpy as np


def weight(distance, radius):
    """w(r) = re/r - 1 for 0 < r < re, else 0."""
    safe = np.where(distance > 0.0, distance, radius)
    return np.where(distance < radius, radius / safe - 1.0, 0.0)


class PairGeometry:
    """Separation vectors and distances of a pair list at given positions."""

    def __init__(self, indptr, rows, cols, position):
        self.indptr = indptr
        self.rows = rows
        self.cols = cols
        self.dimension = position.shape[1]
        self.offset = position[cols] - position[rows]
        self.distance = np.sqrt(np.einsum("pk,pk->p", self.offset, self.offset))

    def weight(self, radius):
        return weight(self.distance, radius)


def number_density(pairs, w, n_rows):
    """n_i = sum_j w_ij."""
    return np.bincount(pairs.rows, weights=w, minlength=n_rows)


def laplacian(pairs, w, field, n_rows, n0, lambda0):
    """<lap phi>_i = 2d/(lambda0 n0) sum_j (phi_j - phi_i) w_ij, for a scalar or N×k field."""
    coefficient = 2.0 * pairs.dimension / (lambda0 * n0)
    difference = field[pairs.cols] - field[pairs.rows]
    if difference.ndim == 1:
        return coefficient * np.bincount(pairs.rows, weights=difference * w, minlength=n_rows)
    return coefficient * np.column_stack([
        np.bincount(pairs.rows, weights=difference[:, k] * w, minlength=n_rows)
        for k in range(difference.shape[1])])


def neighbourhood_minimum(pairs, w, field, n_rows, include):
    """min of field over i and its neighbours j with w_ij > 0 and include[j]."""
    candidate = np.where((w > 0.0) & include[pairs.cols], field[pairs.cols], np.inf)
    minimum = field[:n_rows].copy()
    nonempty = np.diff(pairs.indptr) > 0
    if candidate.size:
        # Rows are grouped, so a segmented reduction replaces a (slow) ufunc.at.
        segment = np.minimum.reduceat(candidate, pairs.indptr[:-1][nonempty])
        minimum[nonempty] = np.minimum(minimum[nonempty], segment)
    return minimum


def gradient(pairs, w, field, n_rows, n0, reference, include):
    """<grad phi>_i = d/n0 sum_j (phi_j - ref_i) r_ij w_ij / |r_ij|^2 over j with include[j].

    With ``reference`` the neighbourhood minimum this is the MPS pressure gradient
    (docs/design.md §1.4); with ``reference = phi_i`` the plain gradient.
    """
    mask = (w > 0.0) & include[pairs.cols]
    rows = pairs.rows[mask]
    factor = (field[pairs.cols[mask]] - reference[rows]) * w[mask] / pairs.distance[mask] ** 2
    offset = pairs.offset[mask]
    return (pairs.dimension / n0) * np.column_stack([
        np.bincount(rows, weights=factor * offset[:, k], minlength=n_rows)
        for k in range(pairs.dimension)])


def divergence(pairs, w, field, n_rows, n0):
    """<div u>_i = d/n0 sum_j (u_j - u_i) . r_ij w_ij / |r_ij|^2."""
    mask = w > 0.0
    rows = pairs.rows[mask]
    difference = field[pairs.cols[mask]] - field[rows]
    projected = np.einsum("pk,pk->p", difference, pairs.offset[mask])
    return (pairs.dimension / n0) * np.bincount(rows, weights=projected * w[mask] /
                                          pairs.distance[mask] ** 2, minlength=n_rows)
