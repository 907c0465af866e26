"""Cell membranes: a shell whose edges are worm-like chains, with dihedral bending and
its total area and volume kept (issue 66; docs/shells.md, Cell membranes).

A ``type = "shell"`` body with ``membrane = "wlc"`` replaces the shell's linear edge and
bending springs by the spring-network cell model of Fedosov, Caswell & Karniadakis (2010):

- every edge a worm-like chain with a repulsive power term (WLC-POW), tension
  kBT/(4p) (1/(1-x)^2 - 1 + 4x) - kp/l^m with x = l/l_max, l_max = l0 * maximum_extension,
  and kp per edge so that it is at rest at its initial length l0 (a stress-free mesh);
  kBT/p is set from ``shear_modulus`` by the linearised modulus of an equilateral net,
  mu0 = sqrt(3)/4 dT/dl(l0) (:func:`wlc_parameters`);
- bending U = kb sum (1 - cos(theta - theta0)) over the dihedral angles of the edges,
  theta0 the initial ones, kb = 2 kappa / sqrt(3) from ``bending_modulus`` kappa;
- the total area (``area_constraint``) and the volume (``volume_constraint``) kept by two
  Lagrange multipliers, a 2x2 system per substep (membrane_kernels.constrain);
- a drag -drag_rate m v on every node: the damping that brings a load to rest without
  changing where it rests.

Arrays in, arrays out; the loops over edges, dihedrals and triangles are compiled
(:mod:`parmps.solids.mass_spring.membrane_kernels`).
"""

import logging
import math

import numpy as np

from parmps.config import Key
from parmps.errors import CaseError, RunFailure
from parmps.solids.mass_spring import membrane_kernels as kernels
from parmps.solids.mass_spring.kernels import drag_prediction

log = logging.getLogger(__name__)

# An edge may reach this share of its maximum length: the chain's tension grows as
# 1/(1-x)^2 and a substep chosen at rest cannot follow it much further.
EXTENSION_LIMIT = 0.95

KEYS = {
    "membrane": Key("str", "springs", choices=("springs", "wlc"),
                    doc="shell: \"springs\": linear edge (stiffness) and bending springs; "
                        "\"wlc\": worm-like-chain edges, dihedral bending and area and volume "
                        "kept (docs/shells.md, Cell membranes)"),
    "shear_modulus": Key("float", 0.0, ge=0.0,
                         doc="membrane wlc: linear shear modulus mu0 [N/m] the edges give"),
    "maximum_extension": Key("float", 2.2, gt=1.0,
                             doc="membrane wlc: an edge's maximum length over its rest "
                                 "length, l_max/l0"),
    "power_exponent": Key("float", 2.0, gt=0.0,
                          doc="membrane wlc: m of the repulsive term kp/l^m"),
    "bending_modulus": Key("float", 0.0, ge=0.0,
                           doc="membrane wlc: bending modulus kappa [J]; dihedral springs "
                               "kb = 2 kappa/sqrt(3)"),
    "area_constraint": Key("bool", True, doc="membrane wlc: keep the total area"),
    "local_area_modulus": Key("float", 0.0, ge=0.0,
                              doc="membrane wlc: K_d [N/m] of each triangle's area energy "
                                  "K_d (A - A0)^2 / (2 A0), which keeps the mesh from "
                                  "crumpling where the total area alone allows it"),
    "drag_rate": Key("float", 0.0, ge=0.0,
                     doc="membrane wlc: drag -drag_rate m v on every node [1/s]"),
}

UNSET = {"shear_modulus": 0.0, "maximum_extension": 2.2, "power_exponent": 2.0,
         "bending_modulus": 0.0, "area_constraint": True, "drag_rate": 0.0,
         "local_area_modulus": 0.0}


