"""Pressure Laplacians: the matrix of the PPE (docs/design.md §1.4, docs/schemes.md).

Both assemble ``-<lap p>_i + (rho c/dt^2) p_i`` row by row with
:func:`parmps.core.kernels.poisson_rows_into` over the Laplacian radius
``re_laplacian``; they differ in the pair weight and its normalisation:

- ``standard``: Koshizuka & Oka's ``2d/(lambda0 n0) sum_j (p_j - p_i) w_ij``,
  w = re/r - 1, exact for quadratic fields on the initial lattice through lambda0;
- ``higher_order``: Khayyer & Gotoh's (2010) ``c sum_j (p_j - p_i) re/r_ij^3``,
  the divergence of the gradient model with the kernel's derivatives kept. The
  factor c is a setting: the paper's ``(5 - d)/n0`` or ``2d / sum_j re/r``
  over the lattice, which makes it exact for quadratics as lambda0 does for the
  standard one (docs/schemes.md, HL, for what each makes true).
"""

from dataclasses import dataclass

import numpy as np

from parmps.config import Key
from parmps.core import kernels
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
                rooms = kernels.poisson_rows_room(indptr, cols, row_number)
            room, other_room = rooms
            columns, values = np.empty(room, index_dtype), np.empty(room)
            other_columns, other_values = np.empty(other_room, index_dtype), np.empty(other_room)
            row_ptr, other_ptr, diagonal_at, entries, other_entries = kernels.poisson_rows_into(
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
