"""Closed surfaces behind one protocol: their signed distance on a block of the lattice.

A surface is a primitive (:class:`Sphere`, :class:`Cylinder`, :class:`Box`, any
dimension: in 2D a sphere or a cylinder is a circle) or a closed triangle mesh
(:class:`MeshSurface`, 3D). Each gives

- ``bounds()``: the lower and upper corners of its bounding box;
- ``lattice_distance(lattice, reach)``: the signed distance (negative inside) at every
  point of ``lattice`` (a :class:`LatticeBlock`), exact within ``reach`` of the surface
  and of the right sign (magnitude at least ``reach``) beyond;
- ``samples(step)``: points on the surface at most about ``step`` apart, each with the
  length (2D) or area (3D) it stands for and the outward normal there (a force probe
  on the wall integrates its pressure over them).

The walls and the fluid of any shape (:mod:`parmps.geometry.walls`) are built from these
alone, so they never ask what shape a surface is. Primitives are exact (analytic
distances); a mesh's inside is the winding number of rays along the lattice's columns
(:func:`parmps.geometry.mesh.lattice_winding`) and its distance the nearest triangle's,
in a compiled loop over the lattice points near each triangle.

Cost, measured on this machine (one of 2 shared cores; a sphere of 20,480 triangles,
200,000 random points): libigl 2.6.3 (it installs here with Debian's numpy 1.24.2) took
11.8 s for ``signed_distance`` and 0.64 s for ``fast_winding_number``; parmps's own ray test
(:func:`parmps.geometry.mesh.points_inside`) 2.1 s and k-d tree distance
(:func:`parmps.core.geometry.surface_distance`) 14.8 s. Points of a lattice need neither:
the columns' rays give the side of every point of a 10.6M-point block about that sphere in
0.5 s, and with the loop below its distance within 4 l0 (1.0M points) in 3.6 s (1.3M
points, 0.25M within 4 l0: 0.07 s and 0.7 s). The scene of a meshed box filled with 1.02M
fluid particles and its 273k wall and dummy particles builds in 0.7-1.0 s against the box
path's 0.4-0.6 s (a tank and a box block of the same particles; ``--check`` of the case
3.0-3.4 s against 4.2 s on one rank). So no new dependency.
"""

import math

import numba
import numpy as np

AXES = "xyz"


class LatticeBlock:
    """The lattice points ``origin + (index + 1/2) l0`` for index in [low, low + shape)
    on each axis: a block of the case's one lattice (``particles.origin``)."""

    def __init__(self, origin, spacing, low, shape):
        self.origin = np.asarray(origin, dtype=float)
        self.spacing = float(spacing)
        self.low = np.asarray(low, dtype=np.int64)
        self.shape = tuple(int(n) for n in shape)

    @classmethod
    def covering(cls, origin, spacing, lower, upper):
        """The block of every lattice point in the box [lower, upper] (none when empty)."""
        origin = np.asarray(origin, dtype=float)
        first = np.ceil((np.asarray(lower, float) - origin) / spacing - 0.5 - 1e-9)
        last = np.floor((np.asarray(upper, float) - origin) / spacing - 0.5 + 1e-9)
        return cls(origin, spacing, first.astype(np.int64),
                   np.maximum(last - first + 1, 0).astype(np.int64))

    @property
    def corner(self):
        """The first point, index ``low``."""
        return self.origin + (self.low + 0.5) * self.spacing

    def axes(self):
        """The coordinates of the points along each axis."""
        return [self.corner[a] + self.spacing * np.arange(n) for a, n in enumerate(self.shape)]

    def points(self, mask=None):
        """The points (n, d) where ``mask`` (an array of ``shape``) holds, all points when
        None, x varying fastest (the order of parmps.geometry.scene's lattices)."""
        mask = np.ones(self.shape, bool) if mask is None else mask
        index = np.argwhere(mask.T)[:, ::-1]
        return self.corner + index * self.spacing

    def values(self, array, mask):
        """The entries of ``array`` (of ``shape``) where ``mask`` holds, in the order of
        :meth:`points`."""
        return array.T[mask.T]


