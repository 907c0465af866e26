"""Weak fluid-solid coupling and solid ownership under MPI (DESIGN.md §1.6, §2 Solids).

Solid nodes live among the fluid's particles as kind SOLID: they add to the
number density, are pressure unknowns and give the viscous term their velocity,
but the fluid step does not move them. After each fluid step:

1. the fluid force on every owned node particle is evaluated from the new
   pressure and velocity, ``F_i = -V_i <grad P>_i + V_i mu <lap u>_i`` with
   ``V_i = l0^2`` and the same MPS operators (minimum-pressure gradient) the
   fluid uses on itself;
2. the forces of each body's nodes, spread over the ranks whose slabs hold
   them, are summed on the body's owner (body k belongs to rank k mod size);
3. the owner runs the body's automatic substeps with the force held, and
   broadcasts the nodes' positions, velocities and fluid forces;
4. every rank writes the new node states into the node particles it owns; the
   decomposition migrates them like any other particle at the next step.

A node's force is computed by exactly one rank and every other rank adds zeros
in the reduction, so the result does not depend on the rank count.

Leaks. The fluid cannot pass a solid thinner than the kernel (a 3-node
membrane) because every node, whatever its depth, repels fluid through the
pressure of its own PPE row, and the collision model reflects a fluid particle
off a node closer than collision_distance as off a wall (the node's velocity
is the wall velocity). A node on a side with no fluid has a low number
density and becomes a Dirichlet (P = 0) particle like a free surface, which is
what that side is. :func:`fluid_inside` counts fluid particles inside each
body's outline every step, so a leak would show in the diagnostics.
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.core import operators
from parmps.errors import CaseError, RunFailure
from parmps.core.neighbours import pair_list, rows_of
from parmps.core.particles import DUMMY, FLUID, INFLOW, SOLID, Particles

log = logging.getLogger(__name__)

# A lattice body's node spacing must match the particle spacing within this.
_SPACING_TOLERANCE = 1e-6


def node_particles(bodies):
    """The material nodes of every body as SOLID particles (ids from 0, body order).

    Anchors (fixed points closing a polygon over a wall) are not particles.
    """
    counts = [body.n_material for body in bodies]
    total = sum(counts)
    return Particles({
        "id": np.arange(total, dtype=np.int64),
        "kind": np.full(total, SOLID, np.int8),
        "position": np.concatenate([body.position[:m] for body, m in zip(bodies, counts)])
        if total else np.empty((0, 2)),
        "velocity": np.concatenate([body.velocity[:m] for body, m in zip(bodies, counts)])
        if total else np.empty((0, 2)),
        "body": np.repeat(np.arange(len(bodies), dtype=np.int32), counts),
        "node": np.concatenate([np.arange(m, dtype=np.int32) for m in counts])
        if total else np.empty(0, np.int32),
    })


def check_body_spacing(case, bodies):
    """In a fluid, a lattice body's nodes must sit l0 apart (they are particles)."""
    spacing = case["particles"]["spacing"]
    for k, spec in enumerate(case["body"]):
        if spec["type"] == "lattice" and \
                abs(spec["spacing"] - spacing) > _SPACING_TOLERANCE * spacing:
            raise CaseError(f"body[{k}] '{bodies[k].name}': spacing {spec['spacing']:g} must "
                            f"equal particles.spacing {spacing:g} in a case with fluid (its "
                            f"nodes are particles of the fluid)")


def fluid_forces(particles, rows, fluid):
    """Fluid force on the particles ``rows`` (owned): ``-V grad P + V mu lap u``.

    ``particles`` must have current ghosts (positions, velocities, pressures);
    ``fluid`` supplies the MPS constants. Returns (len(rows), 2).
    """
    if len(rows) == 0:
        return np.empty((0, 2))
    # Put the rows first so the pair search produces exactly their lists.
    others = np.ones(len(particles), bool)
    others[rows] = False
    order = np.concatenate([rows, np.flatnonzero(others)])
    position = particles.position[order]
    indptr, cols = pair_list(position, fluid.re_laplacian, n_rows=len(rows))
    pairs = operators.PairGeometry(indptr, rows_of(indptr), cols, position)
    n = len(rows)
    pressure = particles.pressure[order]
    has_pressure = particles.kind[order] != DUMMY
    w = pairs.weight(fluid.re_number_density)
    minimum = operators.neighbourhood_minimum(pairs, w, pressure, n, has_pressure)
    gradient = operators.gradient(pairs, w, pressure, n, fluid.n0, minimum, has_pressure)
    volume = fluid.spacing ** 2
    force = -volume * gradient
    if fluid.viscosity > 0.0:
        laplacian = operators.laplacian(pairs, pairs.weight(fluid.re_laplacian),
                                        particles.velocity[order], n, fluid.n0_laplacian,
                                        fluid.lambda0)
        force += volume * fluid.density * fluid.viscosity * laplacian
    return force


