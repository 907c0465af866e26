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
  stays symmetric (:func:`surface_ghost_diagonal`). The
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

import numba
import numpy as np

from parmps.config import Key
from parmps.core.pairs import (for_each_dimension, laplacian_weight, pair_component,
                               pair_distance2, row_length, weight_of_r2)
from parmps.core.symmetric import jacobi_diagonalise
from parmps.fluid.schemes.laplacian import SURFACE_ROW


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
        ``is_unknown``: every local particle's row kind (0, 1 or SURFACE_ROW);
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
        is_surface = is_unknown == SURFACE_ROW
        # The fluid's own surface draws the normals and the level; a wall that rises above
        # the water is not where the water ends.
        fluid_surface = is_surface & moving
        raw = surface_normals(indptr, cols, position, is_surface, c.re_laplacian, n_rows)
        normal = surface_fitted_normals(indptr, cols, position, raw, fluid_surface,
                                        c.re_laplacian, n_rows)
        diagonal = laplacian.coefficient * surface_ghost_diagonal(
            indptr, cols, position, c.re_laplacian, is_unknown != 0, is_surface, fluid_surface,
            normal, laplacian.inverse_cube, 0.5 * c.spacing,
            laplacian.dirichlet_diagonal / laplacian.coefficient, n_rows)
        # Only the fluid's own surface: a body's face to the air keeps P = 0 on its nodes,
        # and the load on it is measured with the gradient's own limit.
        corrected = (fluid_surface[:n_rows], normal, self.eigenvalue_limit)
        return diagonal, corrected


@for_each_dimension
def surface_normals(d, indptr, cols, position, is_surface, radius, n_rows):
    """``-sum_j w_ij r_ij`` over every neighbour (dummies too) of the rows with a free-surface
    particle (``is_surface``, every local particle) in their support or one themselves,
    0 elsewhere: it points away from the neighbours present, to where the missing ones
    are (not normalised): the side a normal of :func:`surface_fitted_normals` points to."""
    normal = np.zeros((n_rows, d))
    for i in range(n_rows):
        # Most rows are deep in the water: find that out from the few surface particles
        # before summing over every pair.
        near_surface = is_surface[i]
        if not near_surface:
            for p in range(indptr[i], indptr[i + 1]):
                j = cols[p]
                if is_surface[j] and weight_of_r2(pair_distance2(position, i, j, d),
                                                   radius) > 0.0:
                    near_surface = True
                    break
        if not near_surface:
            continue
        size = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, d)
            w = weight_of_r2(r2, radius)
            if w <= 0.0:
                continue
            size += w * np.sqrt(r2)
            for k in range(d):
                normal[i, k] -= w * pair_component(position, i, j, k)
        # A full neighbourhood's sum is rounding error, not a direction.
        if row_length(normal, i, d) <= 1e-9 * size:
            for k in range(d):
                normal[i, k] = 0.0
    return normal


# Eigenvalues of the surface particles' spread within this fraction of the largest of the
# smallest one count as tied: surface particles along one line (a lattice's edge, a jet)
# spread alike in every direction across it, and which of those the rotations return
# depends on the order of the sums, i.e. on how the ranks cut the domain (a side wall's
# row at the 3D dam break's corner took normals 113 degrees apart on 1 and 2 ranks).
_SPREAD_TIE = 1e-6


