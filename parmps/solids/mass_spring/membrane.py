"""Cell membranes: a shell whose edges are worm-like chains, with dihedral bending and
its total area and volume kept (issue 66; docs/shells.md, Cell membranes).

A ``type = "shell"`` body with ``membrane = "wlc"`` replaces the shell's linear edge and
bending springs by the spring-network cell model of Fedosov, Caswell & Karniadakis (2010):

- every edge a worm-like chain with a repulsive power term (WLC-POW), tension
  kBT/(4p) (1/(1-x)^2 - 1 + 4x) - kp/l^m with x = l/l_max, l_max = l0 * maximum_extension,
  and kp per edge so that it is at rest at its initial length l0 (a stress-free mesh);
  kBT/p is set from ``shear_modulus`` by the linearised modulus of the net, sqrt(3)/4
  dT/dl(l0) on an equilateral one, sum_e dT/dl l0^2 / (8 A) on any (:func:`wlc_parameters`);
  or, with ``membrane = "skalak"`` or ``"neo_hookean"``, a hyperelastic energy A0 W(C) on
  every triangle instead (membrane_kernels.triangle_forces);
- bending U = kb sum (1 - cos(theta - theta0)) over the dihedral angles of the edges,
  theta0 the initial ones, kb = 2 kappa / sqrt(3) from ``bending_modulus`` kappa;
- the total area (``area_constraint``) and the volume (``volume_constraint``) kept by two
  Lagrange multipliers, a 2x2 system per substep (membrane_kernels.constrain);
- a drag -drag_rate m v on every node: the damping that brings a load to rest without
  changing where it rests;
- the substep from the membrane's own highest frequency (:meth:`Membrane.highest_frequency`),
  and a run stopped, naming the body, a node and the setting, when a chain nears its
  maximum length, two triangles fold over or the surface passes through itself.

Arrays in, arrays out; the loops over edges, dihedrals and triangles are compiled
(:mod:`parmps.solids.mass_spring.membrane_kernels`).
"""

import logging
import math

import numpy as np
from scipy.sparse import linalg as sparse_linalg

from parmps.config import Key
from parmps.errors import CaseError, RunFailure
from parmps.solids.mass_spring import membrane_kernels as kernels
from parmps.solids.mass_spring.kernels import drag_prediction

log = logging.getLogger(__name__)

# An edge may reach this share of its maximum length: the chain's tension grows as
# 1/(1-x)^2 and a substep chosen at rest cannot follow it much further.
EXTENSION_LIMIT = 0.95

# The in-plane laws of a cell membrane: "wlc" on the edges, the others on the triangles
# (membrane_kernels.triangle_forces).
TRIANGLE_LAWS = {"skalak": kernels.SKALAK, "neo_hookean": kernels.NEO_HOOKEAN}
CELL_LAWS = ("wlc",) + tuple(TRIANGLE_LAWS)

KEYS = {
    "membrane": Key("str", "springs", choices=("springs",) + CELL_LAWS,
                    doc="shell: \"springs\": linear edge (stiffness) and bending springs; "
                        "a cell membrane with dihedral bending and its area and volume kept "
                        "(docs/shells.md, Cell membranes) whose in-plane law is \"wlc\" "
                        "(worm-like-chain edges), \"skalak\" or \"neo_hookean\" (on "
                        "the triangles)"),
    "shear_modulus": Key("float", 0.0, ge=0.0,
                         doc="cell membrane: linear shear modulus G_s [N/m]"),
    "maximum_extension": Key("float", 2.2, gt=1.0,
                             doc="membrane wlc: an edge's maximum length over its rest "
                                 "length, l_max/l0"),
    "power_exponent": Key("float", 2.0, gt=0.0,
                          doc="membrane wlc: m of the repulsive term kp/l^m"),
    "skalak_c": Key("float", 1.0, gt=0.0,
                    doc="membrane skalak: C of W = G/4 (I1^2 + 2 I1 - 2 I2 + C I2^2); the "
                        "area modulus is G (1 + 2C)"),
    "bending_modulus": Key("float", 0.0, ge=0.0,
                           doc="cell membrane: bending modulus kappa [J]; dihedral springs "
                               "kb = 2 kappa/sqrt(3)"),
    "area_constraint": Key("bool", True, doc="cell membrane: keep the total area"),
    "local_area_modulus": Key("float", 0.0, ge=0.0,
                              doc="cell membrane: K_d [N/m] of each triangle's area energy "
                                  "K_d (A - A0)^2 / (2 A0), which keeps the mesh from "
                                  "crumpling where the total area alone allows it"),
    "drag_rate": Key("float", 0.0, ge=0.0,
                     doc="cell membrane: drag -drag_rate m v on every node [1/s]"),
}

