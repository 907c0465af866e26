"""Weak fluid-solid coupling and solid ownership under MPI (docs/design.md §1.6).

Solid nodes live among the fluid's particles as kind SOLID: they add to the
number density, are pressure unknowns and give the viscous term their velocity,
but the fluid step does not move them. After each fluid step:

1. the fluid force on every owned node particle is evaluated from the new
   pressure and velocity, ``F_i = -V_i <grad P>_i + V_i mu <lap u>_i`` with
   ``V_i = l0^d``, the pressure gradient of the fluid's own gradient scheme
   (:mod:`parmps.fluid.schemes`) and the MPS Laplacian; the viscous part as a drag
   towards the fluid neighbours' mean velocity (:meth:`WeakCoupling.node_forces`);
2. the forces of each body's nodes, spread over the ranks whose slabs hold
   them, are summed on the body's owner (body k belongs to rank k mod size);
3. the owner advances the body (the solid model's substeps) with the pressure
   force held and the drag taken implicitly in every substep, and broadcasts
   the nodes' positions, velocities and fluid forces;
4. every rank writes the new node states into the node particles it owns; the
   decomposition migrates them like any other particle at the next step.

A node's force is computed by exactly one rank and every other rank adds zeros
in the reduction, so the result does not depend on the rank count.

Light bodies. The pressure is solved as if the nodes would not give way, and
pushes them only afterwards: for a body lighter than the fluid it displaces
(its added mass) that push overshoots and grows every step, the added-mass
instability (box_in_flow at solid/fluid density 0.3 and 0.1). The scheme
warns at the start and names that cause when such a run fails;
:mod:`parmps.coupling.implicit_pressure` is the scheme that holds for them.

Leaks. The fluid cannot pass a solid thinner than the kernel (a 3-node
membrane) because every node, whatever its depth, repels fluid through the
pressure of its own PPE row, and the collision model reflects a fluid particle
off the nodes within a fixed partner's reach as off a wall (their velocity is
the wall's). A node on a side with no fluid has a low number
density and becomes a Dirichlet (P = 0) particle like a free surface, which is
what that side is. :func:`fluid_inside` counts fluid particles inside each
body's closed boundary (its model's ``boundary``, any d) every step, so a leak
would show in the diagnostics.

Closed shells. A shell holding water (``SolidModel.encloses_fluid``) is one node
thick, and the pressure and the collisions do not keep every particle on its
side: the capsule of cases/capsule_3d.toml let particles through at mean edges
of 0.92, 0.97 and 1.41 l0 (none at 1.11). The shell is a membrane, so the
coupling holds the water to its side (:func:`hold_to_side`): every step each
owned fluid particle near the shell gets its side (inside or outside, the
winding number of the shell's triangles) before the fluid moves; after the
bodies have moved, one found on the other side of the shell's new surface is put
back HOLD_DEPTH spacings into its own side, beside the nearest point of the
surface, and its velocity relative to the surface there loses the part that
carried it through. The held particles per step are a series of the body
(``held_back``): how often the membrane needed holding.
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.core.geometry import closed_surface_sides, inside_boundary, nearest_on_surface
from parmps.core.particles import SOLID, owned_fluid_near
from parmps.errors import RunFailure
from parmps.fluid.forces import fluid_force_parts
from parmps.fluid.participant import Participant

log = logging.getLogger(__name__)

# A particle put back through a shell lands this many spacings into its own side: beside
# the surface, not on it, and nearer than any fluid particle of the lattice was left
# (the clearance, half a spacing or more).
HOLD_DEPTH = 0.25
# Particles are given a side within this many spacings of a shell's box: one moves less
# than a spacing a step (time.cfl <= 1), so one that crosses has a side before and after.
SIDE_BAND = 2.0


# How far below 1 a density ratio must lie to be a light body, not rounding.
LIGHT_MARGIN = 1e-9
# How far from a light body's nodes a failure may be blamed on it, in spacings: its
# instability grows over about 60 steps (docs/validation.md, Stability map), in which
# fluid it throws travels at most 30 l0 at a Courant number of 0.5.
REACH = 30.0


def density_ratio(inverse_mass, constants):
    """A body's solid/fluid density: its moving nodes' mean mass over a fluid particle's
    (rho0 l0^d); inf for a body whose nodes are all fixed."""
    inverse_mass = np.asarray(inverse_mass, dtype=float)
    moving = inverse_mass > 0.0
    if not moving.any():
        return np.inf
    return float(np.mean(1.0 / inverse_mass[moving])
                 / (constants.density * constants.spacing ** constants.dimension))


def light_bodies(density_ratio):
    """The bodies of ``density_ratio`` (name -> solid/fluid density) lighter than the fluid,
    named with their ratio, or ''."""
    # Beyond rounding: a body of the fluid's density reads 0.9999999999999998 as the mean
    # of its nodes' masses, and is not lighter.
    light = {name: ratio for name, ratio in density_ratio.items() if ratio < 1.0 - LIGHT_MARGIN}
    return ", ".join(f"body '{name}' (solid/fluid density {ratio:.3g})"
                     for name, ratio in light.items())


def node_mobilities(model, constants):
    """(each body's first node in the concatenation, rho0/rho_i of every node, bodies one
    after the other): rho0 l0^d / m_i for a node that moves, 1 (a wall's) for one that does
    not (1/m = 0)."""
    volume = constants.spacing ** constants.dimension
    node_mobility = []
    for k in range(len(model.bodies)):
        inverse_mass = np.asarray(model.node_inverse_mass(k), dtype=float)
        node_mobility.append(np.where(inverse_mass > 0.0,
                                      constants.density * volume * inverse_mass, 1.0))
    counts = [len(m) for m in node_mobility]
    if not counts:
        return np.zeros(0, np.int64), np.zeros(0)
    first_node = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    return first_node, np.concatenate(node_mobility)


def fluid_inside(particles, vertices, facets, comm, domain=None):
    """How many fluid (or inflow) particles lie inside the closed boundary ``facets`` (m, d)
    of ``vertices`` (n, d): a body's, as its model gives it (``SolidModel.boundary``), across
    a periodic seam of ``domain`` too. Collective."""
    used = np.asarray(vertices)[np.unique(np.asarray(facets, dtype=np.int64))] \
        if len(facets) else np.zeros((0, particles.position.shape[1]))
    local = 0
    if len(used):
        # Only particles in the boundary's box can be inside: the test costs
        # particles x facets.
        _, position = owned_fluid_near(particles, used.min(axis=0), used.max(axis=0), domain)
        local = int(np.count_nonzero(inside_boundary(position, vertices, facets)))
    return comm.allreduce(local, op=MPI.SUM)


def shell_sides(particles, vertices, facets, band, domain=None):
    """(rows, ids, sides, positions) of the owned fluid (or inflow) particles within ``band``
    of the closed surface's box: +1 inside, -1 outside; their positions as the surface sees
    them (across a periodic seam of ``domain``, at the image beside it)."""
    rows, position = owned_fluid_near(particles, vertices.min(axis=0) - band,
                                      vertices.max(axis=0) + band, domain)
    return rows, particles.id[rows], closed_surface_sides(position, vertices, facets), position


def hold_to_side(position, velocity, side, vertices, node_velocity, facets, depth, reach):
    """Put points found on the wrong side of a closed outward surface back on ``side``
    (+1 inside, -1 outside): each to ``depth`` from the surface's nearest point along the
    nearest triangle's normal, its velocity relative to the surface there (the corners'
    velocities, barycentric) stripped of the part pointing out of its side. Arrays in
    place; returns the indices of those still on the wrong side."""
    _, triangle, weights = nearest_on_surface(position, vertices, facets, reach)
    found = triangle >= 0
    corners = vertices[facets[triangle[found]]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    into = -side[found, None] * normal  # inside is against the outward normal
    nearest = np.einsum("kc,kcd->kd", weights[found], corners)
    position[found] = nearest + depth * into
    surface = np.einsum("kc,kcd->kd", weights[found], node_velocity[facets[triangle[found]]])
    relative = np.einsum("kd,kd->k", velocity[found] - surface, into)
    velocity[found] -= np.minimum(relative, 0.0)[:, None] * into
    return np.flatnonzero(closed_surface_sides(position, vertices, facets) != side)


class WeakCoupling(Participant):
    """The bodies of a coupled case, each owned by one rank, and the per-step exchange.

    A participant of the fluid step (:class:`parmps.run.steppers.FluidStepper`):
    it moves the node particles to where they are going before the pressure
    solve, and after the fluid step applies the fluid's force to the bodies.
    """

    # The fluid's answer reaches the nodes a step late: a body lighter than its added mass
    # is unstable (a scheme that puts the nodes' inertia into the pressure solve sets False).
    ANSWERS_A_STEP_LATE = True
    # The bodies' kinetic, elastic and potential energy, which they trade with the fluid [J].
    DIAGNOSTICS = {"body_energy": np.float64}

    def __init__(self, model, comm, fluid):
        self.model = model
        self.comm = comm
        self.fluid = fluid
        self.domain = fluid.domain
        self.owners = [k % comm.size for k in range(len(model.bodies))]
        self.last_substeps = {body.name: 0 for body in model.bodies}
        # Closed shells with water inside: the coupling holds it to its side of them.
        self.enclosures = [k for k in range(len(model.bodies)) if model.encloses_fluid(k)]
        self.sides = {}
        self.held_back = {body.name: 0 for body in model.bodies}
        self.density_ratio = {body.name: density_ratio(model.node_inverse_mass(k),
                                                       fluid.constants)
                              for k, body in enumerate(model.bodies)}
        self.first_node, self.node_mobility = node_mobilities(model, fluid.constants)
        light = self.light_bodies() if self.ANSWERS_A_STEP_LATE else ""
        if light and comm.rank == 0:
            log.warning("%s lighter than the fluid: coupling.scheme = \"weak\" is prone to "
                        "the added-mass instability for it; \"implicit_pressure\" is not",
                        light)

    def light_bodies(self, where=None):
        """The bodies lighter than the fluid named with their density ratio, or ''; with
        ``where`` (a failure's position), only those with a node within REACH of it."""
        ratios = self.density_ratio
        if where is not None:
            reach = REACH * self.fluid.constants.spacing
            near = {body.name for body in self.model.bodies
                    if np.min(np.linalg.norm(body.position - np.asarray(where), axis=1)) < reach}
            ratios = {name: ratio for name, ratio in ratios.items() if name in near}
        return light_bodies(ratios)

    def failure_cause(self, where=None):
        """The added-mass instability, when a body near ``where`` is lighter than the fluid."""
        light = self.light_bodies(where) if self.ANSWERS_A_STEP_LATE else ""
        if not light:
            return None
        return (f"the added-mass instability: {light} lighter than the fluid, and "
                f"coupling.scheme = \"weak\" applies the fluid's answer to a body's motion a "
                f"step late; once the fluid a body pushes aside (its added mass) outweighs "
                f"it, that answer overshoots and grows every step. Use coupling.scheme = "
                f"\"implicit_pressure\"")

    name = "coupling"

    def checkpoint_state(self):
        """Every body's state from its owner: only the owner advances it, so only its
        accelerations and multipliers are current (collective)."""
        state = self.model.state()
        return {"bodies": {body.name: self.comm.bcast(state[body.name], root=self.owners[k])
                           for k, body in enumerate(self.model.bodies)}}

    def restore_state(self, saved):
        # Every rank: the owners differ with the rank count.
        self.model.restore(saved["bodies"])

    def speed(self, time, until):
        """Largest node speed of any body (the same on every rank)."""
        return self.model.max_speed()

    def check(self, particles, step, time):
        self.model.check(step, time)

    def before_pressure(self, particles, time, dt):
        """Move node particles (owned and ghosts) to ``x + dt v`` for the fluid step.

        The pressure then answers to where the nodes are going, as it does for
        the fluid's own predicted positions. A force computed at the nodes'
        current positions and held over the step would make every node's
        pressure response an explicit, undamped-and-growing feedback (a held
        force of stiffness k grows each step by about 1 + k dt^2 / 4m); with
        the prediction the same feedback is damped (factor 1 - k dt^2 / 2m).
        The solid integrates from the true positions afterwards.
        """
        # Each particle's side of a shell, before anything moves (the owners are this
        # step's: the decomposition has migrated the particles already).
        self.sides = {}
        for k in self.enclosures:
            _, ids, sides, position = shell_sides(particles, *self.model.boundary(k),
                                                  self._band(), self.domain)
            self.sides[k] = (ids, sides, position)
        solid = particles.kind == SOLID
        particles.position[solid] += dt * particles.velocity[solid]
        return None

    def after_fluid(self, particles, time, dt, decomposition):
        """Fluid forces to the owners, the bodies advanced, node states back into ``particles``.

        ``particles``: the fluid step's particles (owned + ghosts of the last
        halo). Collective. Updates owned node particles in place.
        """
        comm = self.comm
        model = self.model
        # The fluid step leaves ghost values of the start of the step.
        decomposition.refresh([particles.position, particles.velocity, particles.pressure],
                              positions=(0,))
        n = particles.n_owned
        rows = np.flatnonzero(particles.kind[:n] == SOLID)
        force, rate, target = self.node_forces(particles, rows)
        body_of = particles.body[rows]
        node_of = particles.node[rows]
        d = force.shape[1]
        for k, body in enumerate(model.bodies):
            owner = self.owners[k]
            mine = body_of == k
            # Held force, drag rate and drag target in one reduction.
            local = np.zeros((len(body.position), 2 * d + 1))
            local[node_of[mine]] = np.column_stack([force[mine], rate[mine], target[mine]])
            total = np.zeros_like(local) if comm.rank == owner else None
            comm.Reduce(local, total, op=MPI.SUM, root=owner)
            state = np.empty((3,) + body.position.shape)
            if comm.rank == owner:
                body.fluid_force[:] = total[:, :d]
                model.set_drag(k, total[:, d], total[:, d + 1:])
                self.last_substeps[body.name] = model.advance_body(k, time, dt)
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
            # Inside the period: the body keeps its own positions, unwrapped, across a seam.
            particles.position[index] = self.domain.wrapped(body.position[node_of[mine]])
            particles.velocity[index] = body.velocity[node_of[mine]]
        for k in self.enclosures:
            self.held_back[model.bodies[k].name] = self._hold(particles, k)
        return particles

    def _band(self):
        return SIDE_BAND * self.fluid.constants.spacing

    def _hold(self, particles, k):
        """Put the owned particles that went through shell k this step back on their side
        (:func:`hold_to_side`); returns how many, over every rank (collective)."""
        before_ids, before_sides, before_position = self.sides[k]
        vertices, facets = self.model.boundary(k)
        rows, ids, sides, seen = shell_sides(particles, vertices, facets, self._band(),
                                             self.domain)
        _, now, before = np.intersect1d(ids, before_ids, assume_unique=True,
                                        return_indices=True)
        crossed = sides[now] != before_sides[before]
        index, side = rows[now[crossed]], before_sides[before[crossed]]
        if len(index):
            # Beside the surface (a migration wraps one put past a periodic face).
            position = seen[now[crossed]]
            velocity = particles.velocity[index]
            spacing = self.fluid.constants.spacing
            wrong = hold_to_side(position, velocity, side, vertices,
                                 self.model.bodies[k].velocity, facets, HOLD_DEPTH * spacing,
                                 self._band())
            # Where the surface's nearest point does not settle it (a fold of the shell),
            # the particle goes back to where it started the step, on its side then.
            position[wrong] = before_position[before[crossed]][wrong]
            particles.position[index] = position
            particles.velocity[index] = velocity
        return self.comm.allreduce(len(index), op=MPI.SUM)

    def diagnostics(self):
        return {"body_energy": self.model.mechanical_energy()}

    def node_substeps(self, dt):
        """Each rank's node-substeps in a step of dt: a body's nodes times its substeps, on
        the body's owner (the same on every rank)."""
        counts = self.model.substep_counts(dt)
        work = np.zeros(self.comm.size)
        for k, body in enumerate(self.model.bodies):
            work[self.owners[k]] += len(body.position) * counts[body.name]
        return work

    def mobility_of(self, particles, nodes):
        """rho0/rho_i of the node particles ``nodes`` (indices into ``particles``)."""
        return self.node_mobility[self.first_node[particles.body[nodes]] + particles.node[nodes]]

    def node_forces(self, particles, rows):
        """(held force (n, d), drag rate (n,), drag target (n, d)) of the owned node
        particles ``rows``: the fluid's force split into its pressure part, held over the
        bodies' step, and its viscous part ``k_i (u_bar_i - u_i)``, a drag towards the
        fluid neighbours' mean velocity u_bar at the rate k_i/m_i, taken backward Euler in
        every substep (:func:`parmps.solids.mass_spring.kernels.drag_kick`).

        Why in the substeps: held over the step, the drag that resists a node's motion
        relative to the fluid is fixed at the step's start while the body's own forces act
        for the whole step; a membrane whose nodes relax in mu l0/G_s, shorter than the
        step, then springs back unresisted every step and the shell is stiffer than its law
        (a capsule in shear deformed 5 times less at a Courant step of 31 ms than at 5 ms).
        After a step that took viscosity implicitly u_bar reads the fluid's u* (the
        velocities the fluid's own viscous term solved for beside the nodes)."""
        velocity = self.fluid.viscous_velocity
        constants = self.fluid.constants
        pressure_force, viscous_force, viscous_rate = fluid_force_parts(
            particles, rows, constants, self.fluid.gradient, velocity)
        seen = (particles.velocity if velocity is None else velocity)[rows]
        # k_i (u_bar - u_i) = rho0 V rate0 (u_bar - u_i), rate0 the rate of a fluid particle.
        scale = constants.density * constants.spacing ** constants.dimension * viscous_rate
        slip = np.divide(viscous_force, scale[:, None], out=np.zeros_like(viscous_force),
                         where=scale[:, None] > 0.0)
        return pressure_force, viscous_rate * self.mobility_of(particles, rows), seen + slip

    # Per-body series beyond the solid model's own: fluid particles inside the outline,
    # which would show a leak.
    SERIES = {"fluid_inside": (), "held_back": ()}

    def series(self, state):
        """{body name: {"fluid_inside": count, "held_back": the particles a shell held to
        their side in the last step}} (collective)."""
        return {body.name: {"fluid_inside": fluid_inside(state.particles,
                                                         *self.model.boundary(k), self.comm,
                                                         self.domain),
                            "held_back": self.held_back[body.name]}
                for k, body in enumerate(self.model.bodies)}
