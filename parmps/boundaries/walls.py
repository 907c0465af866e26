"""Walls with prescribed motion: tanks and wall boxes translating at a constant velocity.

A ``[[tank]]`` or ``[[wall_box]]`` with a non-zero ``velocity`` moves, its wall
and dummy particles together, while ``move_start <= t < move_end`` and rests
otherwise. Its displacement is a function of the time alone,
``d(t) = v (clip(t, move_start, move_end) - move_start)``, so where a wall is
does not depend on the step sizes: each step adds ``d(t + dt) - d(t)``, which
telescopes to ``d(t)`` up to round-off.

Which particles. :func:`parmps.geometry.scene.build` numbers particles in the order of
the case's geometry entries, so each tank or wall box owns one contiguous block
of global ids. Ids never change, so the block finds the wall's particles on any
rank after any migration or rebalance without a per-particle field to carry.

When. The time loop calls :meth:`MovingWalls.advance` at the start of each
step, before migration and the halo: the whole fluid step (pair search, number
density, pressure) then sees the walls where they are at the end of the step,
as it sees the fluid at its predicted positions (the choice
:meth:`parmps.coupling.weak.SolidCoupling.predict` makes for solid nodes). Moving
before migration lets the decomposition treat wall particles like any other.

Velocity. A moving wall's particles carry the mean velocity of the step they
are in, ``(d(t + dt) - d(t)) / dt``: the wall velocity the viscous term and the
collision model see, consistent with the displacement. It is ``v`` in a step
inside the motion window, 0 in a step outside it (a stopped wall is at rest),
and a fraction of ``v`` in a step that straddles ``move_start`` or
``move_end``. Before the first step the particles carry the velocity at t = 0.
"""

import math

import numpy as np

from parmps.core.geometry import format_point
from parmps.core.particles import FLUID, INFLOW
from parmps.errors import CaseError
from parmps.geometry.domain import Domain
from parmps.fluid.forces import fluid_force_parts, pressure_force_from
from parmps.fluid.participant import Participant

# The walls that may move: tanks, wall boxes and walls of any shape (parmps.geometry).
SECTIONS = ("tank", "wall_box", "wall")


def travel(spec, time):
    """Displacement d(time) [m] of a tank or wall box entry from its position at t = 0."""
    start, end = spec["move_start"], spec["move_end"]
    moved = min(max(time, start), end) - start
    return np.asarray(spec["velocity"], dtype=float) * moved


def moving_entries(case):
    """``(name, spec)`` of every tank and wall box with a non-zero velocity."""
    return [(f"{section}[{k}]", spec) for section in SECTIONS
            for k, spec in enumerate(case.get(section, ())) if any(spec["velocity"])]


