"""Mass-spring solids that keep their volume (docs/design.md §1.5), in any dimension d.

Physics on plain numpy arrays: spring, damping and external forces, the
volume a body's boundary encloses (its area in 2D) and the Lagrange multiplier
that holds it, the Verlet stability limit and the substep loop. Nothing here
imports PETSc or any fluid machinery, so a solid-only case stays light.

A body is a set of nodes (positions and velocities (n, d), masses) joined by
springs (node index pairs with rest length, stiffness and damping). Its
boundary is a set of outward facets (:mod:`parmps.solids.mass_spring.surface`):
the edges of a counter-clockwise node loop in 2D, triangles in 3D. Pinned
nodes have zero inverse mass: no force moves them and the constraint treats
them as rigid, which is also how a boundary closes over wall nodes.

Velocity Verlet, with forces evaluated at the new position and the half-step
velocity (damping is velocity dependent, so the full-step velocity is not yet
known when the force is needed):

    v_half   = v_n + dt/2 a_n
    x_{n+1}  = x_n + dt v_half
    a_{n+1}  = M^-1 (F(x_{n+1}, v_half, t_{n+1}) - gradPhi lambda)
    v_{n+1}  = v_half + dt/2 a_{n+1}

The next position is then x_{n+2} = x_{n+1} + dt v_half + dt^2 a_{n+1}, which
is exactly the prediction the docs/design.md §1.5 multiplier zeroes to first order
when its ``qdot`` is the half-step velocity:

    lambda = [Phi/dt^2 + gradPhi . (qdot/dt + M^-1 F)] / (gradPhi . M^-1 gradPhi)

That alone leaves the volume swept by the step's displacement, about
dt^2 |v|^2 (dt^2 Omega^2 V for a body rotating at Omega); it does not
accumulate, but it is 1e-7 of the area for the seed's 7x7 body. So by default
(``[solid] constraint_prediction = "iterated"``) lambda is then corrected by
Newton steps on the true volume of the predicted x_{n+2} until its relative
error is below ``constraint_tolerance`` (:func:`volume_multiplier`);
``"linear"`` keeps the single solve.
"""

import logging
import math

import numpy as np

from parmps.errors import CaseError
from parmps.geometry.mesh import determinant_terms, enclosed_moments, enclosed_volume
from parmps.solids.mass_spring.kernels import (body_substeps, drag_kick, drag_prediction,
                                              held_force_substeps, network_forces)
from parmps.solids.mass_spring.statics import highest_frequency, stiffness_matrix
from parmps.solids.mass_spring.surface import volume_gradient

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------
# Forces


def _scatter(n_nodes, springs, pair_force):
    """Add +pair_force to node i and -pair_force to node j of every spring; (n, d)."""
    i, j = springs[:, 0], springs[:, 1]
    d = pair_force.shape[1]
    force = np.empty((n_nodes, d))
    for axis in range(d):
        force[:, axis] = (np.bincount(i, weights=pair_force[:, axis], minlength=n_nodes)
                          - np.bincount(j, weights=pair_force[:, axis], minlength=n_nodes))
    return force


def spring_forces(position, springs, rest_length, stiffness):
    """Hooke forces ``-k (|l| - l0) l/|l|`` on every node, l = x_i - x_j; shape (n, d)."""
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
    # A collapsed spring has no direction; it exerts no force rather than NaN.
    scale = np.divide(stiffness * (length - rest_length), length,
                      out=np.zeros_like(length), where=length > 0)
    return _scatter(len(position), springs, -scale[:, None] * separation)


def damping_forces(velocity, springs, damping):
    """Damping ``-b (v_i - v_j)`` on every node; shape (n, d)."""
    relative = velocity[springs[:, 0]] - velocity[springs[:, 1]]
    return _scatter(len(velocity), springs, -damping[:, None] * relative)


