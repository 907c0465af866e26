"""The compiled pair loops agree with the numpy operators (the readable reference), in 2D and 3D."""

import numpy as np
import pytest

from parmps.core import operators
from parmps.core.density import number_density
from parmps.core.lattice import reference_values
from parmps.core.neighbours import pair_list, pairs_within, rows_near, rows_of
from parmps.core.pairs import for_each_dimension
from parmps.core.symmetric import has_eigenvalue_below, jacobi_diagonalise
from parmps.fluid.collisions import WALL_GAP_CLOSURE, WALL_NORMAL_REACH, collision_change
from parmps.fluid.ppe import sort_row_columns
from parmps.fluid.projection import largest_norm2, lowest_id_not_finite
from parmps.fluid.schemes.gradient import (correct_gradient, correct_normal_component,
                                           corrected_pressure_gradient, pressure_gradient_sum)
from parmps.fluid.schemes.laplacian import (poisson_rows, poisson_rows_into, poisson_rows_room,
                                            rows_in_index_order, variable_density_poisson_rows)
from parmps.fluid.schemes.mixed import divergence_sum
from parmps.fluid.viscous import vector_laplacian_sum

SPACING = 0.01

# Jittered lattices: 30 x 20 in 2D, 12 x 11 x 10 in 3D; the rows are the first
# 3/4 of the particles (the rest play ghosts). Dummies are the two lowest layers in y.
SHAPES = {2: (30, 20), 3: (12, 11, 10)}


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def scene(request):
    dimension = request.param
    rng = np.random.default_rng(7)
    shape = SHAPES[dimension]
    grid = np.indices(shape).reshape(dimension, -1).T * SPACING
    position = grid + rng.normal(0, 0.1 * SPACING, grid.shape)
    velocity = rng.normal(0, 0.1, grid.shape)
    pressure = rng.uniform(0, 100, len(grid))
    is_dummy = grid[:, 1] < 2 * SPACING - 1e-9
    n_rows = 3 * len(grid) // 4
    indptr, cols = pair_list(position, 3.7 * SPACING, n_rows=n_rows)
    pairs = operators.PairGeometry(indptr, rows_of(indptr), cols, position)
    return position, velocity, pressure, is_dummy, n_rows, indptr, cols, pairs


def test_number_density(scene):
    position, _, _, _, n, indptr, cols, pairs = scene
    radius = 2.1 * SPACING
    density, count = number_density(indptr, cols, position, radius, n)
    np.testing.assert_allclose(density, operators.number_density(pairs, pairs.weight(radius), n),
                               rtol=1e-12)
    assert np.array_equal(count, np.bincount(pairs.rows, weights=pairs.weight(radius) > 0,
                                             minlength=n).astype(int))


def test_laplacian_and_divergence(scene):
    position, velocity, _, _, n, indptr, cols, pairs = scene
    radius = 3.1 * SPACING
    d = position.shape[1]
    n0, lambda0 = reference_values(SPACING, radius, d)
    expected = operators.laplacian(pairs, pairs.weight(radius), velocity, n, n0, lambda0)
    got = 2 * d / (lambda0 * n0) * vector_laplacian_sum(
        indptr, cols, position, velocity, radius, n)
    assert got.shape == (n, d)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-8)
    radius = 2.1 * SPACING
    n0, _ = reference_values(SPACING, radius, d)
    expected = operators.divergence(pairs, pairs.weight(radius), velocity, n, n0)
    got = d / n0 * divergence_sum(indptr, cols, position, velocity, radius, n)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-8)


def test_pressure_gradient(scene):
    position, _, pressure, is_dummy, n, indptr, cols, pairs = scene
    radius = 2.1 * SPACING
    d = position.shape[1]
    n0, _ = reference_values(SPACING, radius, d)
    w = pairs.weight(radius)
    include = ~is_dummy
    minimum = operators.neighbourhood_minimum(pairs, w, pressure, n, include)
    expected = operators.gradient(pairs, w, pressure, n, n0, minimum, include)
    got = d / n0 * pressure_gradient_sum(
        indptr, cols, position, pressure, include, radius, n)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-6)


def test_corrected_gradient_is_exact_for_a_linear_field(scene):
    position, _, _, is_dummy, n, indptr, cols, _ = scene
    radius = 2.1 * SPACING
    d = position.shape[1]
    n0, _ = reference_values(SPACING, radius, d)
    slope = np.array([3.0e3, -9.81e3, 1.5e3])[:d]
    pressure = 500.0 + position @ slope
    include = ~is_dummy
    pairs = scene[7]
    # The sums with P_i in place of Pmin_i: the correction makes these exact (the
    # Pmin shift adds (P_i - Pmin_i) sum_j r_ij w / r^2, which it only rescales).
    gradient = operators.gradient(pairs, pairs.weight(radius), pressure, n, n0,
                                  pressure[:n], include)
    plain = gradient.copy()
    corrected = correct_gradient(indptr, cols, position, include, radius,
                                 d / n0, gradient, 0.7)
    # Interior rows (a full neighbourhood of pressure-carrying particles: 3 l0
    # from every side of the lattice, 3 l0 above the dummies) are corrected and
    # exact; the jittered lattice leaves the plain sums off by a few percent.
    top = (np.array(SHAPES[d]) - 1) * SPACING
    interior = np.all((position[:n] > 3 * SPACING) & (position[:n] < top - 3 * SPACING), axis=1)
    interior &= position[:n, 1] > 5 * SPACING
    assert interior.sum() >= 20
    assert corrected >= np.count_nonzero(interior)
    np.testing.assert_allclose(gradient[interior], np.broadcast_to(slope, (interior.sum(), d)),
                               rtol=1e-9)
    assert np.abs(plain[interior] - slope).max() > 1e-3 * np.abs(slope).max()
    # A row with a truncated neighbourhood (the lattice's corner) keeps the plain sum.
    corner = np.argmin(position[:n].sum(axis=1))
    np.testing.assert_array_equal(gradient[corner], plain[corner])


