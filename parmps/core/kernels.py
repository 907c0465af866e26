"""Compiled pair loops for the fluid step, in d = 2 or 3 dimensions.

The same sums as :mod:`parmps.core.operators`, computed row by row over the CSR
neighbour lists with distances evaluated on the fly. In numpy each operator
gathers and masks every pair (about 1.7 M at 40k particles) several times; here
each pair is visited once per operator and nothing is allocated per pair. The
numpy operators stay as the reference the tests compare these against.

Positions and vector fields are (N, d) arrays; d is ``position.shape[1]``.

How the loops are written:

* Every pair is visited through one prologue, :func:`pair_distance2` (|r_ij|^2)
  and :func:`pair_component` (component k of r_ij = x_j - x_i). Component sums run
  over k = 0, 1, ... in order, so in 2D every result is bit for bit what the
  former explicit x/y code gave (0.0 + a + b == a + b; no dot products, no
  sqrt-then-square).
* Each public kernel is a stub that calls its body (``_name``, inlined) with d
  as a literal 2 or 3, so numba compiles one copy per dimension in which the
  component loops have a constant trip count and unroll: with d read at run
  time inside the pair loop the kernels were 15-20 % slower.
"""

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _weight(distance, radius):
    if distance <= 0.0 or distance >= radius:
        return 0.0
    return radius / distance - 1.0


# A relative margin on r^2 for cuts made before the square root (pairs_within, and
# _weight_of_r2's early exit): a kernel tests its radius as sqrt(r^2) < radius or
# r^2 < radius^2, which can disagree in the last bit, so a cut this much wider keeps
# every pair any kernel would weigh, and their sums stay bit for bit the same.
PAIRS_WITHIN_MARGIN = 1e-12


@numba.njit(cache=True, inline="always")
def _weight_of_r2(r2, radius):
    """_weight(sqrt(r2), radius), without the square root for pairs clearly outside."""
    if r2 >= radius * radius * (1.0 + PAIRS_WITHIN_MARGIN):
        return 0.0
    return _weight(np.sqrt(r2), radius)


@numba.njit(cache=True, inline="always")
def pair_distance2(position, i, j, d):
    """|r_ij|^2 for r_ij = x_j - x_i, summed over the d components in order."""
    r2 = 0.0
    for k in range(d):
        delta = position[j, k] - position[i, k]
        r2 += delta * delta
    return r2


@numba.njit(cache=True, inline="always")
def pair_component(position, i, j, k):
    """Component k of r_ij = x_j - x_i (the very value :func:`pair_distance2` squares)."""
    return position[j, k] - position[i, k]


@numba.njit(cache=True)
def _check_dimension(d):
    if d != 2 and d != 3:
        raise ValueError("parmps kernels: positions must have 2 or 3 components")


# --- number density ---------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _number_density(indptr, cols, position, radius, n_rows, d):
    density = np.zeros(n_rows)
    count = np.zeros(n_rows, np.int64)
    for i in range(n_rows):
        total = 0.0
        within = 0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = _weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                total += w
                within += 1
        density[i] = total
        count[i] = within
    return density, count


@numba.njit(cache=True)
def number_density(indptr, cols, position, radius, n_rows):
    """n_i = sum_j w(r_ij) and the count of neighbours within ``radius``."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _number_density(indptr, cols, position, radius, n_rows, 2)
    return _number_density(indptr, cols, position, radius, n_rows, 3)


@numba.njit(cache=True, inline="always")
def wendland(q):
    """Wendland's C2 function (1 - q)^4 (1 + 4q) of q = r / support, 0 from q = 1 on:
    smooth and finite at r = 0 (the density measure of the sources, the probes' weight)."""
    if q >= 1.0:
        return 0.0
    a = 1.0 - q
    return a * a * a * a * (1.0 + 4.0 * q)


@numba.njit(cache=True, inline="always")
def _smooth_weight_of_r2(r2, support):
    if r2 >= support * support:
        return 0.0
    return wendland(np.sqrt(r2) / support)


@numba.njit(cache=True, inline="always")
def _smooth_density(indptr, cols, position, support, n_rows, d):
    density = np.ones(n_rows)  # each particle's own weight, W(0) = 1
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += _smooth_weight_of_r2(pair_distance2(position, i, cols[p], d), support)
        density[i] += total
    return density


@numba.njit(cache=True)
def smooth_density(indptr, cols, position, support, n_rows):
    """sum_j W(r_ij) over j and i itself, W Wendland's C2 function of radius ``support``."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _smooth_density(indptr, cols, position, support, n_rows, 2)
    return _smooth_density(indptr, cols, position, support, n_rows, 3)


@numba.njit(cache=True, inline="always")
def _concentration_gradient(indptr, cols, position, support, rows, n_rows, d):
    gradient = np.zeros((n_rows, d))
    inverse_square = 1.0 / (support * support)
    for i in range(n_rows):
        if not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            if r2 >= support * support:
                continue
            # grad_i W(|x_i - x_j| / s) = 20 (1 - q)^3 r_ij / s^2 for Wendland's C2
            # function (r_ij = x_j - x_i): no 1/r, so coincident pairs are harmless.
            a = 1.0 - np.sqrt(r2) / support
            factor = 20.0 * a * a * a * inverse_square
            for k in range(d):
                gradient[i, k] += factor * pair_component(position, i, j, k)
    return gradient


@numba.njit(cache=True)
def concentration_gradient(indptr, cols, position, support, rows, n_rows):
    """``grad_i sum_j W(r_ij)`` of the rows in ``rows`` (0 for the others), W Wendland's C2
    function of radius ``support``: the gradient of :func:`smooth_density`, which points
    to where the neighbours crowd."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _concentration_gradient(indptr, cols, position, support, rows, n_rows, 2)
    return _concentration_gradient(indptr, cols, position, support, rows, n_rows, 3)


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


# --- pairs within a smaller radius ------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _pairs_within(indptr, cols, position, radius, n_rows, near_indptr, near_cols, d):
    """Fills ``near_indptr`` and as many pairs as ``near_cols`` has room for; returns how
    many pairs lie within ``radius`` (more than the room: the list is incomplete)."""
    limit2 = radius * radius * (1.0 + PAIRS_WITHIN_MARGIN)
    room = near_cols.shape[0]
    total = 0
    for i in range(n_rows):
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if pair_distance2(position, i, j, d) < limit2:
                if total < room:
                    near_cols[total] = j
                total += 1
        near_indptr[i + 1] = total
    return total


@numba.njit(cache=True)
def _pairs_within_into(indptr, cols, position, radius, n_rows, near_indptr, near_cols):
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _pairs_within(indptr, cols, position, radius, n_rows, near_indptr, near_cols, 2)
    return _pairs_within(indptr, cols, position, radius, n_rows, near_indptr, near_cols, 3)


def pairs_within(indptr, cols, position, radius, n_rows, expected_pairs=None, dtype=np.int64):
    """The sub-list of the CSR pair list (rows [0, n_rows)) whose pairs lie within
    ``radius`` at ``position``, in the same order.

    The search radius covers the Laplacian's radius plus a skin, so at the defaults it
    holds twice the pairs within 2.3 l0 in 3D (2.9 l0 against 2.3), and in 2D 1.4 times
    those within 3.1 l0 and 2.6 times those within 2.3 (3.7 l0): the operators on a
    smaller radius visit that share of the pairs over the sub-list and give bit for bit
    the same sums.

    ``expected_pairs``: room to fill in one pass (a little more than the last step's
    count, say); the cut runs again only when the pairs overflow it, and the result is
    the same either way. None: room for the whole list, the result copied to its size
    (a transient of the whole list's size: in 3D a step's largest). ``dtype``: the
    sub-list's index type (32 bits halve it where the particles' count allows).
    """
    near_indptr = np.zeros(n_rows + 1, np.int64)
    room = int(indptr[n_rows]) if expected_pairs is None else max(int(expected_pairs), 0)
    near_cols = np.empty(room, dtype)
    total = _pairs_within_into(indptr, cols, position, radius, n_rows, near_indptr, near_cols)
    if total > room:
        near_cols = np.empty(total, dtype)
        _pairs_within_into(indptr, cols, position, radius, n_rows, near_indptr, near_cols)
    if expected_pairs is None:
        return near_indptr, near_cols[:total].copy()
    return near_indptr, near_cols[:total]


# --- viscous term -----------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _vector_laplacian_sum(indptr, cols, position, field, radius, n_rows, rows, d):
    out = np.zeros((n_rows, d))
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = _weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                for k in range(d):
                    out[i, k] += (field[j, k] - field[i, k]) * w
    return out


@numba.njit(cache=True)
def vector_laplacian_sum(indptr, cols, position, field, radius, n_rows, rows=None):
    """sum_j (u_j - u_i) w(r_ij) for an N×d field (times 2d/(lambda0 n0) gives the Laplacian).

    ``rows``: optional mask of the rows wanted; the others are left 0 (walls do not move).
    """
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _vector_laplacian_sum(indptr, cols, position, field, radius, n_rows, rows, 2)
    return _vector_laplacian_sum(indptr, cols, position, field, radius, n_rows, rows, 3)


@numba.njit(cache=True, inline="always")
def _fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid, rows, d):
    out = np.zeros((n_rows, d))
    weights = np.zeros(n_rows)
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not is_fluid[j]:
                continue
            w = _weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w > 0.0:
                weights[i] += w
                for k in range(d):
                    out[i, k] += (velocity[j, k] - velocity[i, k]) * w
    return out, weights


