"""Pressure Laplacians: the matrix of the PPE (docs/design.md §1.4, docs/schemes.md).

Both assemble ``-<lap p>_i + (rho c/dt^2) p_i`` row by row with
:func:`poisson_rows_into` over the Laplacian radius ``re_laplacian``; they differ in
the pair weight and its normalisation:

- ``standard``: Koshizuka & Oka's ``2d/(lambda0 n0) sum_j (p_j - p_i) w_ij``,
  w = re/r - 1, exact for quadratic fields on the initial lattice through lambda0;
- ``higher_order``: Khayyer & Gotoh's (2010) ``c sum_j (p_j - p_i) re/r_ij^3``,
  the divergence of the gradient model with the kernel's derivatives kept. The
  factor c is a setting: the paper's ``(5 - d)/n0`` or ``2d / sum_j re/r``
  over the lattice, which makes it exact for quadratics as lambda0 does for the
  standard one (docs/schemes.md, HL, for what each makes true).

The rows' kernel writes into the caller's room, sized by :func:`poisson_rows_room` from
the last step, not into room for every pair of the list (which held 1.8 times the
matrix's entries in 3D and lived as long as the matrix); and in the two blocks a
distributed PETSc matrix takes as they are (``MatCreateMPIAIJWithSplitArrays``), where
splitting the rows afterwards cost a pass over every entry and a copy of them
(docs/performance.md).
"""

from dataclasses import dataclass

import numba
import numpy as np

from parmps.config import Key
from parmps.core.pairs import for_each_dimension, laplacian_weight, pair_distance2
from parmps.fluid.schemes.khayyer_gotoh import (HL_NORMALISATIONS,
                                                higher_order_laplacian_coefficient,
                                                lattice_sums)


@dataclass
class PressureRows:
    """A rank's rows of the pressure matrix in two CSR blocks, each (row pointers, columns,
    values): ``owned``, the columns of the rank's own rows numbered from its first row;
    ``other``, the other ranks' columns, global (empty on one rank). ``diagonal_at``: where
    each row's diagonal is among ``owned``'s entries."""

    owned: tuple
    other: tuple
    diagonal_at: np.ndarray


class StandardLaplacian:
    KEYS = {}
    inverse_cube = False
    # The room for the next step's rows in each block: this step's entries and a little more.
    expected_entries = (0, 0)

    def __init__(self, settings, constants):
        self.constants = constants
        self.coefficient = constants.laplacian_coefficient
        # The diagonal of an interior row on the full lattice: a Dirichlet row
        # of the same size keeps the matrix's scale uniform for the smoother.
        self.dirichlet_diagonal = constants.laplacian_coefficient * constants.n0_laplacian

    def rows(self, indptr, cols, position, row_number, is_unknown, diagonal_shift,
             row_order, mobility=None, index_dtype=np.int64):
        """The owned rows with a pressure, in ``row_order`` (the particles in the order of
        their row numbers), as :class:`PressureRows`.

        ``mobility``: rho0/rho of every local particle where bodies' nodes take part
        in the solve (the implicit-pressure coupling), None for one density.
        ``index_dtype``: the columns' type (the solver's, which then takes them as they are).
        """
        if mobility is None:
            mobility = np.ones(len(row_number))
        arguments = (indptr, cols, position, self.constants.re_laplacian, row_number,
                     is_unknown, self.coefficient, diagonal_shift, self.dirichlet_diagonal,
                     self.inverse_cube, mobility)
        # Room for the last step's entries and a little more: the count changes by well
        # under a few percent a step. Room for every pair of the list only when that is
        # short (the first step): that held 1.8 times the entries in 3D, and the matrix
        # keeps its arrays alive.
        for rooms in (self.expected_entries, None):
            if rooms is None:
                rooms = poisson_rows_room(indptr, cols, row_number)
            room, other_room = rooms
            columns, values = np.empty(room, index_dtype), np.empty(room)
            other_columns, other_values = np.empty(other_room, index_dtype), np.empty(other_room)
            row_ptr, other_ptr, diagonal_at, entries, other_entries = poisson_rows_into(
                *arguments, columns, values, other_columns, other_values, row_order)
            if entries >= 0:
                break
        self.expected_entries = (int(1.02 * entries) + 64, int(1.02 * other_entries) + 64)
        return PressureRows((row_ptr, columns[:entries], values[:entries]),
                            (other_ptr, other_columns[:other_entries],
                             other_values[:other_entries]), diagonal_at)