def test_collisions_conserve_momentum_between_moving_particles(scene):
    position, velocity, _, _, n, indptr, cols, _ = scene
    # Squeeze the lattice so many pairs are closer than the collision distance.
    squeezed = position * 0.6
    full_indptr, full_cols = pair_list(squeezed, 3.7 * SPACING)
    moving = np.ones(len(position), bool)
    change = collision_change(full_indptr, full_cols, squeezed, velocity, moving,
                              0.5 * SPACING, 0.2, len(position), squeezed)
    assert np.abs(change).max() > 0
    assert change.shape == position.shape
    np.testing.assert_allclose(change.sum(axis=0), 0.0, atol=1e-12)


def reference_rows(rows, cols, w, unknown_row, global_row, is_dummy, coefficient, shift,
                   mobility=None):
    """The pressure matrix rows by plain numpy, for comparison; with ``mobility`` (rho0/rho
    per particle) pair ij weighs w_ij (m_i + m_j)/2."""
    n_owned = len(unknown_row)
    if mobility is not None:
        w = w * 0.5 * (mobility[rows] + mobility[cols])
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
    density, _ = number_density(indptr, cols, position, 2.1 * SPACING, n)
    n0, _ = reference_values(SPACING, 2.1 * SPACING, position.shape[1])
    unknown = ~is_dummy & (density >= 0.97 * n0)
    row_number = np.full(n, -1, np.int64)
    row_number[~is_dummy] = np.arange(int((~is_dummy).sum()))
    unknown_row = np.full(n, -1, np.int64)
    unknown_row[unknown] = row_number[unknown]
    row_ptr, columns, values = poisson_rows(indptr, cols, position, radius, row_number,
                                            unknown.astype(np.int8), 860.0, 0.45, 7.0,
                                            False)
    expected = reference_rows(pairs.rows, cols, pairs.weight(radius), unknown, unknown_row,
                              is_dummy, 860.0, 0.45)
    for i in np.flatnonzero(~is_dummy & ~unknown):
        expected[(row_number[i], row_number[i])] = 7.0
    got = {}
    assert len(row_ptr) - 1 == int((~is_dummy).sum())
    for k in range(len(row_ptr) - 1):
        row = k
        for p in range(row_ptr[k], row_ptr[k + 1]):
            got[(row, columns[p])] = values[p]
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-12)
        assert got[(key[1], key[0])] == pytest.approx(value, rel=1e-12)


def test_poisson_rows_fill_a_room_of_the_solvers_integer_type_or_say_it_is_short(scene):
    """The rows written into the caller's room (PETSc's 32-bit columns, taken without a
    copy) are poisson_rows' entry for entry; a room one entry short is refused (-1), and
    the Laplacian scheme then assembles again into room for every pair, whatever room the
    last step left it."""
    from types import SimpleNamespace

    from parmps.fluid.schemes.laplacian import StandardLaplacian
    position, _, _, is_dummy, _, _, _, _ = scene
    radius = 3.1 * SPACING
    n = len(position)
    indptr, cols = pair_list(position, 3.7 * SPACING)
    row_number = np.full(n, -1, np.int64)
    row_number[~is_dummy] = np.arange(int((~is_dummy).sum()))
    unknown = (~is_dummy).astype(np.int8)
    unknown[::7] = 0
    arguments = (indptr, cols, position, radius, row_number, unknown, 860.0, 0.45, 7.0, False)
    row_ptr, columns, values = poisson_rows(*arguments)
    entries = len(columns)
    room, other_room = poisson_rows_room(indptr, cols, row_number)
    assert entries < room and other_room == 0
    for room, written in ((entries, entries), (entries - 1, -1)):
        into_columns, into_values = np.empty(room, np.int32), np.empty(room)
        into_ptr, _, _, got, other = poisson_rows_into(
            *arguments, np.ones(n), into_columns, into_values, into_columns[:0],
            into_values[:0], rows_in_index_order(row_number, len(indptr) - 1))
        assert got == written
        if got == entries:
            assert other == 0
            np.testing.assert_array_equal(into_ptr, row_ptr)
            np.testing.assert_array_equal(into_columns, columns)
            np.testing.assert_array_equal(into_values, values)
    laplacian = StandardLaplacian({}, SimpleNamespace(
        laplacian_coefficient=860.0, n0_laplacian=7.0 / 860.0, re_laplacian=radius))
    for expected in (0, entries - 1, entries + 5):
        laplacian.expected_entries = (expected, 0)
        got = laplacian.rows(indptr, cols, position, row_number, unknown, 0.45,
                             np.flatnonzero(~is_dummy), index_dtype=np.dtype(np.int32))
        assert got.owned[1].dtype == np.int32 and len(got.other[1]) == 0
        for a, b in zip(got.owned, (row_ptr, columns, values)):
            np.testing.assert_array_equal(a, b)
        assert laplacian.expected_entries[0] >= entries


