"""The fluid's viscous force on a fixed wall, by momentum exchange with the wall's particles.

Why. A force probe on a wall integrates the pressure sampled on the wall's surface
(:mod:`parmps.probes.observer`): the normal stress. The tangential, viscous stress is what a
drag coefficient at a low Reynolds number is largely made of (Schäfer & Turek's cylinder at
Re 20: about a third of the drag), and sampling a velocity gradient on the surface of a
particle wall is noisy and biased by the wall's layers.

What. The fluid's viscous term feels a wall particle j through the no-slip mirror
``2 U_j - <u>_j`` (:func:`parmps.fluid.viscous.no_slip_velocity`); what the wall exerts on the
fluid is that term's part from the wall's particles, and the wall feels its opposite:
``F_j = 2 rho V nu c sum_i w_ij (u_i - U_j)`` over j's fluid neighbours i, c = 2d/(lambda0 n0),
V = l0^d (:func:`parmps.fluid.forces.fluid_force_parts`, the reaction a body's nodes feel).
Summed over the wall's particles it is minus the viscous force the wall put on the fluid: a
steady periodic channel's walls carry exactly the body force that drives it.

When. After a fluid step at whose end a probe that reads it samples (every step for a probe
with interval 0), with the ghosts refreshed (the step leaves those of its start) and the
step's velocities: the fluid's ``u*`` where it took viscosity implicitly (the velocities its
viscous term saw beside the wall), its new velocities otherwise; the wall's ``dry``
particles (walls the step found away from the water) are left out. The sum is reduced over
the ranks, so every rank holds every wall's force.
"""

import math

import numpy as np

from parmps.fluid.forces import fluid_force_parts
from parmps.fluid.participant import Participant


def probed_blocks(case, ids, origin, sources):
    """probe name -> ``(first id, last id + 1)`` of the particles of the fixed wall each
    force probe on a ``[[wall]]`` or a ``[[wall_box]]`` reads: scene.build numbers each
    geometry entry's particles as one block of ids."""
    names = {spec["name"]: k for k, spec in enumerate(case.get("wall", ())) if spec["name"]}
    blocks = {}
    for probe in case["probe"]:
        if probe["kind"] != "force":
            continue
        if probe.get("wall"):
            source = f"wall[{names[probe['wall']]}]"
        elif probe["wall_box"] >= 0:
            source = f"wall_box[{probe['wall_box']}]"
        else:
            continue
        members = ids[origin == sources.index(source)]
        low, high = int(members.min()), int(members.max()) + 1
        if high - low != len(members):
            raise AssertionError(f"{source}: its particle ids are not one block")
        blocks[probe["name"]] = (low, high)
    return blocks


class WallTraction(Participant):
    """The viscous force of the fluid on the walls the force probes read (see the module
    docstring). ``blocks``: probe name -> the wall's id block (:func:`probed_blocks`);
    ``fluid``: the fluid solver (its constants, gradient and u*)."""

    def __init__(self, blocks, fluid, intervals=(0.0,), end_time=math.inf):
        """``intervals``: the sampling intervals of the probes that read it [s] (0: every
        step); ``end_time``: the run's (the probes sample there too)."""
        self.blocks = dict(blocks)
        self.fluid = fluid
        self.intervals = tuple(intervals)
        self.end_time = end_time
        dimension = fluid.constants.dimension
        self.forces = {name: np.zeros(dimension) for name in self.blocks}

    @classmethod
    def from_scene(cls, case, particles, origin, sources, fluid, end_time=math.inf):
        """The participant, or None when no force probe reads a wall."""
        blocks = probed_blocks(case, particles.id, origin, sources)
        if not blocks:
            return None
        intervals = [probe["interval"] for probe in case["probe"] if probe["name"] in blocks]
        return cls(blocks, fluid, intervals, end_time)

    def due(self, time, dt):
        """Whether a probe may sample at the end of the step [time, time + dt]: a multiple of
        its interval within the step, widened by a thousandth of the step each side so that
        round-off never skips a sample (it may compute a step more), or the run's end."""
        slack = 1e-3 * dt
        if time + dt >= self.end_time - slack:
            return True
        return any(interval <= 0.0 or math.floor((time + dt + slack) / interval)
                   > math.floor((time - slack) / interval) for interval in self.intervals)

    def after_fluid(self, particles, time, dt, decomposition):
        if self.due(time, dt):
            decomposition.refresh([particles.position, particles.velocity,
                                   particles.pressure], positions=(0,))
            self.forces = dict(zip(self.blocks, self.viscous_forces(particles)))
        return particles

    def viscous_forces(self, particles):
        """Each block's viscous force [N, per metre of depth in 2D], summed over the ranks
        (collective); ghosts must be current."""
        n = particles.n_owned
        ids = particles.id[:n]
        velocity = self.fluid.viscous_velocity
        local = []
        for low, high in self.blocks.values():
            rows = np.flatnonzero((ids >= low) & (ids < high) & (particles.dry[:n] == 0))
            viscous = fluid_force_parts(particles, rows, self.fluid.constants,
                                        self.fluid.gradient, velocity)[1]
            local.append(viscous.sum(axis=0))
        return list(self.fluid.comm.allreduce(np.array(local)))

    def viscous_force(self, name):
        """The viscous force on probe ``name``'s wall after the last step."""
        return self.forces[name]
