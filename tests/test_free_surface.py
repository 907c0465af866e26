"""The free-surface conditions on a lattice: the extrapolated one is exact for the linear field
that is zero half a spacing above the top row; the Dirichlet one reads the surface there."""

import numpy as np
import pytest

from parmps.core.density import number_density
from parmps.core.lattice import reference_values
from parmps.core.neighbours import pair_list, pairs_within
from parmps.fluid.schemes.gradient import (correct_gradient, correct_normal_component,
                                           pressure_gradient_sum)
from parmps.fluid.schemes.laplacian import SURFACE_ROW
from parmps.fluid.schemes.surface import (surface_fitted_normals, surface_ghost_diagonal,
                                          surface_normals)

RE, RE_LAPLACIAN = 2.3, 3.1
WIDTH, DEPTH = 40, 12          # fluid particles across and deep, l0 = 1
WALL, DUMMY, FLUID = 1, 2, 0


@pytest.fixture(scope="module")
def layer():
    """A layer of water on a floor (two wall rows, two dummy rows), open to the air above and
    at both ends; P = H - y with H half a spacing above the top row."""
    points, kinds = [], []
    for i in range(WIDTH):
        for j in range(DEPTH):
            points.append((i + 0.5, j + 0.5))
            kinds.append(FLUID)
    for i in range(-4, WIDTH + 4):
        for depth in range(4):
            points.append((i + 0.5, -depth - 0.5))
            kinds.append(WALL if depth < 2 else DUMMY)
    position = np.array(points)
    kind = np.array(kinds)
    n = len(position)
    indptr, cols = pair_list(position, RE_LAPLACIAN + 0.01, n_rows=n)
    n0, _ = reference_values(1.0, RE, 2)
    density, _ = number_density(indptr, cols, position, RE, n)
    has_pressure = kind != DUMMY
    surface = (density < 0.97 * n0) & has_pressure
    pressure = np.where(has_pressure, DEPTH - position[:, 1], 0.0)
    # Away from the layer's open ends and from the floor: where the lattice is cut by the
    # surface only.
    middle = (kind == FLUID) & (np.abs(position[:, 0] - WIDTH / 2) < WIDTH / 2 - 8) & \
        (position[:, 1] > 4)
    return dict(position=position, kind=kind, n=n, indptr=indptr, cols=cols, n0=n0,
                has_pressure=has_pressure, surface=surface, pressure=pressure, middle=middle)


def _ghost_diagonal(s, undirected=0.0):
    raw = surface_normals(s["indptr"], s["cols"], s["position"], s["surface"],
                          RE_LAPLACIAN, s["n"])
    normal = surface_fitted_normals(s["indptr"], s["cols"], s["position"], raw,
                                    s["surface"] & (s["kind"] == FLUID), RE_LAPLACIAN,
                                    s["n"])
    return normal, surface_ghost_diagonal(
        s["indptr"], s["cols"], s["position"], RE_LAPLACIAN, s["has_pressure"], s["surface"],
        s["surface"] & (s["kind"] == FLUID), normal, False, 0.5, undirected, s["n"])


def test_the_surface_is_the_top_row_and_its_normals_point_up(layer):
    s = layer
    top = s["middle"] & (s["position"][:, 1] > DEPTH - 1)
    assert np.array_equal(s["surface"] & s["middle"], top)
    normal, _ = _ghost_diagonal(s)
    # The rows that miss a neighbour: those within the radius of the row above the top one.
    near = s["middle"] & (s["position"][:, 1] > DEPTH + 0.5 - RE_LAPLACIAN)
    np.testing.assert_allclose(normal[near], np.tile([0.0, 1.0], (near.sum(), 1)), atol=1e-12)
    assert not normal[s["middle"] & ~near].any()


def _row_residual(s, diagonal, i):
    """Row i's sum of w (P_j - P_i) over the neighbours present, less the ghosts' diagonal
    times P_i: zero where the row is exact for the layer's linear field."""
    position, pressure = s["position"], s["pressure"]
    total = 0.0
    for j in s["cols"][s["indptr"][i]:s["indptr"][i + 1]]:
        r = np.hypot(*(position[j] - position[i]))
        if s["has_pressure"][j] and 0.0 < r < RE_LAPLACIAN:
            total += (RE_LAPLACIAN / r - 1.0) * (pressure[j] - pressure[i])
    return total - diagonal[i] * pressure[i]


