"""Small geometric predicates shared by the scene, the guards, the coupling and the
post-processing."""

import numba
import numpy as np

# A patch of triangles seen from farther than this many times its radius counts as its
# dipole (below): the first neglected term is of relative size (radius / distance)^2, 1/16.
FAR_FIELD_RATIO = 4.0
# The patches' side in mean edges: smaller patches have nearer far fields but more of them
# to visit; 1.5 was the fastest of 1, 1.5, 2, 3 and 4 on a bent 3D gate (6052 triangles,
# 20,000 points: 0.17 s against 20 s for the exact sum, the winding number within 0.02).
PATCH_EDGES = 1.5


def outside_box(points, lower, upper):
    """Which of the (N, d) points lie outside the closed box [lower, upper] (a NaN
    coordinate is not outside: no comparison with it holds)."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2:
        points = points.reshape(-1, len(lower))
    return _outside_box(points, np.asarray(lower, dtype=float), np.asarray(upper, dtype=float))


# The driver checks every owned particle against the domain and the walls after every
# step: compiled, one pass and no temporaries (numpy's masks took 33 ms a step at 289k
# particles in 3D, 3 % of the step, against 3 ms).
@numba.njit(cache=True)
def _outside_box(points, lower, upper):
    outside = np.zeros(points.shape[0], np.bool_)
    for i in range(points.shape[0]):
        for k in range(points.shape[1]):
            if points[i, k] < lower[k] or points[i, k] > upper[k]:
                outside[i] = True
                break
    return outside


def first_box_holding(points, lower, upper, mask=None):
    """Index of the first of the open boxes (``lower``, ``upper``: (B, d)) holding each of
    the (N, d) points, or -1; -1 too for the points that ``mask`` (N bools) leaves out."""
    points = np.asarray(points, dtype=float)
    if mask is None:
        mask = np.ones(len(points), np.bool_)
    return _first_box_holding(points, np.asarray(lower, dtype=float).reshape(-1, points.shape[1]),
                              np.asarray(upper, dtype=float).reshape(-1, points.shape[1]),
                              np.asarray(mask, dtype=np.bool_))


@numba.njit(cache=True)
def _first_box_holding(points, lower, upper, mask):
    which = np.full(points.shape[0], -1, np.int64)
    for i in range(points.shape[0]):
        if not mask[i]:
            continue
        for b in range(lower.shape[0]):
            inside = True
            for k in range(points.shape[1]):
                if not (lower[b, k] < points[i, k] < upper[b, k]):
                    inside = False
                    break
            if inside:
                which[i] = b
                break
    return which


def _even_odd(points, a, b):
    """Whether each 2D point lies inside the closed curve of the edges a -> b (even-odd
    rule: a ray towards +x crosses an odd number of them), vectorised."""
    x, y = points[:, 0:1], points[:, 1:2]
    straddle = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / \
            (b[None, :, 1] - a[None, :, 1])
    return np.count_nonzero(straddle & (x < cross_x), axis=1) % 2 == 1


def point_in_polygon(points, polygon):
    """Whether each 2D point lies inside the closed polygon (even-odd rule), vectorised."""
    if len(points) == 0:
        return np.zeros(0, bool)
    return _even_odd(np.asarray(points, dtype=float), polygon, np.roll(polygon, -1, axis=0))


def winding_number(points, vertices, triangles, chunk=200_000):
    """Generalised winding number of the closed triangulated surface (outward triangles
    (m, 3) of ``vertices``) at each of ``points`` (k, 3): 1 inside, 0 outside (Jacobson et
    al. 2013), the sum of the triangles' solid angles (Van Oosterom & Strackee 1983) over
    4 pi. Robust where a ray test is not: a point in the plane of a face or on a ray through
    an edge needs no special case. Cost: points x triangles, in chunks of about ``chunk``
    pairs."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    corners = np.asarray(vertices, dtype=float)[np.asarray(triangles, dtype=np.int64)]
    out = np.empty(len(points))
    step = max(1, chunk // max(1, len(corners)))
    for begin in range(0, len(points), step):
        r = corners[None, :, :, :] - points[begin:begin + step, None, None, :]
        a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("...i,...i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("...i,...i", a, b) * lc
               + np.einsum("...i,...i", b, c) * la + np.einsum("...i,...i", c, a) * lb)
        # A point in a triangle's plane sees it edge-on: its solid angle jumps from
        # +2 pi to -2 pi across the triangle; take the mean of the two, 0 (not the
        # +2 pi atan2 gives), so a point on the surface has winding number 1/2.
        angle = np.where(det == 0.0, 0.0, np.arctan2(det, den))
        out[begin:begin + step] = angle.sum(axis=1) / (2.0 * np.pi)
    return out


def cell_runs(points, side, origin=0.0):
    """The points grouped by the cubic cell of ``side`` (cells counted from ``origin``) they
    fall in: (order, starts), ``order`` the indices of the points cell by cell (stable within
    a cell) and ``starts`` where each cell's run begins in it, with len(points) at the end."""
    key = np.floor((np.asarray(points) - origin) / side).astype(np.int64)
    _, cell = np.unique(key, axis=0, return_inverse=True)
    cell = cell.ravel()
    order = np.argsort(cell, kind="stable")
    return order, np.flatnonzero(np.r_[True, np.diff(cell[order]) != 0, True])


def edge_lengths(corners):
    """The lengths (m, k) of the edges of polygons given by their corners (m, k, d)."""
    return np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)