@pytest.mark.parametrize("dimension", [2, 3])
def test_poisson_rows_split_into_this_ranks_columns_and_the_others(dimension):
    """On one rank of several the rows come in PETSc's two blocks: the columns of the rank's
    own rows numbered from its first row, the other ranks' global; together they are the
    rows of the whole matrix, entry for entry, and the rank's own columns ascend where its
    rows are numbered in the search's cell order. A block's room one entry short is
    refused (-1) and the scheme assembles again into room for every pair."""
    from types import SimpleNamespace

    from parmps.fluid.schemes.laplacian import StandardLaplacian
    grid = np.indices((9,) * dimension).reshape(dimension, -1).T * SPACING
    position = grid + np.random.default_rng(5).normal(0, 0.05 * SPACING, grid.shape)
    n = len(position)
    # This rank owns the particles with x below the middle; the rest are its ghosts, whose
    # rows (numbered first, as a rank before this one would) are another rank's.
    mine = position[:, 0] < 4.0 * SPACING
    order = np.concatenate([np.flatnonzero(mine), np.flatnonzero(~mine)])
    position = position[order]
    n_owned = int(mine.sum())
    indptr, cols, cell_order = pair_list(position, 3.7 * SPACING, n_rows=n_owned,
                                         cell_order=True)
    rows = cell_order[cell_order < n_owned]
    first = n - n_owned
    row_number = np.empty(n, np.int64)
    row_number[rows] = first + np.arange(n_owned)
    row_number[n_owned:] = np.arange(n - n_owned)
    unknown = np.ones(n, np.int8)
    unknown[::7] = 0
    arguments = (indptr, cols, position, 3.1 * SPACING, row_number, unknown, 860.0, 0.45, 7.0,
                 False, np.ones(n))
    whole_room = indptr[-1] + n_owned
    whole_columns, whole_values = np.empty(whole_room, np.int64), np.empty(whole_room)
    whole_ptr, _, _, entries, _ = poisson_rows_into(
        *arguments, whole_columns, whole_values, whole_columns[:0], whole_values[:0], rows,
        False)
    room, other_room = poisson_rows_room(indptr, cols, row_number)
    columns, values = np.empty(room, np.int32), np.empty(room)
    other_columns, other_values = np.empty(other_room, np.int32), np.empty(other_room)
    row_ptr, other_ptr, diagonal_at, owned_entries, other_entries = poisson_rows_into(
        *arguments, columns, values, other_columns, other_values, rows)
    assert other_entries > 0 and owned_entries + other_entries == entries
    np.testing.assert_array_equal(columns[diagonal_at], np.arange(n_owned))
    for r in range(n_owned):
        a, b = row_ptr[r], row_ptr[r + 1]
        c, d = other_ptr[r], other_ptr[r + 1]
        # The other ranks' rows are numbered in their own order: that block is sorted later.
        assert np.all(np.diff(columns[a:b]) > 0) and np.all(other_columns[c:d] < first)
        joined = np.concatenate([columns[a:b] + first, other_columns[c:d]])
        joined_values = np.concatenate([values[a:b], other_values[c:d]])
        whole = slice(whole_ptr[r], whole_ptr[r + 1])
        keep, keep_whole = np.argsort(joined), np.argsort(whole_columns[whole])
        np.testing.assert_array_equal(joined[keep], whole_columns[whole][keep_whole])
        np.testing.assert_array_equal(joined_values[keep], whole_values[whole][keep_whole])
    short = poisson_rows_into(*arguments, columns, values,
                              other_columns[:other_entries - 1],
                              other_values[:other_entries - 1], rows)
    assert short[3] == -1
    laplacian = StandardLaplacian({}, SimpleNamespace(
        laplacian_coefficient=860.0, n0_laplacian=7.0 / 860.0, re_laplacian=3.1 * SPACING))
    laplacian.expected_entries = (owned_entries, other_entries - 1)
    got = laplacian.rows(indptr, cols, position, row_number, unknown, 0.45, rows)
    np.testing.assert_array_equal(got.other[1], other_columns[:other_entries])
    np.testing.assert_array_equal(got.owned[2], values[:owned_entries])


def test_variable_density_rows_weigh_each_pair_by_the_mean_inverse_density(scene):
    """With every mobility 1 the rows are poisson_rows' bit for bit; with a light patch
    (rho0/rho = 10, a body at density ratio 0.1) each pair weighs w (m_i + m_j)/2 and the
    matrix stays symmetric."""
    position, _, _, is_dummy, _, _, _, _ = scene
    radius = 3.1 * SPACING
    n = len(position)
    indptr, cols = pair_list(position, 3.7 * SPACING)
    pairs = operators.PairGeometry(indptr, rows_of(indptr), cols, position)
    row_number = np.full(n, -1, np.int64)
    row_number[~is_dummy] = np.arange(int((~is_dummy).sum()))
    unknown = ~is_dummy
    arguments = (indptr, cols, position, radius, row_number, unknown.astype(np.int8), 860.0,
                 0.45, 7.0, False)
    plain = poisson_rows(*arguments)
    uniform = variable_density_poisson_rows(*arguments, np.ones(n))
    for a, b in zip(plain, uniform):
        np.testing.assert_array_equal(a, b)
    centre = position.mean(axis=0)
    mobility = np.where(np.abs(position - centre).max(axis=1) < 2.5 * SPACING, 10.0, 1.0)
    assert 1 < np.count_nonzero(mobility > 1) < n // 2
    row_ptr, columns, values = variable_density_poisson_rows(*arguments, mobility)
    unknown_row = np.where(unknown, row_number, -1)
    expected = reference_rows(pairs.rows, cols, pairs.weight(radius), unknown, unknown_row,
                              is_dummy, 860.0, 0.45, mobility)
    got = {}
    for k in range(len(row_ptr) - 1):
        row = k
        for p in range(row_ptr[k], row_ptr[k + 1]):
            got[(row, columns[p])] = values[p]
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-12)
        assert got[(key[1], key[0])] == pytest.approx(value, rel=1e-12)
    # The light patch's rows really changed: the centre's diagonal is several times heavier.
    centre_row = row_number[np.argmin(np.abs(position - centre).max(axis=1))]
    def diagonal(ptr, cols, vals, row):
        part = slice(ptr[row], ptr[row + 1])
        return vals[part][cols[part] == row][0]

    assert diagonal(row_ptr, columns, values, centre_row) - 0.45 > \
        5 * (diagonal(*plain, centre_row) - 0.45)