@numba.njit(cache=True)
def fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid, rows=None):
    """``(sum_j (u_j - u_i) w_ij, sum_j w_ij)`` over the fluid neighbours j of the rows
    ``n_rows`` (those ``rows`` selects; the others 0): what the no-slip wall's viscous force
    on a wall, body or node particle is made of (:func:`no_slip_velocity`)."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid,
                               rows, 2)
    return _fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid, rows, 3)


@numba.njit(cache=True)
def no_slip_velocity(indptr, cols, position, velocity, radius, n_rows, is_fluid):
    """The velocity the viscous term sees at the rows ``n_rows``: a fluid particle's own; a
    wall's, dummy's or body node's ``2 u_i - <u>_i``, ``<u>_i`` the mean of its fluid
    neighbours' velocities weighted by w(r) (its own where it has none), so that the
    velocity extrapolated across the wall's surface meets the wall's there (Adami, Hu &
    Adams 2012's no-slip wall). From :func:`fluid_drag_sum`: ``2 u_i - <u>_i = u_i -
    sum_j w_ij (u_j - u_i) / sum_j w_ij``."""
    drag, weight = fluid_drag_sum(indptr, cols, position, velocity, radius, n_rows, is_fluid,
                                  ~is_fluid[:n_rows])
    out = velocity[:n_rows].copy()
    for i in range(n_rows):
        if weight[i] > 0.0:
            for k in range(out.shape[1]):
                out[i, k] -= drag[i, k] / weight[i]
    return out


# --- divergence -------------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _divergence_sum(indptr, cols, position, field, radius, n_rows, d):
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            w = _weight_of_r2(r2, radius)
            if w > 0.0:
                projected = 0.0
                for k in range(d):
                    projected += (field[j, k] - field[i, k]) * pair_component(position, i, j, k)
                total += projected * w / r2
        out[i] = total
    return out


@numba.njit(cache=True)
def divergence_sum(indptr, cols, position, field, radius, n_rows):
    """sum_j (u_j - u_i) . r_ij w / |r_ij|^2 (times d/n0 gives the divergence)."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _divergence_sum(indptr, cols, position, field, radius, n_rows, 2)
    return _divergence_sum(indptr, cols, position, field, radius, n_rows, 3)


@numba.njit(cache=True, inline="always")
def _missing_pair_flux(indptr, cols, position, vector, missing, radius, inverse_cube, n_rows, d):
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not missing[j]:
                continue
            w = _laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
            if w > 0.0:
                projected = 0.0
                for k in range(d):
                    projected += vector[k] * pair_component(position, i, j, k)
                total += w * projected
        out[i] = total
    return out


@numba.njit(cache=True)
def missing_pair_flux(indptr, cols, position, vector, missing, radius, inverse_cube, n_rows):
    """sum_j w_ij (a . r_ij) over the neighbours j flagged ``missing`` (0 < r < radius), w
    the Laplacian's weight (:func:`_laplacian_weight`): what those pairs would add to the
    Laplacian's sum of the linear field of gradient ``a`` (times the Laplacian's
    coefficient), the pairs the pressure matrix leaves out (dummies carry no pressure)."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _missing_pair_flux(indptr, cols, position, vector, missing, radius,
                                  inverse_cube, n_rows, 2)
    return _missing_pair_flux(indptr, cols, position, vector, missing, radius, inverse_cube,
                              n_rows, 3)


# --- pressure gradient ------------------------------------------------------------------------

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


@numba.njit(cache=True, inline="always")
def _pressure_gradient_sum(indptr, cols, position, pressure, has_pressure, radius, n_rows, rows,
                           d):
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
            w = _weight_of_r2(r2, radius)
            if w > 0.0:
                factor = (pressure[j] - minimum) * w / r2
                for k in range(d):
                    out[i, k] += factor * pair_component(position, i, j, k)
    return out


@numba.njit(cache=True)
def pressure_gradient_sum(indptr, cols, position, pressure, has_pressure, radius, n_rows,
                          rows=None):
    """sum_j (P_j - Pmin_i) r_ij w / |r_ij|^2 over neighbours that carry a pressure.

    Pmin_i is the minimum of P over i and those neighbours (times d/n0 gives the
    MPS pressure gradient). ``rows``: optional mask of the rows wanted; the others
    are left 0.
    """
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _pressure_gradient_sum(indptr, cols, position, pressure, has_pressure, radius,
                                      n_rows, rows, 2)
    return _pressure_gradient_sum(indptr, cols, position, pressure, has_pressure, radius,
                                  n_rows, rows, 3)


@numba.njit(cache=True, inline="always")
def _pressure_share_sum(indptr, cols, position, pressure, share, radius, n_rows, d):
    out = np.zeros((n_rows, d))
    for i in range(n_rows):
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not share[j]:
                continue
            r2 = pair_distance2(position, i, j, d)
            w = _weight_of_r2(r2, radius)
            if w > 0.0:
                factor = (pressure[i] + pressure[j]) * w / r2
                for k in range(d):
                    out[i, k] += factor * pair_component(position, i, j, k)
    return out


@numba.njit(cache=True)
def pressure_share_sum(indptr, cols, position, pressure, share, radius, n_rows):
    """``sum_j (P_i + P_j) r_ij w / |r_ij|^2`` over the neighbours j in ``share`` (a mask over
    the columns): the part of each row's gradient sum those neighbours exert, in the
    symmetric pair form, whose pair forces are equal and opposite. On a full neighbourhood
    it sums to the gradient's (``2 P_i sum_j r_ij w / r^2`` vanishes there), and across a
    plane of uniform pressure P it gives P on the plane's area: the minimum-pressure form's
    ``P_j - Pmin_i`` splits no force by neighbour, and ``P_j`` alone gives half of it."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _pressure_share_sum(indptr, cols, position, pressure, share, radius, n_rows, 2)
    return _pressure_share_sum(indptr, cols, position, pressure, share, radius, n_rows, 3)


# --- gradient correction ----------------------------------------------------------------------

@numba.njit(cache=True)
def _jacobi_diagonalise(work, vectors, accumulate):
    """Diagonalise the small symmetric ``work`` (d×d) in place by cyclic Jacobi rotations;
    with ``accumulate``, multiply each rotation into ``vectors`` (d×d), whose columns then
    hold the eigenvectors of the diagonal's eigenvalues if it started as the identity.

    Each rotation zeroes one off-diagonal pair; the sweeps converge quadratically and
    leave the eigenvalues on the diagonal to round-off of the largest, also where
    eigenvalues coincide (a closed form through arccos loses sqrt(eps) there, and A_i
    near the identity is the common case).
    """
    d = work.shape[0]
    for _ in range(50):
        off = 0.0
        scale = 0.0
        for k in range(d):
            scale += work[k, k] * work[k, k]
            for m in range(k + 1, d):
                off += work[k, m] * work[k, m]
        if off <= 1e-36 * (scale + off):
            break
        for p in range(d - 1):
            for q in range(p + 1, d):
                apq = work[p, q]
                if apq == 0.0:
                    continue
                # The rotation angle t = tan(phi) that zeroes work[p, q], the smaller root.
                theta = (work[q, q] - work[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(d):
                    if k != p and k != q:
                        akp = work[k, p]
                        akq = work[k, q]
                        work[k, p] = c * akp - s * akq
                        work[p, k] = work[k, p]
                        work[k, q] = s * akp + c * akq
                        work[q, k] = work[k, q]
                work[p, p] -= t * apq
                work[q, q] += t * apq
                work[p, q] = 0.0
                work[q, p] = 0.0
                if accumulate:
                    for k in range(d):
                        vkp = vectors[k, p]
                        vkq = vectors[k, q]
                        vectors[k, p] = c * vkp - s * vkq
                        vectors[k, q] = s * vkp + c * vkq


@numba.njit(cache=True)
def _has_eigenvalue_below(a, limit, work):
    """Whether the symmetric ``a`` (small, d×d) has an eigenvalue below ``limit``: whether
    ``a - limit I`` fails to be positive semi-definite, told by the pivots of its symmetric
    elimination (all of them >= 0, a zero pivot's column below it zero, if and only if it
    is). A few flops where the smallest eigenvalue by Jacobi rotations took some 40 % of
    the corrected gradient in 3D. ``work`` is d×d scratch."""
    d = a.shape[0]
    for k in range(d):
        for m in range(d):
            work[k, m] = a[k, m]
        work[k, k] -= limit
    for k in range(d):
        pivot = work[k, k]
        if pivot < 0.0:
            return True
        if pivot == 0.0:
            for m in range(k + 1, d):
                if work[m, k] != 0.0:
                    return True
            continue
        for m in range(k + 1, d):
            factor = work[m, k] / pivot
            for q in range(k + 1, d):
                work[m, q] -= factor * work[k, q]
    return False


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
        w = _weight_of_r2(r2, radius)
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
    if _has_eigenvalue_below(a, min_eigenvalue, work):
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


@numba.njit(cache=True, inline="always")
def _correct_gradient(indptr, cols, position, has_pressure, radius, scale, gradient,
                      min_eigenvalue, rows, d):
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


@numba.njit(cache=True)
def correct_gradient(indptr, cols, position, has_pressure, radius, scale, gradient,
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
    A_i - min_eigenvalue I (:func:`_has_eigenvalue_below`) and the inverse by the
    adjugate. ``rows``: optional mask of the rows to correct.
    """
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _correct_gradient(indptr, cols, position, has_pressure, radius, scale,
                                 gradient, min_eigenvalue, rows, 2)
    return _correct_gradient(indptr, cols, position, has_pressure, radius, scale,
                             gradient, min_eigenvalue, rows, 3)


@numba.njit(cache=True, inline="always")
def _corrected_pressure_gradient(indptr, cols, position, pressure, has_pressure, radius, scale,
                                 n_rows, min_eigenvalue, rows, surface_rows, normal,
                                 surface_limit, d):
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
            w = _weight_of_r2(r2, radius)
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


@numba.njit(cache=True)
def corrected_pressure_gradient(indptr, cols, position, pressure, has_pressure, radius, scale,
                                n_rows, min_eigenvalue, rows=None, surface_rows=None,
                                normal=None, surface_limit=0.0):
    """The corrected pressure gradient of the rows [0, n_rows) in one pass over each row's
    pairs: ``scale`` times :func:`pressure_gradient_sum`, then corrected by
    :func:`correct_normal_component` on the ``surface_rows`` (along ``normal``, down to
    ``surface_limit``) and by :func:`correct_gradient` on the others (down to
    ``min_eigenvalue``), bit for bit what the three give in turn, without reading the pairs
    twice more for the moment matrices (in 3D the correction's pass cost more than the
    gradient's). ``rows``: optional mask of the rows wanted, the others 0."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _corrected_pressure_gradient(indptr, cols, position, pressure, has_pressure,
                                            radius, scale, n_rows, min_eigenvalue, rows,
                                            surface_rows, normal, surface_limit, 2)
    return _corrected_pressure_gradient(indptr, cols, position, pressure, has_pressure, radius,
                                        scale, n_rows, min_eigenvalue, rows, surface_rows,
                                        normal, surface_limit, 3)


@numba.njit(cache=True, inline="always")
def _row_length(vectors, i, d):
    """The Euclidean length of row i of ``vectors`` (its first d components)."""
    total = 0.0
    for k in range(d):
        total += vectors[i, k] * vectors[i, k]
    return np.sqrt(total)


@numba.njit(cache=True, inline="always")
def _correct_normal_component(indptr, cols, position, has_pressure, radius, scale, gradient,
                              normal, min_eigenvalue, rows, d):
    a = np.empty((d, d))
    corrected = 0
    for i in range(gradient.shape[0]):
        if not rows[i]:
            continue
        if _row_length(normal, i, d) <= 0.0:
            continue
        _moment_matrix(indptr, cols, position, has_pressure, radius, scale, i, a, d)
        if _correct_row_along(a, gradient, normal, i, min_eigenvalue, d):
            corrected += 1
    return corrected


@numba.njit(cache=True, inline="always")
def _correct_row_along(a, gradient, normal, i, min_eigenvalue, d):
    """Row i of ``gradient`` corrected along its ``normal`` by n . A n (``a``, its moment
    matrix: :func:`correct_normal_component`); whether it was. A row without a normal, or
    whose n . A n is below ``min_eigenvalue`` or at least 1, is left as it is."""
    length = _row_length(normal, i, d)
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


@numba.njit(cache=True)
def correct_normal_component(indptr, cols, position, has_pressure, radius, scale, gradient,
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
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _correct_normal_component(indptr, cols, position, has_pressure, radius, scale,
                                         gradient, normal, min_eigenvalue, rows, 2)
    return _correct_normal_component(indptr, cols, position, has_pressure, radius, scale,
                                     gradient, normal, min_eigenvalue, rows, 3)


# --- collisions -------------------------------------------------------------------------------

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
def _collision_change(indptr, cols, position, velocity, moving, distance_limit, restitution,
                      n_rows, d, start):
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


@numba.njit(cache=True)
def collision_change(indptr, cols, position, velocity, moving, distance_limit, restitution,
                     n_rows, start):
    """Velocity changes of moving particles from collisions closer than ``distance_limit``
    at ``position`` (the predicted positions).

    Uses pre-collision velocities only, so the result is independent of pair order:
    two moving particles share the impulse; the fixed partners within reach act as one
    infinitely heavy wall along the normal of the fixed partners around the particle at
    ``start`` (the positions at the start of the step; ``position`` again for a static
    check).
    """
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _collision_change(indptr, cols, position, velocity, moving, distance_limit,
                                 restitution, n_rows, 2, start)
    return _collision_change(indptr, cols, position, velocity, moving, distance_limit,
                             restitution, n_rows, 3, start)


@numba.njit(cache=True, inline="always")
def _stabilisation_change(indptr, cols, position, velocity, moving, fixed, distance,
                          separation, dt, n_rows, d):
    out = np.zeros((n_rows, d))
    limit2 = distance * distance
    for i in range(n_rows):
        if not moving[i]:
            continue
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not (moving[j] or fixed[j]):
                continue
            r2 = pair_distance2(position, i, j, d)
            if r2 >= limit2 or r2 <= 0.0:
                continue
            r = np.sqrt(r2)
            # w: the pair's separation speed along e = r_ij / r; wanted: enough to be
            # ``separation`` of the way back to ``distance`` by the end of the next step.
            w = 0.0
            for k in range(d):
                w += (velocity[j, k] - velocity[i, k]) * (pair_component(position, i, j, k) / r)
            change = separation * (distance - r) / dt - w
            if change <= 0.0:
                continue
            # Two moving particles share the change (equal masses: momentum kept); a
            # fixed partner is infinitely heavy and i takes all of it.
            share = 0.5 if moving[j] else 1.0
            for k in range(d):
                out[i, k] -= share * change * (pair_component(position, i, j, k) / r)
    return out


def stabilisation_change(indptr, cols, position, velocity, moving, fixed, distance,
                         separation, dt, n_rows):
    """Velocity changes of the moving rows [0, n_rows) from the pairs closer than
    ``distance`` at ``position`` with a moving or a ``fixed`` partner (others are left
    out): each such pair whose separation speed along its line is
    below ``separation (distance - r) / dt`` is given that speed, shared equally between two
    moving particles (their momentum is kept), taken whole by a moving particle from a fixed
    partner. ``separation`` = 0 only stops the approach (no pair gains kinetic energy).
    Uses the velocities before any change, so the result is independent of pair order."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _stabilisation_change(indptr, cols, position, velocity, moving, fixed,
                                     distance, separation, dt, n_rows, 2)
    return _stabilisation_change(indptr, cols, position, velocity, moving, fixed, distance,
                                 separation, dt, n_rows, 3)


# A row of the pressure matrix that is an unknown free-surface particle (is_unknown's value).
SURFACE_ROW = 2


# --- pressure matrix --------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _laplacian_weight(r2, radius, inverse_cube):
    # The standard MPS weight re/r - 1, or Khayyer & Gotoh's (2010) higher-order
    # one re/r^3, for 0 < r < re; 0 outside.
    if r2 <= 0.0 or r2 >= radius * radius:
        return 0.0
    if inverse_cube:
        return radius / (r2 * np.sqrt(r2))
    return radius / np.sqrt(r2) - 1.0


@numba.njit(cache=True, inline="always")
def _pressure_rows(row_number, n_owned):
    """How many of the owned particles have a row (a row number >= 0)."""
    rows = 0
    for i in range(n_owned):
        if row_number[i] >= 0:
            rows += 1
    return rows


@numba.njit(cache=True)
def rows_in_index_order(row_number, n_owned):
    """The owned particles with a row (a row number >= 0), in ascending index: the row
    order of :func:`poisson_rows` when the row numbers ascend with the index."""
    return np.flatnonzero(row_number[:n_owned] >= 0)


@numba.njit(cache=True, inline="always")
def _poisson_rows(indptr, cols, position, radius, row_number, is_unknown, coefficient,
                  diagonal_shift, dirichlet_diagonal, inverse_cube, mobility, d, columns, values,
                  other_columns, other_values, row_order, split):
    """The rows of the particles ``row_order`` into the caller's room, in that order.

    The rank's rows are ``row_number[row_order[0]]`` (``first``) on. With ``split``, a
    column of the rank's rows goes into ``columns``/``values`` numbered from ``first``
    (local) and any other into ``other_columns``/``other_values`` (global): the two blocks
    PETSc takes as they are. Without, every entry goes into the first, global.
    Returns (row pointers of each block, where each row's diagonal is in the first,
    entries written in each), with -1 for the entries when a room is too small. The
    diagonal goes before the row's first column of the rank's rows above its own, so a
    row whose columns come ascending stays so."""
    n_rows = row_order.shape[0]
    room, other_room = columns.shape[0], other_columns.shape[0]
    row_ptr = np.zeros(n_rows + 1, np.int64)
    other_ptr = np.zeros(n_rows + 1, np.int64)
    diagonal_at = np.empty(n_rows, np.int64)
    first = row_number[row_order[0]] if n_rows > 0 else 0
    last = first + n_rows
    offset = first if split else 0
    place = 0
    other = 0
    # The room checks are written out at each entry: a helper for them, inlined, made the
    # kernel 18 % slower (3D, 18 M pairs).
    for r in range(n_rows):
        i = row_order[r]
        own = row_number[i]
        if not is_unknown[i]:
            if place >= room:
                return row_ptr, other_ptr, diagonal_at, -1, -1
            columns[place] = own - offset
            values[place] = dirichlet_diagonal
            diagonal_at[r] = place
            place += 1
            row_ptr[r + 1] = place
            other_ptr[r + 1] = other
            continue
        diagonal = diagonal_shift
        at = -1
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if row_number[j] < 0:
                continue
            w = _laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
            if w <= 0.0:
                continue
            # Mobility 1 for both (one density) gives exactly coefficient * w.
            pair = coefficient * w * (0.5 * (mobility[i] + mobility[j]))
            diagonal += pair
            if not is_unknown[j]:
                continue
            column = row_number[j]
            if split and (column < first or column >= last):
                if other >= other_room:
                    return row_ptr, other_ptr, diagonal_at, -1, -1
                other_columns[other] = column
                other_values[other] = -pair
                other += 1
                continue
            if at < 0 and own < column < last:
                if place >= room:
                    return row_ptr, other_ptr, diagonal_at, -1, -1
                at = place
                columns[place] = own - offset
                place += 1
            if place >= room:
                return row_ptr, other_ptr, diagonal_at, -1, -1
            columns[place] = column - offset
            values[place] = -pair
            place += 1
        if at < 0:
            if place >= room:
                return row_ptr, other_ptr, diagonal_at, -1, -1
            at = place
            columns[place] = own - offset
            place += 1
        values[at] = diagonal
        diagonal_at[r] = at
        row_ptr[r + 1] = place
        other_ptr[r + 1] = other
    return row_ptr, other_ptr, diagonal_at, place, other


@numba.njit(cache=True)
def poisson_rows_into(indptr, cols, position, radius, row_number, is_unknown, coefficient,
                      diagonal_shift, dirichlet_diagonal, inverse_cube, mobility, columns,
                      values, other_columns, other_values, row_order, split=True):
    """:func:`variable_density_poisson_rows` into the caller's room, in two blocks: the
    columns of this rank's rows, numbered from its first (``columns``/``values``), and the
    other ranks' columns, global (``other_columns``/``other_values``), or with ``split``
    false every entry in the first, global. The columns may be of any integer type
    (PETSc's, so that the matrix takes them without a copy). Returns (row pointers of
    each block, each row's diagonal's place in the first, entries written in each), the
    entries -1 when a room is too small (see :func:`poisson_rows_room`).

    Why a room: the one-pass assembly into room for every pair of the list held 1.8 times
    the matrix's entries, and the matrix kept that room alive as long as it lived (3D,
    3.1 l0: 8.2 M pairs for 4.6 M entries at 100k particles). Why two blocks: PETSc takes
    a distributed matrix's as they are (``MatCreateMPIAIJWithSplitArrays``); splitting the
    rows afterwards cost a pass over every entry and a second copy of them (35 ms a step
    a rank at 8.5 M entries on two ranks, 3D).

    ``row_order``: the owned particles with a row, in the order of their row numbers
    (``row_number[row_order]`` ascends by one). Numbered in the neighbour search's cell
    order, a row's columns come out ascending, its diagonal in its place
    (:func:`parmps.core.neighbours.pair_list`, ``cell_order``)."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _poisson_rows(indptr, cols, position, radius, row_number, is_unknown,
                             coefficient, diagonal_shift, dirichlet_diagonal, inverse_cube,
                             mobility, 2, columns, values, other_columns, other_values,
                             row_order, split)
    return _poisson_rows(indptr, cols, position, radius, row_number, is_unknown, coefficient,
                         diagonal_shift, dirichlet_diagonal, inverse_cube, mobility, 3,
                         columns, values, other_columns, other_values, row_order, split)


@numba.njit(cache=True)
def poisson_rows_room(indptr, cols, row_number):
    """Entries each block of :func:`poisson_rows_into` (split) can hold at most: this
    rank's, every pair with a particle of this rank's rows and a diagonal a row; the other
    ranks', every other pair. A ghost may carry one of this rank's rows: a periodic image
    of an owned particle."""
    n_owned = indptr.shape[0] - 1
    first, last = _owned_row_range(row_number, n_owned)
    to_others = 0
    for p in range(indptr[n_owned]):
        j = cols[p]
        if j >= n_owned and (row_number[j] < first or row_number[j] > last):
            to_others += 1
    return indptr[n_owned] - to_others + _pressure_rows(row_number, n_owned), to_others


@numba.njit(cache=True)
def _owned_row_range(row_number, n_owned):
    """The smallest and the largest row number of the owned particles (0, -1 if none)."""
    first, last = 0, -1
    for i in range(n_owned):
        r = row_number[i]
        if r >= 0:
            if last < first:
                first, last = r, r
            else:
                first, last = min(first, r), max(last, r)
    return first, last


@numba.njit(cache=True)
def poisson_rows(indptr, cols, position, radius, row_number, is_unknown, coefficient,
                 diagonal_shift, dirichlet_diagonal, inverse_cube):
    """CSR rows of the pressure Poisson matrix, one per owned particle with a pressure.

    ``row_number`` is the global row of every local particle (-1 for dummies,
    which carry no pressure); ``is_unknown`` is false for free-surface
    (Dirichlet) particles. An unknown row i has the diagonal a sum_j w_ij + shift
    over neighbours j with a pressure, and -a w_ij where j is an unknown too: a
    Dirichlet neighbour has P_j = 0 and adds to the diagonal only. A Dirichlet
    row is ``dirichlet_diagonal`` * P_i = 0, decoupled, so the matrix keeps one
    size while particles reach and leave the surface and a preconditioner can
    be reused across steps. The diagonal goes before the row's first column of this
    rank above it. The weight is the standard MPS weight w_ij = re/r - 1, or with
    ``inverse_cube`` Khayyer & Gotoh's higher-order Laplacian weight re/r^3
    (docs/schemes.md, HL); both keep the pairs with 0 < r < re, so the sparsity is the
    same.
    """
    return variable_density_poisson_rows(indptr, cols, position, radius, row_number,
                                         is_unknown, coefficient, diagonal_shift,
                                         dirichlet_diagonal, inverse_cube,
                                         np.ones(len(row_number)))


@numba.njit(cache=True)
def variable_density_poisson_rows(indptr, cols, position, radius, row_number, is_unknown,
                                  coefficient, diagonal_shift, dirichlet_diagonal, inverse_cube,
                                  mobility):
    """:func:`poisson_rows` of ``div (rho0/rho grad P)``: pair ij weighs a w_ij m_ij.

    ``mobility`` is rho0/rho_i of every local particle (owned and ghosts), rho0
    the density ``coefficient`` and the source were made with, and
    m_ij = (m_i + m_j)/2 the arithmetic mean of 1/rho: the pressure difference
    of a pair accelerates i by 1/rho_i and j by 1/rho_j, so their separation
    changes with the sum. Symmetric, because m_ij is; with every m_i = 1 it is
    :func:`poisson_rows` exactly.
    """
    room = indptr[indptr.shape[0] - 1] + _pressure_rows(row_number, indptr.shape[0] - 1)
    columns = np.empty(room, np.int64)
    values = np.empty(room)
    row_ptr, _, _, place, _ = poisson_rows_into(
        indptr, cols, position, radius, row_number, is_unknown, coefficient, diagonal_shift,
        dirichlet_diagonal, inverse_cube, mobility, columns, values, columns[:0], values[:0],
        rows_in_index_order(row_number, indptr.shape[0] - 1), False)
    return row_ptr, columns[:place], values[:place]


@numba.njit(cache=True, inline="always")
def _surface_normals(indptr, cols, position, is_surface, radius, n_rows, d):
    normal = np.zeros((n_rows, d))
    for i in range(n_rows):
        # Most rows are deep in the water: find that out from the few surface particles
        # before summing over every pair.
        near_surface = is_surface[i]
        if not near_surface:
            for p in range(indptr[i], indptr[i + 1]):
                j = cols[p]
                if is_surface[j] and _weight_of_r2(pair_distance2(position, i, j, d),
                                                   radius) > 0.0:
                    near_surface = True
                    break
        if not near_surface:
            continue
        size = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            w = _weight_of_r2(r2, radius)
            if w <= 0.0:
                continue
            size += w * np.sqrt(r2)
            for k in range(d):
                normal[i, k] -= w * pair_component(position, i, j, k)
        # A full neighbourhood's sum is rounding error, not a direction.
        if _row_length(normal, i, d) <= 1e-9 * size:
            for k in range(d):
                normal[i, k] = 0.0
    return normal


@numba.njit(cache=True)
def surface_normals(indptr, cols, position, is_surface, radius, n_rows):
    """``-sum_j w_ij r_ij`` over every neighbour (dummies too) of the rows with a free-surface
    particle (``is_surface``, every local particle) in their support or one themselves,
    0 elsewhere: it points away from the neighbours present, to where the missing ones
    are (not normalised): the side a normal of :func:`surface_fitted_normals` points to."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _surface_normals(indptr, cols, position, is_surface, radius, n_rows, 2)
    return _surface_normals(indptr, cols, position, is_surface, radius, n_rows, 3)


# Eigenvalues of the surface particles' spread within this fraction of the largest of the
# smallest one count as tied: surface particles along one line (a lattice's edge, a jet)
# spread alike in every direction across it, and which of those the rotations return
# depends on the order of the sums, i.e. on how the ranks cut the domain (a side wall's
# row at the 3D dam break's corner took normals 113 degrees apart on 1 and 2 ranks).
_SPREAD_TIE = 1e-6


@numba.njit(cache=True)
def _least_spread_normal(spread, raw, i, work, vectors, out):
    """The unit direction of least ``spread`` (d×d, symmetric), turned to the side of
    ``raw[i]``, into ``out``. Where eigenvalues tie with the smallest (within
    ``_SPREAD_TIE`` of the largest, weighted down linearly across that band) the normal is
    ``raw[i]`` projected on their eigenvectors, so it does not depend on round-off
    (``work`` and ``vectors``: d×d scratch)."""
    d = spread.shape[0]
    for k in range(d):
        for m in range(d):
            work[k, m] = spread[k, m]
            vectors[k, m] = 1.0 if k == m else 0.0
    _jacobi_diagonalise(work, vectors, True)
    smallest = 0
    largest = 0
    for k in range(1, d):
        if work[k, k] < work[smallest, smallest]:
            smallest = k
        if work[k, k] > work[largest, largest]:
            largest = k
    band = _SPREAD_TIE * work[largest, largest]
    tied = False
    raw_length = 0.0
    for m in range(d):
        out[m] = 0.0
        raw_length += raw[i, m] * raw[i, m]
    for k in range(d):
        gap = work[k, k] - work[smallest, smallest]
        if k == smallest:
            share = 1.0
        elif gap < band:
            share = 1.0 - gap / band
            tied = True
        else:
            continue
        along = 0.0
        for m in range(d):
            along += vectors[m, k] * raw[i, m]
        for m in range(d):
            out[m] += share * along * vectors[m, k]
    if tied:
        length = 0.0
        for m in range(d):
            length += out[m] * out[m]
        if length > 1e-24 * raw_length:
            length = np.sqrt(length)
            for m in range(d):
                out[m] /= length
            return
    # One direction of least spread: outwards, on the side of the missing neighbours.
    along = 0.0
    for m in range(d):
        along += vectors[m, smallest] * raw[i, m]
    sign = 1.0 if along >= 0.0 else -1.0
    for m in range(d):
        out[m] = sign * vectors[m, smallest]


@numba.njit(cache=True, inline="always")
def _surface_fitted_normals(indptr, cols, position, raw, on_surface, radius, n_rows, d):
    normal = np.zeros((n_rows, d))
    centre = np.empty(d)
    spread = np.empty((d, d))
    work = np.empty((d, d))
    vectors = np.empty((d, d))
    direction = np.empty(d)
    for i in range(n_rows):
        length = _row_length(raw, i, d)
        if length <= 0.0:
            continue
        # The weighted spread of the free-surface particles about their centre: the
        # surface's normal is its direction of least spread. Positions relative to i.
        total = 0.0
        count = 0
        for k in range(d):
            centre[k] = 0.0
            for m in range(d):
                spread[k, m] = 0.0
        if on_surface[i]:
            total = 1.0
            count = 1
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not on_surface[j]:
                continue
            w = _weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w <= 0.0:
                continue
            total += w
            count += 1
            for k in range(d):
                centre[k] += w * pair_component(position, i, j, k)
                for m in range(d):
                    spread[k, m] += w * pair_component(position, i, j, k) * \
                        pair_component(position, i, j, m)
        fitted = count >= d + 1
        if fitted:
            for k in range(d):
                centre[k] /= total
            for k in range(d):
                for m in range(d):
                    spread[k, m] = spread[k, m] / total - centre[k] * centre[m]
            _least_spread_normal(spread, raw, i, work, vectors, direction)
            for k in range(d):
                normal[i, k] = direction[k]
        else:
            for k in range(d):
                normal[i, k] = raw[i, k] / length
    return normal


@numba.njit(cache=True)
def surface_fitted_normals(indptr, cols, position, raw, on_surface, radius, n_rows):
    """Unit outward normals of the rows near the free surface (where ``raw``, from
    :func:`surface_normals`, is set; 0 elsewhere): the direction in which the
    free-surface particles ``on_surface`` (every local particle) within the radius,
    the row itself included, spread least (weighted by w_ij, the row by 1), turned
    to the side ``raw`` points to; where several directions spread least alike (the
    particles along a line), ``raw`` projected on them. With fewer than d + 1 such
    particles, ``raw`` itself. The missing neighbours' direction alone would lean away from a wall
    that rises above the water: there, only the air's side of the wall misses."""
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _surface_fitted_normals(indptr, cols, position, raw, on_surface, radius,
                                       n_rows, 2)
    return _surface_fitted_normals(indptr, cols, position, raw, on_surface, radius,
                                   n_rows, 3)


@numba.njit(cache=True, inline="always")
def _surface_depth(indptr, cols, position, i, is_surface, draws_level, radius, normal,
                   half_spacing, inverse_cube, d):
    # How far the zero level lies from i along the outward normal: half a spacing plus
    # the mean height above i of the free-surface particles that draw the level (the
    # fluid's), weighted as the sum weighs them, those less than half a spacing above
    # i counting 0 (i's own layer: its jitter does not lift the level). The same for a
    # free-surface particle as below the surface: the layer under the top one sits at
    # n*/n0 = 0.976 on a 2D lattice (re 2.3 l0), so jitter takes many of its particles
    # for surface, and their level is still the top layer's. Walls above the water
    # draw no level (counted, they had pulled it down beside a wall).
    depth = 0.0
    weight_sum = 0.0
    for p in range(indptr[i], indptr[i + 1]):
        j = cols[p]
        if not draws_level[j]:
            continue
        r2 = pair_distance2(position, i, j, d)
        w = _laplacian_weight(r2, radius, inverse_cube)
        if w <= 0.0:
            continue
        height = 0.0
        for k in range(d):
            height += pair_component(position, i, j, k) * normal[k]
        if height > half_spacing:
            depth += w * height
        weight_sum += w
    if weight_sum <= 0.0:
        return half_spacing if is_surface[i] else -1.0
    return half_spacing + depth / weight_sum


@numba.njit(cache=True, inline="always")
def _surface_ghost_diagonal(indptr, cols, position, radius, is_unknown, is_surface,
                            draws_level, normal, inverse_cube, half_spacing, undirected,
                            n_rows, d):
    extra = np.zeros(n_rows)
    for i in range(n_rows):
        if not is_unknown[i]:
            continue
        if is_surface[i]:
            extra[i] = undirected
        if _row_length(normal, i, d) <= 0.0:
            continue
        # The missing neighbours' first moment along the normal: minus the present ones'.
        moment = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = _laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
            if w <= 0.0:
                continue
            for k in range(d):
                moment -= w * pair_component(position, i, j, k) * normal[i, k]
        depth = _surface_depth(indptr, cols, position, i, is_surface, draws_level, radius,
                               normal[i], half_spacing, inverse_cube, d)
        if depth > 0.0 and moment > 0.0:
            extra[i] = moment / depth
    return extra


@numba.njit(cache=True)
def surface_ghost_diagonal(indptr, cols, position, radius, is_unknown, is_surface,
                           draws_level, normal, inverse_cube, half_spacing, undirected,
                           n_rows):
    """Per owned row, the diagonal the missing neighbours add when the pressure is zero
    half a spacing beyond the free-surface particles (before the Laplacian's coefficient).

    ``is_unknown`` and ``is_surface`` mark every local particle: a row solved for,
    a free-surface particle. An unknown row with a free-surface particle in its
    support (or one itself) misses the neighbours beyond the surface. Their first
    moment is minus that of the neighbours present, ``-V_i = -sum_j w_ij r_ij``
    (every neighbour counts, dummies too: only air is missing). A missing neighbour
    g takes the value of the linear field that is P_i at i and 0 on the surface
    ``delta_i`` away along ``-V_i/|V_i|``: ``P_g - P_i = -P_i (r_ig . n)/delta_i``,
    so the missing ones add ``-P_i |V_i| / delta_i`` to the row's sum: the diagonal
    only, and the matrix stays symmetric (Gibou et al. 2002's ghost-fluid Dirichlet
    condition, with the kernel's moment in place of the grid's). ``delta_i`` is
    half a spacing plus the mean height above i, along the normal, of the
    free-surface particles ``draws_level`` (every local particle: the fluid's), those
    less than half a spacing above i counting 0: half a spacing for a particle of
    the top layer, and for a particle below it taken for surface (as jitter takes
    many of the second layer's) the top layer's level still. A linear field that
    is zero on that surface satisfies every such row exactly.

    A free-surface row whose missing neighbours have no direction (it has no
    neighbour, or neighbours all round, as in a sheet one particle thick) gets
    ``undirected`` instead: without it the row would be singular when the
    compressibility is zero. Its size, an interior row's diagonal, holds such a
    particle near zero as the plain Dirichlet condition would.
    """
    _check_dimension(position.shape[1])
    if position.shape[1] == 2:
        return _surface_ghost_diagonal(indptr, cols, position, radius, is_unknown, is_surface,
                                       draws_level, normal, inverse_cube, half_spacing,
                                       undirected, n_rows, 2)
    return _surface_ghost_diagonal(indptr, cols, position, radius, is_unknown, is_surface,
                                   draws_level, normal, inverse_cube, half_spacing, undirected,
                                   n_rows, 3)


# Ciura's gaps for Shell sort, largest first, for rows of at least _SHELL_FROM entries
# (measured: 2D rows of ~30 took 9 ms a step at 40k particles by Shell sort, 4.9 by insertion;
# 3D rows of ~90, 88 ms a step at 100k particles against 125).
_SHELL_GAPS = np.array([701, 301, 132, 57, 23, 10, 4, 1], np.int64)
_SHELL_FROM = 64


# A row with at most one descent per this many entries is sorted by insertion alone.
_NEARLY_SORTED = 8


@numba.njit(cache=True, inline="always")
def _descents(columns, start, end):
    """How many entries of the row [start, end) are smaller than the one before."""
    count = 0
    for p in range(start + 1, end):
        if columns[p] < columns[p - 1]:
            count += 1
    return count


@numba.njit(cache=True)
def sort_row_columns(row_ptr, columns, values):
    """Sort each CSR row's entries by column, in place: insertion sort, preceded for long rows
    by Shell sort's larger gaps (Ciura's).

    PETSc's matrix made directly on CSR arrays (``MatCreateSeqAIJWithArrays``) takes
    the arrays as they are and requires sorted rows; building the matrix row by row
    instead cost 10x more (14 ms against 1.1 ms for 6.8k rows). The neighbour lists come
    cell by cell, so a row is far from sorted in 3D (~120 entries): plain insertion took
    half the 3D solve's time on one rank (125 ms a step at 5.8M entries).

    A row already ascending (the pressure rows numbered in the search's cell order) is
    only read; a nearly ascending one (the same numbering kept while particles move) is
    sorted by insertion alone, in about one pass.
    """
    for row in range(row_ptr.shape[0] - 1):
        start = row_ptr[row]
        length = row_ptr[row + 1] - start
        descents = _descents(columns, start, start + length)
        if descents == 0:
            continue
        nearly_sorted = descents * _NEARLY_SORTED <= length
        for gap in _SHELL_GAPS:
            # Short rows (2D, ~30 entries) are sorted faster by insertion alone.
            if gap >= length or (gap > 1 and (length < _SHELL_FROM or nearly_sorted)):
                continue
            for p in range(start + gap, start + length):
                column = columns[p]
                value = values[p]
                q = p - gap
                while q >= start and columns[q] > column:
                    columns[q + gap] = columns[q]
                    values[q + gap] = values[q]
                    q -= gap
                columns[q + gap] = column
                values[q + gap] = value


# Per-particle reductions for the driver's checks after every step: one pass, no
# temporaries (numpy's masks, fancy-indexed copies and row reductions took 12 ms a step
# at 289k particles in 3D, against 1.5 ms).

@numba.njit(cache=True)
def largest_norm2(vectors, mask):
    """The largest |v|^2 over the rows of ``vectors`` that ``mask`` selects (0 if none);
    each row's squares summed in component order, as numpy's row sums add them."""
    largest = 0.0
    for i in range(vectors.shape[0]):
        if mask[i]:
            norm2 = 0.0
            for k in range(vectors.shape[1]):
                norm2 += vectors[i, k] * vectors[i, k]
            if norm2 > largest:
                largest = norm2
    return largest


@numba.njit(cache=True)
def lowest_id_not_finite(position, velocity, ids):
    """The lowest id among the rows with a NaN or infinite position or velocity, or -1."""
    lowest = -1
    for i in range(position.shape[0]):
        finite = True
        for k in range(position.shape[1]):
            if not (np.isfinite(position[i, k]) and np.isfinite(velocity[i, k])):
                finite = False
        if not finite and (lowest < 0 or ids[i] < lowest):
            lowest = ids[i]
    return lowest
