"""Elastic materials for lattice bodies: springs, masses and dashpots from E, nu, rho.

A lattice body (nx x ny nodes, spacing a) with axial springs k_a (horizontal,
vertical) and both diagonals k_d in every cell is given the spring constants
whose homogenised (Cauchy-Born) elasticity is that of the requested material.
The full derivation is in docs/elastic_lattice.md; in short:

Under a uniform small strain eps a spring along the unit vector n changes
length by l0 n.eps.n. Per cell (area a^2: one horizontal and one vertical
spring, each shared by two cells, and its two diagonals of length a sqrt 2)
the energy density is

    W = k_a/2 (exx^2 + eyy^2) + k_d/2 (exx + eyy)^2 + 2 k_d exy^2

so, per unit depth, C11 = k_a + k_d, C12 = C66 = k_d (independent of a).
Isotropy, C66 = (C11 - C12)/2, needs k_a = 2 k_d; then C11 = 3 k_d, C12 = k_d,
the 2D Poisson ratio C12/C11 = 1/3 and the 2D Young's modulus
(C11^2 - C12^2)/C11 = 8 k_d/3. A body of depth t and 2D modulus E2 thus has

    k_d = 3 E2 t / 8,    k_a = 3 E2 t / 4.

Convention (``plane``): the 2D lattice is a slice of depth ``thickness`` t.
``strain`` (default): the body is long out of the plane (eps_zz = 0), as in
every 2D fluid-structure benchmark, where the fluid too is per unit depth.
Then E2 = E/(1 - nu^2) and nu2 = nu/(1 - nu); the lattice's nu2 = 1/3 is
nu = 1/4. ``stress``: a thin sheet loaded in its plane (sigma_zz = 0); E2 = E,
nu2 = nu, and the lattice's nu is 1/3.

Any other requested nu is accepted with a warning: the lattice keeps its own
nu and matches E2 (E/(1 - nu^2) in plane strain), which makes the bending
stiffness of a plate or beam, D = E t h^3/12(1 - nu^2) (E t h^3/12 in plane
stress), exact; the shear modulus is then 3 E2/8 instead of E/2(1 + nu).

Finite bodies: the material is the rectangle spanned by the nodes,
(nx - 1) a x (ny - 1) a; each node carries a quarter of every cell it touches
(mass rho t a^2, 1/2 of it on an edge, 1/4 at a corner). An axial spring on an
edge line bounds one cell instead of two, so an edge line and the line next to
it together carry 3/2 k_a, and every uniform strain stores exactly
(nx-1)(ny-1) cells' energy however that is shared. The share is set by bending:
with k_a/2 on the edge line, the rows' springs integrate y^2 over the depth by
the trapezoid rule and the diagonals by the midpoint rule, and the bending
stiffness is E2 t (h^3 + 5/4 a^2 h)/12. Moving alpha k_a from the edge line to
the next, alpha = 5 m / (72 (m - 1)) for m cells across, makes it
E2 t h^3/12 exactly (docs/elastic_lattice.md derives it).

Damping (``damping_ratio`` zeta): dashpots along each spring (Kelvin-Voigt,
``-b ((v_i - v_j).e) e``, which leaves rigid rotation undamped) with
b = beta k, so the damping matrix is beta K at rest and every mode n has
zeta_n = beta omega_n / 2. beta = 2 zeta / omega_max sets zeta at the highest
mode of the lattice, omega_max^2 = 4 (k_a + k_d)/m (an x-polarised wave of
wavenumber pi/a); lower modes get zeta omega_n/omega_max, so the body's
bending modes are left practically undamped: it removes grid-scale ringing,
it is not a structural damping of the fundamental mode.

3D (shape (nx, ny, nz), docs/elastic_lattice.md "3D"): the simple cubic lattice with
axial springs k_a and both diagonals k_f of every square face has C11 = (k_a + 2 k_f)/a,
C12 = C44 = k_f/a (the Cauchy relation of central springs); isotropy needs
k_a = k_f = k, so nu = 1/4 and E = 5 k/(2 a): k = 2 E a/5. Another nu keeps E (a
beam's E I exact) with a warning stating the shear modulus 2E/5 against E/2(1 + nu).
Nodes carry their share of the cells they touch (1/2, 1/4, 1/8 on a face, edge,
corner); a spring is weighted by the share of the cells around it the body holds,
and the outer layers' share is moved one layer inwards (alpha = 3m/72(m - 1) of the
axial springs, beta = 7m/72(m - 1) of the face diagonals in planes parallel to a
face, m cells across), which makes a beam's E I and a plate strip's D exact but for
a residual below 0.3 % from 4 nodes through the depth. ``thickness`` and ``plane``
are refused. omega_max^2 = (4 k_a + 8 k_f)/m.
"""