def spring_energy(position, springs, rest_length, stiffness):
    """Elastic energy ``sum k (|l| - l0)^2 / 2``."""
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
    return 0.5 * float(np.sum(stiffness * (length - rest_length) ** 2))


def kinetic_energy(velocity, mass):
    return 0.5 * float(np.sum(mass * np.einsum("ij,ij->i", velocity, velocity)))


def load_factor(time, start, end, ramp):
    """How much of each windowed load acts at ``time``: 0 outside [start, end), 1 inside.

    With a ramp the load rises linearly over [start, start + ramp] and falls over
    [end - ramp, end], which avoids the ringing of a sudden step. Arrays in, array out.
    """
    inside = (time >= start) & (time < end)
    with np.errstate(divide="ignore", invalid="ignore"):
        rise = np.where(ramp > 0, (time - start) / ramp, 1.0)
        fall = np.where(ramp > 0, (end - time) / ramp, 1.0)
    return np.where(inside, np.clip(np.minimum(rise, fall), 0.0, 1.0), 0.0)


# --------------------------------------------------------------------------
# The enclosed volume and its constraint (any d: parmps.solids.mass_spring.surface)


def loop_facets(loop):
    """The facets (i, i+1) of a closed node loop: its edges, last to first included."""
    loop = np.asarray(loop, dtype=np.int64)
    return np.column_stack([loop, np.roll(loop, -1)])


def boundary_facets(boundary):
    """A body's boundary as facets (m, d): a 2D loop's edges, or the given facets."""
    boundary = np.asarray(boundary, dtype=np.int64)
    return loop_facets(boundary) if boundary.ndim == 1 else boundary


def polygon_area(position, loop):
    """Signed area of a node loop: positive counter-clockwise (2D :func:`enclosed_volume`)."""
    return enclosed_volume(position, loop_facets(loop))


def area_gradient(position, loop):
    """dV/dx_i = (y_{i+1} - y_{i-1})/2, dV/dy_i = (x_{i-1} - x_{i+1})/2 for the loop nodes."""
    return volume_gradient(position, loop_facets(loop))[np.asarray(loop)]


def area_multiplier(phi, gradient, velocity, inverse_mass, force, dt):
    """The Lagrange multiplier of docs/design.md §1.5 (seed eq. 12 with Phi_t = 0).

    ``gradient``, ``velocity``, ``force`` are (m, d) on the boundary nodes and
    ``inverse_mass`` (m,) (0 for pinned nodes). The constraint force is
    ``-gradient * lambda``. Returns 0 when no boundary node can move.
    """
    weighted = gradient * inverse_mass[:, None]
    denominator = float(np.sum(weighted * gradient))
    if denominator <= 0.0:
        return 0.0
    numerator = (phi / dt ** 2 + float(np.sum(gradient * velocity)) / dt
                 + float(np.sum(weighted * force)))
    return numerator / denominator


