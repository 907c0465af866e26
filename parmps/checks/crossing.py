"""Fluid through a thin body: particles whose path crossed the body's mid-line (in 3D its
mid-surface).

A thin lattice body (a gate, a plate, a membrane of several node rows) must
hold the fluid back: water may flow round its free end, never through it.
Every step each owned fluid particle near the body gets a side of the
mid-line (:func:`mid_line_sides`): -1 or +1 when its nearest point on the
mid-line lies within it (it is beside the body), 0 when it lies beyond one
of the ends or farther than ``band``. A particle that was beside the body on
one side at the previous step and is beside it on the other side now has
crossed the mid-line within the step: between two points beside a straight
segment on opposite sides the straight path cuts the segment. Going round an
end passes through side 0 and is not counted.

In 3D the body's mid-surface is the mean of its nodes through its thinnest direction, a
grid of points triangulated two triangles a cell (:func:`lattice_mid_surface`); a particle
is beside it when its nearest point on the surface is not on the surface's border, and its
side is the sign of the nearest triangle's normal against it (:func:`mid_surface_sides`).
The 2D mid-line is the same construction one dimension down, and keeps its own code.

Why a step cannot skip the test: the band reaches two spacings beyond the
body's half-thickness on each side, and a particle moves less than a spacing
in a step (the Courant limit, time.cfl <= 1), so a particle that crosses is
seen beside the body on both sides.

The count is a result, not a stop: ``/checks/<name>`` in result.h5 holds, per
step, the time, the crossings in the step and their total so far, and rank 0
logs a warning at the first crossing.
"""

import logging

import numba
import numpy as np
from scipy.spatial import cKDTree

from parmps.core.geometry import cell_runs, closed_surface_sides, edge_lengths
from parmps.core.particles import owned_fluid_near
from parmps.geometry.domain import Domain
from parmps.io.series import Series
from parmps.run.observers import Observer
from parmps.run.schedule import SimulatedInterval

log = logging.getLogger("parmps.run")

# Half-width of the band beside the mid-line, in spacings beyond the half-thickness.
BAND_SPACINGS = 2.0


def lattice_mid_line(position, nx, ny):
    """The mid-line of a lattice body (nodes i + nx j): the mean of each section's nodes
    through the thickness, along the longer side. Returns (max(nx, ny), 2)."""
    grid = np.asarray(position, dtype=float).reshape(ny, nx, 2)
    return grid.mean(axis=1) if ny >= nx else grid.mean(axis=0)


