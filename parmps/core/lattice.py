"""Reference values of the full lattice in d dimensions (docs/design.md §1.1).

MPS normalises its operators by the values a particle has when it sits inside
the undisturbed initial arrangement: the square (d = 2) or cubic (d = 3)
lattice of spacing l0, full on every side.
"""

import numpy as np

from parmps.core.pairs import wendland
from parmps.core.operators import weight


def _lattice_distances(spacing, radius, dimension):
    """Distances from the origin to every other point of the lattice out to past ``radius``.

    The points form a cube of 2c + 1 per side (c = ceil(re / l0) + 1), flattened
    with x varying fastest (in 2D the order of the former meshgrid, so that n0
    and lambda0 are summed in the same order, bit for bit).
    """
    if dimension < 1:
        raise ValueError(f"dimension must be at least 1, got {dimension}")
    cells = int(np.ceil(radius / spacing)) + 1
    offsets = np.arange(-cells, cells + 1) * spacing
    grids = np.meshgrid(*([offsets] * dimension), indexing="ij")
    # grids[-1] is x (it varies fastest), grids[-2] y, ...; distance =
    # hypot(...hypot(hypot(x, y), z)...), in 2D np.hypot(x, y) as before.
    distance = np.abs(grids[-1])
    for component in reversed(grids[:-1]):
        distance = np.hypot(distance, component)
    return distance.ravel()


def reference_values(spacing, radius, dimension):
    """n0 and lambda0 of a particle fully surrounded by the lattice of spacing l0 in d dimensions.

    ``radius`` is re in metres. n0 = sum_j w(r_j), lambda0 = sum_j r_j^2 w / n0.
    """
    distance = _lattice_distances(spacing, radius, dimension)
    distance = distance[distance > 0]
    w = weight(distance, radius)
    n0 = float(w.sum())
    lambda0 = float((distance ** 2 * w).sum() / n0)
    return n0, lambda0


def smooth_reference(spacing, support, dimension):
    """The smooth density sum_j W(r_j), self included, of a particle inside the full lattice.

    W is Wendland's C2 function of radius ``support`` (density.smooth_density).
    """
    q = _lattice_distances(spacing, support, dimension) / support
    return float(np.sum([wendland(value) for value in q]))


def neighbour_count_reference(spacing, radius, dimension):
    """How many lattice neighbours lie within ``radius`` of an interior particle in d dimensions."""
    distance = _lattice_distances(spacing, radius, dimension)
    return int(np.count_nonzero((distance > 0) & (distance < radius)))


def coupling_shells(radius, dimension):
    """The full lattice's shells of neighbours within ``radius`` (in l0) and the weight of one
    neighbour of each relative to the sum over all neighbours, w(r) / sum_j w(r_j), the
    strength with which an algebraic multigrid sees a coupling of the Laplacian on it.

    Returns (distances, relative weights), both ascending in distance.
    """
    distance = _lattice_distances(1.0, radius, dimension)
    distance = distance[(distance > 0) & (distance < radius)]
    total = float(weight(distance, radius).sum())
    shells = np.unique(np.round(distance, 9))
    return shells, weight(shells, radius) / total