def _particle_at(s, x, y):
    """The index of the layer's particle at (x, y)."""
    (index,) = np.flatnonzero((np.abs(s["position"][:, 0] - x) < 0.1) &
                              (np.abs(s["position"][:, 1] - y) < 0.1))
    return index


def test_the_extrapolated_rows_are_exact_for_the_field_that_is_zero_above_the_top_row(layer):
    """Sum_j w (P_j - P_i) over the neighbours present, less the ghosts' diagonal times P_i,
    is the Laplacian of a linear field: zero, row by row, surface rows included."""
    s = layer
    _, diagonal = _ghost_diagonal(s)
    rows = np.flatnonzero(s["middle"])
    residual = np.array([_row_residual(s, diagonal, i) for i in rows])
    scale = diagonal[rows] * s["pressure"][rows]
    assert scale.max() > 1.0            # the rows near the surface do have ghosts
    np.testing.assert_allclose(residual, 0.0, atol=1e-10)
    # Without the ghosts (the Dirichlet condition's rows beside the surface) the field misses.
    assert np.abs(scale).max() > 1.0


def test_a_particle_taken_for_surface_below_the_top_row_keeps_the_level_above_it(layer):
    """The lattice's second row has n*/n0 = 0.976 at re = 2.3 l0, just above beta = 0.97, so
    a jittered tank takes many of its particles for surface (45 % in the 2D still tank). The
    zero level is still half a spacing above the top row for such a particle: half a spacing
    plus the surface particles' mean height above it, 1.5 l0 here. Counted as half a spacing
    above itself, it had pulled the still tank's level 0.1 l0 down (bottom row -0.5 %)."""
    s = dict(layer)
    middle_x = WIDTH / 2 + 0.5
    i = _particle_at(s, middle_x, DEPTH - 1.5)
    assert not s["surface"][i]
    s["surface"] = s["surface"].copy()
    s["surface"][i] = True
    normal, diagonal = _ghost_diagonal(s)
    np.testing.assert_allclose(normal[i], [0.0, 1.0], atol=1e-12)
    assert diagonal[i] * s["pressure"][i] > 1.0
    assert abs(_row_residual(s, diagonal, i)) < 1e-10
    # The top row's particle above it keeps its own: the level half a spacing above it (the
    # others' fitted normals lean a little towards the particle below).
    above = _particle_at(s, middle_x, DEPTH - 0.5)
    assert s["surface"][above] and abs(_row_residual(s, diagonal, above)) < 1e-10


def test_the_corrected_gradient_is_exact_on_the_surface_below_the_limit_and_half_above(layer):
    s = layer
    near_indptr, near_cols = pairs_within(s["indptr"], s["cols"], s["position"], RE,
                                          s["n"])
    rows = s["kind"] == FLUID
    plain = (2 / s["n0"]) * pressure_gradient_sum(
        near_indptr, near_cols, s["position"], s["pressure"], s["has_pressure"], RE, s["n"], rows)
    top = s["middle"] & (s["position"][:, 1] > DEPTH - 1)
    deep = s["middle"] & (s["position"][:, 1] < DEPTH - 2)
    for limit, on_surface in ((0.45, -1.0), (0.7, -0.5)):
        gradient = plain.copy()
        correct_gradient(near_indptr, near_cols, s["position"], s["has_pressure"], RE,
                         2 / s["n0"], gradient, limit, rows)
        np.testing.assert_allclose(gradient[top], np.tile([0.0, on_surface], (top.sum(), 1)),
                                   atol=1e-3 if limit > 0.5 else 1e-12)
        np.testing.assert_allclose(gradient[deep], np.tile([0.0, -1.0], (deep.sum(), 1)),
                                   atol=1e-12)