def mid_line_sides(points, mid_line, band):
    """Side of the polyline ``mid_line`` (m, 2) of each of ``points`` (n, 2): -1 or +1 (the
    sign of the cross product of the nearest segment's direction with the point), 0 where
    the nearest point of the polyline is one of its ends or is farther than ``band``."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    sides = np.zeros(len(points), np.int8)
    if len(points) == 0:
        return sides
    start, end = mid_line[:-1], mid_line[1:]
    direction = end - start
    length2 = np.einsum("ij,ij->i", direction, direction)
    # Every point against every segment: the polyline has tens of segments and the band a
    # few hundred particles.
    offset = points[:, None, :] - start[None, :, :]
    along = np.clip(np.einsum("nmj,mj->nm", offset, direction) / length2, 0.0, 1.0)
    gap = offset - along[..., None] * direction[None, :, :]
    distance2 = np.einsum("nmj,nmj->nm", gap, gap)
    nearest = np.argmin(distance2, axis=1)
    rows = np.arange(len(points))
    t = along[rows, nearest]
    at_end = ((nearest == 0) & (t <= 0.0)) | ((nearest == len(direction) - 1) & (t >= 1.0))
    beside = ~at_end & (distance2[rows, nearest] <= band * band)
    o, d = offset[rows, nearest], direction[nearest]
    cross = d[:, 0] * o[:, 1] - d[:, 1] * o[:, 0]
    sides[beside] = np.where(cross[beside] > 0.0, 1, -1)
    return sides


def lattice_mid_surface(position, shape):
    """The mid-surface of a lattice body of ``shape`` (nx, ny[, nz]) nodes (node i + nx j
    [+ nx ny k]): the mean of its nodes through the thinnest direction (x on a tie), as
    (vertices, facets). 2D: the mid-line of :func:`lattice_mid_line`, facets its segments;
    3D: a grid of points, two triangles (m, 3) a cell, all with the same orientation."""
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    grid = np.asarray(position, dtype=float)[:int(np.prod(shape))].reshape(shape[::-1] + (d,))
    thin = int(np.argmin(shape))  # the lattice axis; the array's axes run reversed
    mid = grid.mean(axis=d - 1 - thin)
    vertices = mid.reshape(-1, d)
    index = np.arange(len(vertices)).reshape(mid.shape[:-1])
    if d == 2:
        return vertices, np.column_stack([index[:-1], index[1:]])
    a, b = index[:-1, :-1].ravel(), index[:-1, 1:].ravel()
    c, e = index[1:, :-1].ravel(), index[1:, 1:].ravel()
    facets = np.concatenate([np.column_stack([a, b, e]), np.column_stack([a, e, c])])
    return vertices, facets


def border_edges(facets):
    """The edges (k, 2) of a triangulated surface that belong to one triangle only."""
    edges = np.sort(np.concatenate([facets[:, [0, 1]], facets[:, [1, 2]],
                                    facets[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return unique[count == 1]


def mid_surface_sides(points, vertices, facets, band):
    """Side of a mid-surface (``vertices`` (v, d), ``facets`` (m, d)) of each of ``points``
    (n, d): -1 or +1, or 0 beyond its border or farther than ``band``. 2D: the mid-line's
    :func:`mid_line_sides` (its vertices run along the line); 3D: the sign of the nearest
    triangle's normal against the point, 0 where the nearest point of the surface lies on
    its border (a point round its edge, as a 2D point beyond an end).

    Only what lies within ``band`` of a point can decide its side, so the points are taken
    a cube of side 2 ``band`` at a time, against the triangles and border edges whose boxes
    come within ``band`` of that cube: the answer of every point against every triangle, in
    the same order (ties go to the first triangle), at a cost that grows with the surface's
    area near the points rather than with points x triangles; points far from every vertex
    are let go first."""
    vertices = np.asarray(vertices, dtype=float)
    d = vertices.shape[1]
    if d == 2:
        return mid_line_sides(points, vertices, band)
    points = np.asarray(points, dtype=float).reshape(-1, d)
    facets = np.asarray(facets, dtype=np.int64)
    sides = np.zeros(len(points), np.int8)
    if len(points) == 0 or len(facets) == 0:
        return sides
    # A point of a triangle lies within the triangle's longest edge of one of its corners:
    # a point farther than band + that from every vertex is beside no triangle.
    longest = edge_lengths(vertices[facets]).max()
    distance, _ = cKDTree(vertices).query(points, distance_upper_bound=band + longest)
    candidates = np.flatnonzero(np.isfinite(distance))
    if len(candidates) == 0:
        return sides
    border = border_edges(facets)
    triangle_box = _boxes(vertices, facets)
    edge_box = _boxes(vertices, border)
    near_points = points[candidates]
    order, starts = cell_runs(near_points, 2.0 * band, near_points.min(axis=0))
    for rows in np.split(candidates[order], starts[1:-1]):
        low = points[rows].min(axis=0) - band
        high = points[rows].max(axis=0) + band
        near = _overlapping(triangle_box, low, high)
        if not near.any():
            continue
        edges = border[_overlapping(edge_box, low, high)]
        sides[rows] = _surface_sides(points[rows], vertices, facets[near], edges, band)
    return sides


def _boxes(vertices, cells):
    """The bounding box (lower (m, d), upper (m, d)) of each cell (m, k) of vertex indices."""
    corners = vertices[cells]
    return corners.min(axis=1), corners.max(axis=1)


def _overlapping(boxes, low, high):
    """Which of the boxes meet the box [low, high]."""
    return np.all((boxes[0] <= high) & (boxes[1] >= low), axis=1)


def _surface_sides(points, vertices, facets, border, band):
    """:func:`mid_surface_sides` in 3D for one group of points against the triangles
    ``facets`` and border edges ``border`` near them (numba: one pass over the pairs)."""
    a, b, c = (vertices[facets[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    unit = normal / np.linalg.norm(normal, axis=1)[:, None]
    # The inward normals of each triangle's edges ab, bc, ca within its plane.
    edge_normal = np.stack([np.cross(unit, b - a), np.cross(unit, c - b),
                            np.cross(unit, a - c)], axis=1)
    return _sides_kernel(np.ascontiguousarray(points, dtype=float), a, b, c, unit, edge_normal,
                         vertices[border[:, 0]], vertices[border[:, 1]], float(band))


@numba.njit(cache=True)
def _segment2(p, start, end):
    """Squared distance of the point p to the segment start -> end."""
    d0, d1, d2 = end[0] - start[0], end[1] - start[1], end[2] - start[2]
    o0, o1, o2 = p[0] - start[0], p[1] - start[1], p[2] - start[2]
    along = (o0 * d0 + o1 * d1 + o2 * d2) / (d0 * d0 + d1 * d1 + d2 * d2)
    along = min(max(along, 0.0), 1.0)
    g0, g1, g2 = o0 - along * d0, o1 - along * d1, o2 - along * d2
    return g0 * g0 + g1 * g1 + g2 * g2


@numba.njit(cache=True)
def _sides_kernel(points, a, b, c, unit, edge_normal, start, end, band):
    sides = np.zeros(len(points), np.int8)
    for i in range(len(points)):
        p = points[i]
        best, height = np.inf, 0.0
        for t in range(len(a)):
            o0, o1, o2 = p[0] - a[t, 0], p[1] - a[t, 1], p[2] - a[t, 2]
            h = o0 * unit[t, 0] + o1 * unit[t, 1] + o2 * unit[t, 2]
            f0, f1, f2 = o0 - h * unit[t, 0], o1 - h * unit[t, 1], o2 - h * unit[t, 2]
            # The foot is inside when it lies on the inner side of all three edges.
            inside = True
            for e in range(3):
                corner = a[t] if e == 0 else (b[t] if e == 1 else c[t])
                r0 = f0 + a[t, 0] - corner[0]
                r1 = f1 + a[t, 1] - corner[1]
                r2 = f2 + a[t, 2] - corner[2]
                if (r0 * edge_normal[t, e, 0] + r1 * edge_normal[t, e, 1]
                        + r2 * edge_normal[t, e, 2]) < 0.0:
                    inside = False
            if inside:
                distance2 = h * h
            else:
                distance2 = min(min(_segment2(p, a[t], b[t]), _segment2(p, b[t], c[t])),
                                _segment2(p, c[t], a[t]))
            if distance2 < best:  # the first nearest triangle, as argmin
                best, height = distance2, h
        border2 = np.inf
        for k in range(len(start)):
            border2 = min(border2, _segment2(p, start[k], end[k]))
        # On the border when no interior point of the surface is nearer than it (rounding aside).
        at_border = border2 <= best * (1.0 + 1e-9) + 1e-30
        if not at_border and best <= band * band:
            sides[i] = 1 if height > 0.0 else -1
    return sides


def count_crossings(previous_ids, previous_sides, ids, sides):
    """How many particles are beside the body on opposite sides now and before (ids sorted
    or not; each id at most once in each set)."""
    _, before, now = np.intersect1d(previous_ids, ids, assume_unique=True,
                                    return_indices=True)
    return int(np.count_nonzero(previous_sides[before].astype(np.int64) * sides[now] < 0))


class BodyCrossing(Observer):
    """``[[check]] kind = "body_crossing"``: fluid particles through a lattice body's
    mid-surface, or through a closed shell's surface (from inside to outside or back)."""

    def __init__(self, spec, case, result, model, interval, end_time):
        self.name = f"check_{spec['name']}"
        self.label = spec["name"]
        self.body_name = spec["body"]
        self.comm = result.comm
        self.result = result
        self.model = model
        self.domain = Domain.from_case(case)
        self.index, body_spec = next((k, b) for k, b in enumerate(case["body"])
                                     if (b["name"] or f"body{k}") == self.body_name)
        spacing = case["particles"]["spacing"]
        # A closed shell holds fluid: its side of a particle is inside or outside.
        self.closed = model.encloses_fluid(self.index)
        if self.closed:
            self.band = BAND_SPACINGS * spacing
        else:
            self.shape = tuple(body_spec[key] for key in ("nx", "ny", "nz")[:case["dimension"]])
            thickness = (min(self.shape) - 1) * body_spec["spacing"]
            self.band = 0.5 * thickness + BAND_SPACINGS * spacing
        group = result.file.require_group("checks").require_group(spec["name"])
        group.attrs["kind"] = spec["kind"]
        group.attrs["body"] = self.body_name
        group.attrs["band"] = self.band
        self.series = Series(group, {"time": (np.float64, ()), "crossings": (np.int64, ()),
                                     "total": (np.int64, ())})
        self.cadence = SimulatedInterval(interval, end_time)
        self.total = 0
        # Rank 0's record of who was beside the body at the last step, and on which side.
        self.ids = np.zeros(0, np.int64)
        self.sides = np.zeros(0, np.int8)
        self.resumed = False

    def _beside(self, particles):
        """(ids, sides) of every rank's owned fluid particles beside the body, on rank 0."""
        if self.closed:
            vertices, facets = self.model.boundary(self.index)
        else:
            body = self.model.body(self.body_name)
            vertices, facets = lattice_mid_surface(body.position, self.shape)
        near, position = owned_fluid_near(particles, vertices.min(axis=0) - self.band,
                                          vertices.max(axis=0) + self.band, self.domain)
        if self.closed:
            # Every particle in the box has a side; one that moves less than the band in a
            # step (time.cfl <= 1) and changes sides went through the surface.
            sides = closed_surface_sides(position, vertices, facets)
        else:
            sides = mid_surface_sides(position, vertices, facets, self.band)
        keep = sides != 0
        gathered = self.comm.gather((particles.id[near][keep].astype(np.int64),
                                     sides[keep]), root=0)
        if self.comm.rank != 0:
            return None, None
        return (np.concatenate([g[0] for g in gathered]),
                np.concatenate([g[1] for g in gathered]).astype(np.int8))

    def start(self, state):
        ids, sides = self._beside(state.particles)
        if self.comm.rank == 0 and not self.resumed:  # a continued run has its record
            self.ids, self.sides = ids, sides

    def observe(self, state):
        ids, sides = self._beside(state.particles)
        crossings = 0
        if self.comm.rank == 0:
            crossings = count_crossings(self.ids, self.sides, ids, sides)
            self.ids, self.sides = ids, sides
        crossings = self.comm.bcast(crossings, root=0)
        if crossings and self.total == 0 and self.comm.rank == 0:
            log.warning("step %d, t = %.6g s: %d fluid particle(s) crossed body '%s' "
                        "(check %s)", state.step, state.time, crossings, self.body_name,
                        self.label)
        self.total += crossings
        self.series.add({"time": state.time, "crossings": crossings, "total": self.total})
        if self.cadence.due(state.time):
            self.series.flush(self.comm.rank)

    def finish(self, state):
        self.series.flush(self.comm.rank)
        if self.comm.rank == 0:
            log.info("check %s: %d fluid particle crossing(s) of body '%s' in %d steps",
                     self.label, self.total, self.body_name, self.series.rows)

    def checkpoint_state(self):
        self.series.flush(self.comm.rank)
        ids = self.comm.bcast(self.ids, root=0)
        sides = self.comm.bcast(self.sides, root=0)
        return {"rows": self.series.rows, "next_time": self.cadence.next_time,
                "total": self.total, "ids": ids, "sides": sides}

    def restore_state(self, saved):
        self.series.truncate(int(saved["rows"]))
        self.cadence.next_time = float(saved["next_time"])
        self.total = int(saved["total"])
        self.ids = np.asarray(saved["ids"], np.int64)
        self.sides = np.asarray(saved["sides"], np.int8)
        self.resumed = True