def reference_collisions(position, velocity, moving, limit, restitution, n_rows, start):
    """collision_change written in numpy: moving pairs pair by pair; the fixed partners
    within their reach (sqrt(d - 1 + 1/4) times the limit) as one wall along the normal
    of every fixed partner within twice that reach at ``start``, weighted (1 - r/R)^2."""
    out = np.zeros((n_rows, position.shape[1]))
    fixed_reach = limit * np.sqrt(position.shape[1] - 1 + WALL_GAP_CLOSURE ** 2)
    reach = np.where(moving, limit, fixed_reach)
    for i in np.flatnonzero(moving[:n_rows]):
        offset = position - position[i]
        r = np.linalg.norm(offset, axis=1)
        close = (r < reach) & (np.arange(len(position)) != i)
        pair = close & moving
        normal = offset[pair] / r[pair, None]
        approach = np.einsum("pk,pk->p", velocity[i] - velocity[pair], normal)
        impulse = np.where(approach > 0, (1 + restitution) * 0.5 * approach, 0.0)
        out[i] = -(impulse[:, None] * normal).sum(axis=0)
        wall = close & ~moving
        if wall.any():
            weight = 1.0 - r[wall] / fixed_reach
            offset_start = start - start[i]
            r_start = np.linalg.norm(offset_start, axis=1)
            support = WALL_NORMAL_REACH * fixed_reach
            around = ~moving & (r_start > 0) & (r_start < support)
            contact = (((1.0 - r_start[around] / support) ** 2 / r_start[around])[:, None]
                       * offset_start[around]).sum(axis=0)
            if np.linalg.norm(contact) <= 1e-12:
                contact = (weight[:, None] * offset[wall] / r[wall, None]).sum(axis=0)
            contact /= np.linalg.norm(contact)
            wall_velocity = (weight[:, None] * velocity[wall]).sum(axis=0) / weight.sum()
            approach = (velocity[i] - wall_velocity) @ contact
            if approach > 0:
                out[i] -= (1 + restitution) * approach * contact
    return out