class MovingWalls(Participant):
    """The moving tanks and wall boxes of a case, each a block of global ids.

    ``fluid``: the fluid solver (its constants and gradient scheme), for the work the
    walls do on the fluid; set once the solver exists."""

    name = "moving_walls"
    # The work the walls did on the fluid so far, summed over the ranks [J]: the pressure
    # force of the walls' particles on the fluid in the symmetric pair form (the
    # correction and the viscous force left out) times the walls' velocity.
    DIAGNOSTICS = {"moving_wall_work": np.float64}

    def __init__(self, case, ids, origin, sources):
        """``ids``, ``origin`` and ``sources``: the global scene of :func:`scene.build`."""
        self.fluid = None
        self.work_done = 0.0  # this rank's share of the work on the fluid so far [J]
        self.walls = []
        for name, spec in moving_entries(case):
            members = ids[origin == sources.index(name)]
            low, high = int(members.min()), int(members.max()) + 1
            if high - low != len(members):
                raise AssertionError(f"{name}: its particle ids are not one block")
            self.walls.append((name, spec, low, high))

    @classmethod
    def from_scene(cls, case, particles, origin, sources):
        """The moving walls of the case, or None when every wall is fixed."""
        if not moving_entries(case):
            return None
        return cls(case, particles.id, origin, sources)

    def speed(self, time, until):
        """Largest wall speed at any time in [time, until) (the same on every rank)."""
        return max((math.hypot(*spec["velocity"]) for _, spec, _, _ in self.walls
                    if spec["move_start"] < until and time < spec["move_end"]), default=0.0)

    def _members(self, particles, low, high):
        ids = particles.id[:particles.n_owned]
        return (ids >= low) & (ids < high)

    def set_velocity(self, particles, time):
        """Give the owned particles of each moving wall its velocity at ``time``."""
        n = particles.n_owned
        for _, spec, low, high in self.walls:
            moving = spec["move_start"] <= time < spec["move_end"]
            particles.velocity[:n][self._members(particles, low, high)] = \
                spec["velocity"] if moving else 0.0

    def advance(self, particles, time, dt):
        """Move the owned particles of each wall from d(time) to d(time + dt), in place.

        Ghosts are left alone: the time loop calls this before migration, which drops them.
        """
        n = particles.n_owned
        for _, spec, low, high in self.walls:
            # Every rank computes the same shift, so a particle ends bit-identical
            # whichever rank owns it.
            shift = travel(spec, time + dt) - travel(spec, time)
            members = self._members(particles, low, high)
            particles.position[:n][members] += shift
            particles.velocity[:n][members] = shift / dt

    def before_exchange(self, particles, time, dt):
        self.advance(particles, time, dt)

    def after_fluid(self, particles, time, dt, decomposition):
        """Add the work the walls did on the fluid in the step: the pressure force their
        particles exert on the owned fluid (:func:`pressure_force_from`) times the walls'
        velocity and dt (collective while a wall moves)."""
        moving = [(spec, low, high) for _, spec, low, high in self.walls
                  if spec["move_start"] < time + dt and time < spec["move_end"]]
        if not moving:
            return particles
        # The fluid step leaves ghost values of the start of the step.
        decomposition.refresh([particles.position, particles.velocity, particles.pressure],
                              positions=(0,))
        n = particles.n_owned
        rows = np.flatnonzero(np.isin(particles.kind[:n], (FLUID, INFLOW)))
        for spec, low, high in moving:
            wall = (particles.id >= low) & (particles.id < high)
            force = pressure_force_from(particles, rows, self.fluid.constants, wall).sum(axis=0)
            # The wall's viscous force on the fluid: the reaction to the fluid's on its owned
            # particles (a sheared lid drives the flow by that alone).
            own = np.flatnonzero(wall[:n])
            force -= fluid_force_parts(particles, own, self.fluid.constants,
                                       self.fluid.gradient)[1].sum(axis=0)
            velocity = (travel(spec, time + dt) - travel(spec, time)) / dt
            self.work_done += dt * float(force @ velocity)
        return particles

    def work(self):
        return self.work_done

    def diagnostics(self):
        return {"moving_wall_work": self.fluid.comm.allreduce(self.work_done)}

    def checkpoint_state(self):
        return {"work": self.fluid.comm.allreduce(self.work_done)}

    def restore_state(self, saved):
        # One rank carries the total so far; the sum over the ranks is the total.
        self.work_done = float(saved.get("work", 0.0)) if self.fluid.comm.rank == 0 else 0.0

    def particle_owner(self, particle_id):
        name = self.name_of(particle_id)
        if name is None:
            return None
        return f"the moving {name}", f"stop it earlier ({name}.move_end) or enlarge the domain"

    def name_of(self, particle_id):
        """The moving wall a particle belongs to, or None."""
        for name, _, low, high in self.walls:
            if low <= particle_id < high:
                return name
        return None

    def check_domain(self, case, particles, end_time):
        """Refuse a wall that would leave the domain before ``end_time`` (CaseError).

        ``particles``: the global scene at t = 0. The motion is a straight line,
        so the wall leaves the box, if at all, where its particles' bounding box
        first touches a side.
        """
        lower = np.asarray(case["domain"]["lower"], dtype=float)
        upper = np.asarray(case["domain"]["upper"], dtype=float)
        for name, spec, low, high in self.walls:
            position = particles.position[(particles.id >= low) & (particles.id < high)]
            first, last = position.min(axis=0), position.max(axis=0)
            velocity = np.asarray(spec["velocity"], dtype=float)
            room = np.where(velocity > 0, upper - last, first - lower)
            # Along a periodic axis a wall wraps like the fluid: it never leaves.
            room[list(Domain.from_case(case).periodic)] = math.inf
            with np.errstate(divide="ignore"):
                allowed = np.where(velocity != 0, room / np.abs(velocity), math.inf)
            duration = min(end_time, spec["move_end"]) - spec["move_start"]
            if duration > allowed.min() * (1 + 1e-12):
                leave = spec["move_start"] + float(allowed.min())
                stop = min(end_time, spec["move_end"])
                until = "the end time" if stop == end_time else f"{name}.move_end"
                raise CaseError(
                    f"{name} moves out of the domain: at {name}.velocity = "
                    f"{format_point(velocity, 'g', '[]')} m/s its particles leave "
                    f"{format_point(lower, 'g', '[]')}-{format_point(upper, 'g', '[]')} at "
                    f"t = {leave:.6g} s, before {until} ({stop:g} s); stop it earlier "
                    f"({name}.move_end) or enlarge domain.lower/domain.upper")