class Sphere:
    """|x - c| = r (a circle in 2D)."""

    def __init__(self, center, radius):
        self.center, self.radius = np.asarray(center, dtype=float), float(radius)

    def bounds(self):
        return self.center - self.radius, self.center + self.radius

    def signed_distance(self, points):
        return np.linalg.norm(points - self.center, axis=-1) - self.radius

    def lattice_distance(self, lattice, reach=None):
        return _grid_eval(self.signed_distance, lattice)

    def samples(self, step):
        if len(self.center) == 2:
            return _circle_samples(self.center, self.radius, step)
        from parmps.geometry.shapes import icosphere

        vertices, triangles = icosphere(self.radius, edge_length=step, center=self.center)
        # Its triangles are already about a step across: one sample each.
        return mesh_samples(vertices, triangles, np.inf)


class Cylinder:
    """A circular cylinder of ``radius`` about ``axis`` through ``center``, ``length`` long
    with flat ends (3D); in 2D the circle of ``radius``."""

    def __init__(self, center, radius, axis="z", length=0.0):
        self.center, self.radius = np.asarray(center, dtype=float), float(radius)
        self.dimension = len(self.center)
        self.axis = AXES.index(axis) if self.dimension == 3 else None
        self.length = float(length)

    def bounds(self):
        half = np.full(self.dimension, self.radius)
        if self.axis is not None:
            half[self.axis] = 0.5 * self.length
        return self.center - half, self.center + half

    def _parts(self, points):
        """(radial distance - r, axial distance - length/2 or -inf in 2D, radial offset)."""
        offset = points - self.center
        along = np.zeros_like(offset)
        if self.axis is not None:
            along[..., self.axis] = offset[..., self.axis]
        radial = offset - along
        axial = (np.abs(along[..., self.axis]) - 0.5 * self.length if self.axis is not None
                 else np.full(offset.shape[:-1], -np.inf))
        return np.linalg.norm(radial, axis=-1) - self.radius, axial, radial

    def signed_distance(self, points):
        r, a, _ = self._parts(points)
        outside = np.hypot(np.maximum(r, 0.0), np.maximum(a, 0.0))
        return np.where((r > 0) | (a > 0), outside, np.maximum(r, a))

    def lattice_distance(self, lattice, reach=None):
        return _grid_eval(self.signed_distance, lattice)

    def samples(self, step):
        if self.axis is None:
            return _circle_samples(self.center, self.radius, step)
        r, half = self.radius, 0.5 * self.length
        sides = max(8, int(np.ceil(2 * np.pi * r / step)))
        levels = max(1, int(np.ceil(self.length / step)))
        angle = 2 * np.pi * (np.arange(sides) + 0.5) / sides
        z = -half + (np.arange(levels) + 0.5) * self.length / levels
        radial = np.repeat(np.column_stack([np.cos(angle), np.sin(angle)]), levels, axis=0)
        local = [np.column_stack([r * radial, np.tile(z, sides)])]
        normals = [np.column_stack([radial, np.zeros(len(radial))])]
        weights = [np.full(len(radial), 2 * np.pi * r / sides * self.length / levels)]
        # Each end: rings of equal width, each ring's area shared by its points.
        rings = max(1, int(np.ceil(r / step)))
        for k in range(rings):
            inner, outer = k * r / rings, (k + 1) * r / rings
            count = max(1, int(np.ceil(2 * np.pi * 0.5 * (inner + outer) / step)))
            phi = 2 * np.pi * (np.arange(count) + 0.5) / count
            ring = 0.5 * (inner + outer) * np.column_stack([np.cos(phi), np.sin(phi)])
            for side in (-1.0, 1.0):
                local.append(np.column_stack([ring, np.full(count, side * half)]))
                normals.append(np.tile([0.0, 0.0, side], (count, 1)))
                weights.append(np.full(count, np.pi * (outer ** 2 - inner ** 2) / count))
        # The local z is the axis: turn it onto the cylinder's by a cyclic permutation.
        turn = {2: [0, 1, 2], 0: [2, 0, 1], 1: [1, 2, 0]}[self.axis]
        return (np.concatenate(local)[:, turn] + self.center, np.concatenate(weights),
                np.concatenate(normals)[:, turn])


