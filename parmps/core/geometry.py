"""Small geometric predicates shared by the scene, the guards and the post-processing."""

import numpy as np


def outside_box(points, lower, upper):
    """Which of the (N, d) points lie outside the closed box [lower, upper]."""
    points = np.asarray(points)
    return np.any((points < np.asarray(lower)) | (points > np.asarray(upper)), axis=1)


def point_in_polygon(points, polygon):
    """Whether each 2D point lies inside the closed polygon (even-odd rule), vectorised."""
    if len(points) == 0:
        return np.zeros(0, bool)
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    x, y = points[:, 0:1], points[:, 1:2]
    straddle = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / \
            (b[None, :, 1] - a[None, :, 1])
    return np.count_nonzero(straddle & (x < cross_x), axis=1) % 2 == 1


def format_point(point, spec=".6g", brackets="()"):
    """A point of any dimension for a message: ``(x, y)`` or ``(x, y, z)``."""
    inner = ", ".join(format(float(c), spec) for c in point)
    return f"{brackets[0]}{inner}{brackets[1]}"
