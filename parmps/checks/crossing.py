"""Fluid through a thin body: particles whose path crossed the body's mid-line.

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

Why a step cannot skip the test: the band reaches two spacings beyond the
body's half-thickness on each side, and a particle moves less than a spacing
in a step (the Courant limit, time.cfl <= 1), so a particle that crosses is
seen beside the body on both sides.

The count is a result, not a stop: ``/checks/<name>`` in result.h5 holds, per
step, the time, the crossings in the step and their total so far, and rank 0
logs a warning at the first crossing.
"""

import logging

import numpy as np

from parmps.core.particles import FLUID, INFLOW
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


def count_crossings(previous_ids, previous_sides, ids, sides):
    """How many particles are beside the body on opposite sides now and before (ids sorted
    or not; each id at most once in each set)."""
    _, before, now = np.intersect1d(previous_ids, ids, assume_unique=True,
                                    return_indices=True)
    return int(np.count_nonzero(previous_sides[before].astype(np.int64) * sides[now] < 0))


class BodyCrossing(Observer):
    """``[[check]] kind = "body_crossing"``: fluid particles through a lattice body."""

    def __init__(self, spec, case, result, model, interval, end_time):
        self.name = f"check_{spec['name']}"
        self.label = spec["name"]
        self.body_name = spec["body"]
        self.comm = result.comm
        self.result = result
        self.model = model
        body_spec = next(b for k, b in enumerate(case["body"])
                         if (b["name"] or f"body{k}") == self.body_name)
        self.shape = (body_spec["nx"], body_spec["ny"])
        spacing = case["particles"]["spacing"]
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
        body = self.model.body(self.body_name)
        mid_line = lattice_mid_line(body.position, *self.shape)
        n = particles.n_owned
        kind = particles.kind[:n]
        position = particles.position[:n]
        low, high = mid_line.min(axis=0) - self.band, mid_line.max(axis=0) + self.band
        near = np.flatnonzero(((kind == FLUID) | (kind == INFLOW)) &
                              np.all((position >= low) & (position <= high), axis=1))
        sides = mid_line_sides(position[near], mid_line, self.band)
        keep = sides != 0
        gathered = self.comm.gather((particles.id[:n][near][keep].astype(np.int64),
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