class HigherOrderLaplacian(StandardLaplacian):
    KEYS = {"normalisation": Key("str", "paper", choices=HL_NORMALISATIONS,
                                 doc="the factor c: \"paper\" (5 - d)/n0; \"projection\" 2/n0; "
                                     "\"lattice\" 2d / sum re/r, exact for quadratics")}
    inverse_cube = True

    def __init__(self, settings, constants):
        self.constants = constants
        self.coefficient = higher_order_laplacian_coefficient(
            constants.spacing, constants.re_laplacian, settings["normalisation"],
            constants.dimension)
        inverse_cube_sum = lattice_sums(constants.spacing, constants.re_laplacian,
                                        constants.dimension)[3]
        self.dirichlet_diagonal = self.coefficient * inverse_cube_sum


# A row of the pressure matrix that is an unknown free-surface particle (is_unknown's value).
SURFACE_ROW = 2


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


@for_each_dimension
def poisson_rows_into(d, indptr, cols, position, radius, row_number, is_unknown, coefficient,
                      diagonal_shift, dirichlet_diagonal, inverse_cube, mobility, columns,
                      values, other_columns, other_values, row_order, split=True):
    """:func:`variable_density_poisson_rows` of the owned particles ``row_order`` (with a
    row, in the order of their row numbers, which ascend by one from ``first``) into the
    caller's room, in two blocks: the columns of this rank's rows, numbered from ``first``
    (``columns``/``values``), and the others, global (``other_columns``/``other_values``);
    with ``split`` false every entry in the first, global. The columns may be of any
    integer type (PETSc's: the matrix takes them without a copy). The diagonal goes before
    the row's first column of this rank's rows above its own, so a row whose columns come
    ascending (numbered in the search's cell order) stays so. Returns (row pointers of each
    block, each row's diagonal's place in the first, entries written in each), the entries
    -1 when a room is too small (:func:`poisson_rows_room`)."""
    n_rows = row_order.shape[0]
    room, other_room = columns.shape[0], other_columns.shape[0]
    row_ptr = np.zeros(n_rows + 1, np.int64)
    other_ptr = np.zeros(n_rows + 1, np.int64)
    diagonal_at = np.empty(n_rows, np.int64)
    first = row_number[row_order[0]] if n_rows > 0 else 0
    last = first + n_rows
    offset = first if split else 0
    place, other = 0, 0
    # The room checks are written out at each entry: a helper for them, inlined, made the
    # kernel 18 % slower (3D, 18 M pairs).
    for r in range(n_rows):
        i = row_order[r]
        own = row_number[i]
        if not is_unknown[i]:
            place = _close_row(columns, values, row_ptr, other_ptr, diagonal_at, r, -1, place,
                               other, own - offset, dirichlet_diagonal)
            if place < 0:
                return row_ptr, other_ptr, diagonal_at, -1, -1
            continue
        diagonal = diagonal_shift
        at = -1
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if row_number[j] < 0:
                continue
            w = laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
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
        place = _close_row(columns, values, row_ptr, other_ptr, diagonal_at, r, at, place, other,
                           own - offset, diagonal)
        if place < 0:
            return row_ptr, other_ptr, diagonal_at, -1, -1
    return row_ptr, other_ptr, diagonal_at, place, other


@numba.njit(cache=True, inline="always")
def _close_row(columns, values, row_ptr, other_ptr, diagonal_at, r, at, place, other, column,
               diagonal):
    """Row r's ``diagonal`` into its place ``at`` in the first block, or, with ``at`` < 0,
    appended there at ``place`` (its ``column``); and the row's end in both blocks. Returns
    the first block's next place, -1 when its room is too small."""
    if at < 0:
        if place >= columns.shape[0]:
            return -1
        at = place
        columns[place] = column
        place += 1
    values[at] = diagonal
    diagonal_at[r] = at
    row_ptr[r + 1] = place
    other_ptr[r + 1] = other
    return place


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

