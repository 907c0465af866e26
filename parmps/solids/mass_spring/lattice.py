"""The geometry of a lattice body in any dimension: nodes, springs and boundary.

``shape`` is (nx, ny) or (nx, ny, nz); node (i, j[, k]) sits at
``lower + (i, j[, k]) spacing`` and has index ``i + nx j (+ nx ny k)``.

Springs, in this order: the axial springs along x, then y (then z), each block
ordered by node index of its first end; then, for every coordinate plane (xy,
then xz, then yz), both diagonals of every square of the lattice in that plane
(the "diagonal" from (a, b) to (a+1, b+1), then the "anti-diagonal" from
(a+1, b) to (a, b+1)). In 2D this is horizontal, vertical, diagonal,
anti-diagonal: the order the 2D runs have always used, so they stay
bit-identical.

Boundary: in 2D the counter-clockwise loop of the outline nodes (bottom row left
to right, right column up, top row right to left, left column down); in 3D the
outer surface as triangles, two per boundary face square, each ordered so that
its normal (x_b - x_a) x (x_c - x_a) points out of the body: the facets of
:func:`parmps.solids.mass_spring.surface.enclosed_volume`.
"""

from collections import namedtuple
from itertools import combinations

import numpy as np

# Per-spring kinds of a lattice.
AXIAL = 0
FACE_DIAGONAL = 1

LatticeGeometry = namedtuple("LatticeGeometry", "position springs kind boundary")


def _grid(shape):
    """Node indices as an array indexed [k, j, i] (reversed axes: i runs fastest)."""
    return np.arange(int(np.prod(shape))).reshape(tuple(shape)[::-1])


def _take(grid, axis, part):
    """``grid`` with lattice axis ``axis`` (0 = x) cut to ``part`` (a slice or an index)."""
    index = [slice(None)] * grid.ndim
    index[grid.ndim - 1 - axis] = part
    return grid[tuple(index)]


def _pairs(first, second):
    return np.column_stack([first.ravel(), second.ravel()])


def _axial_springs(grid, d):
    return [_pairs(_take(grid, a, slice(None, -1)), _take(grid, a, slice(1, None)))
            for a in range(d)]


def _face_diagonals(grid, d):
    """Both diagonals of every square in every coordinate plane (a, b), a < b."""
    low, high = slice(None, -1), slice(1, None)
    blocks = []
    for a, b in combinations(range(d), 2):
        blocks.append(_pairs(_take(_take(grid, a, low), b, low),
                             _take(_take(grid, a, high), b, high)))
        blocks.append(_pairs(_take(_take(grid, a, high), b, low),
                             _take(_take(grid, a, low), b, high)))
    return blocks


def _loop(grid):
    """The counter-clockwise outline of a 2D grid (indexed [j, i]); each corner once."""
    return np.concatenate([grid[0, :], grid[1:, -1], grid[-1, -2::-1], grid[-2:0:-1, 0]])


def _face_triangles(grid, axis, outward):
    """Two triangles per square of the face ``grid`` (a 2D index array on axes b, c).

    ``grid[c, b]`` with (axis, b, c) cyclic, so e_b x e_c = e_axis: corners
    counter-clockwise in (b, c) give the normal +e_axis; ``outward`` is that
    sign.
    """
    p00, p10 = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel()
    p11, p01 = grid[1:, 1:].ravel(), grid[1:, :-1].ravel()
    if outward < 0:
        p10, p01 = p01, p10
    return np.concatenate([np.column_stack([p00, p10, p11]), np.column_stack([p00, p11, p01])])


def _surface(grid):
    """The outer surface of a 3D grid (indexed [k, j, i]) as outward triangles."""
    faces = []
    for axis in range(3):
        b, c = (axis + 1) % 3, (axis + 2) % 3
        for side, outward in ((0, -1), (-1, 1)):
            face = _take(grid, axis, side)
            # ``face`` keeps the remaining array axes in reversed lattice order;
            # put it as [c, b] so its rows run along c and its columns along b.
            remaining = [e for e in (2, 1, 0) if e != axis]
            face = face.transpose([remaining.index(c), remaining.index(b)])
            faces.append(_face_triangles(face, axis, outward))
    return np.concatenate(faces)


def lattice_geometry(shape, spacing, lower):
    """Positions (n, d), springs (m, 2), per-spring kind (AXIAL or FACE_DIAGONAL) and
    boundary of the lattice ``shape`` = (nx, ny) or (nx, ny, nz).

    The boundary is the counter-clockwise node loop in 2D and the outward
    triangles (t, 3) of the outer surface in 3D (module docstring).
    """
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    grid = _grid(shape)
    # Node n has lattice coordinates (n mod nx, n // nx mod ny, ...).
    coordinates = np.indices(shape[::-1]).reshape(d, -1)[::-1].T
    position = np.asarray(lower, dtype=float)[:d] + coordinates * spacing
    axial, diagonal = _axial_springs(grid, d), _face_diagonals(grid, d)
    springs = np.concatenate(axial + diagonal)
    kind = np.full(len(springs), FACE_DIAGONAL, np.int8)
    kind[:sum(len(block) for block in axial)] = AXIAL
    boundary = _loop(grid) if d == 2 else _surface(grid)
    return LatticeGeometry(position, springs, kind, boundary)