@numba.njit(cache=True)
def _least_spread_normal(spread, raw, i, work, vectors, out):
    """The unit direction of least ``spread`` (d×d, symmetric), turned to the side of
    ``raw[i]``, into ``out``. Where eigenvalues tie with the smallest (within
    ``_SPREAD_TIE`` of the largest, weighted down linearly across that band) the normal is
    ``raw[i]`` projected on their eigenvectors, so it does not depend on round-off
    (``work`` and ``vectors``: d×d scratch)."""
    d = spread.shape[0]
    for k in range(d):
        for m in range(d):
            work[k, m] = spread[k, m]
            vectors[k, m] = 1.0 if k == m else 0.0
    jacobi_diagonalise(work, vectors, True)
    smallest = 0
    largest = 0
    for k in range(1, d):
        if work[k, k] < work[smallest, smallest]:
            smallest = k
        if work[k, k] > work[largest, largest]:
            largest = k
    band = _SPREAD_TIE * work[largest, largest]
    tied = False
    raw_length = 0.0
    for m in range(d):
        out[m] = 0.0
        raw_length += raw[i, m] * raw[i, m]
    for k in range(d):
        gap = work[k, k] - work[smallest, smallest]
        if k == smallest:
            share = 1.0
        elif gap < band:
            share = 1.0 - gap / band
            tied = True
        else:
            continue
        along = 0.0
        for m in range(d):
            along += vectors[m, k] * raw[i, m]
        for m in range(d):
            out[m] += share * along * vectors[m, k]
    if tied:
        length = 0.0
        for m in range(d):
            length += out[m] * out[m]
        if length > 1e-24 * raw_length:
            length = np.sqrt(length)
            for m in range(d):
                out[m] /= length
            return
    # One direction of least spread: outwards, on the side of the missing neighbours.
    along = 0.0
    for m in range(d):
        along += vectors[m, smallest] * raw[i, m]
    sign = 1.0 if along >= 0.0 else -1.0
    for m in range(d):
        out[m] = sign * vectors[m, smallest]


@for_each_dimension
def surface_fitted_normals(d, indptr, cols, position, raw, on_surface, radius, n_rows):
    """Unit outward normals of the rows near the free surface (where ``raw``, from
    :func:`surface_normals`, is set; 0 elsewhere): the direction in which the
    free-surface particles ``on_surface`` (every local particle) within the radius,
    the row itself included, spread least (weighted by w_ij, the row by 1), turned
    to the side ``raw`` points to; where several directions spread least alike (the
    particles along a line), ``raw`` projected on them. With fewer than d + 1 such
    particles, ``raw`` itself. The missing neighbours' direction alone would lean away from a wall
    that rises above the water: there, only the air's side of the wall misses."""
    normal = np.zeros((n_rows, d))
    centre = np.empty(d)
    spread = np.empty((d, d))
    work = np.empty((d, d))
    vectors = np.empty((d, d))
    direction = np.empty(d)
    for i in range(n_rows):
        length = row_length(raw, i, d)
        if length <= 0.0:
            continue
        # The weighted spread of the free-surface particles about their centre: the
        # surface's normal is its direction of least spread. Positions relative to i.
        total = 0.0
        count = 0
        for k in range(d):
            centre[k] = 0.0
            for m in range(d):
                spread[k, m] = 0.0
        if on_surface[i]:
            total = 1.0
            count = 1
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not on_surface[j]:
                continue
            w = weight_of_r2(pair_distance2(position, i, j, d), radius)
            if w <= 0.0:
                continue
            total += w
            count += 1
            for k in range(d):
                centre[k] += w * pair_component(position, i, j, k)
                for m in range(d):
                    spread[k, m] += w * pair_component(position, i, j, k) * \
                        pair_component(position, i, j, m)
        fitted = count >= d + 1
        if fitted:
            for k in range(d):
                centre[k] /= total
            for k in range(d):
                for m in range(d):
                    spread[k, m] = spread[k, m] / total - centre[k] * centre[m]
            _least_spread_normal(spread, raw, i, work, vectors, direction)
            for k in range(d):
                normal[i, k] = direction[k]
        else:
            for k in range(d):
                normal[i, k] = raw[i, k] / length
    return normal


