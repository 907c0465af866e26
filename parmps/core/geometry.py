"""Small geometric predicates shared by the scene, the guards, the coupling and the
post-processing."""

import numpy as np


def outside_box(points, lower, upper):
    """Which of the (N, d) points lie outside the closed box [lower, upper]."""
    points = np.asarray(points)
    return np.any((points < np.asarray(lower)) | (points > np.asarray(upper)), axis=1)


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


def inside_boundary(points, vertices, facets):
    """Whether each of ``points`` (k, d) lies inside the closed boundary given as
    ``facets`` (m, d) of node indices into ``vertices`` (n, d): in 2D edges (the even-odd
    rule; a loop's edges give :func:`point_in_polygon`'s answer bit for bit), in 3D
    outward triangles (the winding number above one half)."""
    points = np.asarray(points, dtype=float)
    vertices = np.asarray(vertices, dtype=float)
    facets = np.asarray(facets, dtype=np.int64)
    d = vertices.shape[1]
    if len(points) == 0 or len(facets) == 0:
        return np.zeros(len(points), bool)
    if d == 2:
        return _even_odd(points, vertices[facets[:, 0]], vertices[facets[:, 1]])
    if d == 3:
        return winding_number(points, vertices, facets) > 0.5
    raise ValueError(f"inside_boundary: no inside test for dimension {d}")


def format_point(point, spec=".6g", brackets="()"):
    """A point of any dimension for a message: ``(x, y)`` or ``(x, y, z)``."""
    inner = ", ".join(format(float(c), spec) for c in point)
    return f"{brackets[0]}{inner}{brackets[1]}"