def test_a_row_beside_a_line_of_surface_particles_takes_the_missing_side_across_it():
    """Surface particles along one line (a lattice's edge in 3D, at a corner of the water)
    spread alike in every direction across it, so the direction of least spread is not
    one direction: the normal is the missing neighbours' direction projected across the
    line, whatever order the sums run in (which is the ranks' cut: the Jacobi rotations
    had returned directions 113 degrees apart on 1 and 2 ranks)."""
    row = [[0.0, 0.0, 0.0]]
    line = [[x, 0.0, 1.0] for x in (-2.0, -1.0, 0.0, 1.0, 2.0)]
    missing = np.array([0.3, 0.4, 0.8])
    expected = np.array([0.0, 0.4, 0.8]) / np.hypot(0.4, 0.8)
    for order in ([0, 1, 2, 3, 4], [4, 2, 0, 3, 1], [1, 3, 4, 0, 2]):
        position = np.array(row + [line[k] for k in order])
        n = len(position)
        indptr, cols = pair_list(position, RE_LAPLACIAN + 0.01, n_rows=n)
        on_surface = np.array([False] + [True] * 5)
        raw = np.zeros((n, 3))
        raw[0] = missing / np.linalg.norm(missing)
        normal = surface_fitted_normals(indptr, cols, position, raw, on_surface,
                                        RE_LAPLACIAN, 1)
        np.testing.assert_allclose(normal[0], expected, atol=1e-12)
    # Off the line (the row below a plane of them), one direction of least spread: the plane's.
    plane = np.array([[0.0, 0.0, 0.0]] + [[x, y, 1.0] for x in (-1.0, 0.0, 1.0)
                                          for y in (-1.0, 0.0, 1.0)])
    indptr, cols = pair_list(plane, RE_LAPLACIAN + 0.01, n_rows=len(plane))
    raw = np.zeros((len(plane), 3))
    raw[0] = missing / np.linalg.norm(missing)
    normal = surface_fitted_normals(indptr, cols, plane, raw,
                                    np.arange(len(plane)) > 0, RE_LAPLACIAN, 1)
    np.testing.assert_allclose(normal[0], [0.0, 0.0, 1.0], atol=1e-12)


def test_a_surface_row_without_a_direction_gets_the_undirected_diagonal():
    """One particle alone, and the middle of a one-particle-thick sheet: their missing
    neighbours have no direction, so the ghosts' term is the given fallback, never 0 (a
    singular row without compressibility)."""
    position = np.array([[0.0, 0.0]] + [[10.0 + i, 0.0] for i in range(9)])
    n = len(position)
    indptr, cols = pair_list(position, RE_LAPLACIAN + 0.01, n_rows=n)
    surface = np.ones(n, bool)
    raw = surface_normals(indptr, cols, position, surface, RE_LAPLACIAN, n)
    normal = surface_fitted_normals(indptr, cols, position, raw, surface, RE_LAPLACIAN, n)
    diagonal = surface_ghost_diagonal(indptr, cols, position, RE_LAPLACIAN, surface,
                                      surface, surface, normal, False, 0.5, 7.0, n)
    assert diagonal[0] == 7.0 and diagonal[5] == 7.0
    assert (diagonal > 0.0).all()


