"""Pressure gradients: the minimum-pressure MPS gradient, plain or corrected (docs/design.md).

``<grad P>_i = d/n0 sum_j (P_j - Pmin_i) r_ij w_ij / |r_ij|^2`` over the
neighbours that carry a pressure (not dummies), with ``Pmin_i`` the minimum of P
over i and those neighbours: subtracting it keeps every pair repulsive, which is
the original scheme's stability choice. The corrected gradient multiplies that
by the inverse of the moment matrix ``A_i = d/n0 sum_j r_ij (x) r_ij w / r^2``
(Khayyer & Gotoh 2011), exact for a linear field on any arrangement.
"""

import numba
import numpy as np

from parmps.config import Key
from parmps.core.pairs import (for_each_dimension, pair_component, pair_distance2,
                               row_length, weight_of_r2)
from parmps.core.symmetric import has_eigenvalue_below


class MinimumPressureGradient:
    KEYS = {}

    def __init__(self, settings, constants):
        self.constants = constants

    def gradient(self, indptr, cols, position, pressure, has_pressure, n_rows, rows=None,
                 surface=None):
        """(n_rows, d) pressure gradient of the rows [0, n_rows) of the pair list; with
        ``rows`` (a mask), of those rows only, the others 0. ``surface`` is for the
        corrected gradient; the plain one has nothing to correct."""
        c = self.constants
        return (c.dimension / c.n0) * pressure_gradient_sum(
            indptr, cols, position, pressure, has_pressure, c.re_number_density, n_rows, rows)


class CorrectedGradient(MinimumPressureGradient):
    KEYS = {"eigenvalue_limit": Key("float", 0.7, gt=0.0, le=1.0,
                                    doc="rows whose moment matrix (the identity on the full "
                                        "lattice, 0.5 on a flat free surface) has an "
                                        "eigenvalue below this keep the plain gradient: a "
                                        "splash, a body's face to the air (the free-surface "
                                        "condition may set its own limit for the fluid's "
                                        "surface particles)")}

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.eigenvalue_limit = settings["eigenvalue_limit"]

    def gradient(self, indptr, cols, position, pressure, has_pressure, n_rows, rows=None,
                 surface=None):
        """As the plain gradient, corrected. ``surface``: None, or (rows, normals, limit) from
        the free-surface condition: those rows are corrected along their normal only
        (correct_normal_component) down to that limit, the others as usual; one pass
        over the pairs for both (corrected_pressure_gradient)."""
        c = self.constants
        surface_rows, normal, surface_limit = (None, None, 0.0) if surface is None else surface
        return corrected_pressure_gradient(
            indptr, cols, position, pressure, has_pressure, c.re_number_density,
            c.dimension / c.n0, n_rows, self.eigenvalue_limit, rows, surface_rows, normal,
            surface_limit)


@numba.njit(cache=True, inline="always")
def _row_pressure_minimum(indptr, cols, position, pressure, has_pressure, radius2, i, d):
    """Pmin_i: the least pressure of row i and its neighbours within the radius that carry
    a pressure (the minimum-pressure gradient's reference)."""
    minimum = pressure[i]
    for p in range(indptr[i], indptr[i + 1]):
        j = cols[p]
        if not has_pressure[j]:
            continue
        if pair_distance2(position, i, j, d) < radius2 and pressure[j] < minimum:
            minimum = pressure[j]
    return minimum


@for_each_dimension
def pressure_gradient_sum(d, indptr, cols, position, pressure, has_pressure, radius, n_rows,
                          rows=None):
    """sum_j (P_j - Pmin_i) r_ij w / |r_ij|^2 over neighbours that carry a pressure.

    Pmin_i is the minimum of P over i and those neighbours (times d/n0 gives the
    MPS pressure gradient). ``rows``: optional mask of the rows wanted; the others
    are left 0.
    """
    out = np.zeros((n_rows, d))
    radius2 = radius * radius
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        minimum = _row_pressure_minimum(indptr, cols, position, pressure, has_pressure, radius2,
                                        i, d)
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not has_pressure[j]:
                continue
            r2 = pair_distance2(position, i, j, d)
            w = weight_of_r2(r2, radius)
            if w > 0.0:
                factor = (pressure[j] - minimum) * w / r2
                for k in range(d):
                    out[i, k] += factor * pair_component(position, i, j, k)
    return out


