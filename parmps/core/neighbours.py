"""Neighbour search on cell lists, in d dimensions (positions are N×d).

The pair list is in CSR form: for each row particle i (the owned ones, which
come first), ``indices[indptr[i]:indptr[i+1]]`` are the particles j != i within
``radius`` (owned or ghost). Rows come out grouped, so operators reduce with
``bincount`` and the pressure matrix is assembled without sorting.

The search is a numba kernel: a numpy cell-list search costs about 19 µs per
particle at 40k particles (measured on the project's 2-core machines), four times the whole step's budget.
"""

import math

import numba
import numpy as np

# Cells per search radius. With cells as wide as the radius, the 3^d cells searched hold
# 27 r^3 of space in 3D around a ball of 4.2 r^3; halved, 5^d half-cells hold 15.6 r^3.
CELLS_PER_RADIUS = 2


@numba.njit(cache=True)
def _cell_coordinates(position, origin, cell_size):
    """The integer cell of every particle, one column per dimension."""
    n, d = position.shape
    cell = np.empty((n, d), np.int64)
    for p in range(n):
        for k in range(d):
            cell[p, k] = int((position[p, k] - origin[k]) / cell_size)
    return cell


@numba.njit(cache=True, inline="always")
def _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
              indices, rows, reach, d):
    """Pairs of rows [0, n_rows) within ``radius``, over the (2 reach + 1)^d cells around
    each row (cells at least radius/reach wide).

    Fills ``indptr`` and as many pairs as ``indices`` has room for, and returns
    the number of pairs found: more than ``len(indices)`` means the list is
    incomplete and the search must run again with that room.

    Cells are numbered key = sum_k cell_k stride_k with stride_0 = 1, so the
    cells that differ in the first coordinate only are consecutive and their
    particles one contiguous run of ``order``: the loop walks the 3^(d-1) such
    runs in ascending key (in 2D: rows of cells by y, cells by x within a row).
    """
    radius2 = radius * radius
    lo = np.empty(d, np.int64)
    hi = np.empty(d, np.int64)
    at = np.empty(d, np.int64)
    room = indices.shape[0]
    total = 0
    for i in range(n_rows):
        if rows is not None and not rows[i]:
            indptr[i + 1] = total
            continue
        for k in range(d):
            lo[k] = max(cell[i, k] - reach, 0)
            hi[k] = min(cell[i, k] + reach + 1, cells[k])
            at[k] = lo[k]
        while True:
            base = 0
            for k in range(1, d):
                base += at[k] * stride[k]
            for s in range(cell_start[base + lo[0]], cell_start[base + hi[0]]):
                j = order[s]
                if j == i:
                    continue
                r2 = 0.0
                for k in range(d):
                    delta = position[j, k] - position[i, k]
                    r2 += delta * delta
                if r2 < radius2:
                    if total < room:
                        indices[total] = j
                    total += 1
            # The next run of cells: count up the coordinates 1 .. d-1 like an odometer.
            k = 1
            while k < d:
                at[k] += 1
                if at[k] < hi[k]:
                    break
                at[k] = lo[k]
                k += 1
            if k == d:
                break
        indptr[i + 1] = total
    return total


@numba.njit(cache=True)
def _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr, indices,
            rows, reach):
    # d as a literal, so the component loops unroll (see parmps.core.kernels).
    if position.shape[1] == 2:
        return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                         indptr, indices, rows, reach, 2)
    if position.shape[1] == 3:
        return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                         indptr, indices, rows, reach, 3)
    return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                     indptr, indices, rows, reach, position.shape[1])


def pair_list(position, radius, n_rows=None, rows=None, expected_pairs=0):
    """CSR neighbour lists (indptr, indices) of rows [0, n_rows) against every particle.

    ``position`` is (N, d) for any d >= 1; the cells are d-dimensional. ``rows``:
    optional mask (length >= n_rows) of the rows to search; the others get empty
    lists (they still appear as neighbours of the rows searched).
    ``expected_pairs``: room to fill in one pass (e.g. a little more than the last
    step's count); the search runs a second time only when the pairs overflow it,
    and the result is the same either way.
    """
    position = np.ascontiguousarray(position, dtype=np.float64)
    n = len(position)
    n_rows = n if n_rows is None else int(n_rows)
    indptr = np.zeros(n_rows + 1, np.int64)
    if n == 0 or n_rows == 0:
        return indptr, np.empty(0, np.int64)
    origin = position.min(axis=0) - 1e-12
    extent = position.max(axis=0) - origin
    # Cells 1/CELLS_PER_RADIUS of the radius wide (a hair wider, so that ``reach`` of them
    # span the radius despite rounding): the (2 reach + 1)^d cells around a particle hold
    # every neighbour and little else. Larger when the particles are sparse, so the cell
    # table stays O(n) in memory; ``reach`` then falls to 1.
    cell_size = radius / CELLS_PER_RADIUS * (1.0 + 1e-12)
    while math.prod(int(e / cell_size) + 1 for e in extent) > 4 * n + 4096:
        cell_size *= 1.5
    reach = max(1, math.ceil(radius / cell_size))
    cells = np.array([int(e / cell_size) + 1 for e in extent], np.int64)
    stride = np.concatenate([[1], np.cumprod(cells[:-1])]).astype(np.int64)
    cell = _cell_coordinates(position, origin, cell_size)
    key = cell @ stride
    order = np.argsort(key, kind="stable")
    cell_start = np.searchsorted(key[order], np.arange(int(np.prod(cells)) + 1))
    indices = np.empty(max(int(expected_pairs), 0), np.int64)
    total = _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
                    indices, rows, reach)
    if total > len(indices):
        indices = np.empty(total, np.int64)
        _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
                indices, rows, reach)
    return indptr, indices[:total]


def rows_of(indptr):
    """The row index of every pair: expands CSR indptr to one entry per pair."""
    return np.repeat(np.arange(len(indptr) - 1, dtype=np.int64), np.diff(indptr))


def close_pairs(position, distance):
    """Unique pairs (i < j) closer than ``distance``; used to check geometry."""
    indptr, indices = pair_list(position, distance)
    rows = rows_of(indptr)
    keep = rows < indices
    return rows[keep], indices[keep]
