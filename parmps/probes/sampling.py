"""Kernel sums of the particles around sample points, reduced over the ranks.

Every probe is a row of evenly spaced sample points ``origin + k step u``
(k = 0..count-1; a point probe is a row of one). Each rank adds its *owned*
particles' contributions, then one allreduce combines them, so a sample reads
the same on any rank count whether or not its support crosses a slab edge
(ghosts are never counted, so no particle counts twice).

The weight is Wendland's C2 kernel ``w(q) = (1 - q)^4 (1 + 4q)`` for
``q = r / R < 1``: smooth and finite at r = 0, unlike the MPS weight, so a
particle passing over the point does not dominate the average. Sums are
normalised by ``lattice_sum(R / l0)``, the sum over a full square lattice of
spacing l0 with a particle on the point.
"""

import math

import numba
import numpy as np
from mpi4py import MPI

from parmps.core.kernels import wendland
from parmps.core.lattice import smooth_reference
from parmps.core.particles import DUMMY, FLUID, INFLOW, WALL

# Columns of the per-sample sums.
FLUID_WEIGHT, FLUID_PRESSURE, OCCUPIED_WEIGHT = 0, 1, 2


@numba.njit(cache=True)
def _accumulate(position, kind, pressure, n_owned, origin, direction, step, count, start,
                radius, box, sums):
    for i in range(n_owned):
        k = kind[i]
        fluid = k == FLUID or k == INFLOW
        if not (fluid or k == WALL or k == DUMMY):
            continue
        x = position[i, 0]
        y = position[i, 1]
        for g in range(origin.shape[0]):
            if x < box[g, 0] or x > box[g, 2] or y < box[g, 1] or y > box[g, 3]:
                continue
            # Only the samples within the radius along the row: its index range.
            dx = x - origin[g, 0]
            dy = y - origin[g, 1]
            first = 0
            last = count[g] - 1
            if count[g] > 1:
                along = (dx * direction[g, 0] + dy * direction[g, 1]) / step[g]
                reach = radius[g] / step[g]
                first = max(first, int(math.ceil(along - reach)))
                last = min(last, int(math.floor(along + reach)))
            for s in range(first, last + 1):
                sx = dx - s * step[g] * direction[g, 0]
                sy = dy - s * step[g] * direction[g, 1]
                w = wendland(math.sqrt(sx * sx + sy * sy) / radius[g])
                if w > 0.0:
                    row = start[g] + s
                    sums[row, OCCUPIED_WEIGHT] += w
                    if fluid:
                        sums[row, FLUID_WEIGHT] += w
                        sums[row, FLUID_PRESSURE] += w * pressure[i]


def lattice_sum(radius_in_spacings):
    """The kernel's sum over a full square lattice of unit spacing, a node on the point."""
    return smooth_reference(1.0, radius_in_spacings, 2)


class SampleRows:
    """Rows of sample points: ``origin`` (G×2), unit ``direction`` (G×2), ``step`` and
    ``radius`` [m] (G), ``count`` (G), laid out one after the other."""

    def __init__(self, origin, direction, step, count, radius):
        self.origin = np.ascontiguousarray(origin, dtype=np.float64).reshape(-1, 2)
        self.direction = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, 2)
        self.step = np.ascontiguousarray(step, dtype=np.float64)
        self.count = np.ascontiguousarray(count, dtype=np.int64)
        self.radius = np.ascontiguousarray(radius, dtype=np.float64)
        self.start = np.concatenate([[0], np.cumsum(self.count)[:-1]]).astype(np.int64)
        self.total = int(self.count.sum())
        end = self.origin + ((self.count - 1) * self.step)[:, None] * self.direction
        lower = np.minimum(self.origin, end) - self.radius[:, None]
        upper = np.maximum(self.origin, end) + self.radius[:, None]
        self.box = np.ascontiguousarray(np.hstack([lower, upper]))

    def points(self, g):
        k = np.arange(self.count[g])
        return self.origin[g] + (k * self.step[g])[:, None] * self.direction[g]


def kernel_sums(rows, position, kind, pressure, n_owned, comm):
    """Per sample point (rows.total × 3): the fluid's weight sum, its pressure-weighted sum
    and the weight sum of fluid, walls and dummies, over every rank's owned particles."""
    sums = np.zeros((rows.total, 3))
    if n_owned and rows.total:
        _accumulate(np.ascontiguousarray(position), np.ascontiguousarray(kind),
                    np.ascontiguousarray(pressure), int(n_owned), rows.origin, rows.direction,
                    rows.step, rows.count, rows.start, rows.radius, rows.box, sums)
    total = np.empty_like(sums)
    comm.Allreduce(sums, total, op=MPI.SUM)
    return total


def shepard_pressure(sums, full_sum, min_fill):
    """Σ w p / Σ w over the fluid; NaN where Σ w < min_fill × the full lattice's sum."""
    weight = sums[:, FLUID_WEIGHT]
    enough = weight >= min_fill * full_sum
    out = np.full(len(sums), np.nan)
    out[enough] = sums[enough, FLUID_PRESSURE] / weight[enough]
    return out


def surface_height(sums, full_sum, y):
    """The free surface along a vertical row of samples at heights ``y`` (ascending).

    The fill fraction f = Σ w / (full lattice sum) over fluid, walls and dummies
    is 1 inside the water and 0 in the air; the surface is the highest height at
    which f falls through 0.5, interpolated linearly between the samples either
    side. ``y[0]`` when f < 0.5 already there (a dry line), ``y[-1]`` when the
    line is full to its top.
    """
    fill = sums[:, OCCUPIED_WEIGHT] / full_sum
    wet = np.flatnonzero(fill >= 0.5)
    if len(wet) == 0:
        return float(y[0])
    k = wet[-1]
    if k == len(y) - 1:
        return float(y[-1])
    return float(y[k] + (fill[k] - 0.5) / (fill[k] - fill[k + 1]) * (y[k + 1] - y[k]))
