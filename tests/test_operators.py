"""MPS operators on a square lattice, where they are exact (DESIGN.md §1.1)."""

import numpy as np
import pytest

from parmps.core import operators
from parmps.core.neighbours import close_pairs, pair_list, rows_of

SPACING = 0.01


def lattice(n=21):
    return np.mgrid[0:n, 0:n].reshape(2, -1).T * SPACING


def geometry(position, radius):
    indptr, cols = pair_list(position, radius)
    return operators.PairGeometry(indptr, rows_of(indptr), cols, position)


def interior(position, margin):
    lo, hi = position.min() + margin, position.max() - margin
    return np.all((position > lo) & (position < hi), axis=1)


def test_reference_values_match_hand_computation():
    # re = 2.1 l0: 4 neighbours at l0 (w = 1.1), 4 at sqrt(2) l0, 4 at 2 l0.
    n0, lambda0 = operators.reference_values(SPACING, 2.1 * SPACING)
    w1, w2, w3 = 2.1 - 1, 2.1 / np.sqrt(2) - 1, 2.1 / 2 - 1
    assert n0 == pytest.approx(4 * (w1 + w2 + w3), rel=1e-14)
    expected_lambda = 4 * (w1 * 1 + w2 * 2 + w3 * 4) * SPACING ** 2 / n0
    assert lambda0 == pytest.approx(expected_lambda, rel=1e-14)
    # re = 3.1 l0 adds the rings at sqrt5, sqrt8, 3 l0.
    n0_lap, lambda_lap = operators.reference_values(SPACING, 3.1 * SPACING)
    rings = {1: 4, 2: 4, 4: 4, 5: 8, 8: 4, 9: 4}
    hand = sum(count * (3.1 / np.sqrt(r2) - 1) for r2, count in rings.items())
    hand_lambda = sum(count * (3.1 / np.sqrt(r2) - 1) * r2 for r2, count in rings.items())
    assert n0_lap == pytest.approx(hand, rel=1e-14)
    assert lambda_lap == pytest.approx(hand_lambda / hand * SPACING ** 2, rel=1e-14)


def test_neighbour_search_matches_brute_force():
    rng = np.random.default_rng(1)
    position = rng.uniform(0, 0.2, size=(600, 2))
    radius = 0.031
    indptr, cols = pair_list(position, radius, n_rows=400)
    distance = np.linalg.norm(position[:400, None, :] - position[None, :, :], axis=2)
    for i in range(400):
        expected = set(np.flatnonzero((distance[i] < radius) & (np.arange(600) != i)))
        assert set(cols[indptr[i]:indptr[i + 1]]) == expected
    i, j = close_pairs(position, 0.005)
    brute = {(a, b) for a in range(600) for b in range(a + 1, 600)
             if np.linalg.norm(position[a] - position[b]) < 0.005}
    assert set(zip(i.tolist(), j.tolist())) == brute


def test_number_density_of_interior_particle_is_n0():
    position = lattice()
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = operators.reference_values(SPACING, radius)
    density = operators.number_density(pairs, pairs.weight(radius), len(position))
    inside = interior(position, 3 * SPACING)
    np.testing.assert_allclose(density[inside], n0, rtol=1e-12)


def test_laplacian_of_r_squared_is_2d():
    position = lattice()
    radius = 3.1 * SPACING
    pairs = geometry(position, radius)
    n0, lambda0 = operators.reference_values(SPACING, radius)
    field = (position ** 2).sum(axis=1)
    result = operators.laplacian(pairs, pairs.weight(radius), field, len(position), n0, lambda0)
    inside = interior(position, 4 * SPACING)
    np.testing.assert_allclose(result[inside], 2 * operators.DIMENSION, rtol=1e-10)


@pytest.mark.parametrize("shift", [True, False])
def test_gradient_of_linear_field_is_exact(shift):
    position = lattice()
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = operators.reference_values(SPACING, radius)
    w = pairs.weight(radius)
    field = 3.0 * position[:, 0] - 2.0 * position[:, 1] + 5.0
    include = np.ones(len(position), bool)
    reference = (operators.neighbourhood_minimum(pairs, w, field, len(position), include)
                 if shift else field)
    result = operators.gradient(pairs, w, field, len(position), n0, reference, include)
    inside = interior(position, 3 * SPACING)
    # Tolerance: round-off of sums of ~12 terms of size 1/l0.
    np.testing.assert_allclose(result[inside], [[3.0, -2.0]] * int(inside.sum()), atol=1e-9)


def test_divergence_of_linear_velocity():
    position = lattice()
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = operators.reference_values(SPACING, radius)
    velocity = np.column_stack([2.0 * position[:, 0], -0.5 * position[:, 1]])
    result = operators.divergence(pairs, pairs.weight(radius), velocity, len(position), n0)
    inside = interior(position, 3 * SPACING)
    np.testing.assert_allclose(result[inside], 1.5, rtol=1e-10)


def test_neighbourhood_minimum_respects_include_mask():
    position = lattice(5)
    radius = 1.5 * SPACING
    pairs = geometry(position, radius)
    field = np.arange(len(position), dtype=float)
    include = np.ones(len(position), bool)
    include[0] = False
    minimum = operators.neighbourhood_minimum(pairs, pairs.weight(radius), field,
                                              len(position), include)
    # Particle 1's neighbours are 0 (excluded), 2, 5, 6 (diagonal at sqrt2 < 1.5): min is itself.
    assert minimum[1] == 1.0
    assert minimum[0] == 0.0