@numba.njit(cache=True, inline="always")
def _surface_depth(indptr, cols, position, i, is_surface, draws_level, radius, normal,
                   half_spacing, inverse_cube, d):
    # How far the zero level lies from i along the outward normal: half a spacing plus
    # the mean height above i of the free-surface particles that draw the level (the
    # fluid's), weighted as the sum weighs them, those less than half a spacing above
    # i counting 0 (i's own layer: its jitter does not lift the level). The same for a
    # free-surface particle as below the surface: the layer under the top one sits at
    # n*/n0 = 0.976 on a 2D lattice (re 2.3 l0), so jitter takes many of its particles
    # for surface, and their level is still the top layer's. Walls above the water
    # draw no level (counted, they had pulled it down beside a wall).
    depth = 0.0
    weight_sum = 0.0
    for p in range(indptr[i], indptr[i + 1]):
        j = cols[p]
        if not draws_level[j]:
            continue
        r2 = pair_distance2(position, i, j, d)
        w = laplacian_weight(r2, radius, inverse_cube)
        if w <= 0.0:
            continue
        height = 0.0
        for k in range(d):
            height += pair_component(position, i, j, k) * normal[k]
        if height > half_spacing:
            depth += w * height
        weight_sum += w
    if weight_sum <= 0.0:
        return half_spacing if is_surface[i] else -1.0
    return half_spacing + depth / weight_sum


@for_each_dimension
def surface_ghost_diagonal(d, indptr, cols, position, radius, is_unknown, is_surface,
                           draws_level, normal, inverse_cube, half_spacing, undirected, n_rows):
    """Per owned row, the diagonal the missing neighbours add when the pressure is zero
    half a spacing beyond the free-surface particles (before the Laplacian's coefficient).

    ``is_unknown`` and ``is_surface`` mark every local particle: a row solved for,
    a free-surface particle. An unknown row with a free-surface particle in its
    support (or one itself) misses the neighbours beyond the surface. Their first
    moment is minus that of the neighbours present, ``-V_i = -sum_j w_ij r_ij``
    (every neighbour counts, dummies too: only air is missing). A missing neighbour
    g takes the value of the linear field that is P_i at i and 0 on the surface
    ``delta_i`` away along ``-V_i/|V_i|``: ``P_g - P_i = -P_i (r_ig . n)/delta_i``,
    so the missing ones add ``-P_i |V_i| / delta_i`` to the row's sum: the diagonal
    only, and the matrix stays symmetric (Gibou et al. 2002's ghost-fluid Dirichlet
    condition, with the kernel's moment in place of the grid's). ``delta_i`` is
    half a spacing plus the mean height above i, along the normal, of the
    free-surface particles ``draws_level`` (every local particle: the fluid's), those
    less than half a spacing above i counting 0: half a spacing for a particle of
    the top layer, and for a particle below it taken for surface (as jitter takes
    many of the second layer's) the top layer's level still. A linear field that
    is zero on that surface satisfies every such row exactly.

    A free-surface row whose missing neighbours have no direction (it has no
    neighbour, or neighbours all round, as in a sheet one particle thick) gets
    ``undirected`` instead: without it the row would be singular when the
    compressibility is zero. Its size, an interior row's diagonal, holds such a
    particle near zero as the plain Dirichlet condition would.
    """
    extra = np.zeros(n_rows)
    for i in range(n_rows):
        if not is_unknown[i]:
            continue
        if is_surface[i]:
            extra[i] = undirected
        if row_length(normal, i, d) <= 0.0:
            continue
        # The missing neighbours' first moment along the normal: minus the present ones'.
        moment = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            w = laplacian_weight(pair_distance2(position, i, j, d), radius, inverse_cube)
            if w <= 0.0:
                continue
            for k in range(d):
                moment -= w * pair_component(position, i, j, k) * normal[i, k]
        depth = _surface_depth(indptr, cols, position, i, is_surface, draws_level, radius,
                               normal[i], half_spacing, inverse_cube, d)
        if depth > 0.0 and moment > 0.0:
            extra[i] = moment / depth
    return extra