def volume_multiplier(position, facets, rest_volume, velocity, inverse_mass, force, dt,
                      tolerance=0.0, iterations=0, kick=1.0):
    """The multiplier that puts the next substep's boundary on its rest volume.

    Arrays on the boundary nodes: ``position``, ``velocity`` (the half-step
    velocity), ``force`` (everything but the constraint) (s, d), ``inverse_mass``
    (s,), ``facets`` indexing them. Starts from eq. 12 (:func:`area_multiplier`),
    which zeroes the next position's volume to first order, then takes up to
    ``iterations`` Newton steps on lambda alone, each on the true volume of the
    predicted position x + dt v + dt^2 M^-1 (F - gradV lambda), until
    |V - V0| <= tolerance V0. As in SHAKE, the slope dV/dlambda is taken at the
    current position, -dt^2 gradV.M^-1 gradV (eq. 12's denominator), not at the
    predicted one: each step then shrinks the error by about the step's
    displacement over the body's size, and needs the volume alone. Returns
    (lambda, gradV (s, d), the Newton steps taken).

    ``kick``: the share of dt^2 M^-1 F the next position takes: 1 inside the Verlet
    loop (``velocity`` is then the half-step velocity, and the next drift carries two
    half kicks), 1/2 at a body's very first evaluation, where ``velocity`` is the
    initial one and the first substep moves x + dt v + dt^2/2 a. Eq. 12 for that
    prediction is eq. 12 with dt sqrt(kick) and v / sqrt(kick).
    """
    dt, velocity = dt * math.sqrt(kick), velocity / math.sqrt(kick)
    gradient = volume_gradient(position, facets)
    phi = enclosed_volume(position, facets) - rest_volume
    multiplier = area_multiplier(phi, gradient, velocity, inverse_mass, force, dt)
    if iterations <= 0 or multiplier == 0.0:
        return multiplier, gradient, 0
    free = position + dt * velocity + dt ** 2 * inverse_mass[:, None] * force
    push = dt ** 2 * inverse_mass[:, None] * gradient
    slope = float(np.sum(push * gradient))
    limit = tolerance * abs(rest_volume)
    for step in range(iterations):
        residual = enclosed_volume(free - push * multiplier, facets) - rest_volume
        if abs(residual) <= limit:
            return multiplier, gradient, step
        multiplier += residual / slope
    return multiplier, gradient, iterations


# --------------------------------------------------------------------------
# Stability


def stiffest_frequency(mass, springs, stiffness, damping=None):
    """Upper bounds of the highest angular frequency and damping rate of the network.

    For every node ``sum_j k_ij (1/m_i + 1/sqrt(m_i m_j))``; its maximum bounds
    the largest eigenvalue of M^-1 K (with equal masses it is twice the textbook
    ``sum_j k_ij / m_i``: two equal masses on one spring oscillate at
    sqrt(2k/m), not sqrt(k/m), so the plain node sum is not a safe bound).
    The same sum over ``b_ij`` bounds the damping rate. Pinned nodes should be
    given their real mass: pinning only lowers the frequencies.
    """
    i, j = springs[:, 0], springs[:, 1]
    coupling = 1.0 / np.sqrt(mass[i] * mass[j])
    n = len(mass)

    def node_bound(weights):
        per_node = (np.bincount(i, weights=weights * (1.0 / mass[i] + coupling), minlength=n)
                    + np.bincount(j, weights=weights * (1.0 / mass[j] + coupling), minlength=n))
        return float(per_node.max()) if n else 0.0

    omega = math.sqrt(node_bound(stiffness))
    rate = node_bound(damping) if damping is not None else 0.0
    return omega, rate


def verlet_limit(omega, rate):
    """Largest stable step of the central-difference/Verlet scheme.

    ``2/omega (sqrt(1 + xi^2) - xi)`` with xi = rate/(2 omega) (the classic
    explicit-dynamics bound with damping); ``2/rate`` without stiffness.
    """
    if omega <= 0.0:
        return math.inf if rate <= 0.0 else 2.0 / rate
    xi = rate / (2.0 * omega)
    return 2.0 / omega * (math.sqrt(1.0 + xi * xi) - xi)


def substep_count(dt_outer, dt_sub):
    """Substeps of at most ``dt_sub`` that fill ``dt_outer`` (rounding noise ignored)."""
    return max(1, math.ceil(dt_outer / dt_sub * (1.0 - 1e-12)))


# --------------------------------------------------------------------------
# A body and the system of bodies