class Box:
    """The box [lower, upper], any dimension."""

    def __init__(self, lower, upper):
        self.lower, self.upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)

    def bounds(self):
        return self.lower, self.upper

    def signed_distance(self, points):
        centre, half = 0.5 * (self.lower + self.upper), 0.5 * (self.upper - self.lower)
        q = np.abs(points - centre) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        return outside + np.minimum(q.max(axis=-1), 0.0)

    def lattice_distance(self, lattice, reach=None):
        return _grid_eval(self.signed_distance, lattice)

    def samples(self, step):
        d = len(self.lower)
        points, weights, normals = [], [], []
        for axis in range(d):
            others = [a for a in range(d) if a != axis]
            counts = [max(1, int(np.ceil((self.upper[a] - self.lower[a]) / step)))
                      for a in others]
            sizes = [(self.upper[a] - self.lower[a]) / n for a, n in zip(others, counts)]
            grids = np.meshgrid(*[self.lower[a] + (np.arange(n) + 0.5) * h
                                  for a, n, h in zip(others, counts, sizes)], indexing="ij")
            for side, plane in ((-1.0, self.lower[axis]), (1.0, self.upper[axis])):
                face = np.empty((grids[0].size, d))
                face[:, axis] = plane
                for a, g in zip(others, grids):
                    face[:, a] = g.ravel()
                normal = np.zeros((len(face), d))
                normal[:, axis] = side
                points.append(face)
                weights.append(np.full(len(face), float(np.prod(sizes))))
                normals.append(normal)
        return np.concatenate(points), np.concatenate(weights), np.concatenate(normals)


