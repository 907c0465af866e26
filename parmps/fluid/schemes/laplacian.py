"""Pressure Laplacians: the matrix of the PPE (docs/design.md §1.4, docs/schemes.md).

Both assemble ``-<lap p>_i + (rho c/dt^2) p_i`` row by row with
:func:`parmps.core.kernels.poisson_rows` over the Laplacian radius
``re_laplacian``; they differ in the pair weight and its normalisation:

- ``standard``: Koshizuka & Oka's ``2d/(lambda0 n0) sum_j (p_j - p_i) w_ij``,
  w = re/r - 1, exact for quadratic fields on the initial lattice through lambda0;
- ``higher_order``: Khayyer & Gotoh's (2010) ``c sum_j (p_j - p_i) re/r_ij^3``,
  the divergence of the gradient model with the kernel's derivatives kept. The
  factor c is a setting: the paper's ``(5 - d)/n0`` or ``2d / sum_j re/r``
  over the lattice, which makes it exact for quadratics as lambda0 does for the
  standard one (docs/schemes.md, HL, for what each makes true).
"""

from parmps.config import Key
from parmps.core import kernels
from parmps.fluid.schemes.khayyer_gotoh import (HL_NORMALISATIONS,
                                                higher_order_laplacian_coefficient,
                                                lattice_sums)


class StandardLaplacian:
    KEYS = {}
    inverse_cube = False

    def __init__(self, settings, constants):
        self.constants = constants
        self.coefficient = constants.laplacian_coefficient
        # The diagonal of an interior row on the full lattice: a Dirichlet row
        # of the same size keeps the matrix's scale uniform for the smoother.
        self.dirichlet_diagonal = constants.laplacian_coefficient * constants.n0_laplacian

    def rows(self, indptr, cols, position, row_number, is_unknown, diagonal_shift,
             mobility=None):
        """CSR (row pointers, global columns, values) of the owned rows with a pressure.

        ``mobility``: rho0/rho of every local particle where bodies' nodes take part
        in the solve (the implicit-pressure coupling), None for one density.
        """
        arguments = (indptr, cols, position, self.constants.re_laplacian, row_number,
                     is_unknown, self.coefficient, diagonal_shift, self.dirichlet_diagonal,
                     self.inverse_cube)
        if mobility is None:
            return kernels.poisson_rows(*arguments)
        return kernels.variable_density_poisson_rows(*arguments, mobility)


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