def test_collisions_match_pairwise_reference(scene):
    position, velocity, _, is_dummy, n, _, _, _ = scene
    squeezed = position * 0.6
    indptr, cols = pair_list(squeezed, 3.7 * SPACING, n_rows=n)
    moving = ~is_dummy
    # The start of the step: a step of the velocities back, so the fixed partners'
    # directions there differ from those at the predicted positions.
    start = squeezed - 0.05 * velocity
    for begin in (squeezed, start):
        change = collision_change(indptr, cols, squeezed, velocity, moving,
                                  0.5 * SPACING, 0.2, n, begin)
        expected = reference_collisions(squeezed, velocity, moving, 0.5 * SPACING, 0.2, n,
                                        begin)
        assert np.count_nonzero(np.any(expected != 0, axis=1)) > 10
        np.testing.assert_allclose(change, expected, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("dimension", [2, 3])
def test_a_fast_droplet_aimed_at_a_walls_gap_is_turned_back(dimension):
    """A wall of two layers (a square lattice of spacing l0, its front layer in the plane
    x = 0) and a droplet flying at it along -x, a tenth of a spacing off the centre of a
    gap between the front layer's particles, from 0.49 l0 in front of the plane, beyond
    the fixed partners' reach of its gap. A step of half a spacing (Courant 0.5) lands
    it in the plane, half a spacing from the gap's particles on either side: seen from
    there they lie sideways, and their combined normal would hardly slow it. From where
    it came, over the partners on both sides of the gap, the wall lies ahead: it must be
    turned back, its approach reversed with nearly the restitution, and the correction
    must take it back in front of the plane."""
    g = np.meshgrid(np.arange(-1.0, 1.0), *[np.arange(-3.0, 4.0)] * (dimension - 1),
                    indexing="ij")
    wall = np.column_stack([axis.ravel() for axis in g])
    start = np.vstack([np.r_[0.49, np.full(dimension - 1, 0.6)], wall])
    speed, dt = 1.0, 0.5
    velocity = np.zeros_like(start)
    velocity[0, 0] = -speed
    position = start.copy()
    position[0] += dt * velocity[0]
    moving = np.r_[True, np.zeros(len(wall), bool)]
    indptr, cols = pair_list(position, 1.5, n_rows=1)
    change = collision_change(indptr, cols, position, velocity, moving, 0.5, 0.2, 1,
                              start)
    after = velocity[0] + change[0]
    assert after[0] > 0.1 * speed
    assert position[0, 0] + dt * change[0, 0] > 0.0
    # At the predicted positions alone the normal lies nearly in the plane.
    static = collision_change(indptr, cols, position, velocity, moving, 0.5, 0.2, 1,
                              position)
    assert velocity[0, 0] + static[0, 0] < 0.0


@pytest.mark.parametrize("dimension", [2, 3])
def test_a_droplet_resting_on_a_wall_does_not_sink_down_its_gaps(dimension):
    """Three wall layers (a square lattice of spacing l0 below z = 0, y = 0 in 2D) and a
    fluid particle falling from 0.8 l0 above the top layer, a fiftieth of a spacing off the
    centre of a gap along each axis, under gravity alone (no pressure holds a droplet on a
    dry wall): 3000 steps of the explicit part and the collision model. The collisions
    steer it onto the gap's centre, whose line runs straight down the lattice 0.71 l0 (3D)
    or 0.5 l0 (2D) from every wall particle; it must come to rest above the top layer's
    plane, where the gap closes (a quarter spacing). With each fixed partner acting alone,
    or a reach that closes the gaps only at the plane, it fell through all three layers."""
    g = np.meshgrid(*[np.arange(-3.0, 4.0)] * (dimension - 1), np.arange(-2.0, 1.0),
                    indexing="ij")
    wall = np.column_stack([axis.ravel() for axis in g])
    position = np.vstack([np.r_[np.full(dimension - 1, 0.52), 0.8], wall])
    velocity = np.zeros_like(position)
    moving = np.r_[True, np.zeros(len(wall), bool)]
    # l0 = 2.5 cm: g is 392 spacings/s^2; dt = 2 ms is a droplet's step at Courant 0.2.
    dt, gravity = 0.002, 9.81 / 0.025
    lowest = np.inf
    for _ in range(3000):
        start = position.copy()
        velocity[0, -1] -= dt * gravity
        position[0] += dt * velocity[0]
        indptr, cols = pair_list(position, 1.5, n_rows=1)
        change = collision_change(indptr, cols, position, velocity, moving, 0.5, 0.2, 1,
                                  start)
        velocity[0] += change[0]
        position[0] += dt * change[0]
        lowest = min(lowest, position[0, -1])
    assert lowest > 0.2
    # At rest on the gap: its speed is what one step of gravity gives it.
    assert abs(velocity[0, -1]) < 2 * dt * gravity
    np.testing.assert_allclose(position[0, :-1], 0.5, atol=0.02)


@pytest.mark.parametrize("dimension", [2, 3])
def test_jacobi_rotations_find_the_smallest_eigenvalue(dimension):
    """jacobi_diagonalise (the 3D surface normal's) leaves the eigenvalues on the
    diagonal: the smallest of them against numpy's."""
    rng = np.random.default_rng(3)
    # Diagonal, the identity, rank one, a double eigenvalue with a small
    # coupling, and random symmetric positive definite matrices.
    d = dimension
    matrices = [np.diag(np.linspace(2.0, 0.5, d)), np.eye(d), np.full((d, d), 1.0),
                np.diag([1.0] * (d - 1) + [3.0]) + 1e-9 * np.ones((d, d))]
    for _ in range(200):
        m = rng.normal(size=(d, d))
        matrices.append(m @ m.T + rng.uniform(0, 2) * np.eye(d))
    work = np.empty((d, d))
    for a in matrices:
        expected = np.linalg.eigvalsh(a)[0]
        work[:] = a
        jacobi_diagonalise(work, work, False)
        got = np.diagonal(work).min()
        assert got == pytest.approx(expected, abs=1e-13 * np.abs(a).max())


@pytest.mark.parametrize("dimension", [2, 3])
def test_an_eigenvalue_below_a_limit_is_told_by_the_pivots(dimension):
    """The corrected gradient's test (3D) against numpy's eigenvalues: random symmetric
    matrices around the default limit, singular ones, and the limit hit exactly."""
    rng = np.random.default_rng(5)
    d = dimension
    work = np.empty((d, d))
    cases = []
    for _ in range(2000):
        q, _ = np.linalg.qr(rng.normal(size=(d, d)))
        eigenvalues = rng.uniform(-0.2, 1.5, size=d)
        cases.append((q @ np.diag(eigenvalues) @ q.T, eigenvalues.min()))
    # Exactly at the limit (a diagonal matrix has its eigenvalues exactly), and a zero pivot
    # with a column below it that is not zero.
    cases += [(np.diag([1.0] * (d - 1) + [0.7]), 0.7), (np.diag([0.7] * d), 0.7)]
    singular = np.eye(d) * 0.7
    singular[0, 1] = singular[1, 0] = 0.1
    cases.append((singular, 0.6))
    limit = 0.7
    for a, smallest in cases:
        a = np.ascontiguousarray((a + a.T) / 2)
        if abs(smallest - limit) < 1e-12 and smallest != limit:
            continue
        assert has_eigenvalue_below(a, limit, work) == (smallest < limit), (a, smallest)


@pytest.mark.parametrize("dimension", [2, 3])
def test_the_corrected_gradient_in_one_pass_is_the_three_kernels_in_turn(dimension):
    """corrected_pressure_gradient against the gradient's sum scaled, the correction
    along the normal on the surface rows and the full correction on the others, bit for bit:
    a jittered lattice with a ragged top (rows corrected and left alone), a row mask, surface
    rows with and without a normal, and dummies that carry no pressure."""
    rng = np.random.default_rng(11)
    m = 14 if dimension == 3 else 40
    grid = np.stack(np.meshgrid(*[np.arange(m)] * dimension, indexing="ij"), -1)
    position = grid.reshape(-1, dimension) + 0.12 * rng.standard_normal((m ** dimension,
                                                                         dimension))
    position = position[~((position[:, -1] > 0.6 * m) & (rng.random(len(position)) < 0.3))]
    n = len(position)
    radius = 2.3
    indptr, cols = pair_list(position, radius, n_rows=n)
    pressure = rng.random(n)
    has_pressure = rng.random(n) > 0.05
    rows = rng.random(n) > 0.1
    surface_rows = rng.random(n) < 0.2
    normal = rng.standard_normal((n, dimension))
    normal[rng.random(n) < 0.1] = 0.0
    # d/n0 with n0 the full lattice's number density: A_i near the identity inside.
    n0 = np.percentile(number_density(indptr, cols, position, radius, n)[0], 90)
    scale, limit, surface_limit = dimension / n0, 0.7, 0.3
    for surface in (False, True):
        expected = scale * pressure_gradient_sum(indptr, cols, position, pressure,
                                                 has_pressure, radius, n, rows)
        every = rows
        if surface:
            every = rows & ~surface_rows
            along = correct_normal_component(indptr, cols, position, has_pressure,
                                             radius, scale, expected, normal,
                                             surface_limit, surface_rows)
            assert 0 < along < np.count_nonzero(surface_rows)
        counted = correct_gradient(indptr, cols, position, has_pressure, radius, scale,
                                   expected, limit, every)
        assert 0 < counted < np.count_nonzero(every)
        got = corrected_pressure_gradient(
            indptr, cols, position, pressure, has_pressure, radius, scale, n, limit, rows,
            surface_rows if surface else None, normal if surface else None, surface_limit)
        np.testing.assert_array_equal(got, expected)
        assert np.all(got[~rows] == 0.0)


def test_kernels_want_two_or_three_components():
    position = np.zeros((3, 4))
    indptr, cols = np.zeros(4, np.int64), np.empty(0, np.int64)
    with pytest.raises(ValueError, match="2 or 3"):
        number_density(indptr, cols, position, 1.0, 3)


@pytest.mark.parametrize("dimension", [2, 3])
def test_a_loop_written_once_is_a_kernel_with_the_loops_signature(dimension):
    """for_each_dimension's kernel takes the loop's arguments but d, with their defaults, by
    position or by name, and gives what the loop gives for the positions' dimension."""
    rng = np.random.default_rng(5)
    position = rng.uniform(0.0, 0.05, (40, dimension))
    field = rng.normal(size=(40, dimension))
    indptr, cols = pair_list(position, 0.03)
    rows = np.arange(40) % 3 != 0
    whole = vector_laplacian_sum(indptr, cols, position, field, 0.03, 40)
    some = vector_laplacian_sum(indptr, cols, position, field, 0.03, 40, rows=rows)
    assert whole.shape == (40, dimension) and np.abs(whole).max() > 0.0
    assert np.array_equal(some[rows], whole[rows]) and not some[~rows].any()
    assert vector_laplacian_sum.__doc__.startswith("sum_j (u_j - u_i) w(r_ij)")
    with pytest.raises(TypeError, match="d first"):
        for_each_dimension(lambda position, d: d)


def test_row_masks_leave_the_other_rows_empty_and_the_rows_kept_unchanged(scene):
    """A mask of rows (the fluid step's: no dummies in the pair list, only moving
    particles for the viscous term and the gradient) changes nothing in the rows kept."""
    position, velocity, pressure, is_dummy, n, indptr, cols, _ = scene
    keep = ~is_dummy[:n]
    masked_indptr, masked_cols = pair_list(position, 3.7 * SPACING, n_rows=n, rows=keep)
    lengths, masked_lengths = np.diff(indptr), np.diff(masked_indptr)
    assert np.all(masked_lengths[~keep] == 0)
    np.testing.assert_array_equal(masked_lengths[keep], lengths[keep])
    np.testing.assert_array_equal(masked_cols, np.concatenate(
        [cols[indptr[i]:indptr[i + 1]] for i in np.flatnonzero(keep)]))
    moving = keep & (position[:n, 0] > 5 * SPACING)
    radius = 3.1 * SPACING
    full = vector_laplacian_sum(indptr, cols, position, velocity, radius, n)
    some = vector_laplacian_sum(indptr, cols, position, velocity, radius, n, moving)
    np.testing.assert_array_equal(some[moving], full[moving])
    assert np.all(some[~moving] == 0.0)
    include = ~is_dummy
    radius = 2.1 * SPACING
    full = pressure_gradient_sum(indptr, cols, position, pressure, include, radius, n)
    some = pressure_gradient_sum(indptr, cols, position, pressure, include, radius, n,
                                 moving)
    np.testing.assert_array_equal(some[moving], full[moving])
    assert np.all(some[~moving] == 0.0)
    corrected_full, corrected_some = full.copy(), some.copy()
    correct_gradient(indptr, cols, position, include, radius, 0.5, corrected_full, 0.7)
    correct_gradient(indptr, cols, position, include, radius, 0.5, corrected_some, 0.7,
                     moving)
    np.testing.assert_array_equal(corrected_some[moving], corrected_full[moving])


def test_rows_numbered_in_the_searchs_cell_order_come_out_ascending(scene):
    """Numbered in the order of the search's cells, each pressure row's columns ascend,
    its diagonal in its place (and where the kernel says): the sort has nothing to do.
    The matrix is the one numbered by index, its rows and columns permuted."""
    position, _, _, is_dummy, _, _, _, _ = scene
    n = len(position)
    indptr, cols, order = pair_list(position, 3.7 * SPACING, cell_order=True)
    assert sorted(order) == list(range(n))
    rows = order[~is_dummy[order]]
    row_number = np.full(n, -1, np.int64)
    row_number[rows] = np.arange(len(rows))
    unknown = (~is_dummy).astype(np.int8)
    unknown[::7] = 0
    arguments = (indptr, cols, position, 3.1 * SPACING, row_number, unknown, 860.0, 0.45, 7.0,
                 False, np.ones(n))
    room, _ = poisson_rows_room(indptr, cols, row_number)
    columns, values = np.empty(room, np.int64), np.empty(room)
    row_ptr, _, diagonal_at, entries, _ = poisson_rows_into(
        *arguments, columns, values, columns[:0], values[:0], rows)
    columns, values = columns[:entries], values[:entries]
    np.testing.assert_array_equal(columns[diagonal_at], np.arange(len(rows)))
    for r in range(len(rows)):
        assert np.all(np.diff(columns[row_ptr[r]:row_ptr[r + 1]]) > 0)
    by_index = np.full(n, -1, np.int64)
    by_index[~is_dummy] = np.arange(len(rows))
    index_ptr, index_columns, index_values = poisson_rows(
        indptr, cols, position, 3.1 * SPACING, by_index, unknown, 860.0, 0.45, 7.0, False)
    sort_row_columns(index_ptr, index_columns, index_values)
    # Row r of the cell-ordered matrix is particle rows[r], whose index-ordered row is
    # by_index[rows[r]]; its columns map the same way.
    to_index = by_index[rows]
    for r in range(len(rows)):
        a, b = row_ptr[r], row_ptr[r + 1]
        k = to_index[r]
        c, d = index_ptr[k], index_ptr[k + 1]
        mapped = to_index[columns[a:b]]
        keep = np.argsort(mapped)
        np.testing.assert_array_equal(mapped[keep], index_columns[c:d])
        np.testing.assert_array_equal(values[a:b][keep], index_values[c:d])


def test_sort_row_columns_sorts_rows_nearly_ascending_or_leaves_ascending_ones():
    # Rows of 100: ascending; one entry out of place; every other pair swapped (too many
    # descents for insertion alone: Shell's gaps first).
    ascending = np.arange(0, 300, 3)
    one_out = ascending.copy()
    one_out[[10, 70]] = one_out[[70, 10]]
    swapped = ascending.reshape(-1, 2)[:, ::-1].ravel()
    columns = np.concatenate([ascending, one_out, swapped]).astype(np.int32)
    row_ptr = np.array([0, 100, 200, 300], np.int32)
    values = columns * 10.0 + 1.0
    sort_row_columns(row_ptr, columns, values)
    np.testing.assert_array_equal(columns, np.tile(ascending, 3))
    np.testing.assert_array_equal(values, columns * 10.0 + 1.0)


def test_sort_row_columns_sorts_rows_short_and_long_with_their_values():
    rng = np.random.default_rng(4)
    lengths = np.array([0, 1, 2, 9, 30, 122, 300, 1000])
    row_ptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    columns = np.concatenate([rng.permutation(5000)[:k] for k in lengths]).astype(np.int32)
    values = columns * 10.0 + 1.0
    expected = np.concatenate([np.sort(columns[a:b]) for a, b in zip(row_ptr[:-1],
                                                                      row_ptr[1:])])
    sort_row_columns(row_ptr, columns, values)
    np.testing.assert_array_equal(columns, expected)
    np.testing.assert_array_equal(values, columns * 10.0 + 1.0)


def test_sort_row_columns_sorts_each_row_with_its_values():
    rng = np.random.default_rng(3)
    row_ptr = np.array([0, 1, 5, 5, 12], np.int32)
    columns = np.concatenate([[4], rng.permutation(4), [], rng.permutation(7) + 10])
    columns = columns.astype(np.int32)
    values = columns * 10.0 + 1.0
    sort_row_columns(row_ptr, columns, values)
    for row in range(len(row_ptr) - 1):
        part = columns[row_ptr[row]:row_ptr[row + 1]]
        assert np.all(np.diff(part) > 0)
    np.testing.assert_array_equal(values, columns * 10.0 + 1.0)


def test_pairs_within_keeps_the_pairs_inside_in_order_and_the_sums_over_them_are_identical(
        scene):
    position, velocity, pressure, is_dummy, n, indptr, cols, _ = scene
    radius = 2.1 * SPACING
    d = position.shape[1]
    near_indptr, near_cols = pairs_within(indptr, cols, position, radius, n)
    for i in range(n):
        full = cols[indptr[i]:indptr[i + 1]]
        inside = full[((position[full] - position[i]) ** 2).sum(axis=1) < radius ** 2]
        assert np.array_equal(near_cols[near_indptr[i]:near_indptr[i + 1]], inside)
    assert near_indptr[-1] < 0.6 * indptr[-1]
    # Bit for bit: the pairs left out weigh exactly 0 in every sum on this radius.
    for over_full, over_near in zip(
            number_density(indptr, cols, position, radius, n),
            number_density(near_indptr, near_cols, position, radius, n)):
        assert np.array_equal(over_full, over_near)
    assert np.array_equal(divergence_sum(indptr, cols, position, velocity, radius, n),
                          divergence_sum(near_indptr, near_cols, position, velocity,
                                         radius, n))
    include = ~is_dummy
    full = pressure_gradient_sum(indptr, cols, position, pressure, include, radius, n)
    near = pressure_gradient_sum(near_indptr, near_cols, position, pressure, include,
                                 radius, n)
    assert np.array_equal(full, near)
    n0, _ = reference_values(SPACING, radius, d)
    correct_gradient(indptr, cols, position, include, radius, d / n0, full, 0.5)
    correct_gradient(near_indptr, near_cols, position, include, radius, d / n0, near,
                     0.5)
    assert np.array_equal(full, near)


@pytest.mark.parametrize("expected_pairs", [0, 1, 500, 10 ** 6])
def test_pairs_within_is_the_same_whatever_room_it_is_given(scene, expected_pairs):
    position, _, _, _, n, indptr, cols, _ = scene
    radius = 2.1 * SPACING
    exact_indptr, exact_cols = pairs_within(indptr, cols, position, radius, n)
    got_indptr, got_cols = pairs_within(indptr, cols, position, radius, n,
                                        expected_pairs=expected_pairs)
    assert np.array_equal(got_indptr, exact_indptr)
    assert np.array_equal(got_cols, exact_cols)
    assert 0 < len(exact_cols) < indptr[n]


def test_pairs_within_keeps_a_pair_a_rounding_error_inside_the_radius():
    # |r| = 0.3 exactly cannot be held in binary: sqrt(r^2) and r^2 against radius^2
    # may disagree in the last bit, and the sub-list must keep the pair either way.
    position = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.3]])
    indptr, cols = pair_list(position, 1.0)
    for radius in (0.1, 0.3, np.nextafter(0.1, 1.0), np.nextafter(0.3, 1.0)):
        near_indptr, near_cols = pairs_within(indptr, cols, position, radius, 3)
        for i in range(3):
            kept = set(near_cols[near_indptr[i]:near_indptr[i + 1]])
            for j in cols[indptr[i]:indptr[i + 1]]:
                distance = np.sqrt(((position[j] - position[i]) ** 2).sum())
                if distance < radius:
                    assert j in kept