def fast_winding_number(points, vertices, triangles, patch=None):
    """:func:`winding_number` in a time that grows with the surface's area near each point,
    not with all its triangles (the fast winding number of Barill et al. 2018, to first
    order). The triangles are grouped into patches by their centroids' cells of side
    ``patch`` (default: PATCH_EDGES times the mean edge); a patch seen from farther than
    FAR_FIELD_RATIO times its radius adds the solid angle of its vector area at its centroid,
    A n . (c - p) / |c - p|^3, nearer ones add each triangle's exact solid angle.

    The far patches' error is of order (radius / distance)^2 of their solid angle, a few
    hundredths of the winding number at most; off the surface the winding number of a
    closed surface is 0 or 1, so ``> 1/2`` classifies as the exact sum does."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    corners = vertices[triangles]
    centroid = corners.mean(axis=1)
    if patch is None:
        edges = edge_lengths(corners)
        patch = PATCH_EDGES * float(edges.mean()) if len(edges) else 1.0
    order, starts = cell_runs(centroid, patch)
    corners = corners[order]
    area = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    patch_area = np.add.reduceat(area, starts[:-1], axis=0)
    weight = np.linalg.norm(area, axis=1)
    # The patch's centre: its triangles' centroids weighted by area (the mean if degenerate).
    total = np.add.reduceat(weight, starts[:-1])
    weighted = np.add.reduceat(centroid[order] * weight[:, None], starts[:-1], axis=0)
    plain = np.add.reduceat(centroid[order], starts[:-1], axis=0) / np.diff(starts)[:, None]
    centre = np.where(total[:, None] > 0.0, weighted / np.where(total > 0.0, total, 1.0)[:, None],
                      plain)
    reach = np.linalg.norm(corners - np.repeat(centre, np.diff(starts), axis=0)[:, None, :],
                           axis=2).max(axis=1)
    radius = np.maximum.reduceat(reach, starts[:-1])
    return _fast_winding(points, corners, starts, centre, patch_area, radius,
                         FAR_FIELD_RATIO)


@numba.njit(cache=True)
def _fast_winding(points, corners, starts, centre, patch_area, radius, ratio):
    out = np.empty(len(points))
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        for q in range(len(centre)):
            dx, dy, dz = centre[q, 0] - px, centre[q, 1] - py, centre[q, 2] - pz
            d2 = dx * dx + dy * dy + dz * dz
            far = ratio * radius[q]
            if d2 > far * far:
                total += (patch_area[q, 0] * dx + patch_area[q, 1] * dy
                          + patch_area[q, 2] * dz) / (d2 * np.sqrt(d2))
                continue
            for t in range(starts[q], starts[q + 1]):
                ax, ay, az = corners[t, 0, 0] - px, corners[t, 0, 1] - py, corners[t, 0, 2] - pz
                bx, by, bz = corners[t, 1, 0] - px, corners[t, 1, 1] - py, corners[t, 1, 2] - pz
                cx, cy, cz = corners[t, 2, 0] - px, corners[t, 2, 1] - py, corners[t, 2, 2] - pz
                la = np.sqrt(ax * ax + ay * ay + az * az)
                lb = np.sqrt(bx * bx + by * by + bz * bz)
                lc = np.sqrt(cx * cx + cy * cy + cz * cz)
                det = (ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz)
                       + az * (bx * cy - by * cx))
                if det == 0.0:  # edge-on, as in winding_number
                    continue
                den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                       + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
                total += 2.0 * np.arctan2(det, den)
        out[i] = total / (4.0 * np.pi)
    return out


def inside_boundary(points, vertices, facets):
    """Whether each of ``points`` (k, d) lies inside the closed boundary given as
    ``facets`` (m, d) of node indices into ``vertices`` (n, d): in 2D edges (the even-odd
    rule; a loop's edges give :func:`point_in_polygon`'s answer bit for bit), in 3D
    outward triangles (the winding number above one half, :func:`fast_winding_number`)."""
    points = np.asarray(points, dtype=float)
    vertices = np.asarray(vertices, dtype=float)
    facets = np.asarray(facets, dtype=np.int64)
    d = vertices.shape[1]
    if len(points) == 0 or len(facets) == 0:
        return np.zeros(len(points), bool)
    if d == 2:
        return _even_odd(points, vertices[facets[:, 0]], vertices[facets[:, 1]])
    if d == 3:
        return fast_winding_number(points, vertices, facets) > 0.5
    raise ValueError(f"inside_boundary: no inside test for dimension {d}")


def _near_triangles(points, corners, reach):
    """For each point the triangles whose centroid lies within reach plus the longest edge
    (every triangle within reach of it, since a triangle's points lie within its
    circumradius, less than its longest edge, of its centroid): (starts, candidates), a
    ragged list."""
    from scipy.spatial import cKDTree

    longest = float(edge_lengths(corners).max())
    near = cKDTree(corners.mean(axis=1)).query_ball_point(points, reach + longest)
    count = np.fromiter((len(n) for n in near), np.int64, len(near))
    starts = np.concatenate([[0], np.cumsum(count)])
    return starts, np.fromiter((t for n in near for t in n), np.int64, int(count.sum()))


def nearest_on_surface(points, vertices, triangles, reach):
    """The nearest point of the triangulated surface ``triangles`` (m, 3) of ``vertices``
    (n, 3) to each of ``points`` (k, 3) within ``reach``: (distance (k,), triangle (k,),
    barycentric weights (k, 3) of its corners). Beyond reach: inf, -1 and zeros."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    corners = np.asarray(vertices, dtype=float)[np.asarray(triangles, dtype=np.int64)]
    distance = np.full(len(points), np.inf)
    triangle = np.full(len(points), -1, np.int64)
    weights = np.zeros((len(points), 3))
    if len(points) == 0 or len(corners) == 0:
        return distance, triangle, weights
    starts, candidates = _near_triangles(points, corners, reach)
    _nearest_on_surface(points, corners, starts, candidates, distance, triangle, weights)
    beyond = distance > reach
    distance[beyond], triangle[beyond], weights[beyond] = np.inf, -1, 0.0
    return distance, triangle, weights