import functools
import logging
import math
from collections import namedtuple

import numpy as np

from parmps.errors import CaseError

log = logging.getLogger(__name__)

# The Poisson ratio the isotropic square lattice represents, by convention.
REPRESENTABLE_POISSON = {"strain": 0.25, "stress": 1.0 / 3.0}
LATTICE_POISSON_2D = 1.0 / 3.0
# Central springs obey the Cauchy relation C12 = C44: isotropic means nu = 1/4.
LATTICE_POISSON_3D = 0.25

LatticeMaterial = namedtuple("LatticeMaterial",
                             "stiffness mass damping axial_damping properties")


# --------------------------------------------------------------------------
# Elastic constants


def plane_modulus(youngs_modulus, poisson_ratio, plane):
    """The 2D Young's modulus E2 and Poisson ratio nu2 of a slice (plane strain or stress)."""
    if plane == "strain":
        return youngs_modulus / (1.0 - poisson_ratio ** 2), poisson_ratio / (1.0 - poisson_ratio)
    return youngs_modulus, poisson_ratio


def lattice_stiffnesses(plane_youngs_modulus, thickness):
    """Axial and diagonal spring constants [N/m] of the isotropic lattice with modulus E2."""
    diagonal = 3.0 * plane_youngs_modulus * thickness / 8.0
    return 2.0 * diagonal, diagonal


def lattice_moduli(axial, diagonal):
    """C11, C12, C66 [N/m] of the lattice with axial and diagonal springs (Cauchy-Born)."""
    return axial + diagonal, diagonal, diagonal


def highest_lattice_frequency(axial, diagonal, node_mass):
    """omega_max [rad/s] of the infinite lattice: x-polarised wave with wavenumber (pi/a, 0)."""
    return math.sqrt(4.0 * (axial + diagonal) / node_mass)


def cubic_stiffnesses(youngs_modulus, spacing):
    """Axial and face-diagonal spring constants [N/m] of the isotropic simple cubic lattice:
    k_a = k_f = 2 E a / 5 (C11 = 3 k/a, C12 = C44 = k/a; nu = 1/4, E = 5 k/(2 a))."""
    stiffness = 2.0 * youngs_modulus * spacing / 5.0
    return stiffness, stiffness


def cubic_moduli(axial, face, spacing):
    """C11, C12, C44 [Pa] of the simple cubic lattice (Cauchy-Born, per unit volume)."""
    return (axial + 2.0 * face) / spacing, face / spacing, face / spacing


def highest_cubic_frequency(axial, face, node_mass):
    """omega_max [rad/s] of the infinite cubic lattice: x-polarised wave (pi/a, 0, 0)."""
    return math.sqrt((4.0 * axial + 8.0 * face) / node_mass)


# --------------------------------------------------------------------------
# The lattice's springs and nodes


