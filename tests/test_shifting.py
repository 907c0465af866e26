"""Particle shifting (parmps/fluid/schemes/shifting.py) on lattices in 2D and 3D.

The concentration gradient against finite differences of the smooth density it is the
gradient of; the Fickian shift: none for a particle at rest, none on the full lattice,
a jittered lattice made more even, and nothing across a flat free surface.
"""

import numpy as np
import pytest

from parmps.core.density import smooth_density
from parmps.core.lattice import smooth_reference
from parmps.core.neighbours import pair_list
from parmps.core.particles import FLUID, SOLID, WALL
from parmps.fluid.constants import MPSConstants
from parmps.fluid.schemes import SHIFTINGS, scheme_class
from parmps.fluid.schemes.shifting import concentration_gradient

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
    gradient = concentration_gradient(indptr, cols, position, support, rows, n)
    h = 1e-7 * SPACING
    for i in np.flatnonzero(_inside(position, side, 2))[:5]:
        for k in range(d):
            shifted = []
            for sign in (1, -1):
                moved = position.copy()
                moved[i, k] += sign * h
                shifted.append(smooth_density(indptr, cols, moved, support, n)[i])
            assert gradient[i, k] == pytest.approx((shifted[0] - shifted[1]) / (2 * h),
                                                   rel=1e-5, abs=1e-6 / SPACING)
    full = _lattice(d, side)
    indptr, cols = pair_list(full, support * 1.2)
    gradient = concentration_gradient(indptr, cols, full, support, rows, n)
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
        density = smooth_density(indptr, cols, x, constants.re_number_density, n)
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
    gradient = concentration_gradient(indptr, cols, position,
                                      constants.re_number_density, near, n)
    assert np.all(gradient[near & top, -1] < 0.0)
    length = np.sqrt((shift ** 2).sum(axis=1))
    assert length[near].max() > 0.0
    # The fitted normal of a jittered flat surface is close to vertical, not exactly:
    # the shift is perpendicular to it, so its vertical part is small, not zero.
    assert np.all(np.abs(shift[near & top, -1]) <= 0.3 * length[near & top] + 1e-300)
    deep = rows & ~near
    assert np.abs(shift[deep, -1]).max() > 0.3 * length[deep].max()


def _stabilisation(d, **settings):
    cls = scheme_class(SHIFTINGS, "dynamic_stabilisation")
    defaults = {key: spec.default for key, spec in cls.KEYS.items()}
    return cls({**defaults, **settings}, _constants(d))


@pytest.mark.parametrize("d", [2, 3])
def test_the_dynamic_stabilisation_takes_a_still_pair_back_to_its_distance(d):
    """With separation 1, two fluid particles at rest 0.6 l0 apart (0.8 l0 the distance):
    after the change and the step's move they stand 0.8 l0 apart, to 1e-12 l0, with
    opposite velocities; beside a fixed partner the fluid particle alone moves, the whole
    way; a body's node is left out."""
    stabilisation = _stabilisation(d, separation=1.0)
    dt = 1e-3
    position = np.zeros((2, d))
    position[1, 0] = 0.6 * SPACING
    velocity = np.zeros((2, d))
    indptr, cols = pair_list(position, 3 * SPACING)
    for kind, expected in (([FLUID, FLUID], 0.1), ([FLUID, WALL], 0.2)):
        shift, change = stabilisation.regularise(indptr, cols, position, velocity, None, None,
                                                 np.array(kind, np.int8), dt, 2)
        moved = position + shift
        assert np.linalg.norm(moved[1] - moved[0]) == pytest.approx(0.8 * SPACING,
                                                                    abs=1e-12 * SPACING)
        assert shift[0, 0] == pytest.approx(-expected * SPACING, abs=1e-12 * SPACING)
        assert np.allclose(shift, dt * change, rtol=0, atol=1e-15)
        if kind[1] == FLUID:
            assert np.allclose(change.sum(axis=0), 0.0, rtol=0, atol=1e-12)
    _, change = stabilisation.regularise(indptr, cols, position, velocity, None, None,
                                         np.array([FLUID, SOLID], np.int8), dt, 2)
    assert np.all(change == 0.0)


@pytest.mark.parametrize("d, side", [(2, 12), (3, 6)])
def test_the_dynamic_stabilisation_keeps_momentum_and_leaves_a_lattice(d, side):
    """On a lattice jittered by 0.3 l0 with random velocities every close pair shares its
    change: the changes sum to zero (1e-12 of the largest); with separation 0 only pairs
    that approach change, and each two-particle exchange loses kinetic energy; on the
    regular lattice (every pair at l0 or more) nothing changes."""
    dt = 1e-3
    rng = np.random.default_rng(7)
    position = _lattice(d, side, jitter=0.3, seed=2)
    n = len(position)
    velocity = rng.normal(0.0, 0.1 * SPACING / dt, position.shape)
    indptr, cols = pair_list(position, 3 * SPACING)
    kind = np.full(n, FLUID, np.int8)
    for separation in (1.0, 0.0):
        _, change = _stabilisation(d, separation=separation).regularise(
            indptr, cols, position, velocity, None, None, kind, dt, n)
        largest = np.abs(change).max()
        assert largest > 0.0
        assert np.abs(change.sum(axis=0)).max() < 1e-12 * largest * n
    pair = np.array([[0.0] * d, [0.7 * SPACING] + [0.0] * (d - 1)])
    approach = np.zeros((2, d))
    approach[0, 0], approach[0, -1] = 1.0, 0.5
    indptr2, cols2 = pair_list(pair, 3 * SPACING)
    _, change = _stabilisation(d, separation=0.0).regularise(
        indptr2, cols2, pair, approach, None, None, np.full(2, FLUID, np.int8), dt, 2)
    after = approach + change
    assert after[1, 0] - after[0, 0] == pytest.approx(0.0, abs=1e-15)
    assert (after ** 2).sum() < (approach ** 2).sum()
    full = _lattice(d, side)
    indptr, cols = pair_list(full, 3 * SPACING)
    _, change = _stabilisation(d).regularise(indptr, cols, full, velocity, None, None,
                                             kind, dt, n)
    assert np.all(change == 0.0)