@pytest.mark.parametrize("expected_pairs", [0, 1, 1000, 10 ** 6])
def test_pair_list_is_the_same_whatever_room_it_is_given(scene, expected_pairs):
    position, _, _, _, n, indptr, cols, _ = scene
    got_indptr, got_cols = pair_list(position, 3.7 * SPACING, n_rows=n,
                                     expected_pairs=expected_pairs)
    assert np.array_equal(got_indptr, indptr)
    assert np.array_equal(got_cols, cols)


@pytest.mark.parametrize("expected_pairs", [0, 10 ** 6])
def test_rows_kept_only_near_a_marked_particle(scene, expected_pairs):
    """``only_near``/``near`` (the fluid step's dry walls): a flagged row keeps its list,
    unchanged, when it holds a ``near`` particle and gets an empty one otherwise; the
    other rows are as without the flags, whether the search fits its room or not."""
    position, _, _, _, n, indptr, cols, _ = scene
    # A few 'water' particles in one corner: most flagged rows have none within reach.
    near = np.all(position < 4 * SPACING, axis=1)
    only_near = np.arange(n) % 3 != 0
    got_indptr, got_cols = pair_list(position, 3.7 * SPACING, n_rows=n,
                                     expected_pairs=expected_pairs, only_near=only_near,
                                     near=near)
    kept = 0
    for i in range(n):
        full = cols[indptr[i]:indptr[i + 1]]
        expected = full if not only_near[i] or near[full].any() else full[:0]
        np.testing.assert_array_equal(got_cols[got_indptr[i]:got_indptr[i + 1]], expected)
        kept += only_near[i] and len(expected) > 0
    # Both outcomes occur: some flagged rows kept, most emptied.
    assert 0 < kept < np.count_nonzero(only_near) // 2


