"""Free-surface conditions: where the pressure is zero (docs/design.md §1.4).

A free-surface particle is one with ``n* < beta n0``. The condition says what
its row of the pressure equation is and what the rows beside it lack:

- ``dirichlet``: Koshizuka & Oka's P = 0 on the free-surface particles
  themselves; their rows are decoupled, and the rows beside them simply miss
  the neighbours beyond the surface. The water then ends where its last
  particles' centres are, half a spacing short of where its volume ends.
- ``extrapolated`` (default): zero half a spacing beyond the free-surface
  fluid particles, where the fluid's volume ends. They and the free-surface
  wall particles are unknowns with no source of their own; bodies' nodes and
  buffers at the surface keep P = 0 on themselves. Every row with a
  free-surface particle in its support counts its missing neighbours as ghosts
  carrying the linear field
  that is its own P_i and zero on that surface: a diagonal term, so the matrix
  stays symmetric (:func:`parmps.core.kernels.surface_ghost_diagonal`). The
  corrected gradient is exact for that linear field over a surface particle's
  own neighbours, so the condition asks it to correct the free-surface fluid
  particles along the surface's normal, down to ``[mps.extrapolated]
  eigenvalue_limit`` (their moment matrix is 0.5 along the normal of a flat
  surface, under the gradient's own limit for every other row). Uncorrected,
  their gradient is half a linear field's and they sink into the row below. The
  full inverse of the moment matrix would do the same on a flat surface, but on
  a jet's tip it turns the gradient along the flow towards the floor: the peer
  dam break's tip went into the far wall's corner with it.
"""

import numpy as np

from parmps.config import Key
from parmps.core import kernels


class DirichletSurface:
    KEYS = {}

    def __init__(self, settings, constants):
        self.constants = constants

    def unknowns(self, has_pressure, surface, container):
        """(rows solved with a source, free-surface rows solved without one); ``container``:
        the fluid and wall particles, whose surface is the water's."""
        return has_pressure & ~surface, np.zeros_like(surface)

    def terms(self, indptr, cols, position, is_unknown, moving, laplacian, n_rows):
        """What the condition adds to the step: (each owned row's extra diagonal, or None;
        the gradient's surface rows as (mask of owned rows, unit normals, limit), or None).
        ``is_unknown``: every local particle's row kind (0, 1 or kernels.SURFACE_ROW);
        ``moving``: every local particle that draws the surface, the fluid's (not a wall's
        that rises above the water, not a body's)."""
        return None, None


class ExtrapolatedSurface(DirichletSurface):
    KEYS = {"eigenvalue_limit": Key("float", 0.45, gt=0.0, le=1.0,
                                    doc="the free-surface fluid particles get their gradient "
                                        "corrected along the surface's normal (with "
                                        "mps.gradient = \"corrected\") where the moment "
                                        "matrix along it is above this (0.5 on a flat "
                                        "surface)")}

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.eigenvalue_limit = settings["eigenvalue_limit"]

    def unknowns(self, has_pressure, surface, container):
        # Bodies' nodes and buffers at the surface keep P = 0: a body's face to the air is
        # where the load on it ends (its own thickness is no water), and a buffer's
        # surface is a gap the inlet has not filled yet. A wall beside the water carries
        # the water's pressure at its height, so it takes part.
        return has_pressure & ~surface, has_pressure & surface & container

    def terms(self, indptr, cols, position, is_unknown, moving, laplacian, n_rows):
        c = self.constants
        is_surface = is_unknown == kernels.SURFACE_ROW
        # The fluid's own surface draws the normals and the level; a wall that rises above
        # the water is not where the water ends.
        fluid_surface = is_surface & moving
        raw = kernels.surface_normals(indptr, cols, position, is_surface, c.re_laplacian, n_rows)
        normal = kernels.surface_fitted_normals(indptr, cols, position, raw, fluid_surface,
                                                c.re_laplacian, n_rows)
        diagonal = laplacian.coefficient * kernels.surface_ghost_diagonal(
            indptr, cols, position, c.re_laplacian, is_unknown != 0, is_surface, fluid_surface,
            normal, laplacian.inverse_cube, 0.5 * c.spacing,
            laplacian.dirichlet_diagonal / laplacian.coefficient, n_rows)
        # Only the fluid's own surface: a body's face to the air keeps P = 0 on its nodes,
        # and the load on it is measured with the gradient's own limit.
        corrected = (fluid_surface[:n_rows], normal, self.eigenvalue_limit)
        return diagonal, corrected
