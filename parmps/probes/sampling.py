"""Kernel sums of the particles around sample points, reduced over the ranks.

Every probe is a row of evenly spaced sample points ``origin + k step u``
(k = 0..count-1; a point probe is a row of one), or a grid of them (a patch of
a 3D wall: rows repeated along a second direction). Each rank adds its *owned*
particles' contributions, then one allreduce combines them, so a sample reads
the same on any rank count whether or not its support crosses a slab edge
(ghosts are never counted, so no particle counts twice).

The weight is Wendland's C2 kernel ``w(q) = (1 - q)^4 (1 + 4q)`` for
``q = r / R < 1``: smooth and finite at r = 0, unlike the MPS weight, so a
particle passing over the point does not dominate the average. Sums are
normalised by ``lattice_sum(R / l0, d)``, the sum over a full square (cubic)
lattice of spacing l0 with a particle on the point.
"""

import math

import numba
import numpy as np
from mpi4py import MPI

from parmps.core.pairs import wendland
from parmps.core.lattice import smooth_reference
from parmps.core.particles import DUMMY, FLUID, INFLOW, WALL

# Columns of the per-sample sums.
FLUID_WEIGHT, FLUID_PRESSURE, OCCUPIED_WEIGHT = 0, 1, 2


@numba.njit(cache=True)
def _index_range(offset, direction, step, count, radius):
    """The indices k of a row's samples within ``radius`` of a point ``offset`` from its origin."""
    if count == 1:
        return 0, 0
    along = 0.0
    for a in range(offset.shape[0]):
        along += offset[a] * direction[a]
    along /= step
    reach = radius / step
    return max(0, int(math.ceil(along - reach))), min(count - 1, int(math.floor(along + reach)))


@numba.njit(cache=True)
def _accumulate(position, kind, pressure, n_owned, origin, direction, step, count, cross,
                cross_step, cross_count, start, radius, box, sums):
    d = position.shape[1]
    offset = np.empty(d)
    for i in range(n_owned):
        k = kind[i]
        fluid = k == FLUID or k == INFLOW
        if not (fluid or k == WALL or k == DUMMY):
            continue
        for g in range(origin.shape[0]):
            inside = True
            for a in range(d):
                if position[i, a] < box[g, a] or position[i, a] > box[g, d + a]:
                    inside = False
            if not inside:
                continue
            for a in range(d):
                offset[a] = position[i, a] - origin[g, a]
            # Only the samples within the radius along each direction: their index ranges.
            first, last = _index_range(offset, direction[g], step[g], count[g], radius[g])
            first_c, last_c = _index_range(offset, cross[g], cross_step[g], cross_count[g],
                                           radius[g])
            for c in range(first_c, last_c + 1):
                for s in range(first, last + 1):
                    r2 = 0.0
                    for a in range(d):
                        ds = offset[a] - s * step[g] * direction[g, a] \
                            - c * cross_step[g] * cross[g, a]
                        r2 += ds * ds
                    w = wendland(math.sqrt(r2) / radius[g])
                    if w > 0.0:
                        row = start[g] + c * count[g] + s
                        sums[row, OCCUPIED_WEIGHT] += w
                        if fluid:
                            sums[row, FLUID_WEIGHT] += w
                            sums[row, FLUID_PRESSURE] += w * pressure[i]


def mean_sum(radius_in_spacings, dimension=2):
    """The kernel's integral over space in units of l0^d: its sum over particles of unit
    spacing averaged over where the point lies among them, the sum a full but disordered
    neighbourhood gives. Between two columns of a square lattice the sum at radius 2 is
    1.4 % below it, on a column 1.5 % above; the on-node lattice_sum is 3.8 % above."""
    d = dimension
    sphere = 2.0 * math.pi ** (d / 2) / math.gamma(d / 2)
    beta = math.gamma(d) * math.gamma(5) / math.gamma(d + 5)
    beta_next = math.gamma(d + 1) * math.gamma(5) / math.gamma(d + 6)
    # (1 - q)^4 (1 + 4q) q^(d-1) integrated over 0..1: two Beta functions.
    return sphere * radius_in_spacings ** d * (beta + 4.0 * beta_next)