def test_rows_near_marks_the_rows_with_a_marked_particle_within_the_radius(scene):
    """``rows_near`` (the fluid step's wet walls): a row is marked exactly when its pair list
    holds a ``near`` particle; rows not asked about are not marked."""
    position, _, _, _, n, indptr, cols, _ = scene
    near = np.all(position < 4 * SPACING, axis=1)
    rows = np.arange(n) % 3 != 0
    got = rows_near(position, 3.7 * SPACING, rows, near)
    expected = np.array([rows[i] and near[cols[indptr[i]:indptr[i + 1]]].any()
                         for i in range(n)])
    np.testing.assert_array_equal(got, expected)
    assert 0 < expected.sum() < rows.sum() // 2
    assert not rows_near(position, 3.7 * SPACING, rows, np.zeros(len(position), bool)).any()


@pytest.mark.parametrize("dimension", [1, 2, 3])
def test_the_cell_order_is_a_stable_sort_by_cell_and_the_lists_match_brute_force(dimension):
    """The counting sort gives what a stable argsort of the cell keys gives, with each cell's
    run starting where the keys below it end, also in a box mostly empty (a cluster far
    from the rest); the pair lists on it are the brute-force pairs within the radius."""
    from parmps.core.neighbours import _cell_coordinates, _cell_order, _grid
    rng = np.random.default_rng(7)
    position = rng.random((400, dimension)) * 0.2
    position[:40] += 1.5
    radius = 0.03
    origin, cell_size, _, cells, stride = _grid(position, radius)
    cell = _cell_coordinates(position, origin, cell_size)
    order, cell_start = _cell_order(cell, cells, stride)
    key = cell @ stride
    assert np.array_equal(order, np.argsort(key, kind="stable"))
    assert np.array_equal(cell_start, np.searchsorted(np.sort(key), np.arange(np.prod(cells) + 1)))
    indptr, indices = pair_list(position, radius)
    distance = np.linalg.norm(position[:, None] - position[None], axis=-1)
    for i in range(len(position)):
        expected = np.flatnonzero((distance[i] < radius) & (np.arange(len(position)) != i))
        assert np.array_equal(np.sort(indices[indptr[i]:indptr[i + 1]]), expected)


@pytest.mark.parametrize("dimension", [2, 3])
def test_the_checks_reductions_are_numpys(dimension):
    """The largest speed and the lowest non-finite id, compiled, against numpy: the same
    bits, masked rows left out, and every kind of non-finite value found."""
    rng = np.random.default_rng(dimension)
    velocity = rng.normal(size=(3000, dimension)) * rng.uniform(0, 10, (3000, 1))
    mask = rng.uniform(size=3000) < 0.5
    expected = (velocity[mask] ** 2).sum(axis=1).max()
    assert largest_norm2(velocity, mask) == expected
    assert largest_norm2(velocity, np.zeros(3000, bool)) == 0.0
    position = rng.uniform(size=(3000, dimension))
    ids = rng.permutation(3000).astype(np.int64) + 10
    assert lowest_id_not_finite(position, velocity, ids) == -1
    bad = [17, 400, 2999]
    position[17, -1] = np.inf
    velocity[400, 0] = np.nan
    position[2999, 0] = -np.inf
    assert lowest_id_not_finite(position, velocity, ids) == ids[bad].min()
