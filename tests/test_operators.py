"""MPS operators on a square lattice, where they are exact (docs/design.md §1.1)."""

import numpy as np
import pytest

from parmps.core import neighbours, operators
from parmps.core.lattice import reference_values
from parmps.core.neighbours import close_pairs, pair_list, rows_of

SPACING = 0.01


# Lattice sides: 21 points in 2D, 13 in 3D (2197 particles, 27 deep in the interior).
SIDE = {2: 21, 3: 13}


def lattice(n=21, dimension=2):
    return np.indices((n,) * dimension).reshape(dimension, -1).T * SPACING


def geometry(position, radius):
    indptr, cols = pair_list(position, radius)
    return operators.PairGeometry(indptr, rows_of(indptr), cols, position)


def interior(position, margin):
    lo, hi = position.min() + margin, position.max() - margin
    return np.all((position > lo) & (position < hi), axis=1)


@pytest.mark.parametrize("dimension", [1, 2, 3])
def test_neighbour_search_matches_brute_force(dimension):
    rng = np.random.default_rng(1)
    # About 14 neighbours per particle in every dimension.
    n, radius = 600, {1: 0.0025, 2: 0.031, 3: 0.06}[dimension]
    extent = {1: 0.1, 2: 0.2, 3: 0.2}[dimension]
    position = rng.uniform(0, extent, size=(n, dimension))
    indptr, cols = pair_list(position, radius, n_rows=400)
    distance = np.linalg.norm(position[:400, None, :] - position[None, :, :], axis=2)
    for i in range(400):
        expected = set(np.flatnonzero((distance[i] < radius) & (np.arange(n) != i)))
        found = cols[indptr[i]:indptr[i + 1]]
        assert len(found) == len(set(found))
        assert set(found) == expected
    assert np.mean(np.diff(indptr)) > 5
    close = 0.3 * radius
    i, j = close_pairs(position, close)
    brute = {(a, b) for a in range(n) for b in range(a + 1, n)
             if np.linalg.norm(position[a] - position[b]) < close}
    assert set(zip(i.tolist(), j.tolist())) == brute


def test_neighbour_search_3d_sparse_cells():
    # A few clusters far apart: the cell size grows to keep the cell table O(n),
    # and every row still finds exactly its neighbours.
    rng = np.random.default_rng(4)
    centres = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 7.0, 3.0], [4.0, 4.0, 9.0]])
    position = (centres[:, None, :] + rng.uniform(-0.05, 0.05, (4, 150, 3))).reshape(-1, 3)
    radius = 0.03
    indptr, cols = pair_list(position, radius)
    distance = np.linalg.norm(position[:, None, :] - position[None, :, :], axis=2)
    for i in range(len(position)):
        expected = np.flatnonzero((distance[i] < radius) & (np.arange(len(position)) != i))
        assert sorted(cols[indptr[i]:indptr[i + 1]]) == list(expected)


@pytest.mark.parametrize("dimension", [2, 3])
def test_neighbours_come_in_cell_order(dimension):
    # Within a row, neighbours come cell by cell in ascending cell number
    # x + nx (y + ny z) (cells of side re / CELLS_PER_RADIUS from the lower corner), and
    # within a cell in particle index order.
    rng = np.random.default_rng(2)
    radius = 0.05
    position = rng.uniform(0, 0.3, size=(800, dimension))
    indptr, cols = pair_list(position, radius)
    side = radius / neighbours.CELLS_PER_RADIUS * (1.0 + 1e-12)
    origin = position.min(axis=0) - 1e-12
    cells = ((position.max(axis=0) - origin) / side).astype(int) + 1
    cell = ((position - origin) / side).astype(int)
    key = np.ravel_multi_index(cell.T[::-1], cells[::-1])
    for i in range(len(position)):
        found = cols[indptr[i]:indptr[i + 1]]
        assert list(found) == sorted(found, key=lambda j: (key[j], j))


@pytest.mark.parametrize("dimension", [2, 3])
def test_number_density_of_interior_particle_is_n0(dimension):
    position = lattice(SIDE[dimension], dimension)
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = reference_values(SPACING, radius, dimension)
    density = operators.number_density(pairs, pairs.weight(radius), len(position))
    inside = interior(position, 3 * SPACING)
    assert inside.sum() > 0
    np.testing.assert_allclose(density[inside], n0, rtol=1e-12)


@pytest.mark.parametrize("dimension", [2, 3])
def test_laplacian_of_r_squared_is_2d(dimension):
    position = lattice(SIDE[dimension], dimension)
    radius = 3.1 * SPACING
    pairs = geometry(position, radius)
    assert pairs.dimension == dimension
    n0, lambda0 = reference_values(SPACING, radius, dimension)
    field = (position ** 2).sum(axis=1)
    result = operators.laplacian(pairs, pairs.weight(radius), field, len(position), n0, lambda0)
    inside = interior(position, 4 * SPACING)
    assert inside.sum() > 0
    np.testing.assert_allclose(result[inside], 2 * dimension, rtol=1e-10)


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("shift", [True, False])
def test_gradient_of_linear_field_is_exact(shift, dimension):
    position = lattice(SIDE[dimension], dimension)
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = reference_values(SPACING, radius, dimension)
    w = pairs.weight(radius)
    slope = np.array([3.0, -2.0, 0.5])[:dimension]
    field = position @ slope + 5.0
    include = np.ones(len(position), bool)
    reference = (operators.neighbourhood_minimum(pairs, w, field, len(position), include)
                 if shift else field)
    result = operators.gradient(pairs, w, field, len(position), n0, reference, include)
    inside = interior(position, 3 * SPACING)
    assert inside.sum() > 0
    # Tolerance: round-off of sums of ~12 (2D) or ~32 (3D) terms of size 1/l0.
    np.testing.assert_allclose(result[inside], np.broadcast_to(slope, (inside.sum(), dimension)),
                               atol=1e-9)


@pytest.mark.parametrize("dimension", [2, 3])
def test_divergence_of_linear_velocity(dimension):
    position = lattice(SIDE[dimension], dimension)
    radius = 2.1 * SPACING
    pairs = geometry(position, radius)
    n0, _ = reference_values(SPACING, radius, dimension)
    rates = np.array([2.0, -0.5, 1.25])[:dimension]
    velocity = position * rates
    result = operators.divergence(pairs, pairs.weight(radius), velocity, len(position), n0)
    inside = interior(position, 3 * SPACING)
    np.testing.assert_allclose(result[inside], rates.sum(), rtol=1e-10)


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
