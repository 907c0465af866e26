"""The compiled pair loops agree with the numpy operators (the readable reference)."""

import numpy as np
import pytest

from parmps.core import kernels, operators
from parmps.core.neighbours import pair_list, rows_of

SPACING = 0.01


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(7)
    grid = np.mgrid[0:30, 0:20].reshape(2, -1).T * SPACING
    position = grid + rng.normal(0, 0.1 * SPACING, grid.shape)
    velocity = rng.normal(0, 0.1, grid.shape)
    pressure = rng.uniform(0, 100, len(grid))
    is_dummy = grid[:, 1] < 2 * SPACING - 1e-9
    n_rows = 450
    indptr, cols = pair_list(position, 3.7 * SPACING, n_rows=n_rows)
    pairs = operators.PairGeometry(indptr, rows_of(indptr), cols, position)
    return position, velocity, pressure, is_dummy, n_rows, indptr, cols, pairs


def test_number_density(scene):
    position, _, _, _, n, indptr, cols, pairs = scene
    radius = 2.1 * SPACING
    density, count = kernels.number_density(indptr, cols, position, radius, n)
    np.testing.assert_allclose(density, operators.number_density(pairs, pairs.weight(radius), n),
                               rtol=1e-12)
    assert np.array_equal(count, np.bincount(pairs.rows, weights=pairs.weight(radius) > 0,
                                             minlength=n).astype(int))


def test_laplacian_and_divergence(scene):
    position, velocity, _, _, n, indptr, cols, pairs = scene
    radius = 3.1 * SPACING
    n0, lambda0 = operators.reference_values(SPACING, radius)
    expected = operators.laplacian(pairs, pairs.weight(radius), velocity, n, n0, lambda0)
    got = 2 * operators.DIMENSION / (lambda0 * n0) * kernels.vector_laplacian_sum(
        indptr, cols, position, velocity, radius, n)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-8)
    radius = 2.1 * SPACING
    n0, _ = operators.reference_values(SPACING, radius)
    expected = operators.divergence(pairs, pairs.weight(radius), velocity, n, n0)
    got = operators.DIMENSION / n0 * kernels.divergence_sum(indptr, cols, position, velocity,
                                                            radius, n)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-8)


def test_pressure_gradient(scene):
    position, _, pressure, is_dummy, n, indptr, cols, pairs = scene
    radius = 2.1 * SPACING
    n0, _ = operators.reference_values(SPACING, radius)
    w = pairs.weight(radius)
    include = ~is_dummy
    minimum = operators.neighbourhood_minimum(pairs, w, pressure, n, include)
    expected = operators.gradient(pairs, w, pressure, n, n0, minimum, include)
    got = operators.DIMENSION / n0 * kernels.pressure_gradient_sum(
        indptr, cols, position, pressure, include, radius, n)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-6)


def test_corrected_gradient_is_exact_for_a_linear_field(scene):
    position, _, _, is_dummy, n, indptr, cols, _ = scene
    radius = 2.1 * SPACING
    n0, _ = operators.reference_values(SPACING, radius)
    slope = np.array([3.0e3, -9.81e3])
    pressure = 500.0 + position @ slope
    include = ~is_dummy
    pairs = scene[7]
    # The sums with P_i in place of Pmin_i: the correction makes these exact (the
    # Pmin shift adds (P_i - Pmin_i) sum_j r_ij w / r^2, which it only rescales).
    gradient = operators.gradient(pairs, pairs.weight(radius), pressure, n, n0,
                                  pressure[:n], include)
    plain = gradient.copy()
    corrected = kernels.correct_gradient(indptr, cols, position, include, radius,
                                         operators.DIMENSION / n0, gradient, 0.7)
    # Interior rows (a full neighbourhood of pressure-carrying particles) are corrected
    # and exact; the jittered lattice leaves the plain sums off by a few percent.
    x, y = position[:n, 0], position[:n, 1]
    interior = (x > 3 * SPACING) & (x < 26 * SPACING) & (y > 5 * SPACING) & (y < 16 * SPACING)
    assert corrected >= np.count_nonzero(interior)
    np.testing.assert_allclose(gradient[interior], np.broadcast_to(slope, (interior.sum(), 2)),
                               rtol=1e-9)
    assert np.abs(plain[interior] - slope).max() > 1e-3 * np.abs(slope).max()
    # A row with a truncated neighbourhood (the lattice's corner) keeps the plain sum.
    corner = np.argmin(x + y)
    np.testing.assert_array_equal(gradient[corner], plain[corner])


def test_collisions_conserve_momentum_between_moving_particles(scene):
    position, velocity, _, _, n, indptr, cols, _ = scene
    # Squeeze the lattice so many pairs are closer than the collision distance.
    squeezed = position * 0.6
    full_indptr, full_cols = pair_list(squeezed, 3.7 * SPACING)
    moving = np.ones(len(position), bool)
    change = kernels.collision_change(full_indptr, full_cols, squeezed, velocity, moving,
                                      0.5 * SPACING, 0.2, len(position))
    assert np.abs(change).max() > 0
    np.testing.assert_allclose(change.sum(axis=0), 0.0, atol=1e-12)


def reference_rows(rows, cols, w, unknown_row, global_row, is_dummy, coefficient, shift):
    """The pressure matrix rows by plain numpy, for comparison."""
    n_owned = len(unknown_row)
    active = unknown_row[rows] & (w > 0.0) & ~is_dummy[cols]
    diagonal = coefficient * np.bincount(rows[active], weights=w[active], minlength=n_owned)
    diagonal += shift
    matrix = {}
    for i in np.flatnonzero(unknown_row):
        matrix[(global_row[i], global_row[i])] = diagonal[i]
    coupled = active & (global_row[cols] >= 0)
    for i, j, value in zip(rows[coupled], cols[coupled], w[coupled]):
        matrix[(global_row[i], global_row[j])] = -coefficient * value
    return matrix


def test_poisson_rows_match_reference_and_are_symmetric(scene):
    position, _, _, is_dummy, _, _, _, _ = scene
    radius = 3.1 * SPACING
    n = len(position)
    indptr, cols = pair_list(position, 3.7 * SPACING)
    pairs = operators.PairGeometry(indptr, rows_of(indptr), cols, position)
    density, _ = kernels.number_density(indptr, cols, position, 2.1 * SPACING, n)
    n0, _ = operators.reference_values(SPACING, 2.1 * SPACING)
    unknown = ~is_dummy & (density >= 0.97 * n0)
    row_number = np.full(n, -1, np.int64)
    row_number[~is_dummy] = np.arange(int((~is_dummy).sum()))
    unknown_row = np.full(n, -1, np.int64)
    unknown_row[unknown] = row_number[unknown]
    row_ptr, columns, values = kernels.poisson_rows(indptr, cols, position, radius, row_number,
                                                    unknown.astype(np.int8), 860.0, 0.45, 7.0)
    expected = reference_rows(pairs.rows, cols, pairs.weight(radius), unknown, unknown_row,
                              is_dummy, 860.0, 0.45)
    for i in np.flatnonzero(~is_dummy & ~unknown):
        expected[(row_number[i], row_number[i])] = 7.0
    got = {}
    assert len(row_ptr) - 1 == int((~is_dummy).sum())
    for k in range(len(row_ptr) - 1):
        row = columns[row_ptr[k]]
        for p in range(row_ptr[k], row_ptr[k + 1]):
            got[(row, columns[p])] = values[p]
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-12)
        assert got[(key[1], key[0])] == pytest.approx(value, rel=1e-12)
