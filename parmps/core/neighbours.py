"""Neighbour search on cell lists, in d dimensions (positions are N×d).

The pair list is in CSR form: for each row particle i (the owned ones, which
come first), ``indices[indptr[i]:indptr[i+1]]`` are the particles j != i within
``radius`` (owned or ghost), in the order of the search's cells. Rows come out
grouped, so operators reduce with ``bincount``.

The search is a numba kernel: a numpy cell-list search costs about 19 µs per
particle at 40k particles (measured on the project's 2-core machines), four
times the whole step's budget.
"""

import math

import numba
import numpy as np
from parmps.core.pairs import PAIRS_WITHIN_MARGIN, for_each_dimension, pair_distance2

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
def _next_run(at, lo, hi, d):
    """Move ``at`` to the next run of cells in [lo, hi): count up the coordinates 1 .. d-1
    like an odometer (coordinate 0 spans the run). False once past the last run."""
    k = 1
    while k < d:
        at[k] += 1
        if at[k] < hi[k]:
            return True
        at[k] = lo[k]
        k += 1
    return False


@numba.njit(cache=True, inline="always")
def _any_near_in_block(lo, hi, at, stride, cell_start, near_before, d):
    """Whether the cells [lo, hi) hold a particle counted in ``near_before`` (the number of
    such particles before each place of the cell order)."""
    for k in range(d):
        at[k] = lo[k]
    while True:
        base = 0
        for k in range(1, d):
            base += at[k] * stride[k]
        if near_before[cell_start[base + hi[0]]] > near_before[cell_start[base + lo[0]]]:
            return True
        if not _next_run(at, lo, hi, d):
            return False