UNSET = {"shear_modulus": 0.0, "maximum_extension": 2.2, "power_exponent": 2.0,
         "bending_modulus": 0.0, "area_constraint": True, "drag_rate": 0.0,
         "local_area_modulus": 0.0, "skalak_c": 1.0}
# The keys of one in-plane law only.
LAW_KEYS = {"maximum_extension": ("wlc",), "power_exponent": ("wlc",), "skalak_c": ("skalak",)}


def check_keys(label, spec):
    """Refuse membrane keys where they do not apply, in one line naming the key."""
    law = spec.get("membrane", "springs")
    if law != "springs" and spec["type"] != "shell":
        raise CaseError(f"{label}.membrane applies to shell bodies only (type = \"shell\")")
    for key, unset in UNSET.items():
        if spec.get(key, unset) == unset:
            continue
        if law == "springs":
            raise CaseError(f"{label}.{key} applies to a cell membrane only (membrane = "
                            f"{' or '.join(repr(c) for c in CELL_LAWS)})")
        if law not in LAW_KEYS.get(key, CELL_LAWS):
            raise CaseError(f"{label}.{key} applies to membrane = "
                            f"\"{LAW_KEYS[key][0]}\" only, not \"{law}\"")
    if law == "springs":
        return
    for key in ("stiffness", "bending_stiffness"):
        if spec.get(key) not in (None, 0.0):
            raise CaseError(f"{label}.{key} is a linear spring's; membrane = \"{law}\" takes "
                            f"shear_modulus and bending_modulus instead")
    if not spec["shear_modulus"] > 0:
        raise CaseError(f"{label}.shear_modulus must be > 0 [N/m] with membrane = \"{law}\"")


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


def wlc_parameters(rest_length, shear_modulus, maximum_extension, exponent, area=None):
    """(kBT/p, l_max (E,), kp (E,)) of edges at rest at ``rest_length`` (E,) whose net has
    the linear shear modulus ``shear_modulus``.

    Edge e is as stiff as k_e = (kBT/p) C / l_e at rest (:func:`linear_stiffness`), and a
    net of central springs under a small uniform shear, averaged over its orientations,
    stores the energy of the modulus sum_e k_e l_e^2 / (8 A) (sqrt(3) k/4 on an equilateral
    net): with the net's ``area`` A, kBT/p gives that modulus, whatever the edges' lengths
    (one kBT/p makes short edges stiffer: the modulus is the net's mean). Without it, the
    equilateral net of the mean rest length."""
    x0 = 1.0 / maximum_extension
    if area is None:
        area = len(rest_length) * math.sqrt(3.0) / 6.0 * float(np.mean(rest_length)) ** 2
        total = len(rest_length) * float(np.mean(rest_length))
    else:
        total = float(np.sum(rest_length))
    kbt_over_p = 8.0 * shear_modulus * area / (total * wlc_modulus_factor(x0, exponent))
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


