"""Pressure gradients: the minimum-pressure MPS gradient, plain or corrected (docs/design.md).

``<grad P>_i = d/n0 sum_j (P_j - Pmin_i) r_ij w_ij / |r_ij|^2`` over the
neighbours that carry a pressure (not dummies), with ``Pmin_i`` the minimum of P
over i and those neighbours: subtracting it keeps every pair repulsive, which is
the original scheme's stability choice. The corrected gradient multiplies that
by the inverse of the moment matrix ``A_i = d/n0 sum_j r_ij (x) r_ij w / r^2``
(Khayyer & Gotoh 2011), exact for a linear field on any arrangement.
"""

from parmps.config import Key
from parmps.core import kernels


class MinimumPressureGradient:
    KEYS = {}

    def __init__(self, settings, constants):
        self.constants = constants

    def gradient(self, indptr, cols, position, pressure, has_pressure, n_rows, rows=None):
        """(n_rows, d) pressure gradient of the rows [0, n_rows) of the pair list; with
        ``rows`` (a mask), of those rows only, the others 0."""
        c = self.constants
        return (c.dimension / c.n0) * kernels.pressure_gradient_sum(
            indptr, cols, position, pressure, has_pressure, c.re_number_density, n_rows, rows)


class CorrectedGradient(MinimumPressureGradient):
    KEYS = {"eigenvalue_limit": Key("float", 0.7, gt=0.0, le=1.0,
                                    doc="rows whose moment matrix (the identity on the full "
                                        "lattice) has an eigenvalue below this keep the plain "
                                        "gradient: a truncated neighbourhood at a free surface "
                                        "or in a splash")}

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.eigenvalue_limit = settings["eigenvalue_limit"]

    def gradient(self, indptr, cols, position, pressure, has_pressure, n_rows, rows=None):
        c = self.constants
        gradient = super().gradient(indptr, cols, position, pressure, has_pressure, n_rows,
                                    rows)
        kernels.correct_gradient(indptr, cols, position, has_pressure, c.re_number_density,
                                 c.dimension / c.n0, gradient, self.eigenvalue_limit, rows)
        return gradient