def check_keys(label, spec):
    """Refuse membrane keys where they do not apply, in one line naming the key."""
    wlc = spec.get("membrane", "springs") == "wlc"
    if spec.get("membrane", "springs") != "springs" and spec["type"] != "shell":
        raise CaseError(f"{label}.membrane applies to shell bodies only (type = \"shell\")")
    for key, unset in UNSET.items():
        if not wlc and spec.get(key, unset) != unset:
            raise CaseError(f"{label}.{key} applies to membrane = \"wlc\" only")
    if not wlc:
        return
    for key in ("stiffness", "bending_stiffness"):
        if spec.get(key) not in (None, 0.0):
            raise CaseError(f"{label}.{key} is a linear spring's; membrane = \"wlc\" takes "
                            f"shear_modulus and bending_modulus instead")
    if not spec["shear_modulus"] > 0:
        raise CaseError(f"{label}.shear_modulus must be > 0 [N/m] with membrane = \"wlc\"")


# --------------------------------------------------------------------------
# The laws, on arrays


def wlc_pow_energy(length, max_length, kbt_over_p, kp, exponent):
    """Energy of WLC-POW springs: kBT l_max/(4p) (3x^2 - 2x^3)/(1-x) + kp/((m-1) l^(m-1))
    (m = 1: -kp ln l); arrays."""
    x = length / max_length
    chain = 0.25 * kbt_over_p * max_length * (3.0 * x ** 2 - 2.0 * x ** 3) / (1.0 - x)
    if exponent == 1.0:
        return chain - kp * np.log(length)
    return chain + kp / ((exponent - 1.0) * length ** (exponent - 1.0))


def wlc_pow_tension(length, max_length, kbt_over_p, kp, exponent):
    """dU/dl of WLC-POW springs (> 0 pulls the ends together); arrays."""
    x = length / max_length
    return (0.25 * kbt_over_p * (1.0 / (1.0 - x) ** 2 - 1.0 + 4.0 * x)
            - kp / length ** exponent)


def wlc_modulus_factor(extension_ratio, exponent):
    """C of mu0 = sqrt(3)/4 (kBT/p) C / l0 for springs at rest at x0 = l0/l_max: l0 dT/dl
    over kBT/p, the chain's x0/(2(1-x0)^3) + x0 plus the power term's m T_chain(x0)."""
    x = extension_ratio
    at_rest = 0.25 * (1.0 / (1.0 - x) ** 2 - 1.0 + 4.0 * x)
    return x / (2.0 * (1.0 - x) ** 3) + x + exponent * at_rest


def wlc_parameters(rest_length, shear_modulus, maximum_extension, exponent):
    """(kBT/p, l_max (E,), kp (E,)) of edges at rest at ``rest_length`` (E,) whose net has
    the linear shear modulus ``shear_modulus`` at the mean rest length."""
    x0 = 1.0 / maximum_extension
    mean = float(np.mean(rest_length))
    kbt_over_p = 4.0 * shear_modulus * mean / (math.sqrt(3.0) * wlc_modulus_factor(x0, exponent))
    at_rest = 0.25 * kbt_over_p * (1.0 / (1.0 - x0) ** 2 - 1.0 + 4.0 * x0)
    return kbt_over_p, rest_length * maximum_extension, at_rest * rest_length ** exponent


def wlc_pow_stiffness(length, max_length, kbt_over_p, kp, exponent):
    """d^2U/dl^2 of WLC-POW springs: the stiffness of each at its length; arrays."""
    x = length / max_length
    return (0.25 * kbt_over_p * (2.0 / (1.0 - x) ** 3 + 4.0) / max_length
            + exponent * kp / length ** (exponent + 1.0))


def linear_stiffness(rest_length, kbt_over_p, extension_ratio, exponent):
    """dT/dl of each edge at rest: kBT/p C / l0 (the stiffness of the linearised net)."""
    return kbt_over_p * wlc_modulus_factor(extension_ratio, exponent) / rest_length