def rest_frames(position, triangles):
    """Dm^-1 (T, 2, 2) of every triangle: Dm its edges x1 - x0 and x2 - x0 in an
    orthonormal frame of its own plane (the first axis along x1 - x0)."""
    a, b, c = (position[triangles[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    length = np.linalg.norm(e1, axis=1)
    u = e1 / length[:, None]
    normal = np.cross(e1, e2)
    w = np.cross(normal / np.linalg.norm(normal, axis=1)[:, None], u)
    frame = np.zeros((len(triangles), 2, 2))
    frame[:, 0, 0] = length
    frame[:, 0, 1] = np.einsum("ij,ij->i", e2, u)
    frame[:, 1, 1] = np.einsum("ij,ij->i", e2, w)
    return np.linalg.inv(frame)


def cauchy_green(position, triangles, rest_inverse):
    """(C11, C12, C22) of every triangle's right Cauchy-Green tensor F^T F."""
    a, b, c = (position[triangles[:, k]] for k in range(3))
    d = np.stack([b - a, c - a], axis=2)                       # (T, 3, 2)
    f = np.einsum("tmb,tba->tma", d, rest_inverse)
    return (np.einsum("tm,tm->t", f[:, :, 0], f[:, :, 0]),
            np.einsum("tm,tm->t", f[:, :, 0], f[:, :, 1]),
            np.einsum("tm,tm->t", f[:, :, 1], f[:, :, 1]))


def triangle_law_energy(position, triangles, rest_inverse, rest_area, law, modulus,
                        dilation):
    """sum A0 W(C) of membrane_kernels.triangle_forces' laws; arrays."""
    c11, c12, c22 = cauchy_green(position, triangles, rest_inverse)
    i1, i2 = c11 + c22 - 2.0, c11 * c22 - c12 ** 2 - 1.0
    if law == kernels.SKALAK:
        w = 0.25 * modulus * (i1 ** 2 + 2.0 * i1 - 2.0 * i2 + dilation * i2 ** 2)
    else:
        w = 0.5 * modulus * (i1 + 2.0 + 1.0 / (i2 + 1.0) - 3.0)
    return float(np.sum(rest_area * w))


def membrane_energy(position, membrane):
    """Elastic energy of the membrane: its edges or triangles and its dihedrals."""
    edges = membrane.edges
    length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
    chain = wlc_pow_energy(length, membrane.max_length, membrane.kbt_over_p, membrane.kp,
                           membrane.exponent)
    a, b, c = (position[membrane.triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    local = 0.5 * membrane.local_modulus * np.sum((area - membrane.rest_area) ** 2
                                                  / membrane.rest_area)
    law = 0.0
    if membrane.law:
        law = triangle_law_energy(position, membrane.triangles, membrane.rest_inverse,
                                  membrane.rest_area, membrane.law, membrane.modulus,
                                  membrane.dilation)
    return (float(chain.sum()) + float(local) + law
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
                 local_area_modulus=0.0, law="wlc", skalak_c=1.0):
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.quads = dihedral_quads(self.triangles)
        self.edges = np.ascontiguousarray(self.quads[:, :2])
        self.rest_length = np.linalg.norm(position[self.edges[:, 0]]
                                          - position[self.edges[:, 1]], axis=1)
        self.exponent = float(exponent)
        # 0: the edges' WLC-POW law; else the triangles' (membrane_kernels.triangle_forces).
        self.law = TRIANGLE_LAWS.get(law, 0)
        self.modulus, self.dilation = float(shear_modulus), float(skalak_c)
        self.rest_inverse = rest_frames(position, self.triangles)
        if self.law:
            self._no_chains(position)
        else:
            self.kbt_over_p, self.max_length, self.kp = wlc_parameters(
                self.rest_length, shear_modulus, maximum_extension, self.exponent,
                triangle_area_total(position, self.triangles))
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

    def _no_chains(self, position):
        """The edges of a triangle law: no tension (their dashpots stay), and a linear
        stand-in as stiff as the law at rest for the substep: an edge of stiffness
        (8/3) max(G, K/2) (A1 + A2)/l^2 (A1, A2 its triangles' areas) gives an
        equilateral net the shear modulus G or the area modulus K."""
        self.kbt_over_p = 0.0
        self.kp = np.zeros(len(self.edges))
        self.max_length = self.rest_length / EXTENSION_LIMIT * 1e6   # never reached
        area = {kernels.SKALAK: self.modulus * (1.0 + 2.0 * self.dilation),
                kernels.NEO_HOOKEAN: 3.0 * self.modulus}[self.law]
        a, b, c, d = (position[self.quads[:, k]] for k in range(4))
        pair = 0.5 * (np.linalg.norm(np.cross(b - a, c - a), axis=1)
                      + np.linalg.norm(np.cross(a - b, d - b), axis=1))
        self.stiffness = (8.0 / 3.0 * max(self.modulus, 0.5 * area) * pair
                          / self.rest_length ** 2)

    def triangle_law(self):
        """(law, Dm^-1, G, C) for the kernels (law 0: the edges carry the law)."""
        return (np.int64(self.law), self.rest_inverse, self.modulus, self.dilation)

    def elastic_force(self, position):
        """The membrane's elastic forces alone (edges or triangles, dihedrals, local area;
        no dashpots, drag or constraints); (n, 3)."""
        force = np.zeros_like(position)
        still = np.zeros_like(position)
        kernels.edge_forces(position, still, self.edges, self.max_length, self.kp,
                            self.kbt_over_p, self.exponent, 0.0, 1.0, force)
        if self.kb:
            kernels.bending_forces(position, self.quads, self.rest_cosine, self.rest_sine,
                                   self.kb, force)
        if self.local_modulus:
            kernels.local_area_forces(position, self.triangles, self.rest_area,
                                      self.local_modulus, force)
        if self.law:
            kernels.triangle_forces(position, self.triangles, self.rest_inverse,
                                    self.rest_area, self.law, self.modulus, self.dilation,
                                    force)
        return force

    def highest_frequency(self, position, mass):
        """The membrane's own highest angular frequency [rad/s] at ``position``: Lanczos
        (ARPACK, from a fixed start so every rank finds the same) on M^-1/2 K M^-1/2, K u
        from central differences of :meth:`elastic_force` (a step of 1e-6 of an edge):
        the true stiffness of every term, where a linear stand-in of springs is only near
        it (1.2 times it for the red cell's chains, 0.9 for the neo-Hookean sheet)."""
        n = len(position)
        scale = 1.0 / np.sqrt(np.repeat(np.asarray(mass, float), 3))
        step = 1e-6 * float(self.rest_length.mean())

        def stiffness_times(u):
            w = (scale * u).reshape(n, 3)
            size = float(np.abs(w).max())
            if size == 0.0:
                return np.zeros_like(u)
            a = step / size
            change = self.elastic_force(position + a * w) - self.elastic_force(position - a * w)
            return -scale * change.ravel() / (2.0 * a)

        operator = sparse_linalg.LinearOperator((3 * n, 3 * n), matvec=stiffness_times,
                                                dtype=float)
        start = np.random.default_rng(0).standard_normal(3 * n)
        largest = sparse_linalg.eigsh(operator, k=1, which="LA", v0=start, tol=1e-8,
                                      return_eigenvectors=False)[0]
        return math.sqrt(max(float(largest), 0.0))

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
            self.local_modulus, self.drag, self.triangle_law(), force)
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
        if self.law:
            return self._triangle_stiffening(position)
        edges = self.edges
        length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
        length = np.minimum(length, EXTENSION_LIMIT * self.max_length)
        now = wlc_pow_stiffness(length, self.max_length, self.kbt_over_p, self.kp,
                                self.exponent)
        return max(1.0, float(np.max(now / self.stiffness)))

    def _triangle_stiffening(self, position):
        """A triangle law's tangent grows with the stretch (Skalak's as lambda^2 along
        it) and, neo-Hookean, as a triangle shrinks (its 1/det C term): the square of
        the largest of lambda_max^2 and 1/J over the triangles."""
        c11, c12, c22 = cauchy_green(position, self.triangles, self.rest_inverse)
        stretch = 0.5 * (c11 + c22 + np.sqrt((c11 - c22) ** 2 + 4.0 * c12 ** 2))
        shrink = 1.0 / np.sqrt(np.maximum(c11 * c22 - c12 ** 2, 1e-12))
        return max(1.0, float(max(stretch.max(), shrink.max()))) ** 2

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
            self.kb, self.rest_area, self.local_modulus, self.drag, self.triangle_law(),
            self.triangles, self.rest,
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
        self.check_crossing(name, position)

    def check_crossing(self, name, position):
        """Stop a membrane that passed through itself (an edge through one of its own
        triangles: two faces crossed, which no dihedral shows where they are far apart on
        the surface), naming the body, a node of each and the settings to change."""
        edges = self.edges
        length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
        # Cells no smaller than the longest edge, and at most ~100 along the body.
        cell = max(float(length.max()), float(np.ptp(position, axis=0).max()) / 100.0)
        edge, triangle = kernels.first_crossing(position, edges, self.triangles, cell)
        if edge >= 0:
            raise RunFailure(
                f"body '{name}': its membrane passed through itself: the edge at node "
                f"{int(edges[edge, 0])} crosses the triangle at node "
                f"{int(self.triangles[triangle, 0])}: raise bending_modulus (or the loads "
                f"that press its faces together are too large), refine the shell, or "
                f"shorten the substep (solid.safety)")


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
                        spec["local_area_modulus"], spec["membrane"], spec["skalak_c"])
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
    log.info("%s: membrane %s, %d nodes, %d edges (mean %.4g m), mu0 %.4g N/m, kBT/p %.4g N, "
             "kb %.4g J, area %.6g m^2, volume %.6g m^3", label, spec["membrane"],
             body.n_nodes,
             len(membrane.edges), mean, spec["shear_modulus"], membrane.kbt_over_p,
             membrane.kb, membrane.rest[0], membrane.rest[1])
    return body
