"""Mass-spring solids that keep their area (docs/design.md §1.5).

Physics on plain numpy arrays: spring, damping and external forces, the area
of a body's boundary polygon and its gradient, the Lagrange multiplier that
holds that area, the Verlet stability limit and the substep loop. Nothing here
imports PETSc or any fluid machinery, so a solid-only case stays light.

A body is a set of nodes (positions, velocities, masses) joined by springs
(node index pairs with rest length, stiffness and damping). Pinned nodes have
zero inverse mass: no force moves them and the constraint treats them as rigid,
which is also how a boundary polygon closes over wall nodes.

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

so the area error stays at the level of the quadratic term: the area swept by
the step's displacement, about dt^2 |v|^2 (dt^2 Omega^2 V for a body rotating
at Omega). It does not accumulate: the next multiplier removes it. With
``[solid] constraint_prediction = "quadratic"`` that term is predicted too.
"""

import logging
import math

import numpy as np

from parmps.errors import CaseError
from parmps.solids.mass_spring.kernels import held_force_substeps, network_forces

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------
# Forces


def _scatter(n_nodes, springs, pair_force):
    """Add +pair_force to node i and -pair_force to node j of every spring."""
    i, j = springs[:, 0], springs[:, 1]
    force = np.empty((n_nodes, 2))
    for axis in range(2):
        force[:, axis] = (np.bincount(i, weights=pair_force[:, axis], minlength=n_nodes)
                          - np.bincount(j, weights=pair_force[:, axis], minlength=n_nodes))
    return force


def spring_forces(position, springs, rest_length, stiffness):
    """Hooke forces ``-k (|l| - l0) l/|l|`` on every node, l = x_i - x_j; shape (n, 2)."""
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
    # A collapsed spring has no direction; it exerts no force rather than NaN.
    scale = np.divide(stiffness * (length - rest_length), length,
                      out=np.zeros_like(length), where=length > 0)
    return _scatter(len(position), springs, -scale[:, None] * separation)


def damping_forces(velocity, springs, damping):
    """Damping ``-b (v_i - v_j)`` on every node; shape (n, 2)."""
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
# Area of the boundary polygon and its constraint


def polygon_area(position, loop):
    """Signed area ``1/2 sum (x_i y_{i+1} - x_{i+1} y_i)``: positive counter-clockwise."""
    p = position[loop]
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def area_gradient(position, loop):
    """dV/dx_i = (y_{i+1} - y_{i-1})/2, dV/dy_i = (x_{i-1} - x_{i+1})/2 for the loop nodes."""
    p = position[loop]
    after = np.roll(p, -1, axis=0)
    before = np.roll(p, 1, axis=0)
    return 0.5 * np.column_stack([after[:, 1] - before[:, 1], before[:, 0] - after[:, 0]])