def lattice_offsets(shape, springs):
    """Per spring: the lattice coordinates (m, d) of its first node and the offset (m, d)
    to its second, in spacings (entries -1, 0, 1). Nodes are numbered i + nx j (+ nx ny k),
    as parmps.solids.mass_spring.lattice builds them."""
    strides = np.cumprod((1,) + tuple(shape[:-1]))
    coordinates = (springs[..., None] // strides) % np.asarray(shape)
    return coordinates[:, 0], coordinates[:, 1] - coordinates[:, 0]


def spring_kinds(shape, springs):
    """Per spring (2D): whether it is axial, and the edge it lies on or next to.

    Returns ``is_axial`` and, per spring, ``lines``: the number of node lines
    (rows for a horizontal spring, columns for a vertical one) across the body
    in the spring's direction of bending, and ``position``: the index of its
    line, 0 .. lines-1 (-1 for diagonals).
    """
    nx, ny = shape
    i, j = springs % nx, springs // nx
    horizontal = j[:, 0] == j[:, 1]
    vertical = i[:, 0] == i[:, 1]
    lines = np.where(horizontal, ny, np.where(vertical, nx, 0))
    position = np.where(horizontal, j[:, 0], np.where(vertical, i[:, 0], -1))
    return horizontal | vertical, lines, position


def edge_transfer(lines, share=5.0):
    """alpha: the share of a spring family moved from an edge line to the next line.

    With ``lines`` node lines across the body (m = lines - 1 cells), alpha =
    share m / (72 (m - 1)). 2D axial springs: share 5 (the lattice's bending
    stiffness is E2 t (h^3 + 5/4 a^2 h)/12 with the edge lines at k_a/2; moving
    alpha k_a from each edge line to the next removes 4 alpha (m - 1) k_d a^3,
    the excess being 5 m/18 k_d a^3). 3D: share 3 for axial springs and 7 for
    face diagonals in planes parallel to a face (docs/elastic_lattice.md, "3D").
    A body one cell deep (m = 1) has no inner line to move it to: 0.
    """
    cells = np.asarray(lines) - 1
    return np.where(cells >= 2, share * cells / (72.0 * np.maximum(cells - 1, 1)), 0.0)


def line_weight(lines, position, alpha):
    """Weight of a spring on node line ``position`` of ``lines`` across the body:
    1/2 - alpha on an edge line, 1 + alpha next to an edge (1 + 2 alpha next to both),
    1 elsewhere. The weights across the body add up to lines - 1 whole cells."""
    on_edge = (position == 0) | (position == lines - 1)
    # A line next to both edges (three lines across) receives from both.
    next_to_edge = ((position == 1).astype(float) + (position == lines - 2).astype(float))
    return np.where(on_edge, 0.5 - alpha, 1.0 + next_to_edge * alpha)


def axial_weights(shape, springs):
    """Per spring (2D), its stiffness as a multiple of k_a (axial) or k_d (diagonal).

    Axial springs on an edge line bound one cell and carry 1/2 - alpha, those on
    the line next to an edge 1 + alpha (1 + 2 alpha when one line lies next to
    both edges), all others 1; see :func:`edge_transfer`. The total along every
    line of cells stays that of whole cells, so uniform strains (the patch
    tests) are unchanged, and the bending stiffness is E2 t h^3/12 exactly.
    """
    is_axial, lines, position = spring_kinds(shape, springs)
    alpha = np.where(is_axial, edge_transfer(np.maximum(lines, 2)), 0.0)
    return np.where(is_axial, line_weight(lines, position, alpha), 1.0)


def cubic_weights(shape, springs):
    """Per spring of a 3D lattice: whether it is axial, and its stiffness as a multiple of
    k_a (axial) or k_f (face diagonal).

    A spring's weight is the share of the four (axial) or two (face diagonal) cells
    around it that the body holds, with the bending correction: an axial spring along
    axis e weighs the product over the two other axes of :func:`line_weight` with
    alpha = 3 m/(72 (m - 1)); a face diagonal weighs :func:`line_weight` across its
    plane's normal with beta = 7 m/(72 (m - 1)) (docs/elastic_lattice.md, "3D").
    """
    start, offset = lattice_offsets(shape, springs)
    moved = np.count_nonzero(offset, axis=1)
    if (moved < 1).any() or (moved > 2).any():
        raise ValueError("a 3D elastic lattice has axial and face-diagonal springs only")
    weight = np.ones(len(springs))
    for axis, lines in enumerate(shape):
        across = offset[:, axis] == 0
        # Axial springs (one axis moved) weigh both transverse axes, face
        # diagonals (two moved) only their plane's normal.
        share = np.where(moved == 1, 3.0, 7.0)
        alpha = edge_transfer(np.full(len(springs), max(lines, 2)), share)
        factor = line_weight(lines, start[:, axis], alpha)
        weight = np.where(across, weight * factor, weight)
    return moved == 1, weight


def cell_share(shape):
    """Fraction of a cell each node carries: the product over the axes of 1 inside and 1/2
    on an end (2D: 1/2 on an edge, 1/4 at a corner; 3D: 1/2, 1/4, 1/8 on a face, edge,
    corner), in node order i + nx j (+ nx ny k)."""
    shares = [np.where((np.arange(n) == 0) | (np.arange(n) == n - 1), 0.5, 1.0)
              for n in shape]
    return functools.reduce(np.multiply.outer, shares[::-1]).ravel()


def axial_damping_forces(position, velocity, springs, damping):
    """Dashpots along the springs, ``-b ((v_i - v_j).e) e`` with e = (x_i - x_j)/|x_i - x_j|.

    Unlike ``-b (v_i - v_j)`` they exert no force on a rigid rotation. Shape (n, d).
    """
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    length_squared = np.einsum("ij,ij->i", separation, separation)
    relative = velocity[springs[:, 0]] - velocity[springs[:, 1]]
    rate = np.einsum("ij,ij->i", relative, separation)
    scale = np.divide(damping * rate, length_squared, out=np.zeros_like(rate),
                      where=length_squared > 0)
    pair_force = -scale[:, None] * separation
    force = np.empty(position.shape)
    for axis in range(position.shape[1]):
        force[:, axis] = (np.bincount(springs[:, 0], weights=pair_force[:, axis],
                                      minlength=len(position))
                          - np.bincount(springs[:, 1], weights=pair_force[:, axis],
                                        minlength=len(position)))
    return force


# --------------------------------------------------------------------------
# From a [[body]] table


def is_elastic(spec):
    return spec.get("youngs_modulus", 0.0) > 0.0


def check_not_elastic(label, spec):
    """Refuse material keys on a body that gives no youngs_modulus (or is not a lattice)."""
    for key, unset in (("poisson_ratio", None), ("damping_ratio", 0.0), ("plane", "strain"),
                       ("thickness", 1.0)):
        if spec.get(key, unset) != unset:
            raise CaseError(f"{label}.{key} applies to a lattice body with youngs_modulus")


def _check_material(label, spec):
    """The refusals common to 2D and 3D elastic lattices."""
    for key in ("stiffness", "shear_stiffness", "node_mass"):
        if spec[key]:
            raise CaseError(f"{label}.{key} cannot be combined with youngs_modulus: the "
                            f"material sets the springs and masses")
    if not spec["density"] > 0:
        raise CaseError(f"{label}.density [kg/m^3] is needed with youngs_modulus")
    if spec["damping"] and spec["damping_ratio"]:
        raise CaseError(f"{label}: give damping [N s/m] or damping_ratio, not both")


def _dashpots(spec, stiffness, omega_max, count):
    """Dashpot constants per spring and whether they act along the springs only."""
    if spec["damping_ratio"] > 0:
        return 2.0 * spec["damping_ratio"] / omega_max * stiffness, True
    return np.full(count, spec["damping"]), False


def elastic_lattice(label, spec, shape, springs):
    """Spring constants, node masses and dashpots of a lattice ``[[body]]`` with a material.

    ``spec`` is the validated table (youngs_modulus > 0); ``shape`` = (nx, ny) or
    (nx, ny, nz); ``springs`` the lattice's index pairs (numbered as
    parmps.solids.mass_spring.lattice does). Returns a :class:`LatticeMaterial`.
    """
    _check_material(label, spec)
    if len(shape) == 3:
        return _cubic_lattice(label, spec, shape, np.asarray(springs))
    plane, thickness, spacing = spec["plane"], spec["thickness"], spec["spacing"]
    youngs = spec["youngs_modulus"]
    representable = REPRESENTABLE_POISSON[plane]
    requested = representable if spec["poisson_ratio"] is None else spec["poisson_ratio"]
    plane_youngs, _ = plane_modulus(youngs, requested, plane)
    if abs(requested - representable) > 1e-9:
        shear_requested = youngs / (2.0 * (1.0 + requested)) * thickness
        shear_lattice = 3.0 * plane_youngs * thickness / 8.0
        _, nu2_requested = plane_modulus(youngs, requested, plane)
        log.warning("%s.poisson_ratio %.4g is not representable by the square lattice "
                    "(plane %s: only %.4g); using %.4g with E2 = %.4g Pa matched, so the bending "
                    "stiffness D = %s is exact; shear modulus %+.1f %%, in-plane Poisson "
                    "ratio 1/3 instead of %.3f", label, requested, plane, representable,
                    representable, plane_youngs,
                    "E t h^3/12(1-nu^2)" if plane == "strain" else "E t h^3/12",
                    100.0 * (shear_lattice / shear_requested - 1.0), nu2_requested)
    if min(shape) == 2:
        log.warning("%s is one cell deep (%d x %d nodes): its bending stiffness across that "
                    "cell is 9/4 of E2 t h^3/12 (no inner line of springs to correct it); use "
                    "at least 3 nodes through the depth of a bending member", label, *shape)
    axial, diagonal = lattice_stiffnesses(plane_youngs, thickness)
    is_axial, _, _ = spring_kinds(shape, springs)
    stiffness = np.where(is_axial, axial, diagonal) * axial_weights(shape, springs)
    cell_mass = spec["density"] * thickness * spacing ** 2
    mass = cell_mass * cell_share(shape)
    omega_max = highest_lattice_frequency(axial, diagonal, cell_mass)
    damping, axial_damping = _dashpots(spec, stiffness, omega_max, len(springs))
    properties = {"plane_youngs_modulus": plane_youngs,
                  "effective_poisson_ratio": representable,
                  "axial_stiffness": axial, "diagonal_stiffness": diagonal,
                  "omega_max": omega_max,
                  "width": (shape[0] - 1) * spacing, "height": (shape[1] - 1) * spacing}
    log.debug("%s: E2 = %.6g Pa, k_a = %.6g N/m, k_d = %.6g N/m, omega_max = %.6g rad/s",
              label, plane_youngs, axial, diagonal, omega_max)
    return LatticeMaterial(stiffness, mass, damping, axial_damping, properties)


def _cubic_lattice(label, spec, shape, springs):
    """The 3D part of :func:`elastic_lattice`: the simple cubic lattice with k_a = k_f."""
    # Defaults of the 2D keys: anything else was set by the user (a 3D body's
    # extent is its nodes', and it is neither a slice nor a sheet).
    for key, unset in (("thickness", 1.0), ("plane", "strain")):
        if spec[key] != unset:
            raise CaseError(f"{label}.{key} applies to 2D bodies only; a 3D body's depth is "
                            f"its nodes' extent")
    youngs, spacing = spec["youngs_modulus"], spec["spacing"]
    requested = LATTICE_POISSON_3D if spec["poisson_ratio"] is None else spec["poisson_ratio"]
    if abs(requested - LATTICE_POISSON_3D) > 1e-9:
        shear_requested = youngs / (2.0 * (1.0 + requested))
        log.warning("%s.poisson_ratio %.4g is not representable by the cubic lattice (central "
                    "springs: only 0.25); using 0.25 with E = %.4g Pa matched, so a beam's "
                    "bending stiffness E I is exact; shear modulus %.4g Pa instead of %.4g Pa "
                    "(%+.1f %%)", label, requested, youngs, 0.4 * youngs, shear_requested,
                    100.0 * (0.4 * youngs / shear_requested - 1.0))
    if min(shape) == 2:
        log.warning("%s is one cell deep (%s nodes): no inner layer of springs corrects its "
                    "bending stiffness across that cell; use at least 3 nodes through the "
                    "depth of a bending member", label, " x ".join(map(str, shape)))
    axial, face = cubic_stiffnesses(youngs, spacing)
    is_axial, weight = cubic_weights(shape, springs)
    stiffness = np.where(is_axial, axial, face) * weight
    cell_mass = spec["density"] * spacing ** 3
    mass = cell_mass * cell_share(shape)
    omega_max = highest_cubic_frequency(axial, face, cell_mass)
    damping, axial_damping = _dashpots(spec, stiffness, omega_max, len(springs))
    c11, c12, c44 = cubic_moduli(axial, face, spacing)
    properties = {"youngs_modulus": youngs, "effective_poisson_ratio": LATTICE_POISSON_3D,
                  "axial_stiffness": axial, "face_diagonal_stiffness": face,
                  "c11": c11, "c12": c12, "c44": c44, "omega_max": omega_max,
                  "extent": tuple((n - 1) * spacing for n in shape)}
    log.debug("%s: E = %.6g Pa, k_a = k_f = %.6g N/m, omega_max = %.6g rad/s", label, youngs,
              axial, omega_max)
    return LatticeMaterial(stiffness, mass, damping, axial_damping, properties)