def dihedral_quads(triangles):
    """(a, b, c, d) for every edge a-b: (a, b, c) and (b, a, d) its two outward triangles."""
    triangles = np.asarray(triangles, dtype=np.int64)
    start = triangles.ravel()
    end = triangles[:, [1, 2, 0]].ravel()
    opposite = triangles[:, [2, 0, 1]].ravel()
    n = int(triangles.max()) + 1
    key = start * n + end
    order = np.argsort(key)
    own = np.flatnonzero(start < end)
    twin = order[np.searchsorted(key, end[own] * n + start[own], sorter=order)]
    if not np.array_equal(key[twin], end[own] * n + start[own]):
        raise ValueError("dihedral_quads needs a closed, consistently oriented mesh")
    return np.column_stack([start[own], end[own], opposite[own], opposite[twin]])


def dihedral_angles(position, quads):
    """Signed angle between the outward normals of (a, b, c) and (b, a, d) of every quad
    (a, b, c, d): 0 where the surface is flat; arrays."""
    a, b, c, d = (position[quads[:, k]] for k in range(4))
    e = b - a
    n1, n2 = np.cross(e, c - a), np.cross(a - b, d - b)
    sine = np.einsum("ij,ij->i", np.cross(n1, n2), e) / np.linalg.norm(e, axis=1)
    return np.arctan2(sine, np.einsum("ij,ij->i", n1, n2))


def bending_energy(position, quads, rest_angle, kb):
    """kb sum (1 - cos(theta - theta0)) over the dihedrals."""
    return float(kb * np.sum(1.0 - np.cos(dihedral_angles(position, quads) - rest_angle)))