class MeshSurface:
    """A triangle mesh (vertices (n, 3), triangles (m, 3)) checked by
    :func:`parmps.geometry.mesh.check_wall_surface`: closed and outward oriented, or
    ``open`` (with a rim), its fluid on the side its triangles face.

    A closed surface's side is its winding number; an open one's is the side of the
    nearest point's pseudo-normal (the face's normal, or at an edge or corner the sum of
    its faces' normals, weighted by their angles at a corner: Baerentzen & Aanaes 2005),
    and a point nearest to the rim lies beyond the surface's edge, on no side of it
    (+inf): an open tank's walls end where its faces end."""

    def __init__(self, vertices, triangles, open=False):
        self.vertices = np.asarray(vertices, dtype=float)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.open = bool(open)
        self._normals = _pseudo_normals(self.vertices, self.triangles)
        self._layers = (self._normals[0], *_fans(self.triangles, len(self.vertices)),
                        self.triangles, _neighbours(self.triangles))

    def bounds(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def lattice_distance(self, lattice, reach=0.0):
        """The signed distance (> 0 outside a closed surface, on the facing side of an open
        one) at the block's points, within ``reach`` counted as a tank's layers count it
        (:func:`_layer_depth`), +-inf beyond; ``reach`` 0: the sign alone."""
        from parmps.geometry.mesh import lattice_winding

        if self.open and not reach:
            raise ValueError("an open surface has no inside: its sides are known within reach")
        corners = np.ascontiguousarray(self.vertices[self.triangles])
        if reach:
            # A square corner's points lie up to sqrt(3) times their depth from its vertex.
            search = reach * math.sqrt(3.0)
            best = np.full(lattice.shape, search * search)
            which = np.full(lattice.shape, -1, np.int64)
            _band_distance(corners, lattice.corner, lattice.spacing, np.array(lattice.shape),
                           float(search), best, which)
            band = which >= 0
            points, nearest = lattice.points(band), lattice.values(which, band)
            depth = _layer_depth(points, nearest, corners, *self._layers)
            # Beyond reach the distance is only known to exceed it.
            depth[depth > reach] = np.inf
        if self.open:
            side = _open_signed(points, nearest, corners, *self._normals)
            signed = np.full(lattice.shape, np.inf)
            # points() runs x fastest: set the values in that order too.
            signed.T[band.T] = np.where(np.isinf(side), np.inf, np.copysign(depth, side))
            return signed
        grid = lattice.origin + 0.5 * lattice.spacing
        winding = lattice_winding(self.vertices, self.triangles, lattice.spacing, grid,
                                  lattice.low, lattice.shape)
        sign = np.where(winding > 0.5, -1.0, 1.0)
        if not reach:
            return sign * np.inf
        distance = np.full(lattice.shape, np.inf)
        distance.T[band.T] = depth
        return sign * distance

    def open_signed_distance(self, points):
        """An open surface's signed distance at any ``points`` (k, 3), as
        :meth:`lattice_distance` counts it, by the nearest of all its triangles: +inf
        beyond its rim, > 0 on the side its triangles face."""
        corners = np.ascontiguousarray(self.vertices[self.triangles])
        points = np.ascontiguousarray(points, dtype=float)
        nearest = _nearest_triangle(points, corners)
        side = _open_signed(points, nearest, corners, *self._normals)
        depth = _layer_depth(points, nearest, corners, *self._layers)
        return np.where(np.isinf(side), np.inf, np.copysign(depth, side))

    def samples(self, step):
        return mesh_samples(self.vertices, self.triangles, step)


class PolylineSurface:
    """A 2D wall's curve: vertices (n, 2) and segments (m, 2) of a polyline mesh checked by
    :func:`parmps.geometry.mesh.check_polyline`, each segment a -> b facing its right-hand
    side (dy, -dx): a closed loop counter-clockwise (facing out), or ``open`` (with two
    ends), its fluid on the side its segments face.

    The signed distance is the nearest point's, signed by its pseudo-normal (a segment's
    normal, at a vertex the sum of its two segments'), > 0 on the facing side, and a point
    nearest to an open curve's end lies beyond it, on no side (+inf). As for meshes, a point
    behind a vertex is as deep as it is from the farther of its two segments' lines (square
    corners, a tank's layers)."""

    # Point-segment pairs a vectorised pass holds (a few arrays of this many pairs).
    PAIRS = 1 << 21

    def __init__(self, vertices, segments, open=False):
        self.vertices = np.asarray(vertices, dtype=float)
        self.segments = np.asarray(segments, dtype=np.int64)
        self.open = bool(open)
        a, b = self.vertices[self.segments[:, 0]], self.vertices[self.segments[:, 1]]
        direction = b - a
        self._start, self._direction = a, direction
        self._normal = np.column_stack([direction[:, 1], -direction[:, 0]]) / \
            np.linalg.norm(direction, axis=1)[:, None]
        n = len(self.vertices)
        # Each vertex's segments in and out (-1 at an open curve's ends).
        self._into, self._out = np.full(n, -1), np.full(n, -1)
        self._into[self.segments[:, 1]] = np.arange(len(self.segments))
        self._out[self.segments[:, 0]] = np.arange(len(self.segments))

    def bounds(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def signed_distance(self, points):
        points = np.asarray(points, dtype=float)
        out = np.empty(len(points))
        chunk = max(1, self.PAIRS // len(self.segments))
        for begin in range(0, len(points), chunk):
            out[begin:begin + chunk] = self._signed(points[begin:begin + chunk])
        return out

    def _signed(self, points):
        offset = points[:, None, :] - self._start[None]
        length2 = np.einsum("ij,ij->i", self._direction, self._direction)
        t = np.clip(np.einsum("kij,ij->ki", offset, self._direction) / length2, 0.0, 1.0)
        gap = offset - t[..., None] * self._direction[None]
        distance2 = np.einsum("kij,kij->ki", gap, gap)
        nearest = np.argmin(distance2, axis=1)
        rows = np.arange(len(points))
        t, gap = t[rows, nearest], gap[rows, nearest]
        # At an end of the segment the nearest point is a vertex: its two segments decide.
        vertex = np.where(t <= 0.0, self.segments[nearest, 0],
                          np.where(t >= 1.0, self.segments[nearest, 1], -1))
        at_vertex = vertex >= 0
        before, after = self._into[vertex], self._out[vertex]
        rim = at_vertex & ((before < 0) | (after < 0))
        normal = self._normal[nearest].copy()
        corner = at_vertex & ~rim
        normal[corner] = self._normal[before[corner]] + self._normal[after[corner]]
        depth = np.sqrt(distance2[rows, nearest])
        lines = [np.abs(np.einsum("ij,ij->i", points[corner] - self._start[k],
                                  self._normal[k])) for k in (before[corner], after[corner])]
        depth[corner] = np.maximum(*lines)
        signed = np.where(np.einsum("ij,ij->i", gap, normal) >= 0.0, depth, -depth)
        signed[rim] = np.inf
        return signed

    def lattice_distance(self, lattice, reach=None):
        return _grid_eval(self.signed_distance, lattice)

    def samples(self, step):
        """Points about every ``step`` along each segment, their lengths and the segments'
        normals (the facing side's)."""
        lengths = np.linalg.norm(self._direction, axis=1)
        counts = np.maximum(1, np.ceil(lengths / step).astype(np.int64))
        segment = np.repeat(np.arange(len(self.segments)), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        fraction = (np.arange(len(segment)) - first + 0.5) / counts[segment]
        points = self._start[segment] + fraction[:, None] * self._direction[segment]
        return points, (lengths / counts)[segment], self._normal[segment]


def _fans(triangles, n_vertices):
    """The triangles around each vertex as (start (n + 1,), triangles): vertex v's are
    ``triangles[start[v]:start[v + 1]]``."""
    vertex = triangles.ravel()
    order = np.argsort(vertex, kind="stable")
    start = np.zeros(n_vertices + 1, np.int64)
    start[1:] = np.cumsum(np.bincount(vertex, minlength=n_vertices))
    return start, (order // 3).astype(np.int64)


def _neighbours(triangles):
    """The triangle across each side (ab, bc, ca) of every triangle, (m, 3); -1 on a rim."""
    from parmps.geometry.mesh import _edge_groups, _half_edges

    start, end, _ = _half_edges(triangles)
    order, first, counts = _edge_groups(start, end)
    across = np.full(len(start), -1, np.int64)
    pair = first[counts == 2]
    across[order[pair]] = order[pair + 1] // 3
    across[order[pair + 1]] = order[pair] // 3
    return across.reshape(-1, 3)


def _pseudo_normals(vertices, triangles):
    """Per triangle: its unit normal (m, 3); at each corner the vertex's angle-weighted
    normal (m, 3, 3) and whether the vertex is on the rim (m, 3); on each side (ab, bc,
    ca) the edge's normal, the sum of its faces' (m, 3, 3), and whether it is a rim edge
    (m, 3)."""
    from parmps.geometry.mesh import _edge_groups, _half_edges

    x = vertices[triangles]
    face = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    face /= np.linalg.norm(face, axis=1)[:, None]
    angle = np.empty((len(triangles), 3))
    for c in range(3):
        u, v = x[:, (c + 1) % 3] - x[:, c], x[:, (c + 2) % 3] - x[:, c]
        cosine = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1)
                                                * np.linalg.norm(v, axis=1))
        angle[:, c] = np.arccos(np.clip(cosine, -1.0, 1.0))
    vertex = np.zeros_like(vertices)
    for c in range(3):
        np.add.at(vertex, triangles[:, c], angle[:, c, None] * face)
    vertex /= np.linalg.norm(vertex, axis=1)[:, None]
    start, end, _ = _half_edges(triangles)
    order, first, counts = _edge_groups(start, end)
    group = np.empty(len(start), np.int64)
    group[order] = np.repeat(np.arange(len(first)), counts)
    edge = np.zeros((len(first), 3))
    np.add.at(edge, group, np.repeat(face, 3, axis=0))
    edge /= np.linalg.norm(edge, axis=1)[:, None]
    rim_edge = (counts == 1)[group].reshape(-1, 3)
    rim_vertex = np.zeros(len(vertices), bool)
    rim_vertex[start[rim_edge.ravel()]] = True
    rim_vertex[end[rim_edge.ravel()]] = True
    return (face, np.ascontiguousarray(vertex[triangles]), rim_vertex[triangles],
            np.ascontiguousarray(edge[group].reshape(-1, 3, 3)), rim_edge)


def _circle_samples(center, radius, step):
    """Points every arc of at most ``step`` round the circle, their arc lengths and the
    outward normals."""
    count = max(8, int(np.ceil(2 * np.pi * radius / step)))
    angle = 2 * np.pi * (np.arange(count) + 0.5) / count
    normal = np.column_stack([np.cos(angle), np.sin(angle)])
    return center + radius * normal, np.full(count, 2 * np.pi * radius / count), normal


def mesh_samples(vertices, triangles, step):
    """The centroids of every triangle cut into n^2 equal ones (n its longest edge over
    ``step``, rounded up), with their areas and the triangle's outward unit normal."""
    corners = np.asarray(vertices, float)[np.asarray(triangles, np.int64)]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    cuts = np.maximum(1, np.ceil(longest / step - 1e-9)).astype(np.int64)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    unit = cross / (2.0 * area)[:, None]
    points, weights, normals = [], [], []
    for n in np.unique(cuts):
        mine = np.flatnonzero(cuts == n)
        # Barycentric centroids of the n^2 sub-triangles: n(n+1)/2 upright, n(n-1)/2 not.
        i, j = np.triu_indices(n)
        j = j - i
        up = np.column_stack([i + 1 / 3, j + 1 / 3])
        keep = i + j <= n - 2
        down = np.column_stack([i[keep] + 2 / 3, j[keep] + 2 / 3])
        uv = np.vstack([up, down]) / n
        a, b, c = corners[mine, 0], corners[mine, 1], corners[mine, 2]
        p = (a[:, None] + uv[None, :, 0, None] * (b - a)[:, None]
             + uv[None, :, 1, None] * (c - a)[:, None])
        points.append(p.reshape(-1, 3))
        weights.append(np.repeat(area[mine] / n ** 2, len(uv)))
        normals.append(np.repeat(unit[mine], len(uv), axis=0))
    return np.concatenate(points), np.concatenate(weights), np.concatenate(normals)


def _grid_eval(function, lattice, chunk=1 << 20):
    """``function`` (points (k, d) -> values (k,)) at every point of the block, as an
    array of its shape, a chunk of points at a time (x-major order, reshaped back)."""
    axes = lattice.axes()
    out = np.empty(lattice.shape)
    flat = out.reshape(-1)
    count = flat.size
    strides = np.cumprod([1, *lattice.shape[:0:-1]])[::-1]
    for begin in range(0, count, chunk):
        index = np.arange(begin, min(count, begin + chunk))
        points = np.column_stack([axes[a][(index // strides[a]) % n]
                                  for a, n in enumerate(lattice.shape)])
        flat[begin:begin + len(index)] = function(points)
    return out


@numba.njit(cache=True)
def _closest(px, py, pz, t, corners):
    """p minus its closest point on triangle t of ``corners`` (m, 3, 3), and the region that
    point lies in: 0 the face, 1-3 the corners a, b, c, 4-6 the sides ab, bc, ca (Ericson,
    Real-Time Collision Detection 5.1.5), in scalars: no temporary arrays in the innermost
    loop."""
    ax, ay, az = corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2]
    abx, aby, abz = corners[t, 1, 0] - ax, corners[t, 1, 1] - ay, corners[t, 1, 2] - az
    acx, acy, acz = corners[t, 2, 0] - ax, corners[t, 2, 1] - ay, corners[t, 2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    v, w, region = 0.0, 0.0, 1
    if d1 > 0.0 or d2 > 0.0:
        bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v, w, region = 1.0, 0.0, 2
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v, w, region = d1 / (d1 - d3), 0.0, 4
        elif d6 >= 0.0 and d5 <= d6:
            v, w, region = 0.0, 1.0, 3
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            v, w, region = 0.0, d2 / (d2 - d6), 6
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            v, region = 1.0 - w, 5
        else:
            total = va + vb + vc
            v, w, region = vb / total, vc / total, 0
    gx = apx - v * abx - w * acx
    gy = apy - v * aby - w * acy
    gz = apz - v * abz - w * acz
    return gx, gy, gz, region


@numba.njit(cache=True)
def _triangle_distance2(px, py, pz, t, corners):
    """Squared distance from p to triangle t of ``corners`` (m, 3, 3)."""
    gx, gy, gz, _ = _closest(px, py, pz, t, corners)
    return gx * gx + gy * gy + gz * gz


@numba.njit(cache=True)
def _open_signed(points, which, corners, face, corner_normal, corner_rim, side_normal,
                 side_rim):
    """Signed distance of ``points`` (k, 3) to their nearest triangles ``which`` (k,) of an
    open surface: the distance, signed by the nearest point's pseudo-normal (> 0 on the
    side the triangles face), +inf where that point is on the rim."""
    out = np.empty(len(points))
    for n in range(len(points)):
        t = which[n]
        gx, gy, gz, region = _closest(points[n, 0], points[n, 1], points[n, 2], t, corners)
        if region == 0:
            nx, ny, nz, rim = face[t, 0], face[t, 1], face[t, 2], False
        elif region <= 3:
            c = region - 1
            nx, ny, nz = corner_normal[t, c, 0], corner_normal[t, c, 1], corner_normal[t, c, 2]
            rim = corner_rim[t, c]
        else:
            e = region - 4
            nx, ny, nz = side_normal[t, e, 0], side_normal[t, e, 1], side_normal[t, e, 2]
            rim = side_rim[t, e]
        distance = math.sqrt(gx * gx + gy * gy + gz * gz)
        out[n] = np.inf if rim else (distance if gx * nx + gy * ny + gz * nz >= 0.0
                                     else -distance)
    return out


@numba.njit(cache=True)
def _nearest_triangle(points, corners):
    """The index of each point's nearest triangle, over all of them (k m work)."""
    which = np.empty(len(points), np.int64)
    for n in range(len(points)):
        best = np.inf
        for t in range(corners.shape[0]):
            d2 = _triangle_distance2(points[n, 0], points[n, 1], points[n, 2], t, corners)
            if d2 < best:
                best, which[n] = d2, t
    return which


@numba.njit(cache=True)
def _layer_depth(points, which, corners, face, fan_start, fan_faces, triangles, neighbour):
    """How deep ``points`` (k, 3) lie behind their nearest triangles ``which``, as a tank's
    layers count it: the distance to the nearest point where that is inside a face, else
    the largest distance to the planes of the faces meeting at the nearest edge or corner
    (a box's layers turn its edges and corners square, as a tank's do, where the distance
    to the edge would round them; on a finely faceted curve the two agree)."""
    out = np.empty(len(points))
    for n in range(len(points)):
        t = which[n]
        px, py, pz = points[n, 0], points[n, 1], points[n, 2]
        gx, gy, gz, region = _closest(px, py, pz, t, corners)
        if region == 0:
            out[n] = math.sqrt(gx * gx + gy * gy + gz * gz)
            continue
        deepest = 0.0
        if region <= 3:
            vertex = triangles[t, region - 1]
            for k in range(fan_start[vertex], fan_start[vertex + 1]):
                deepest = max(deepest, _plane_distance(px, py, pz, fan_faces[k], corners, face))
        else:
            deepest = _plane_distance(px, py, pz, t, corners, face)
            other = neighbour[t, region - 4]
            if other >= 0:
                deepest = max(deepest, _plane_distance(px, py, pz, other, corners, face))
        out[n] = deepest
    return out


@numba.njit(cache=True)
def _plane_distance(px, py, pz, t, corners, face):
    """|distance| from p to the plane of triangle t."""
    return abs((px - corners[t, 0, 0]) * face[t, 0] + (py - corners[t, 0, 1]) * face[t, 1]
               + (pz - corners[t, 0, 2]) * face[t, 2])


@numba.njit(cache=True)
def _band_distance(corners, first, spacing, shape, reach, best, which):
    """The least squared distance to the triangles (m, 3, 3), into ``best`` (the block's
    shape, holding reach^2 or less), and the triangle it is to, into ``which``, of the
    lattice points ``first + spacing index`` within ``reach`` of each triangle's bounding
    box: cost the triangles times the points near each."""
    for t in range(corners.shape[0]):
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for a in range(3):
            low = min(corners[t, 0, a], corners[t, 1, a], corners[t, 2, a]) - reach
            high = max(corners[t, 0, a], corners[t, 1, a], corners[t, 2, a]) + reach
            lo[a] = max(int(np.ceil((low - first[a]) / spacing)), 0)
            hi[a] = min(int(np.floor((high - first[a]) / spacing)), shape[a] - 1)
        for i in range(lo[0], hi[0] + 1):
            px = first[0] + spacing * i
            for j in range(lo[1], hi[1] + 1):
                py = first[1] + spacing * j
                for k in range(lo[2], hi[2] + 1):
                    pz = first[2] + spacing * k
                    d2 = _triangle_distance2(px, py, pz, t, corners)
                    if d2 < best[i, j, k]:
                        best[i, j, k] = d2
                        which[i, j, k] = t
