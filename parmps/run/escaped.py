"""Particles outside the domain box after a step: fluid spray is removed, anything else stops.

A dam break throws spray: one droplet flung over a tank wall and out of the
domain box is no reason to end a run of hours. With ``domain.escaped_fluid =
"remove"`` (the default) the fluid particles outside the box after a step are
dropped from the owned particles of every rank, in the step's check, before the
next step's decomposition update; that update migrates the owned particles and
rebuilds every halo from them, so no rank keeps a ghost copy and the particle
set does not depend on the rank count. They are counted (the diagnostics'
cumulative ``n_escaped``, the end-of-run summary, the checkpoint), with a
WARNING naming the first one and an INFO line at most every few seconds of wall
time while more leave. Particle codes do the same (DualSPHysics excludes them,
MPS-Basic turns them into ghosts).

The run still stops, as it does with ``"stop"`` for any particle:

- when more than ``domain.max_escaped_fraction`` of the fluid particles there
  were at t = 0 have left: a flood is not spray but a leaking wall, a domain too
  small or an unstable run;
- when a particle of any other kind leaves. Walls and dummies, body nodes and
  inflow buffers go where the case moves them (inlets lie inside the domain and
  move into it; outflow buffers are removed at their outlet by the open
  boundaries), so one outside the box is a case or a body gone wrong, not
  spray. The message names the particle (a body's node by its body and index),
  the domain bound it crossed and its speed; the participant that owns it (a
  moving wall), or for a node the domain and the body's own keys, say what to
  change.

Every decision is taken from one allgather of each rank's few numbers, so
every rank takes the same branch.
"""

import logging

import numpy as np

from parmps.geometry.domain import Domain
from parmps.core.particles import FLUID, KIND_NAMES
from parmps.errors import RunFailure
from parmps.run.schedule import WallInterval

log = logging.getLogger(__name__)

def _lowest_id(particles, mask):
    """(id, kind, body, node, speed, position) of the lowest-id particle among the owned
    ``mask``, or None.

    The lowest id, not the first in memory: the particle named is then the same
    on any rank count."""
    if not np.any(mask):
        return None
    index = np.flatnonzero(mask)
    first = index[np.argmin(particles.id[index])]
    return (int(particles.id[first]), int(particles.kind[first]), int(particles.body[first]),
            int(particles.node[first]), float(np.linalg.norm(particles.velocity[first])),
            tuple(float(x) for x in particles.position[first]))


def _place(where):
    return ", ".join(f"{x:.4g}" for x in where)


def _side(where, lower, upper):
    """Which bound of the domain box a point lies beyond, as the key to change."""
    for a, x in enumerate(where):
        axis = "xyz"[a] if len(where) <= 3 else str(a)
        if x < lower[a]:
            return f"below {axis} = {lower[a]:.4g} (domain.lower[{a}])"
        if x > upper[a]:
            return f"above {axis} = {upper[a]:.4g} (domain.upper[{a}])"
    return "on its boundary"