def area_multiplier(phi, gradient, velocity, inverse_mass, force, dt):
    """The Lagrange multiplier of docs/design.md §1.5 (seed eq. 12 with Phi_t = 0).

    ``gradient``, ``velocity``, ``force`` are (m, 2) on the loop nodes and
    ``inverse_mass`` (m,) (0 for pinned nodes). The constraint force is
    ``-gradient * lambda``. Returns 0 when no loop node can move.
    """
    weighted = gradient * inverse_mass[:, None]
    denominator = float(np.sum(weighted * gradient))
    if denominator <= 0.0:
        return 0.0
    numerator = (phi / dt ** 2 + float(np.sum(gradient * velocity)) / dt
                 + float(np.sum(weighted * force)))
    return numerator / denominator


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
    """One mass-spring body: arrays, the boundary loop and its windowed loads.

    The arrays are owned by the body and updated in place by :meth:`advance`.
    Build bodies with :func:`parmps.solids.mass_spring.build.build_bodies`; this class checks
    nothing about the input.
    """

    def __init__(self, name, position, velocity, mass, springs, stiffness, damping,
                 boundary, volume_constraint=True, pinned=None, gravity=(0.0, 0.0),
                 loads=(), anchors=0, outline=None, axial_damping=False):
        self.name = name
        self.position = np.array(position, dtype=float).reshape(-1, 2)
        self.velocity = np.array(velocity, dtype=float).reshape(-1, 2)
        n = len(self.position)
        self.mass = np.broadcast_to(np.asarray(mass, dtype=float), (n,)).copy()
        self.springs = np.asarray(springs, dtype=np.int64).reshape(-1, 2)
        m = len(self.springs)
        self.stiffness = np.broadcast_to(np.asarray(stiffness, dtype=float), (m,)).copy()
        self.damping = np.broadcast_to(np.asarray(damping, dtype=float), (m,)).copy()
        # Dashpots along the springs (elastic materials) instead of on the whole
        # relative velocity, which would also damp a rigid rotation.
        self.axial_damping = bool(axial_damping)
        separation = self.position[self.springs[:, 0]] - self.position[self.springs[:, 1]]
        self.rest_length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
        self.boundary = np.asarray(boundary, dtype=np.int64)
        # The last ``anchors`` nodes are fixed points that close the boundary
        # polygon (over a rigid wall): pinned, no springs, not part of the material.
        self.n_material = n - int(anchors)
        # The material's own outline (the boundary loop unless anchors close it).
        self.outline = self.boundary if outline is None else np.asarray(outline, np.int64)
        self.volume_constraint = bool(volume_constraint) and len(self.boundary) >= 3
        self.pinned = np.zeros(n, bool) if pinned is None else np.asarray(pinned, bool).copy()
        self.inverse_mass = np.where(self.pinned, 0.0, 1.0 / self.mass)
        self.velocity[self.pinned] = 0.0
        self.gravity = np.asarray(gravity, dtype=float)
        # Loads as arrays: per-load force fields (L, n, 2) and windows, so the
        # external force at time t is one tensordot.
        loads = list(loads)
        self.load_field = np.zeros((len(loads), n, 2))
        for k, (nodes, force, _, _, _) in enumerate(loads):
            self.load_field[k, nodes] = force
        self.load_start = np.array([load[2] for load in loads], dtype=float)
        self.load_end = np.array([load[3] for load in loads], dtype=float)
        self.load_ramp = np.array([load[4] for load in loads], dtype=float)
        self.rest_volume = self.volume() if len(self.boundary) >= 3 else 0.0
        self.fluid_force = np.zeros((n, 2))
        self.acceleration = None  # set by the first force evaluation
        self.quadratic_prediction = False  # True: see MassSpringModel's constraint_prediction
        self.multiplier = 0.0

    # -- geometry and diagnostics --------------------------------------------
    @property
    def n_nodes(self):
        return len(self.position)

    def volume(self):
        return polygon_area(self.position, self.boundary)

    def volume_error(self):
        """(V - V0)/V0 of the boundary polygon (0 for a body without one)."""
        if self.rest_volume == 0.0:
            return 0.0
        return (self.volume() - self.rest_volume) / self.rest_volume

    def centroid(self):
        """Centre of mass of the (material) nodes."""
        m = self.n_material
        return self.mass[:m] @ self.position[:m] / self.mass[:m].sum()

    def total_fluid_force(self):
        return self.fluid_force.sum(axis=0)

    def momentum(self):
        return self.mass @ self.velocity

    def energy(self):
        """Kinetic and elastic energy (external work is not included)."""
        return (kinetic_energy(self.velocity, self.mass),
                spring_energy(self.position, self.springs, self.rest_length, self.stiffness))

    def stability_limit(self):
        """The Verlet step limit of this body [s]."""
        omega, rate = stiffest_frequency(self.mass, self.springs, self.stiffness, self.damping)
        return verlet_limit(omega, rate)

    # -- dynamics --------------------------------------------------------------
    def external_force(self, time):
        force = self.mass[:, None] * self.gravity + self.fluid_force
        if len(self.load_field):
            factor = load_factor(time, self.load_start, self.load_end, self.load_ramp)
            force = force + np.tensordot(factor, self.load_field, axes=1)
        return force

    def acceleration_at(self, time, velocity, dt):
        """M^-1 (F - gradPhi lambda) at the current positions, for a step of length dt."""
        force = self.external_force(time)
        network_forces(self.position, velocity, self.springs, self.rest_length, self.stiffness,
                       self.damping, self.axial_damping, force)
        if self.volume_constraint:
            loop = self.boundary
            gradient = area_gradient(self.position, loop)
            phi = self.volume() - self.rest_volume
            inverse_mass = self.inverse_mass[loop]
            self.multiplier = area_multiplier(phi, gradient, velocity[loop], inverse_mass,
                                              force[loop], dt)
            if self.quadratic_prediction:
                # V is quadratic in the positions, so V(x + d) = V(x) + gradV.d + V(d)
                # exactly. The linear prediction misses V(d), about dt^2 Omega^2 V for
                # a body spinning at Omega; one more pass with it added removes that.
                step = dt * velocity[loop] + dt ** 2 * inverse_mass[:, None] * (
                    force[loop] - gradient * self.multiplier)
                swept = polygon_area(step, np.arange(len(loop)))
                self.multiplier = area_multiplier(phi + swept, gradient, velocity[loop],
                                                  inverse_mass, force[loop], dt)
            # Loop nodes may repeat only if the loop is invalid (refused on
            # input), so plain fancy-index subtraction is safe here.
            force[loop] -= gradient * self.multiplier
        return force * self.inverse_mass[:, None]

    def advance(self, time, dt_outer, dt_sub):
        """Run n = ceil(dt_outer/dt_sub) Verlet substeps from ``time``; return n."""
        n_sub = substep_count(dt_outer, dt_sub)
        h = dt_outer / n_sub
        if self.acceleration is None:
            self.acceleration = self.acceleration_at(time, self.velocity, h)
        position, velocity = self.position, self.velocity
        if not self.volume_constraint and not len(self.load_field):
            # Nothing in the force but the springs changes within the step: the whole
            # substep loop runs compiled (a stiff body takes ~1000 substeps a step).
            external = self.mass[:, None] * self.gravity + self.fluid_force
            held_force_substeps(position, velocity, self.acceleration, self.inverse_mass,
                                self.springs, self.rest_length, self.stiffness, self.damping,
                                self.axial_damping, external, h, n_sub)
            return n_sub
        for step in range(n_sub):
            velocity += 0.5 * h * self.acceleration
            position += h * velocity
            self.acceleration = self.acceleration_at(time + (step + 1) * h, velocity, h)
            velocity += 0.5 * h * self.acceleration
        return n_sub