def surface_distance(points, vertices, triangles, reach):
    """The distance of each of ``points`` (k, 3) to the triangulated surface, exact within
    ``reach`` and inf beyond (:func:`nearest_on_surface`)."""
    return nearest_on_surface(points, vertices, triangles, reach)[0]


@numba.njit(cache=True)
def _closest_on_triangle(p, a, b, c):
    """(squared distance, u, v, w) from p to the triangle abc, its nearest point being
    u a + v b + w c (Ericson, Real-Time Collision Detection, 5.1.5: the Voronoi regions
    of the corners, the edges and the face)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    u, v, w = 1.0, 0.0, 0.0
    if d1 > 0.0 or d2 > 0.0:
        bp = p - b
        d3, d4 = ab @ bp, ac @ bp
        cp = p - c
        d5, d6 = ab @ cp, ac @ cp
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            u, v, w = 0.0, 1.0, 0.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            t = d1 / (d1 - d3)
            u, v, w = 1.0 - t, t, 0.0
        elif d6 >= 0.0 and d5 <= d6:
            u, v, w = 0.0, 0.0, 1.0
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            t = d2 / (d2 - d6)
            u, v, w = 1.0 - t, 0.0, t
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            u, v, w = 0.0, 1.0 - t, t
        else:
            total = va + vb + vc
            v, w = vb / total, vc / total
            u = 1.0 - v - w
    g = p - (u * a + v * b + w * c)
    return g @ g, u, v, w


@numba.njit(cache=True)
def _nearest_on_surface(points, corners, starts, candidates, distance, triangle, weights):
    for i in range(len(points)):
        best = np.inf
        for k in range(starts[i], starts[i + 1]):
            t = candidates[k]
            d2, u, v, w = _closest_on_triangle(points[i], corners[t, 0], corners[t, 1],
                                               corners[t, 2])
            if d2 < best:  # the first nearest triangle
                best = d2
                triangle[i] = t
                weights[i, 0], weights[i, 1], weights[i, 2] = u, v, w
        distance[i] = np.sqrt(best)


def closed_surface_sides(points, vertices, facets):
    """Side of the closed boundary ``facets`` of each of ``points``: +1 inside, -1 outside
    (:func:`inside_boundary`), as int8."""
    return np.where(inside_boundary(points, vertices, facets), 1, -1).astype(np.int8)


def format_point(point, spec=".6g", brackets="()"):
    """A point of any dimension for a message: ``(x, y)`` or ``(x, y, z)``."""
    inner = ", ".join(format(float(c), spec) for c in point)
    return f"{brackets[0]}{inner}{brackets[1]}"