class EscapedFluid:
    """The domain check of a fluid run and the count of the fluid particles it removed.

    ``initial_fluid``: the fluid particles at t = 0 (the scene's), the base of
    ``domain.max_escaped_fraction``; ``report_seconds``: the wall time between
    INFO lines while particles keep leaving.
    """

    name = "escaped_fluid"

    def __init__(self, case, comm, initial_fluid, report_seconds=None):
        domain = case["domain"]
        self.comm = comm
        self.domain = Domain.from_case(case)
        self.lower, self.upper = self.domain.lower, self.domain.upper
        self.remove = domain["escaped_fluid"] == "remove"
        self.max_fraction = domain["max_escaped_fraction"]
        self.initial_fluid = int(initial_fluid)
        self.body_names = [spec["name"] or f"body{k}" for k, spec in enumerate(case["body"])]
        self.total = 0  # removed so far, over every restart
        self.reported = 0  # the total the last log line gave (rank 0's is the one that counts)
        self.report = WallInterval() if report_seconds is None else WallInterval(report_seconds)

    @property
    def limit(self):
        """The most fluid particles that may leave before the run stops."""
        return self.max_fraction * self.initial_fluid

    def checkpoint_state(self):
        return {"total": self.total}

    def restore_state(self, saved):
        self.total = int(saved["total"])
        self.reported = self.total

    def apply(self, particles, step, time, owner):
        """Stop if a particle outside the domain must stop the run; else remove the fluid
        outside it (collective).

        ``owner(pid)``: the participants' ``(description, advice)`` for a particle, or
        None. Returns the particles (owned only on a rank that removed some) and the
        largest speed among the removed ones, for the Courant check: a particle
        thrown out by an unstable step is reported as the instability it is.
        """
        n = particles.n_owned
        # Along a periodic axis nothing is outside: the next update wraps it.
        outside = self.domain.outside(particles.position[:n])
        fluid = outside & (particles.kind[:n] == FLUID)
        other = outside & ~fluid
        count = int(np.count_nonzero(fluid))
        speed = float(np.sqrt((particles.velocity[:n][fluid] ** 2).sum(axis=1).max())) \
            if count else 0.0
        gathered = self.comm.allgather((count, speed, _lowest_id(particles, fluid),
                                        _lowest_id(particles, other)))
        others = [item[3] for item in gathered if item[3] is not None]
        fluids = [item[2] for item in gathered if item[2] is not None]
        if others or (fluids and not self.remove):
            first = min(others if self.remove else others + fluids)
            raise RunFailure(self._left(step, first, owner), where=first[-1])
        removed = sum(item[0] for item in gathered)
        if removed:
            if count:
                # Owned only: the next update rebuilds the halo from the owned particles.
                particles = particles.select(np.flatnonzero(~fluid))
            self._count(removed, min(fluids), step, time)
        self._summarise(step, time)
        return particles, max(item[1] for item in gathered)

    def _left(self, step, first, owner):
        """The one line for a particle whose leaving stops the run: what it is, where it
        left, how fast it moved, and what to change."""
        pid, kind, body, node, speed, where = first
        place = (f"left the domain at ({_place(where)}), "
                 f"{_side(where, self.lower, self.upper)}, moving at {speed:.3g} m/s")
        found = owner(pid)
        if found is not None:
            description, advice = found
            return f"step {step}: particle {pid} of {description} {place}; {advice}"
        if body >= 0:
            name = self.body_names[body]
            return (f"step {step}: node {node} of body '{name}' (particle {pid}) {place}: the "
                    f"body moved out of the domain box. If that motion is expected, enlarge "
                    f"the domain (domain.lower, domain.upper); if not, the body went unstable "
                    f"(its stiffness, damping and loads in [[body]] '{name}')")
        advice = "through a wall, or the domain is too small"
        if kind == FLUID:
            advice += "; domain.escaped_fluid = \"remove\" removes fluid spray instead"
        return f"step {step}: {KIND_NAMES[kind]} particle {pid} {place} ({advice})"

    def _count(self, removed, first, step, time):
        before = self.total
        self.total += removed
        pid, where = first[0], first[-1]
        if self.total > self.limit:
            raise RunFailure(
                f"step {step}: {self.total} fluid particles have left the domain, more than "
                f"domain.max_escaped_fraction = {self.max_fraction:g} of the "
                f"{self.initial_fluid} at t = 0 (this step particle {pid} at ({_place(where)})"
                f"): fluid pouring out is a leaking wall, a domain too small or an unstable "
                f"run, not spray", where=where)
        if before == 0:
            others = f" with {removed - 1} other(s)" if removed > 1 else ""
            if self.comm.rank == 0:
                log.warning("step %d, t = %.6g s: fluid particle %d left the domain at (%s) "
                            "and was removed%s (domain.escaped_fluid = \"remove\"); n_escaped "
                            "in the diagnostics counts every one removed", step, time,
                            pid, _place(where), others)
            self.reported = self.total
            # The summaries follow the warning by their interval, not at once.
            self.report = WallInterval(self.report.seconds)

    def _summarise(self, step, time):
        # Rank 0 alone decides, by its own clock, and only whether to log.
        if self.comm.rank != 0 or self.total == self.reported or not self.report.due():
            return
        log.info("step %d, t = %.6g s: %d fluid particle(s) have left the domain and been "
                 "removed so far (%d since the last report; %.3g %% of the %d at t = 0, the "
                 "run stops above %.3g %%)", step, time, self.total,
                 self.total - self.reported, 100.0 * self.total / max(self.initial_fluid, 1),
                 self.initial_fluid, 100.0 * self.max_fraction)
        self.reported = self.total

    def summary(self):
        """The end-of-run summary's clause, or "" when no particle left."""
        if not self.total:
            return ""
        return f"; {self.total} fluid particle(s) left the domain and were removed"