@for_each_dimension
def pressure_share_sum(d, indptr, cols, position, pressure, share, radius, n_rows):
    """``sum_j (P_i + P_j) r_ij w / |r_ij|^2`` over the neighbours j in ``share`` (a mask over
    the columns): the part of each row's gradient sum those neighbours exert, in the
    symmetric pair form, whose pair forces are equal and opposite. On a full neighbourhood
    it sums to the gradient's (``2 P_i sum_j r_ij w / r^2`` vanishes there), and across a
    plane of uniform pressure P it gives P on the plane's area: the minimum-pressure form's
    ``P_j - Pmin_i`` splits no force by neighbour, and ``P_j`` alone gives half of it."""
    out = np.zeros((n_rows, d))
    for i in range(n_rows):
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not share[j]:
                continue
            r2 = pair_distance2(position, i, j, d)
            w = weight_of_r2(r2, radius)
            if w > 0.0:
                factor = (pressure[i] + pressure[j]) * w / r2
                for k in range(d):
                    out[i, k] += factor * pair_component(position, i, j, k)
    return out


@numba.njit(cache=True, inline="always")
def _moment_matrix(indptr, cols, position, has_pressure, radius, scale, i, a, d):
    """Row i's moment matrix ``A_i = scale sum_j r_ij (x) r_ij w_ij / r_ij^2`` over its
    neighbours with a pressure, into ``a`` (d×d): the identity on the full lattice with
    scale = d/n0."""
    for k in range(d):
        for m in range(d):
            a[k, m] = 0.0
    for p in range(indptr[i], indptr[i + 1]):
        j = cols[p]
        if not has_pressure[j]:
            continue
        r2 = pair_distance2(position, i, j, d)
        w = weight_of_r2(r2, radius)
        if w > 0.0:
            _add_moment(a, position, i, j, w, r2, d)
    _scale_moment(a, scale, d)


@numba.njit(cache=True, inline="always")
def _add_moment(a, position, i, j, w, r2, d):
    """Pair (i, j)'s term r_ij (x) r_ij w / r^2 added to the upper triangle of ``a``."""
    for k in range(d):
        for m in range(k, d):
            a[k, m] += pair_component(position, i, j, k) * \
                pair_component(position, i, j, m) * w / r2


@numba.njit(cache=True, inline="always")
def _scale_moment(a, scale, d):
    """The summed upper triangle of ``a`` times ``scale``, mirrored to the lower."""
    for k in range(d):
        for m in range(k, d):
            a[k, m] *= scale
            a[m, k] = a[k, m]


@numba.njit(cache=True, inline="always")
def _correct_row(a, work, gradient, i, min_eigenvalue, d):
    """Row i of ``gradient`` times A^-1 (``a``, its moment matrix), unless A has an eigenvalue
    below ``min_eigenvalue``; whether it was corrected. ``work`` is d×d scratch."""
    if d == 2:
        trace = a[0, 0] + a[1, 1]
        det = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
        smallest = 0.5 * trace - np.sqrt(max(0.25 * trace * trace - det, 0.0))
        if smallest < min_eigenvalue:
            return False
        g0 = gradient[i, 0]
        g1 = gradient[i, 1]
        gradient[i, 0] = (a[1, 1] * g0 - a[0, 1] * g1) / det
        gradient[i, 1] = (a[0, 0] * g1 - a[0, 1] * g0) / det
        return True
    if has_eigenvalue_below(a, min_eigenvalue, work):
        return False
    # A^-1 g by the adjugate (A is symmetric, and so are its cofactors).
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c01 = a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]
    c02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]
    c12 = a[0, 1] * a[0, 2] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    g0 = gradient[i, 0]
    g1 = gradient[i, 1]
    g2 = gradient[i, 2]
    gradient[i, 0] = (c00 * g0 + c01 * g1 + c02 * g2) / det
    gradient[i, 1] = (c01 * g0 + c11 * g1 + c12 * g2) / det
    gradient[i, 2] = (c02 * g0 + c12 * g1 + c22 * g2) / det
    return True


@for_each_dimension
def correct_gradient(d, indptr, cols, position, has_pressure, radius, scale, gradient,
                     min_eigenvalue, rows=None):
    """Apply the corrective matrix to MPS pressure gradients, in place.

    ``gradient`` holds d/n0 sum_j (P_j - Pmin_i) r_ij w / r^2 per row and
    ``scale`` is d/n0. With A_i = d/n0 sum_j r_ij (x) r_ij w / r^2 over the same
    neighbours (those that carry a pressure), which is the identity on the full
    initial lattice, the row becomes A_i^-1 times itself (Khayyer & Gotoh 2011's
    gradient correction): exact for a linear field on any particle arrangement
    for the sum over P_j - P_i; the Pmin shift's part (P_i - Pmin_i) d/n0
    sum_j r_ij w / r^2 is only rescaled. Rows whose A_i has an eigenvalue below
    ``min_eigenvalue`` (a truncated neighbourhood at a free surface or in a
    splash) are left as they are. Returns how many rows were corrected. A_i is d×d:
    in 2D its eigenvalue and inverse in closed form; in 3D the test by the pivots of
    A_i - min_eigenvalue I (:func:`has_eigenvalue_below`) and the inverse by the
    adjugate. ``rows``: optional mask of the rows to correct.
    """
    a = np.empty((d, d))
    work = np.empty((d, d))
    n_rows = gradient.shape[0]
    corrected = 0
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        _moment_matrix(indptr, cols, position, has_pressure, radius, scale, i, a, d)
        if _correct_row(a, work, gradient, i, min_eigenvalue, d):
            corrected += 1
    return corrected


