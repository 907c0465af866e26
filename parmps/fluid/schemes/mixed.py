"""The mixed source of Tanaka & Masunaga (2010; docs/design.md §1.4).

``rhs_i = -rho/dt <div u*>_i + gamma rho/dt^2 (n_i - n0)/n0``: the divergence of
the predicted velocity at the predicted positions, plus a weak density term at the
start-of-step positions that stops the volume drifting. It gives far less pressure
noise than the density source alone, and it takes out each step the inflow that
keeps carrying water into a corner: the density source corrects positions only, so
after the Lobovsky dam break's impact its corner stays compressed and its wall
pressure reads 24-33 % high (docs/case_overrides.md).

Beside a body (``[mps.mixed] beside_bodies = "density"``, the default) a row whose
support holds a body's node (or a buffer particle) takes the density source's right-hand
side instead, ``gamma_b rho/dt^2 (n*_i - n0)/n0`` at the predicted positions. Why: the
divergence term answers the nodes' velocities as if the projection moved them, but a
node moves after the solve, by its springs and its body's volume constraint under the
fluid force held over the step. For a body lighter than the fluid in a fast flow that
mismatch grows from step to step: the box-in-flow map lost 5 of its 20 runs (solid/fluid
density 0.01 and 0.1 from 5 U0, 0.3 at 10 U0) with the divergence there (gamma 0.1), and
ran all 20 with the density source beside the box; at gamma 0.05, 19 (0.1 at 10 U0
stops). The density source answers the nodes' positions only, which the coupling was
validated with; its gamma_b stays the density source's 0.2 (at 0.1 the membrane tube
stops and the plate reads 6 % high). The same holds for an open boundary's buffer
particles, whose motion is prescribed after the solve: with the divergence beside its
inlet buffer the 3D capsule's duct (cases/capsule_3d.toml) put a particle through the
floor's corner at the inlet at t = 0.95 s.

The body force (``[mps.mixed] body_force = "laplacian"``, the default): the divergence
is taken of u* less the step's dt g, and the body force enters as the flux that the
matrix's left-out pairs (those with dummies, which carry no pressure) would carry for
the field of gradient rho g. Why: with walls at rest beside water falling at dt g, the
divergence stops the water at its face, but the matrix closes the flux of that field at
the dummies, two layers deeper, so the hydrostatic field left a residual of -0.47 rho
g/l0 in the first fluid row and +0.70 in the second wall layer, which the density term
balanced with a density error ~ g dt^2/(gamma l0) (the bottom row expanded by 0.4 % at
2 cm in 3D). Now the hydrostatic field solves those rows (tests/test_mixed_still_column.py;
docs/design.md §1.4). ``"divergence"``: the earlier form.
"""

import numpy as np

from parmps.config import Key
from parmps.core.density import rows_beside
from parmps.core.pairs import (for_each_dimension, laplacian_weight, pair_component,
                               pair_distance2, weight_of_r2)
from parmps.core.particles import DUMMY, FLUID, INFLOW, SOLID
from parmps.fluid.schemes.density import MeasuredSource, kernel_key

BESIDE_BODIES = ("density", "mixed")
BODY_FORCES = ("laplacian", "divergence")