def lattice_sum(radius_in_spacings, dimension=2):
    """The kernel's sum over a full lattice (square, cubic) of unit spacing, a node on the point."""
    return smooth_reference(1.0, radius_in_spacings, dimension)


class SampleRows:
    """Rows of sample points: ``origin`` (G×d), unit ``direction`` (G×d), ``step`` and
    ``radius`` [m] (G), ``count`` (G), laid out one after the other.

    A row may be a grid: ``cross`` (G×d), ``cross_step`` and ``cross_count`` (G) repeat it
    along a second direction (a patch of a 3D wall); by default each row is one line.
    Sample ``c count + s`` of a row lies at ``origin + s step direction + c cross_step cross``.
    """

    def __init__(self, origin, direction, step, count, radius, cross=None, cross_step=None,
                 cross_count=None):
        self.origin = np.ascontiguousarray(origin, dtype=np.float64)
        self.origin = self.origin.reshape(len(self.origin), -1)
        d = self.origin.shape[1]
        self.direction = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, d)
        self.step = np.ascontiguousarray(step, dtype=np.float64)
        self.count = np.ascontiguousarray(count, dtype=np.int64)
        self.radius = np.ascontiguousarray(radius, dtype=np.float64)
        groups = len(self.origin)
        self.cross = np.ascontiguousarray(np.zeros((groups, d)) if cross is None else cross,
                                          dtype=np.float64).reshape(-1, d)
        self.cross_step = np.ascontiguousarray(
            np.ones(groups) if cross_step is None else cross_step, dtype=np.float64)
        self.cross_count = np.ascontiguousarray(
            np.ones(groups) if cross_count is None else cross_count, dtype=np.int64)
        sizes = self.count * self.cross_count
        self.start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.total = int(sizes.sum())
        along = ((self.count - 1) * self.step)[:, None] * self.direction
        across = ((self.cross_count - 1) * self.cross_step)[:, None] * self.cross
        corners = np.stack([self.origin, self.origin + along, self.origin + across,
                            self.origin + along + across])
        lower = corners.min(axis=0) - self.radius[:, None]
        upper = corners.max(axis=0) + self.radius[:, None]
        self.box = np.ascontiguousarray(np.hstack([lower, upper]))

    def points(self, g):
        s = np.tile(np.arange(self.count[g]), self.cross_count[g])
        c = np.repeat(np.arange(self.cross_count[g]), self.count[g])
        return (self.origin[g] + (s * self.step[g])[:, None] * self.direction[g]
                + (c * self.cross_step[g])[:, None] * self.cross[g])


def kernel_sums(rows, position, kind, pressure, n_owned, comm):
    """Per sample point (rows.total × 3): the fluid's weight sum, its pressure-weighted sum
    and the weight sum of fluid, walls and dummies, over every rank's owned particles."""
    sums = np.zeros((rows.total, 3))
    if n_owned and rows.total:
        _accumulate(np.ascontiguousarray(position), np.ascontiguousarray(kind),
                    np.ascontiguousarray(pressure), int(n_owned), rows.origin, rows.direction,
                    rows.step, rows.count, rows.cross, rows.cross_step, rows.cross_count,
                    rows.start, rows.radius, rows.box, sums)
    total = np.empty_like(sums)
    comm.Allreduce(sums, total, op=MPI.SUM)
    return total


def open_support(sums, full_sum):
    """Per sample, the kernel sum of the part of its support outside walls and dummies:
    ``full_sum`` less their weights."""
    return full_sum - (sums[:, OCCUPIED_WEIGHT] - sums[:, FLUID_WEIGHT])


