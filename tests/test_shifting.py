"""Particle shifting (parmps/fluid/schemes/shifting.py) on lattices in 2D and 3D.

The concentration gradient against finite differences of the smooth density it is the
gradient of; the Fickian shift: none for a particle at rest, none on the full lattice,
a jittered lattice made more even, and nothing across a flat free surface.
"""

import numpy as np
import pytest

from parmps.core import kernels
from parmps.core.lattice import smooth_reference
from parmps.core.neighbours import pair_list
from parmps.fluid.constants import MPSConstants
from parmps.fluid.schemes import SHIFTINGS, scheme_class

SPACING = 0.01


def _lattice(d, side, jitter=0.0, seed=0):
    grid = np.stack(np.meshgrid(*[np.arange(side)] * d, indexing="ij"), -1).reshape(-1, d)
    position = grid * SPACING
    if jitter:
        position = position + np.random.default_rng(seed).uniform(
            -jitter * SPACING, jitter * SPACING, position.shape)
    return position


def _inside(position, side, margin):
    site = np.rint(position / SPACING)
    return np.all((site >= margin) & (site <= side - 1 - margin), axis=1)


def _constants(d):
    from parmps.core import lattice
    n0, _ = lattice.reference_values(SPACING, 2.3 * SPACING, d)
    n0_laplacian, lambda0 = lattice.reference_values(SPACING, 3.1 * SPACING, d)
    return MPSConstants(dimension=d, spacing=SPACING, re_number_density=2.3 * SPACING,
                        re_laplacian=3.1 * SPACING, search_radius=3.4 * SPACING, n0=n0,
                        n0_laplacian=n0_laplacian, lambda0=lambda0,
                        neighbour_count0=lattice.neighbour_count_reference(
                            SPACING, 2.3 * SPACING, d),
                        density=1000.0, viscosity=1e-6)


def _fickian(d, **settings):
    cls = scheme_class(SHIFTINGS, "fickian")
    defaults = {key: spec.default for key, spec in cls.KEYS.items()}
    return cls({**defaults, **settings}, _constants(d))


@pytest.mark.parametrize("d, side", [(2, 12), (3, 7)])
def test_the_concentration_gradient_is_the_gradient_of_the_smooth_density(d, side):
    """grad_i sum_j W(|x_i - x_j|) against central differences in x_i (1e-7 l0 steps), on a
    lattice jittered by 0.2 l0; 0 on the full lattice's interior (1e-10 of a one-spacing
    gradient)."""
    support = 2.3 * SPACING
    position = _lattice(d, side, jitter=0.2, seed=3)
    n = len(position)
    indptr, cols = pair_list(position, support * 1.2)
    rows = np.ones(n, bool)
    gradient = kernels.concentration_gradient(indptr, cols, position, support, rows, n)
    h = 1e-7 * SPACING
    for i in np.flatnonzero(_inside(position, side, 2))[:5]:
        for k in range(d):
            shifted = []
            for sign in (1, -1):
                moved = position.copy()
                moved[i, k] += sign * h
                shifted.append(kernels.smooth_density(indptr, cols, moved, support, n)[i])
            assert gradient[i, k] == pytest.approx((shifted[0] - shifted[1]) / (2 * h),
                                                   rel=1e-5, abs=1e-6 / SPACING)
    full = _lattice(d, side)
    indptr, cols = pair_list(full, support * 1.2)
    gradient = kernels.concentration_gradient(indptr, cols, full, support, rows, n)
    inside = _inside(full, side, 3)
    assert np.abs(gradient[inside]).max() < 1e-10 / SPACING
    assert np.abs(gradient[~inside]).max() > 1.0 / SPACING  # the lattice's edge


@pytest.mark.parametrize("d, side", [(2, 20), (3, 10)])
def test_the_fickian_shift_evens_a_jittered_lattice_and_leaves_a_still_one(d, side):
    """One shift at |u| dt = 0.2 l0 lowers the spread of the smooth density over the
    interior of a lattice jittered by 0.15 l0 by a fifth at least; a particle at rest is
    not shifted; no shift exceeds max_shift."""
    constants = _constants(d)
    shifting = _fickian(d)
    position = _lattice(d, side, jitter=0.15, seed=5)
    n = len(position)
    indptr, cols = pair_list(position, constants.search_radius)
    dt = 1e-3
    velocity = np.zeros_like(position)
    velocity[:, 0] = 0.2 * SPACING / dt
    velocity[0] = 0.0
    on_surface = np.zeros(n, bool)
    rows = _inside(position, side, 1)
    shift = shifting.shift(indptr, cols, position, velocity, on_surface, rows, dt, n)
    assert np.all(shift[0] == 0.0) and np.all(shift[~rows] == 0.0)
    assert np.sqrt((shift ** 2).sum(axis=1)).max() <= shifting.max_shift * (1 + 1e-12)
    judged = _inside(position, side, 3)
    reference = smooth_reference(SPACING, constants.re_number_density, d)

    def spread(x):
        density = kernels.smooth_density(indptr, cols, x, constants.re_number_density, n)
        return np.std(density[judged] / reference)

    before, after = spread(position), spread(position + shift)
    assert after < 0.8 * before, (before, after)


@pytest.mark.parametrize("d, side", [(2, 16), (3, 8)])
def test_the_fickian_shift_keeps_only_the_surface_component_near_a_free_surface(d, side):
    """Water below a flat free surface (the top layer on the surface): within the Laplacian's
    radius of it the shift has no component along the normal (1e-12 of the shift), while
    the concentration gradient there points down, into the water."""
    constants = _constants(d)
    shifting = _fickian(d)
    position = _lattice(d, side, jitter=0.1, seed=11)
    top = np.rint(position[:, -1] / SPACING) == side - 1
    n = len(position)
    indptr, cols = pair_list(position, constants.search_radius)
    dt = 1e-3
    velocity = np.full_like(position, 0.1 * SPACING / dt)
    rows = _inside(position[:, :-1], side, 2) & (np.rint(position[:, -1] / SPACING) >= 2)
    shift = shifting.shift(indptr, cols, position, velocity, top, rows, dt, n)
    near = rows & (position[:, -1] > (side - 1 - 3.1) * SPACING)
    gradient = kernels.concentration_gradient(indptr, cols, position,
                                              constants.re_number_density, near, n)
    assert np.all(gradient[near & top, -1] < 0.0)
    length = np.sqrt((shift ** 2).sum(axis=1))
    assert length[near].max() > 0.0
    # The fitted normal of a jittered flat surface is close to vertical, not exactly:
    # the shift is perpendicular to it, so its vertical part is small, not zero.
    assert np.all(np.abs(shift[near & top, -1]) <= 0.3 * length[near & top] + 1e-300)
    deep = rows & ~near
    assert np.abs(shift[deep, -1]).max() > 0.3 * length[deep].max()