@for_each_dimension
def corrected_pressure_gradient(d, indptr, cols, position, pressure, has_pressure, radius,
                                scale, n_rows, min_eigenvalue, rows=None, surface_rows=None,
                                normal=None, surface_limit=0.0):
    """The corrected pressure gradient of the rows [0, n_rows) in one pass over each row's
    pairs: ``scale`` times :func:`pressure_gradient_sum`, then corrected by
    :func:`correct_normal_component` on the ``surface_rows`` (along ``normal``, down to
    ``surface_limit``) and by :func:`correct_gradient` on the others (down to
    ``min_eigenvalue``), bit for bit what the three give in turn, without reading the pairs
    twice more for the moment matrices (in 3D the correction's pass cost more than the
    gradient's). ``rows``: optional mask of the rows wanted, the others 0."""
    out = np.zeros((n_rows, d))
    a = np.empty((d, d))
    work = np.empty((d, d))
    radius2 = radius * radius
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        minimum = _row_pressure_minimum(indptr, cols, position, pressure, has_pressure, radius2,
                                        i, d)
        for k in range(d):
            for m in range(d):
                a[k, m] = 0.0
        # The gradient's sum and the moment matrix in one pass over the pairs, each term
        # as pressure_gradient_sum and _moment_matrix write it (the same sums, bit for bit).
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not has_pressure[j]:
                continue
            r2 = pair_distance2(position, i, j, d)
            w = weight_of_r2(r2, radius)
            if w > 0.0:
                factor = (pressure[j] - minimum) * w / r2
                for k in range(d):
                    out[i, k] += factor * pair_component(position, i, j, k)
                _add_moment(a, position, i, j, w, r2, d)
        for k in range(d):
            out[i, k] = scale * out[i, k]
        _scale_moment(a, scale, d)
        if surface_rows is not None and surface_rows[i]:
            _correct_row_along(a, out, normal, i, surface_limit, d)
        else:
            _correct_row(a, work, out, i, min_eigenvalue, d)
    return out


@numba.njit(cache=True, inline="always")
def _correct_row_along(a, gradient, normal, i, min_eigenvalue, d):
    """Row i of ``gradient`` corrected along its ``normal`` by n . A n (``a``, its moment
    matrix: :func:`correct_normal_component`); whether it was. A row without a normal, or
    whose n . A n is below ``min_eigenvalue`` or at least 1, is left as it is."""
    length = row_length(normal, i, d)
    if length <= 0.0:
        return False
    # n . A_i n, the moment matrix along the normal.
    along = 0.0
    for k in range(d):
        for m in range(d):
            along += normal[i, k] * a[k, m] * normal[i, m]
    along /= length * length
    if along < min_eigenvalue or along >= 1.0:
        return False
    component = 0.0
    for k in range(d):
        component += gradient[i, k] * normal[i, k]
    factor = (1.0 / along - 1.0) * component / (length * length)
    for k in range(d):
        gradient[i, k] += factor * normal[i, k]
    return True


@for_each_dimension
def correct_normal_component(d, indptr, cols, position, has_pressure, radius, scale, gradient,
                             normal, min_eigenvalue, rows):
    """Correct the gradient of the ``rows`` (a mask) along their ``normal`` only, in place.

    ``gradient`` is as for :func:`correct_gradient`. With ``a_n = n . A_i n`` (A_i
    its moment matrix, n the unit normal), the component along n is divided by
    a_n and the rest is left alone: ``g + (1/a_n - 1)(g . n) n``. On a flat free
    surface A_i is diagonal in the surface's frame, with a_n = 0.5 and 1 along
    it, so this is A_i^-1 g exactly; on a splash or a jet's tip, where A_i has
    no full direction and its inverse would turn a strong gradient along the
    flow towards a wall, it only scales the part towards the air. Rows with a_n
    below ``min_eigenvalue`` or at least 1, or without a normal, are left as
    they are. Returns how many rows were corrected.
    """
    a = np.empty((d, d))
    corrected = 0
    for i in range(gradient.shape[0]):
        if not rows[i]:
            continue
        if row_length(normal, i, d) <= 0.0:
            continue
        _moment_matrix(indptr, cols, position, has_pressure, radius, scale, i, a, d)
        if _correct_row_along(a, gradient, normal, i, min_eigenvalue, d):
            corrected += 1
    return corrected