def membrane_energy(position, membrane):
    """Elastic energy of the membrane: its edges and its dihedrals."""
    edges = membrane.edges
    length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
    chain = wlc_pow_energy(length, membrane.max_length, membrane.kbt_over_p, membrane.kp,
                           membrane.exponent)
    a, b, c = (position[membrane.triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    local = 0.5 * membrane.local_modulus * np.sum((area - membrane.rest_area) ** 2
                                                  / membrane.rest_area)
    return (float(chain.sum()) + float(local)
            + bending_energy(position, membrane.quads, membrane.rest_angle, membrane.kb))


def triangle_area_total(position, triangles):
    a, b, c = (position[triangles[:, k]] for k in range(3))
    return 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


# --------------------------------------------------------------------------
# A membrane body


class Membrane:
    """The membrane forces and constraints of one shell body (arrays; see the module)."""

    def __init__(self, position, triangles, shear_modulus, maximum_extension, exponent,
                 bending_modulus, area_constraint, volume_constraint, drag_rate, damping,
                 local_area_modulus=0.0):
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.quads = dihedral_quads(self.triangles)
        self.edges = np.ascontiguousarray(self.quads[:, :2])
        self.rest_length = np.linalg.norm(position[self.edges[:, 0]]
                                          - position[self.edges[:, 1]], axis=1)
        self.exponent = float(exponent)
        self.kbt_over_p, self.max_length, self.kp = wlc_parameters(
            self.rest_length, shear_modulus, maximum_extension, self.exponent)
        self.stiffness = linear_stiffness(self.rest_length, self.kbt_over_p,
                                          1.0 / maximum_extension, self.exponent)
        self.kb = 2.0 * bending_modulus / math.sqrt(3.0)
        self.rest_angle = dihedral_angles(position, self.quads)
        self.rest_cosine, self.rest_sine = np.cos(self.rest_angle), np.sin(self.rest_angle)
        self.rest = np.array([triangle_area_total(position, self.triangles),
                              _volume(position, self.triangles)])
        self.active = np.array([bool(area_constraint), bool(volume_constraint)])
        self.drag = float(drag_rate)
        self.local_modulus = float(local_area_modulus)
        a, b, c = (position[self.triangles[:, k]] for k in range(3))
        self.rest_area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        self.damping = float(damping)
        self.multiplier = np.zeros(2)
        self.extension = 0.0  # the largest l/l_max of the last advance
        self.worst_edge = 0   # and its edge

    def stability_springs(self):
        """(pairs, stiffness) of a linear network as stiff as the membrane at rest: its
        edges, and across each edge a spring of the dihedral's kb/h^2 (h the mean
        height of its two triangles over the edge), for the body's eigen solve."""
        across = self.kb / self._heights ** 2 if self.kb else np.zeros(len(self.quads))
        pairs = np.concatenate([self.edges, self.quads[:, 2:]])
        # A triangle's area term is about as stiff as K_d on each of its edges.
        return pairs, np.concatenate([self.stiffness + 2.0 * self.local_modulus, across])

    def set_heights(self, position):
        a, b, c, d = (position[self.quads[:, k]] for k in range(4))
        e = np.linalg.norm(b - a, axis=1)
        h1 = np.linalg.norm(np.cross(b - a, c - a), axis=1) / e
        h2 = np.linalg.norm(np.cross(a - b, d - b), axis=1) / e
        self._heights = 0.5 * (h1 + h2)

    def force(self, body, time, velocity):
        """Every force on the nodes but the constraints' at ``time``; (n, 3)."""
        force = np.empty_like(body.position)
        held = body.mass[:, None] * body.gravity + body.fluid_force
        self.extension, self.worst_edge = kernels.membrane_force(
            body.position, velocity, body.mass, held, body.load_field, body.load_start,
            body.load_end, body.load_ramp, time, self.edges, self.max_length, self.kp,
            self.kbt_over_p, self.exponent, self.damping, EXTENSION_LIMIT, self.quads,
            self.rest_cosine, self.rest_sine, self.kb, self.triangles, self.rest_area,
            self.local_modulus, self.drag, force)
        return force

    def first_acceleration(self, body, time, h):
        """The acceleration of the very first substep (kick 1/2: body.volume_multiplier)."""
        force = self.force(body, time, body.velocity)
        gradients = np.empty((2,) + body.position.shape)
        # x + h v + h^2/2 a, or where one half kick with the fluid's drag puts the nodes.
        velocity, inverse_mass = np.empty_like(body.velocity), np.empty(len(body.velocity))
        drag_prediction(body.velocity, body.inverse_mass, body.drag_rate, body.drag_target, h,
                        1, velocity, inverse_mass)
        self.multiplier, _ = kernels.constrain(
            body.position, velocity, inverse_mass, force, self.triangles, self.rest,
            self.active, h, body.constraint_tolerance, body.constraint_iterations, gradients)
        return force * body.inverse_mass[:, None]

    def stiffening(self, position):
        """How much stiffer than at rest the stiffest edge is now: the chain stiffens as
        1/(1-x)^3, and a substep chosen at rest would not be stable on it."""
        edges = self.edges
        length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
        length = np.minimum(length, EXTENSION_LIMIT * self.max_length)
        now = wlc_pow_stiffness(length, self.max_length, self.kbt_over_p, self.kp,
                                self.exponent)
        return max(1.0, float(np.max(now / self.stiffness)))

    def advance(self, body, time, h, count):
        """Substeps of ``body`` over ``count`` h (body.Body.advance), each shorter by the
        square root of the edges' :meth:`stiffening`; returns how many."""
        factor = math.sqrt(self.stiffening(body.position))
        if factor > 1.0 + 1e-9:
            span = h * count
            count = math.ceil(count * factor)
            h = span / count
        if body.acceleration is None:
            body.acceleration = self.first_acceleration(body, time, h)
        held = body.mass[:, None] * body.gravity + body.fluid_force
        (self.multiplier, body.newton_steps, self.extension,
         self.worst_edge) = kernels.membrane_substeps(
            body.position, body.velocity, body.acceleration, body.mass, body.inverse_mass,
            held, body.load_field, body.load_start, body.load_end, body.load_ramp, time, h,
            count, self.edges, self.max_length, self.kp, self.kbt_over_p, self.exponent,
            self.damping, EXTENSION_LIMIT, self.quads, self.rest_cosine, self.rest_sine,
            self.kb, self.rest_area, self.local_modulus, self.drag, self.triangles, self.rest,
            self.active, body.constraint_tolerance, body.constraint_iterations,
            body.drag_rate, body.drag_target)
        body.multiplier = float(self.multiplier[1])
        return count

    def area_error(self, position):
        """(A - A0)/A0 of the membrane's total area."""
        return triangle_area_total(position, self.triangles) / self.rest[0] - 1.0

    def check_extension(self, name):
        """Stop a membrane whose chains reached their limit in the last advance."""
        if self.extension >= EXTENSION_LIMIT:
            node = int(self.edges[self.worst_edge, 0])
            raise RunFailure(
                f"body '{name}': the edge at node {node} reached {self.extension:.3f} of "
                f"its maximum length (limit {EXTENSION_LIMIT}): the load is too large for "
                f"the membrane, or raise maximum_extension")

    def check(self, name, position):
        """Stop a membrane that tore or folded over, naming the body, a node and the
        setting to change."""
        self.check_extension(name)
        # The turn from rest, wrapped to [0, pi].
        turn = np.abs(np.angle(np.exp(1j * (dihedral_angles(position, self.quads)
                                             - self.rest_angle))))
        if turn.max() > FOLD_LIMIT:
            worst = int(np.argmax(turn))
            raise RunFailure(
                f"body '{name}': its membrane folded over at node {self.quads[worst, 0]} "
                f"(two triangles turned {math.degrees(turn[worst]):.0f} degrees from "
                f"rest): raise bending_modulus, refine the shell, or shorten "
                f"the substep (solid.safety)")


# A triangle turned this far against its neighbour [rad] has inverted: the surface folds.
FOLD_LIMIT = math.radians(120.0)


def _volume(position, triangles):
    gradients = np.empty((2, 0, 3))
    return kernels.area_volume(position, triangles, gradients, False)[1]


# The cosine between dA/dx and dV/dx above which the two constraints are one: on a
# sphere (the most volume for its area) they are parallel and nothing may deform.
PARALLEL_CONSTRAINTS = 0.999


def _check_constraints_independent(label, position, triangles):
    gradients = np.empty((2,) + position.shape)
    kernels.area_volume(position, triangles, gradients, True)
    area, volume = gradients[0].ravel(), gradients[1].ravel()
    cosine = float(area @ volume / (np.linalg.norm(area) * np.linalg.norm(volume)))
    if cosine > PARALLEL_CONSTRAINTS:
        raise CaseError(f"{label}: its area and volume constraints are one (the shape is "
                        f"nearly a sphere, which no deformation keeps both on): set "
                        f"area_constraint = false or volume_constraint = false")


def attach(body, label, spec):
    """Give a shell ``body`` (built with placeholder springs) the membrane ``spec`` asks
    for: its forces, constraints and the linear network its substep is chosen from."""
    membrane = Membrane(body.position, body.facets, spec["shear_modulus"],
                        spec["maximum_extension"], spec["power_exponent"],
                        spec["bending_modulus"], spec["area_constraint"],
                        spec["volume_constraint"], spec["drag_rate"], spec["damping"],
                        spec["local_area_modulus"])
    membrane.set_heights(body.position)
    if membrane.active.all():
        _check_constraints_independent(label, body.position, membrane.triangles)
    pairs, stiffness = membrane.stability_springs()
    body.springs = pairs
    body.stiffness = stiffness
    body.damping = np.zeros(len(pairs))
    separation = body.position[pairs[:, 0]] - body.position[pairs[:, 1]]
    body.rest_length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
    body.membrane = membrane
    mean = float(membrane.rest_length.mean())
    log.info("%s: membrane wlc, %d nodes, %d edges (mean %.4g m), mu0 %.4g N/m, kBT/p %.4g N, "
             "kb %.4g J, area %.6g m^2, volume %.6g m^3", label, body.n_nodes,
             len(membrane.edges), mean, spec["shear_modulus"], membrane.kbt_over_p,
             membrane.kb, membrane.rest[0], membrane.rest[1])
    return body
