"""Fluid through a wall of any shape: particles that went across a ``[[wall]]``'s surface into
its material within a step.

Every step each owned fluid particle gets its depth in the wall's material, the signed
distance to its surface on the side away from the fluid
(:class:`parmps.geometry.walls.MaterialDepth`, the guard's own test; a moving wall where its
motion has taken it). A particle deeper than half a spacing (the guard's ``WALL_MARGIN``:
there its centre is level with the first layer of a flat wall's particles) now that was not
at the previous step went through the wall's surface in the step; one that stays counts
once. Contact is not a count: the first layer of a curved wall's particles, laid on the
lattice, lies 0.07-1 l0 behind its surface (a 2D circle of 10 l0 radius; a pipe's 0.28-1
l0), so water pressed against it may sit a quarter of a spacing behind the surface where the
layer lies deep; the deepest any fluid particle sat is recorded each step (``deepest``).
The guard (parmps.run.guards) stops the run once a particle is that deep in a tank's or a
wall box's material; here the check is the record (a run that must go on).

The count is a result, not a stop: ``/checks/<name>`` in result.h5 holds, per step, the
time, the crossings in the step, their total so far and the deepest fluid particle's depth
[m] (negative: none in the material).
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.boundaries.walls import travel
from parmps.core.particles import FLUID
from parmps.geometry.walls import MaterialDepth
from parmps.io.series import Series
from parmps.run.guards import WALL_MARGIN
from parmps.run.observers import Observer
from parmps.run.schedule import SimulatedInterval

log = logging.getLogger(__name__)


class WallCrossing(Observer):
    """``[[check]] kind = "wall_crossing"``: fluid particles into a named wall's material."""

    def __init__(self, spec, case, result, model, interval, end_time):
        self.name = f"check_{spec['name']}"
        self.label = spec["name"]
        self.wall_name = spec["wall"]
        self.comm = result.comm
        index = next(k for k, wall in enumerate(case["wall"]) if wall["name"] == spec["wall"])
        self.spec = case["wall"][index]
        one = dict(case, wall=[self.spec])
        self.depth = MaterialDepth(one)
        group = result.file.require_group("checks").require_group(spec["name"])
        group.attrs["kind"] = spec["kind"]
        group.attrs["wall"] = self.wall_name
        self.series = Series(group, {"time": (np.float64, ()), "crossings": (np.int64, ()),
                                     "total": (np.int64, ()), "deepest": (np.float64, ())})
        self.margin = WALL_MARGIN * case["particles"]["spacing"]
        self.cadence = SimulatedInterval(interval, end_time)
        self.total = 0
        # Rank 0's record of the fluid particles in the material at the last step.
        self.inside = np.zeros(0, np.int64)
        self.resumed = False

    def _in_material(self, particles, time):
        """The ids of every rank's owned fluid particles through the wall's surface (deeper
        than the margin), on rank 0, and the deepest one's depth (on every rank)."""
        n = particles.n_owned
        fluid = np.flatnonzero(particles.kind[:n] == FLUID)
        depth, _ = self.depth.depth(particles.position[fluid], [travel(self.spec, time)])
        ids = particles.id[fluid[depth > self.margin]].astype(np.int64)
        deepest = self.comm.allreduce(float(depth.max()) if len(depth) else -np.inf,
                                      op=MPI.MAX)
        gathered = self.comm.gather(ids, root=0)
        if self.comm.rank != 0:
            return None, deepest
        return np.sort(np.concatenate(gathered)), deepest

    def start(self, state):
        inside, _ = self._in_material(state.particles, state.time)
        if self.comm.rank == 0 and not self.resumed:  # a continued run has its record
            self.inside = inside

    def observe(self, state):
        inside, deepest = self._in_material(state.particles, state.time)
        crossings = 0
        if self.comm.rank == 0:
            crossings = int(np.count_nonzero(~np.isin(inside, self.inside,
                                                      assume_unique=True)))
            self.inside = inside
        crossings = self.comm.bcast(crossings, root=0)
        if crossings and self.total == 0 and self.comm.rank == 0:
            log.warning("step %d, t = %.6g s: %d fluid particle(s) went into wall '%s' "
                        "(check %s)", state.step, state.time, crossings, self.wall_name,
                        self.label)
        self.total += crossings
        self.series.add({"time": state.time, "crossings": crossings, "total": self.total,
                         "deepest": deepest if np.isfinite(deepest) else np.nan})
        if self.cadence.due(state.time):
            self.series.flush(self.comm.rank)

    def finish(self, state):
        self.series.flush(self.comm.rank)
        if self.comm.rank == 0:
            log.info("check %s: %d fluid particle crossing(s) into wall '%s' in %d steps",
                     self.label, self.total, self.wall_name, self.series.rows)

    def checkpoint_state(self):
        self.series.flush(self.comm.rank)
        inside = self.comm.bcast(self.inside, root=0)
        return {"rows": self.series.rows, "next_time": self.cadence.next_time,
                "total": self.total, "inside": inside}

    def restore_state(self, saved):
        self.series.truncate(int(saved["rows"]))
        self.cadence.next_time = float(saved["next_time"])
        self.total = int(saved["total"])
        self.inside = np.asarray(saved["inside"], np.int64)
        self.resumed = True