def shepard_pressure(sums, full_sum, min_fill):
    """Σ w p / Σ w over the fluid where the sample is wet, NaN where it is dry.

    Wet: the fluid fills at least ``min_fill`` of the part of the support outside walls
    and dummies (``full_sum`` less their weights), the share the level probe's surface
    is drawn at (0.5). A sample beside a wall is then wet once the water around it is,
    as a wall sensor is: measured against the whole support, a sample half a spacing
    from a wall needed about 0.63 of its open part filled, at a box's edge or a floor
    corner 0.7 or more, so a thin sheet running up or over a wall read dry. A support
    less than IN_WALL_SHARE outside walls (a point inside one) is measured against that
    share of ``full_sum``."""
    weight = sums[:, FLUID_WEIGHT]
    open_part = open_support(sums, full_sum)
    enough = (weight > 0.0) & (weight >= min_fill * np.maximum(open_part,
                                                               IN_WALL_SHARE * full_sum))
    out = np.full(len(sums), np.nan)
    out[enough] = sums[enough, FLUID_PRESSURE] / weight[enough]
    return out


# A sample whose support lies less than this share outside walls is inside a wall: it
# counts as filled, so a line that starts in the floor reads from the floor.
IN_WALL_SHARE = 0.25
# Above the column's surface, a fill that rises this much above its lowest value since
# it fell through 0.5 is water not joined to the column (a jet, a drop passing over):
# the column ends at that lowest value. One particle on the line alone adds 1/W0 = 0.54
# at radius 2; the ripple of a still surface's fill between samples is ~0.01.
RISE = 0.1


def fluid_fill(sums, full_sum):
    """Per sample, the fluid's share of the part of the support outside walls and dummies:
    about 1 in the water, also beside a floor or a side wall, 0 in the air; 1 inside a
    wall (less than IN_WALL_SHARE of the support outside it). Not clipped at 1: the
    lattice's ripple about ``full_sum`` averages out along the line only unclipped."""
    fluid = sums[:, FLUID_WEIGHT]
    open_part = open_support(sums, full_sum)
    fill = np.ones(len(sums))
    outside = open_part >= IN_WALL_SHARE * full_sum
    fill[outside] = fluid[outside] / open_part[outside]
    return fill


def water_depth(sums, full_sum, heights):
    """What a wave gauge reads along a vertical row of samples at ``heights`` (ascending):
    ``heights[0]`` plus the integral of the fluid fill over the water column standing on
    the line's bottom (trapezoids between the samples).

    The column ends where its fill has fallen through 0.5 and, above that, rises again
    by RISE or more (:func:`column_end`), so a jet or a drop passing above the water does
    not count; the fill above the column's surface does (the kernel's tail), so a still
    layer of depth H with the line from its floor reads H, and a line dry at its
    bottom reads ``heights[0]``. ``full_sum``: :func:`mean_sum`, so that the fill of
    disordered water averages 1. Any dimension: the row runs along the vertical axis.
    """
    fill = fluid_fill(sums, full_sum)
    end = column_end(fill) + 1
    f, y = fill[:end], np.asarray(heights[:end], float)
    return float(y[0] + np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(y)))


def column_end(fill):
    """The index of the column's last sample: the lowest fill between its fall through
    0.5 and the first sample at RISE or more above the running minimum; the last sample
    when the fill never rises again."""
    below = np.flatnonzero(fill < 0.5)
    if len(below) == 0:
        return len(fill) - 1
    tail = fill[below[0]:]
    risen = np.flatnonzero(tail > np.minimum.accumulate(tail) + RISE)
    if len(risen) == 0:
        return len(fill) - 1
    return int(below[0] + np.argmin(tail[:risen[0]]))


def surface_height(sums, full_sum, y):
    """The level probe's ``reading = "crossing"``: the highest free surface along a
    vertical row of samples at heights ``y`` (ascending).

    The fill fraction f = Σ w / (full lattice sum) over fluid, walls and dummies
    is 1 inside the water and 0 in the air; the surface is the highest height at
    which f falls through 0.5, interpolated linearly between the samples either
    side. ``y[0]`` when f < 0.5 already there (a dry line), ``y[-1]`` when the
    line is full to its top. A jet passing above the water reads as its top.
    """
    fill = sums[:, OCCUPIED_WEIGHT] / full_sum
    wet = np.flatnonzero(fill >= 0.5)
    if len(wet) == 0:
        return float(y[0])
    k = wet[-1]
    if k == len(y) - 1:
        return float(y[-1])
    return float(y[k] + (fill[k] - 0.5) / (fill[k] - fill[k + 1]) * (y[k + 1] - y[k]))
