"""Small symmetric matrices (d x d) in compiled loops: their eigen-decomposition by Jacobi
rotations (the free surface's fitted normal) and whether an eigenvalue lies below a limit
(the gradient correction's test)."""

import numba
import numpy as np


@numba.njit(cache=True)
def jacobi_diagonalise(work, vectors, accumulate):
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
def has_eigenvalue_below(a, limit, work):
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

