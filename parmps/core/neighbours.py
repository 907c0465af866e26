"""Neighbour search on cell lists.

The pair list is in CSR form: for each row particle i (the owned ones, which
come first), ``indices[indptr[i]:indptr[i+1]]`` are the particles j != i within
``radius`` (owned or ghost). Rows come out grouped, so operators reduce with
``bincount`` and the pressure matrix is assembled without sorting.

The search is a numba kernel: a numpy cell-list search costs about 19 µs per
particle at 40k particles (DESIGN.md §6), four times the whole step's budget.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def _cell_keys(position, origin, cell_size, ncx):
    n = position.shape[0]
    cx = np.empty(n, np.int64)
    cy = np.empty(n, np.int64)
    for p in range(n):
        cx[p] = int((position[p, 0] - origin[0]) / cell_size)
        cy[p] = int((position[p, 1] - origin[1]) / cell_size)
    return cx, cy


@numba.njit(cache=True)
def _search(position, n_rows, radius, cell_size, origin, ncx, ncy, order, cell_start,
            cx, cy, count_only, indptr, indices):
    radius2 = radius * radius
    total = 0
    for i in range(n_rows):
        if not count_only:
            total = indptr[i]
        xi = position[i, 0]
        yi = position[i, 1]
        for ky in range(max(cy[i] - 1, 0), min(cy[i] + 2, ncy)):
            for kx in range(max(cx[i] - 1, 0), min(cx[i] + 2, ncx)):
                cell = ky * ncx + kx
                for s in range(cell_start[cell], cell_start[cell + 1]):
                    j = order[s]
                    if j == i:
                        continue
                    dx = position[j, 0] - xi
                    dy = position[j, 1] - yi
                    if dx * dx + dy * dy < radius2:
                        if not count_only:
                            indices[total] = j
                        total += 1
        if count_only:
            indptr[i + 1] = total
    return total


def pair_list(position, radius, n_rows=None):
    """CSR neighbour lists (indptr, indices) of rows [0, n_rows) against every particle."""
    position = np.ascontiguousarray(position, dtype=np.float64)
    n = len(position)
    n_rows = n if n_rows is None else int(n_rows)
    indptr = np.zeros(n_rows + 1, np.int64)
    if n == 0 or n_rows == 0:
        return indptr, np.empty(0, np.int64)
    origin = position.min(axis=0) - 1e-12
    extent = position.max(axis=0) - origin
    # Cells no smaller than the radius, so 3x3 cells hold every neighbour; larger
    # when the particles are sparse, so the cell table stays O(n) in memory.
    cell_size = radius
    while (int(extent[0] / cell_size) + 1) * (int(extent[1] / cell_size) + 1) > 4 * n + 4096:
        cell_size *= 1.5
    ncx = int(extent[0] / cell_size) + 1
    ncy = int(extent[1] / cell_size) + 1
    cx, cy = _cell_keys(position, origin, cell_size, ncx)
    key = cy * ncx + cx
    order = np.argsort(key, kind="stable")
    cell_start = np.searchsorted(key[order], np.arange(ncx * ncy + 1))
    _search(position, n_rows, radius, cell_size, origin, ncx, ncy, order, cell_start,
            cx, cy, True, indptr, np.empty(0, np.int64))
    indices = np.empty(indptr[-1], np.int64)
    _search(position, n_rows, radius, cell_size, origin, ncx, ncy, order, cell_start,
            cx, cy, False, indptr, indices)
    return indptr, indices


def rows_of(indptr):
    """The row index of every pair: expands CSR indptr to one entry per pair."""
    return np.repeat(np.arange(len(indptr) - 1, dtype=np.int64), np.diff(indptr))


def close_pairs(position, distance):
    """Unique pairs (i < j) closer than ``distance``; used to check geometry."""
    indptr, indices = pair_list(position, distance)
    rows = rows_of(indptr)
    keep = rows < indices
    return rows[keep], indices[keep]