class MixedSource(MeasuredSource):
    # gamma is the still tank's quietest (l0 = 1 cm, 0.5-5 s, pressure.rtol 1e-12, the
    # smooth measure and the extrapolated surface): the bottom row's standard deviation
    # over time 0.77 / 0.58 / 0.70 / 0.94 % of rho g H and the whole tank's noise 0.94 /
    # 0.91 / 1.13 / 1.40 % at gamma 0.03 / 0.05 / 0.1 / 0.2. At 0.01 the pressure alternates
    # from step to step. (With n and P = 0 on the surface particles 0.1 was the quietest.)
    KEYS = {"relaxation": Key("float", 0.05, gt=0.0, le=1.0,
                              doc="gamma of the number-density term"),
            # The smooth measure keeps the still tank's column within -0.2 to -0.3 %;
            # with n it rose by 1.2 % (docs/validation_schemes.md).
            "kernel": kernel_key("smooth"),
            "beside_bodies": Key("str", "density", choices=BESIDE_BODIES,
                                 doc="the source of the rows with a body's node or a buffer "
                                     "particle in their support: \"density\" (the density "
                                     "source, relaxation body_relaxation) or \"mixed\" (this "
                                     "source)"),
            "body_relaxation": Key("float", 0.2, gt=0.0, le=1.0,
                                   doc="gamma of the density source beside bodies (the "
                                       "density source's own default)"),
            "body_force": Key("str", "laplacian", choices=BODY_FORCES,
                              doc="how the body force's share of the predicted velocity "
                                  "enters the source: \"laplacian\" (as the flux the "
                                  "Laplacian's dummy pairs would carry for the field of "
                                  "gradient rho g, which the matrix leaves out) or "
                                  "\"divergence\" (in the divergence of u*, walls at rest)")}

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.beside_bodies = settings["beside_bodies"]
        self.body_relaxation = settings["body_relaxation"]
        self.body_force = settings["body_force"]

    def rhs(self, step):
        c = self.constants
        index = step.unknown_index
        velocity = step.velocity_star
        split = self.body_force == "laplacian"
        if split:
            # The body force's share of u* leaves the divergence: walls at rest beside
            # fluid falling at dt g would put its stop at the water's face (the first fluid
            # row and wall layer), while the matrix (dummies carry no pressure) closes the
            # flux of the field whose gradient is rho g at the dummies, two wall layers
            # deeper. It comes back as that flux over the pairs with dummies the matrix
            # leaves out, so the hydrostatic field solves a still column's rows
            # (docs/design.md §1.4).
            moving = (step.kind == FLUID) | (step.kind == INFLOW)
            velocity = velocity.copy()
            velocity[moving] -= step.dt * np.asarray(step.gravity)
        divergence = (c.dimension / c.n0) * divergence_sum(
            step.near_indptr, step.near_cols, step.position_star, velocity,
            c.re_number_density, step.n_owned)
        rhs = (-(c.density / step.dt) * divergence[index]
               + self.relaxation * (c.density / step.dt ** 2)
               * self.density_error(step, predicted=False))
        if split:
            laplacian = step.laplacian
            flux = missing_pair_flux(
                step.indptr, step.cols, step.position_star,
                np.asarray(step.gravity, dtype=float), step.kind == DUMMY, c.re_laplacian,
                laplacian.inverse_cube, step.n_owned)
            rhs += laplacian.coefficient * c.density * flux[index]
        if self.beside_bodies == "density":
            beside = self.beside_body(step)[index]
            if np.any(beside):
                density = (self.body_relaxation * (c.density / step.dt ** 2)
                           * self.density_error(step, predicted=True))
                rhs[beside] = density[beside]
        return rhs

    @staticmethod
    def beside_body(step):
        """The owned rows with a body's node or a buffer particle within the number
        density's radius at the predicted positions, or that are one (none on a rank that
        holds neither). A buffer particle, like a node, is moved after the solve (by its
        open boundary's prescribed motion), not by the projection."""
        node = (step.kind == SOLID) | (step.kind == INFLOW)
        if not np.any(node):
            return np.zeros(step.n_owned, bool)
        return rows_beside(step.near_indptr, step.near_cols, node, step.n_owned)


@for_each_dimension
def divergence_sum(d, indptr, cols, position, field, radius, n_rows):
    """sum_j (u_j - u_i) . r_ij w / |r_ij|^2 (times d/n0 gives the divergence)."""
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            w = weight_of_r2(r2, radius)
            if w > 0.0:
                projected = 0.0
                for k in range(d):
                    projected += (field[j, k] - field[i, k]) * pair_component(position, i, j, k)
                total += projected * w / r2
        out[i] = total
    return out


@for_each_dimension
def missing_pair_flux(d, indptr, cols, position, vector, missing, radius, inverse_cube, n_rows):
    """sum_j w_ij (a . r_ij) over the neighbours j flagged ``missing`` (0 < r < radius), w
    the Laplacian's weight (:func:`laplacian_weight`): what those pairs would add to the
    Laplacian's sum of the linear field of gradient ``a`` (times the Laplacian's
    coefficient), the pairs the pressure matrix leaves out (dummies carry no pressure)."""
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not missing[j]:
                continue
            w = laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
            if w > 0.0:
                projected = 0.0
                for k in range(d):
                    projected += vector[k] * pair_component(position, i, j, k)
                total += w * projected
        out[i] = total
    return out