class Body:
    """One mass-spring body: arrays, the boundary facets and its windowed loads.

    The arrays are owned by the body and updated in place by :meth:`advance`.
    ``boundary``: a 2D node loop (counter-clockwise) or facets (m, d).
    Build bodies with :func:`parmps.solids.mass_spring.build.build_bodies`; this class checks
    nothing about the input.
    """

    def __init__(self, name, position, velocity, mass, springs, stiffness, damping,
                 boundary, volume_constraint=True, pinned=None, gravity=None,
                 loads=(), anchors=0, outline=None, axial_damping=False,
                 encloses_fluid=False):
        self.name = name
        self.position = np.array(np.atleast_2d(position), dtype=float)
        n, d = self.position.shape
        self.velocity = np.array(velocity, dtype=float).reshape(n, d)
        self.mass = np.broadcast_to(np.asarray(mass, dtype=float), (n,)).copy()
        self.springs = np.asarray(springs, dtype=np.int64).reshape(-1, 2)
        m = len(self.springs)
        self.stiffness = np.broadcast_to(np.asarray(stiffness, dtype=float), (m,)).copy()
        self.damping = np.broadcast_to(np.asarray(damping, dtype=float), (m,)).copy()
        # Dashpots along the springs (elastic materials) instead of on the whole
        # relative velocity, which would also damp a rigid rotation.
        self.axial_damping = bool(axial_damping)
        # A closed shell with fluid inside it (build.py sets it for type = "shell").
        self.encloses_fluid = bool(encloses_fluid)
        separation = self.position[self.springs[:, 0]] - self.position[self.springs[:, 1]]
        self.rest_length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
        self.boundary = np.asarray(boundary, dtype=np.int64)
        self._set_surface(boundary_facets(self.boundary) if self.boundary.size
                          else np.empty((0, d), np.int64))
        # The last ``anchors`` nodes are fixed points that close the boundary
        # (over a rigid wall): pinned, no springs, not part of the material.
        self.n_material = n - int(anchors)
        # The material's own outline (the boundary unless anchors close it).
        self.outline = self.boundary if outline is None else np.asarray(outline, np.int64)
        self.pinned = np.zeros(n, bool) if pinned is None else np.asarray(pinned, bool).copy()
        self.inverse_mass = np.where(self.pinned, 0.0, 1.0 / self.mass)
        self.velocity[self.pinned] = 0.0
        self.gravity = np.zeros(d) if gravity is None else np.asarray(gravity, dtype=float)
        self._set_loads(list(loads))
        self.rest_volume = self.volume() if len(self.facets) else 0.0
        self.volume_constraint = bool(volume_constraint) and self.rest_volume != 0.0
        self.fluid_force = np.zeros((n, d))
        # The fluid's viscous drag, rate (target - v) per unit mass, taken implicitly in
        # every substep's kicks (set_drag; 0 without a fluid).
        self.drag_rate = np.zeros(n)
        self.drag_target = np.zeros((n, d))
        self.acceleration = None  # set by the first force evaluation
        # Newton steps on the multiplier (see volume_multiplier); set by MassSpringModel.
        self.constraint_iterations = 0
        self.constraint_tolerance = 0.0
        self.multiplier = 0.0
        self.newton_steps = 0  # the most any substep of the last advance took
        # False: the substeps with loads or the constraint run acceleration_at, the numpy
        # statement the compiled body_substeps is tested against.
        self.compiled = True
        self._determinant_terms = determinant_terms(d)
        # A cell membrane's forces and constraints (membrane.attach), instead of the
        # springs' and the volume constraint's; the springs then only set the substep.
        self.membrane = None

    def _set_surface(self, facets):
        """The boundary facets, and the same facets over the boundary nodes alone: the
        constraint works on those."""
        self.facets = np.asarray(facets, dtype=np.int64)
        self.surface_nodes = np.unique(self.facets)
        self.surface_facets = np.searchsorted(self.surface_nodes, self.facets)

    def _set_loads(self, loads):
        """Loads as arrays: per-load force fields (L, n, d) and windows, so the
        external force at time t is one tensordot."""
        self.load_field = np.zeros((len(loads),) + self.position.shape)
        for k, (nodes, force, _, _, _) in enumerate(loads):
            self.load_field[k, nodes] = force
        self.load_start = np.array([load[2] for load in loads], dtype=float)
        self.load_end = np.array([load[3] for load in loads], dtype=float)
        self.load_ramp = np.array([load[4] for load in loads], dtype=float)

    # -- geometry and diagnostics --------------------------------------------
    @property
    def n_nodes(self):
        return len(self.position)

    @property
    def dimension(self):
        return self.position.shape[1]

    def volume(self):
        """The volume the boundary facets enclose (the area in 2D)."""
        return enclosed_volume(self.position[self.surface_nodes], self.surface_facets)

    def volume_error(self):
        """(V - V0)/V0 of the enclosed volume (0 for a body without a boundary)."""
        if self.rest_volume == 0.0:
            return 0.0
        return (self.volume() - self.rest_volume) / self.rest_volume

    def second_moment(self):
        """int (x - c)(x - c)^T dV (d, d) of the enclosed region about its centre (zeros for
        a body without a boundary): the shape a capsule's deformation is read from."""
        if self.rest_volume == 0.0:
            d = self.dimension
            return np.zeros((d, d))
        return enclosed_moments(self.position[self.surface_nodes], self.surface_facets)[2]

    def centroid(self):
        """Centre of mass of the (material) nodes."""
        m = self.n_material
        return self.mass[:m] @ self.position[:m] / self.mass[:m].sum()

    def set_drag(self, rate, target):
        """The drag ``m_i rate_i (target_i - v_i)`` [N] of the next advance: ``rate`` (n,)
        [1/s], ``target`` (n, d) [m/s] (kernels.drag_kick); a pinned node feels none."""
        self.drag_rate[:] = np.where(self.inverse_mass > 0.0, rate, 0.0)
        self.drag_target[:] = target

    def total_fluid_force(self):
        return self.fluid_force.sum(axis=0)

    def momentum(self):
        return self.mass @ self.velocity

    def energy(self):
        """Kinetic and elastic energy (external work is not included)."""
        if self.membrane is not None:
            # Its springs are only the stand-in the substep is chosen from.
            from parmps.solids.mass_spring.membrane import membrane_energy
            return (kinetic_energy(self.velocity, self.mass),
                    membrane_energy(self.position, self.membrane))
        return (kinetic_energy(self.velocity, self.mass),
                spring_energy(self.position, self.springs, self.rest_length, self.stiffness))

    def potential_energy(self):
        """``-sum m g.x`` over the nodes that move (pinned nodes hold no energy)."""
        free = ~self.pinned
        return -float(self.mass[free] @ (self.position[free] @ self.gravity))

    def stability_limit(self):
        """The Verlet step limit of this body [s], from its highest frequency at rest.

        The network's own highest frequency (statics.highest_frequency), not the per-node
        bound of :func:`stiffest_frequency`: in a cubic lattice that bound is twice the
        true frequency, and the substeps it asked for cost twice what is needed. The
        damping rate keeps its node bound.
        """
        _, rate = stiffest_frequency(self.mass, self.springs, self.stiffness, self.damping)
        if self.membrane is not None:
            # A cell membrane's own stiffness, not its springs' stand-in.
            rate += self.membrane.drag
            return verlet_limit(self.membrane.highest_frequency(self.position, self.mass), rate)
        omega = highest_frequency(stiffness_matrix(self.position, self.springs, self.stiffness),
                                  self.mass)
        return verlet_limit(omega, rate)

    # -- dynamics --------------------------------------------------------------
    def external_force(self, time):
        force = self.mass[:, None] * self.gravity + self.fluid_force
        if len(self.load_field):
            factor = load_factor(time, self.load_start, self.load_end, self.load_ramp)
            force = force + np.tensordot(factor, self.load_field, axes=1)
        return force

    def acceleration_at(self, time, velocity, dt, kick=1.0):
        """M^-1 (F - gradPhi lambda) at the current positions, for a step of length dt
        (``kick``: see :func:`volume_multiplier`)."""
        force = self.external_force(time)
        network_forces(self.position, velocity, self.springs, self.rest_length, self.stiffness,
                       self.damping, self.axial_damping, force)
        if self.volume_constraint:
            nodes = self.surface_nodes
            seen_velocity, seen_inverse_mass = velocity, self.inverse_mass
            if self.drag_rate.any():
                # Where the drag's kicks will put the nodes (kernels.drag_prediction): two
                # half kicks inside the loop, one from a step's first evaluation.
                seen_velocity, seen_inverse_mass = np.empty_like(velocity), np.empty(len(velocity))
                drag_prediction(velocity, self.inverse_mass, self.drag_rate, self.drag_target,
                                dt, 2 if kick == 1.0 else 1, seen_velocity, seen_inverse_mass)
                kick = 1.0
            self.multiplier, gradient, steps = volume_multiplier(
                self.position[nodes], self.surface_facets, self.rest_volume,
                seen_velocity[nodes], seen_inverse_mass[nodes], force[nodes], dt,
                self.constraint_tolerance, self.constraint_iterations, kick)
            self.newton_steps = max(self.newton_steps, steps)
            # surface_nodes are unique, so plain fancy-index subtraction is safe.
            force[nodes] -= gradient * self.multiplier
        return force * self.inverse_mass[:, None]

    def advance(self, time, dt_outer, dt_sub):
        """Run n = ceil(dt_outer/dt_sub) Verlet substeps from ``time``; return n.

        With a drag set (:meth:`set_drag`), ``fluid_force`` is the held part on entry and the
        held part plus the step's mean drag on return: the drag at the nodes' mean velocity
        over the step, their displacement over dt_outer."""
        n_sub = substep_count(dt_outer, dt_sub)
        h = dt_outer / n_sub
        start = None
        if self.drag_rate.any():
            start = self.position.copy()
            # The step's first kick feels a new drag: the first evaluation's multiplier is
            # taken again for it (the last substep's predicted the old drag's position).
            self.acceleration = None
        if self.membrane is not None:
            # A stretched membrane takes more substeps than n_sub.
            n_sub = self.membrane.advance(self, time, h, n_sub)
        else:
            self._substeps(time, h, n_sub)
        if start is not None:
            mean_velocity = (self.position - start) / dt_outer
            self.fluid_force += (self.mass * self.drag_rate)[:, None] * (self.drag_target
                                                                         - mean_velocity)
        return n_sub

    def _substeps(self, time, h, n_sub):
        if self.acceleration is None:
            # The first substep drifts by h v + h^2/2 a from the initial velocity.
            self.acceleration = self.acceleration_at(time, self.velocity, h, kick=0.5)
        position, velocity = self.position, self.velocity
        rate, target = self.drag_rate, self.drag_target
        self.newton_steps = 0
        # Gravity and the fluid force are held over the step.
        held = self.mass[:, None] * self.gravity + self.fluid_force
        if not self.volume_constraint and not len(self.load_field):
            # Nothing in the force but the springs changes within the step: the whole
            # substep loop runs compiled (a stiff body takes ~1000 substeps a step).
            held_force_substeps(position, velocity, self.acceleration, self.inverse_mass,
                                self.springs, self.rest_length, self.stiffness, self.damping,
                                self.axial_damping, held, h, n_sub, rate, target)
        elif self.compiled:
            # Loads and the constraint too: the same physics as acceleration_at.
            self.multiplier, self.newton_steps = body_substeps(
                position, velocity, self.acceleration, self.inverse_mass, self.springs,
                self.rest_length, self.stiffness, self.damping, self.axial_damping, held,
                self.load_field, self.load_start, self.load_end, self.load_ramp, time, h,
                n_sub, self.volume_constraint, self.surface_nodes, self.surface_facets,
                self.rest_volume, self.constraint_tolerance, self.constraint_iterations,
                *self._determinant_terms, rate, target)
        else:
            for step in range(n_sub):
                drag_kick(velocity, self.acceleration, rate, target, 0.5 * h)
                position += h * velocity
                self.acceleration = self.acceleration_at(time + (step + 1) * h, velocity, h)
                drag_kick(velocity, self.acceleration, rate, target, 0.5 * h)