def point_in_polygon(points, polygon):
    """Whether each point lies inside the closed polygon (even-odd rule), vectorised."""
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


def fluid_inside(particles, body, comm):
    """How many fluid (or inflow) particles lie inside the body's material outline."""
    n = particles.n_owned
    kind = particles.kind[:n]
    polygon = body.position[body.outline]
    position = particles.position[:n]
    low, high = polygon.min(axis=0), polygon.max(axis=0)
    near = ((kind == FLUID) | (kind == INFLOW)) & np.all((position >= low) &
                                                        (position <= high), axis=1)
    local = int(np.count_nonzero(point_in_polygon(position[near], polygon)))
    return comm.allreduce(local, op=MPI.SUM)


class SolidCoupling:
    """The bodies of a coupled case, each owned by one rank, and the per-step exchange."""

    def __init__(self, system, comm):
        self.system = system
        self.comm = comm
        self.owners = [k % comm.size for k in range(len(system.bodies))]
        self.last_substeps = {body.name: 0 for body in system.bodies}

    def max_speed(self):
        """Largest node speed of any body (the same on every rank)."""
        return max((float(np.sqrt((body.velocity ** 2).sum(axis=1)).max())
                    for body in self.system.bodies), default=0.0)

    def predict(self, particles, dt):
        """Move node particles (owned and ghosts) to ``x + dt v`` for the fluid step.

        The pressure then answers to where the nodes are going, as it does for
        the fluid's own predicted positions. A force computed at the nodes'
        current positions and held over the step would make every node's
        pressure response an explicit, undamped-and-growing feedback (a held
        force of stiffness k grows each step by about 1 + k dt^2 / 4m); with
        the prediction the same feedback is damped (factor 1 - k dt^2 / 2m).
        The solid integrates from the true positions afterwards.
        """
        solid = particles.kind == SOLID
        particles.position[solid] += dt * particles.velocity[solid]

    def step(self, particles, fluid, decomposition, time, dt):
        """Fluid forces to the owners, solid substeps, node states back into ``particles``.

        ``particles``: the fluid step's particles (owned + ghosts of the last
        halo). Collective. Updates owned node particles in place.
        """
        comm = self.comm
        # The fluid step leaves ghost values of the start of the step.
        decomposition.refresh([particles.position, particles.velocity, particles.pressure])
        n = particles.n_owned
        rows = np.flatnonzero(particles.kind[:n] == SOLID)
        force = fluid_forces(particles, rows, fluid)
        body_of = particles.body[rows]
        node_of = particles.node[rows]
        for k, body in enumerate(self.system.bodies):
            owner = self.owners[k]
            mine = body_of == k
            local = np.zeros((body.n_nodes, 2))
            local[node_of[mine]] = force[mine]
            total = np.zeros_like(local) if comm.rank == owner else None
            comm.Reduce(local, total, op=MPI.SUM, root=owner)
            state = np.empty((3, body.n_nodes, 2))
            if comm.rank == owner:
                body.fluid_force[:] = total
                self.last_substeps[body.name] = body.advance(time, dt,
                                                             self.system.substeps[body.name])
                state[0], state[1], state[2] = body.position, body.velocity, body.fluid_force
            comm.Bcast(state, root=owner)
            if comm.rank != owner:
                body.position[:] = state[0]
                body.velocity[:] = state[1]
                body.fluid_force[:] = state[2]
            if not np.all(np.isfinite(state)):
                raise RunFailure(f"body '{body.name}' became non-finite at t = "
                                 f"{time + dt:.6g} s (the fluid force or the substeps went "
                                 f"unstable)")
            index = rows[mine]
            particles.position[index] = body.position[node_of[mine]]
            particles.velocity[index] = body.velocity[node_of[mine]]

    def extra_rows(self, particles):
        """Per-body values beyond the solid system's own diagnostics (collective)."""
        return {body.name: {"fluid_inside": fluid_inside(particles, body, self.comm)}
                for body in self.system.bodies}
