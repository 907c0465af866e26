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

    def gradient(self, indptr, cols, position, pressure, has_pressure, n_rows, rows=None,
                 surface=None):
        """(n_rows, d) pressure gradient of the rows [0, n_rows) of the pair list; with
        ``rows`` (a mask), of those rows only, the others 0. ``surface`` is for the
        corrected gradient; the plain one has nothing to correct."""
        c = self.constants
        return (c.dimension / c.n0) * kernels.pressure_gradient_sum(
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
        (kernels.correct_normal_component) down to that limit, the others as usual; one pass
        over the pairs for both (kernels.corrected_pressure_gradient)."""
        c = self.constants
        surface_rows, normal, surface_limit = (None, None, 0.0) if surface is None else surface
        return kernels.corrected_pressure_gradient(
            indptr, cols, position, pressure, has_pressure, c.re_number_density,
            c.dimension / c.n0, n_rows, self.eigenvalue_limit, rows, surface_rows, normal,
            surface_limit)