@numba.njit(cache=True, inline="always")
def _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
              indices, rows, reach, only_near, near, near_before, d):
    """Pairs of rows [0, n_rows) within ``radius``, over the (2 reach + 1)^d cells around
    each row (cells at least radius/reach wide).

    Fills ``indptr`` and as many pairs as ``indices`` has room for, and returns
    the number of pairs found: more than ``len(indices)`` means the list is
    incomplete and the search must run again with that room.

    Cells are numbered key = sum_k cell_k stride_k with stride_0 = 1, so the
    cells that differ in the first coordinate only are consecutive and their
    particles one contiguous run of ``order``: the loop walks the 3^(d-1) such
    runs in ascending key (in 2D: rows of cells by y, cells by x within a row).

    A row flagged in ``only_near`` keeps its pairs only when one of them is a
    particle flagged in ``near``, and gets an empty list otherwise; when its
    cells hold no such particle at all (``near_before``: how many come before
    each place of ``order``), it is not searched.
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
        found = only_near.shape[0] == 0 or not only_near[i]
        if not found and not _any_near_in_block(lo, hi, at, stride, cell_start, near_before,
                                                d):
            indptr[i + 1] = total
            continue
        start = total
        for k in range(d):
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
                    if not found and near[j]:
                        found = True
            if not _next_run(at, lo, hi, d):
                break
        if not found:
            total = start
        indptr[i + 1] = total
    return total


@numba.njit(cache=True)
def _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr, indices,
            rows, reach, only_near, near, near_before):
    # d as a literal, so the component loops unroll (see parmps.core.pairs).
    if position.shape[1] == 2:
        return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                         indptr, indices, rows, reach, only_near, near, near_before, 2)
    if position.shape[1] == 3:
        return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                         indptr, indices, rows, reach, only_near, near, near_before, 3)
    return _search_d(position, n_rows, radius, cells, stride, order, cell_start, cell,
                     indptr, indices, rows, reach, only_near, near, near_before,
                     position.shape[1])


def _grid(position, radius):
    """The cells over ``position``: origin, cell size, reach (cells per radius), cells per
    axis and strides. Cells 1/CELLS_PER_RADIUS of the radius wide (a hair wider, so that
    ``reach`` of them span the radius despite rounding): the (2 reach + 1)^d cells around a
    particle hold every neighbour and little else. Larger when the particles are sparse,
    so the cell table stays O(n) in memory; ``reach`` then falls to 1."""
    lowest, highest = _bounds(position)
    origin = lowest - 1e-12
    extent = highest - origin
    cell_size = radius / CELLS_PER_RADIUS * (1.0 + 1e-12)
    while math.prod(int(e / cell_size) + 1 for e in extent) > 4 * len(position) + 4096:
        cell_size *= 1.5
    reach = max(1, math.ceil(radius / cell_size))
    cells = np.array([int(e / cell_size) + 1 for e in extent], np.int64)
    stride = np.concatenate([[1], np.cumprod(cells[:-1])]).astype(np.int64)
    return origin, cell_size, reach, cells, stride


@numba.njit(cache=True)
def _bounds(position):
    """The smallest and largest coordinate along each axis, in one pass over the rows
    (numpy's ``min(axis=0)`` and ``max(axis=0)`` over n x d positions took 1.1-1.3 ms for
    22k particles in 2D against 0.07 ms here, 7-8.5 against 0.6 ms for 150k in 3D)."""
    n, d = position.shape
    lowest = position[0].copy()
    highest = position[0].copy()
    for p in range(1, n):
        for k in range(d):
            x = position[p, k]
            if x < lowest[k]:
                lowest[k] = x
            elif x > highest[k]:
                highest[k] = x
    return lowest, highest


@numba.njit(cache=True)
def _cell_order(cell, cells, stride):
    """The particles in cell order (stable: by index within a cell), and where each cell's
    run of them starts: a counting sort, O(particles + cells). A rank's cells span the box
    of its particles and ghosts, mostly empty where a tank's walls rise above the water; an
    argsort and a binary search per cell cost three times as much there."""
    n, d = cell.shape
    n_cells = 1
    for k in range(d):
        n_cells *= cells[k]
    key = np.empty(n, np.int64)
    cell_start = np.zeros(n_cells + 1, np.int64)
    for p in range(n):
        value = 0
        for k in range(d):
            value += cell[p, k] * stride[k]
        key[p] = value
        cell_start[value + 1] += 1
    for c in range(n_cells):
        cell_start[c + 1] += cell_start[c]
    filled = cell_start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[filled[key[p]]] = p
        filled[key[p]] += 1
    return order, cell_start


@numba.njit(cache=True)
def _rows_near(position, row_index, row_cell, members, cell_start, cells, stride, reach,
               radius, found):
    """found[i] for each row i = row_index[r] (in cell row_cell[r]): whether one of
    ``members`` (in cell order, runs from ``cell_start``) other than i lies within
    ``radius``. Stops at the first."""
    d = position.shape[1]
    radius2 = radius * radius
    lo = np.empty(d, np.int64)
    hi = np.empty(d, np.int64)
    at = np.empty(d, np.int64)
    for r in range(row_index.shape[0]):
        i = row_index[r]
        for k in range(d):
            lo[k] = max(row_cell[r, k] - reach, 0)
            hi[k] = min(row_cell[r, k] + reach + 1, cells[k])
            at[k] = lo[k]
        while not found[i]:
            base = 0
            for k in range(1, d):
                base += at[k] * stride[k]
            for s in range(cell_start[base + lo[0]], cell_start[base + hi[0]]):
                j = members[s]
                if j == i:
                    continue
                r2 = 0.0
                for k in range(d):
                    delta = position[j, k] - position[i, k]
                    r2 += delta * delta
                if r2 < radius2:
                    found[i] = True
                    break
            if not _next_run(at, lo, hi, d):
                break


def rows_near(position, radius, rows, near):
    """Which of the rows flagged in ``rows`` (a mask over the first ``len(rows)``
    particles) have a particle flagged in ``near`` (a mask over all of them) within
    ``radius``: a boolean mask like ``rows``. Searches the cells of the ``near``
    particles only, and stops at the first found."""
    position = np.ascontiguousarray(position, dtype=np.float64)
    rows = np.asarray(rows, np.bool_)
    found = np.zeros(len(rows), np.bool_)
    candidates = np.flatnonzero(np.asarray(near, np.bool_))
    row_index = np.flatnonzero(rows)
    if len(candidates) == 0 or len(row_index) == 0:
        return found
    origin, cell_size, reach, cells, stride = _grid(position, radius)
    order, cell_start = _cell_order(_cell_coordinates(position[candidates], origin, cell_size),
                                    cells, stride)
    _rows_near(position, row_index, _cell_coordinates(position[row_index], origin, cell_size),
               candidates[order], cell_start, cells, stride, reach, radius, found)
    return found


def pair_list(position, radius, n_rows=None, rows=None, expected_pairs=0, only_near=None,
              near=None, cell_order=False):
    """CSR neighbour lists (indptr, indices) of rows [0, n_rows) against every particle.

    ``position`` is (N, d) for any d >= 1; the cells are d-dimensional. ``rows``:
    optional mask (length >= n_rows) of the rows to search; the others get empty
    lists (they still appear as neighbours of the rows searched).
    ``expected_pairs``: room to fill in one pass (e.g. a little more than the last
    step's count); the search runs a second time only when the pairs overflow it,
    and the result is the same either way.
    ``only_near`` (mask of rows) and ``near`` (mask of every particle): the rows
    flagged in ``only_near`` keep their list only when a particle of ``near`` is in
    it, and get an empty one otherwise (walls away from any water, say).
    ``cell_order``: also return the particles in the order of the search's cells (stable
    by index within a cell). Each row lists its neighbours in that order, so anything
    numbered in it (the pressure matrix's columns) comes out ascending row by row.
    """
    if (only_near is None) != (near is None):
        raise ValueError("pair_list: only_near and near go together")
    if only_near is None:
        only_near = near = np.zeros(0, np.bool_)
    only_near = np.asarray(only_near, np.bool_)
    near = np.asarray(near, np.bool_)
    position = np.ascontiguousarray(position, dtype=np.float64)
    n = len(position)
    n_rows = n if n_rows is None else int(n_rows)
    indptr = np.zeros(n_rows + 1, np.int64)
    if n == 0 or n_rows == 0:
        empty = np.empty(0, np.int64)
        if cell_order:
            return indptr, empty, np.arange(n, dtype=np.int64)
        return indptr, empty
    origin, cell_size, reach, cells, stride = _grid(position, radius)
    cell = _cell_coordinates(position, origin, cell_size)
    order, cell_start = _cell_order(cell, cells, stride)
    near_before = np.zeros(n + 1 if len(only_near) else 1, np.int64)
    if len(only_near):
        np.cumsum(near[order], out=near_before[1:])
    indices = np.empty(max(int(expected_pairs), 0), np.int64)
    total = _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
                    indices, rows, reach, only_near, near, near_before)
    if total > len(indices):
        indices = np.empty(total, np.int64)
        _search(position, n_rows, radius, cells, stride, order, cell_start, cell, indptr,
                indices, rows, reach, only_near, near, near_before)
    if cell_order:
        return indptr, indices[:total], order
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


@for_each_dimension
def _pairs_within_into(d, indptr, cols, position, radius, n_rows, near_indptr, near_cols):
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