def test_the_extrapolated_condition_corrects_the_fluids_surface_and_nothing_else(layer):
    """The corrected gradient keeps its own limit (0.7) for every row but the free-surface fluid
    particles the extrapolated condition names: those it corrects along their normal down to
    0.45, exact for the field that is zero above them; a free-surface particle it does not name
    (a body's node at its face to the air) keeps the plain gradient, half the field's. The
    Dirichlet condition names none and adds no diagonal."""
    from types import SimpleNamespace

    from parmps.fluid.schemes.gradient import CorrectedGradient
    from parmps.fluid.schemes.surface import DirichletSurface, ExtrapolatedSurface

    s = layer
    laplacian = SimpleNamespace(coefficient=1.0, inverse_cube=False, dirichlet_diagonal=7.0)
    constants = SimpleNamespace(dimension=2, n0=s["n0"], re_number_density=RE,
                                re_laplacian=RE_LAPLACIAN, spacing=1.0)
    near_indptr, near_cols = pairs_within(s["indptr"], s["cols"], s["position"], RE,
                                          s["n"])
    top = s["middle"] & (s["position"][:, 1] > DEPTH - 1)
    is_unknown = np.where(s["surface"], SURFACE_ROW, s["has_pressure"]).astype(np.int8)
    # Half the top row stands in for a body's face: not the fluid, so not its surface.
    body_face = top & (s["position"][:, 0] < WIDTH / 2)
    fluid = (s["kind"] == FLUID) & ~body_face
    fluid_face = top & ~body_face
    gradient = CorrectedGradient({"eigenvalue_limit": 0.7}, constants)
    assert DirichletSurface({}, constants).terms(s["indptr"], s["cols"], s["position"],
                                                  is_unknown, fluid, laplacian, s["n"]) == \
        (None, None)
    diagonal, surface = ExtrapolatedSurface({"eigenvalue_limit": 0.45}, constants).terms(
        s["indptr"], s["cols"], s["position"], is_unknown, fluid, laplacian, s["n"])
    assert np.array_equal(surface[0] & s["middle"], fluid_face) and surface[2] == 0.45
    assert (diagonal[top] > 0.0).all()
    rows = s["kind"] != DUMMY
    corrected = gradient.gradient(near_indptr, near_cols, s["position"], s["pressure"],
                                  s["has_pressure"], s["n"], rows, surface=surface)
    np.testing.assert_allclose(corrected[fluid_face],
                               np.tile([0.0, -1.0], (fluid_face.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(corrected[body_face],
                               np.tile([0.0, -0.5], (body_face.sum(), 1)), atol=1e-3)
    # Without the condition's rows: every row at the gradient's own limit, as before.
    plain_surface = gradient.gradient(near_indptr, near_cols, s["position"], s["pressure"],
                                      s["has_pressure"], s["n"], rows)
    np.testing.assert_allclose(plain_surface[fluid_face],
                               np.tile([0.0, -0.5], (fluid_face.sum(), 1)), atol=1e-3)
    deep = s["middle"] & (s["position"][:, 1] < DEPTH - 2)
    np.testing.assert_array_equal(corrected[deep], plain_surface[deep])


def test_the_normal_correction_scales_the_normal_part_and_never_turns_the_rest():
    """On a jet's tip (few neighbours, behind and below) the full inverse of the moment matrix
    turns a gradient along the flow; the normal correction changes only its part along the
    normal, by 1/(n . A n), and leaves the rest as it was. On a flat surface it is the full
    inverse (the test above)."""
    rng = np.random.default_rng(3)
    # A tip: a few particles behind (x < 0) and below (y < 0) of particle 0 at the origin.
    position = np.vstack([[0.0, 0.0], rng.uniform([-2.2, -2.2], [0.3, 0.2], (9, 2))])
    n = len(position)
    indptr, cols = pair_list(position, RE + 0.01, n_rows=n)
    has_pressure = np.ones(n, bool)
    n0, _ = reference_values(1.0, RE, 2)
    pressure = 3.0 * position[:, 0] + 0.2 * position[:, 1] + 10.0
    rows = np.zeros(n, bool)
    rows[0] = True
    plain = (2 / n0) * pressure_gradient_sum(indptr, cols, position, pressure,
                                             has_pressure, RE, n, rows)
    normal = np.zeros((n, 2))
    normal[0] = [0.6, 0.8]
    along = (2 / n0) * sum((RE / np.hypot(*r) - 1.0) * (r @ normal[0]) ** 2 / (r @ r)
                           for r in position[1:] - position[0] if 0 < np.hypot(*r) < RE)
    assert 0.0 < along < 1.0
    scaled = plain.copy()
    count = correct_normal_component(indptr, cols, position, has_pressure, RE, 2 / n0,
                                     scaled, normal, 0.0, rows)
    assert count == 1
    tangent = np.array([-0.8, 0.6])
    np.testing.assert_allclose(scaled[0] @ tangent, plain[0] @ tangent, rtol=1e-12)
    np.testing.assert_allclose(scaled[0] @ normal[0], plain[0] @ normal[0] / along, rtol=1e-12)
    np.testing.assert_array_equal(scaled[1:], plain[1:])
    # Below the limit it is left alone.
    kept = plain.copy()
    assert correct_normal_component(indptr, cols, position, has_pressure, RE, 2 / n0,
                                    kept, normal, along + 1e-9, rows) == 0
    np.testing.assert_array_equal(kept, plain)
