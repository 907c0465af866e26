"""Elastic materials for lattice bodies (parmps.solids.mass_spring.elastic).

A lattice patch given E, nu (plane strain or plane stress) and a depth t is
loaded by prescribed boundary displacements; the static equilibrium of its
springs (a direct solve of the linearised network) must reproduce the
continuum's C11, C12, C66, E and nu within 1 %. The references are the
isotropic formulas in the chosen convention, not the code's own conversion.
"""

import logging
import math

import numpy as np
import pytest

from parmps import config, schema
from parmps.errors import CaseError
from parmps.solids.mass_spring.model import MassSpringModel
from parmps.solids.mass_spring.build import build_bodies
from parmps.solids.mass_spring.elastic import elastic_lattice, highest_lattice_frequency
from parmps.solids.mass_spring.statics import static_displacement, stiffness_matrix

NX, NY, SPACING = 7, 5, 0.1
THICKNESS = 0.5
YOUNGS = 2.0e6

CASE = """
[domain]
lower = [-1.0, -1.0]
upper = [2.0, 2.0]
[physics]
gravity = [0.0, 0.0]
[time]
end = 0.01
[[body]]
name = "patch"
nx = {nx}
ny = {ny}
spacing = {spacing}
volume_constraint = false
{material}
"""


def build(material, nx=NX, ny=NY, spacing=SPACING):
    text = CASE.format(nx=nx, ny=ny, spacing=spacing, material=material)
    (body,) = build_bodies(schema.validate(config.load_text(text)))
    return body


def isotropic_moduli(youngs, poisson, plane, thickness):
    """C11, C12, C66 per unit depth times t, of the isotropic continuum."""
    if plane == "strain":
        lame = youngs * poisson / ((1 + poisson) * (1 - 2 * poisson))
    else:
        lame = youngs * poisson / (1 - poisson ** 2)
    shear = youngs / (2 * (1 + poisson))
    return ((lame + 2 * shear) * thickness, lame * thickness, shear * thickness)


def sides(position):
    x, y = position[:, 0], position[:, 1]
    return {"left": np.isclose(x, x.min()), "right": np.isclose(x, x.max()),
            "bottom": np.isclose(y, y.min()), "top": np.isclose(y, y.max())}


def affine_reactions(body, gradient):
    """Every boundary node displaced by u = gradient . x; the interior solved for."""
    edge = sides(body.position)
    boundary = edge["left"] | edge["right"] | edge["bottom"] | edge["top"]
    prescribed = body.position @ np.asarray(gradient).T
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    displacement, reaction = static_displacement(matrix, np.zeros_like(body.position), boundary,
                                                 prescribed)
    # The interior must follow the affine field too (Cauchy-Born is exact here).
    assert np.allclose(displacement, prescribed, atol=1e-9 * np.abs(prescribed).max())
    return reaction, edge


PLANES = [("strain", 0.25), ("stress", 1.0 / 3.0)]


@pytest.mark.parametrize("plane, poisson", PLANES)
def test_uniaxial_strain_gives_c11_and_c12(plane, poisson):
    body = build(f"youngs_modulus = {YOUNGS}\npoisson_ratio = {poisson}\nplane = \"{plane}\"\n"
                 f"thickness = {THICKNESS}\ndensity = 1000.0")
    strain = 1e-4
    reaction, edge = affine_reactions(body, [[strain, 0.0], [0.0, 0.0]])
    width, height = (NX - 1) * SPACING, (NY - 1) * SPACING
    c11 = reaction[edge["right"], 0].sum() / (strain * height)
    c12 = reaction[edge["top"], 1].sum() / (strain * width)
    c11_ref, c12_ref, _ = isotropic_moduli(YOUNGS, poisson, plane, THICKNESS)
    assert c11 == pytest.approx(c11_ref, rel=0.01)
    assert c12 == pytest.approx(c12_ref, rel=0.01)


@pytest.mark.parametrize("plane, poisson", PLANES)
def test_simple_shear_gives_c66(plane, poisson):
    body = build(f"youngs_modulus = {YOUNGS}\npoisson_ratio = {poisson}\nplane = \"{plane}\"\n"
                 f"thickness = {THICKNESS}\ndensity = 1000.0")
    shear = 1e-4
    reaction, edge = affine_reactions(body, [[0.0, shear], [0.0, 0.0]])
    c66 = reaction[edge["top"], 0].sum() / (shear * (NX - 1) * SPACING)
    assert c66 == pytest.approx(isotropic_moduli(YOUNGS, poisson, plane, THICKNESS)[2],
                                rel=0.01)


@pytest.mark.parametrize("plane, poisson", PLANES)
def test_uniaxial_stress_gives_youngs_modulus_and_poisson_ratio(plane, poisson):
    """Ends pulled apart, top and bottom free: the force and the contraction give E2, nu2.

    The strip is 5 times as long as it is deep and the contraction is read on its middle
    third: the end columns' vertical springs carry 1/2 - alpha and 1 + alpha of k_a (the
    bending correction), which puts a force alpha k_a a eps_yy on the free corners; like
    any end effect it dies away within about the depth (docs/elastic_lattice.md).
    """
    nx = 5 * (NY - 1) + 1
    body = build(f"youngs_modulus = {YOUNGS}\npoisson_ratio = {poisson}\nplane = \"{plane}\"\n"
                 f"thickness = {THICKNESS}\ndensity = 1000.0", nx=nx)
    edge = sides(body.position)
    strain = 1e-4
    width, height = (nx - 1) * SPACING, (NY - 1) * SPACING
    fixed = np.zeros((body.n_nodes, 2), bool)
    fixed[edge["left"] | edge["right"], 0] = True
    fixed[np.flatnonzero(edge["left"] & edge["bottom"]), 1] = True
    prescribed = np.zeros((body.n_nodes, 2))
    prescribed[edge["right"], 0] = strain * width
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    displacement, reaction = static_displacement(matrix, np.zeros_like(prescribed), fixed,
                                                 prescribed)
    youngs_2d = reaction[edge["right"], 0].sum() / (strain * height)
    column = np.round(body.position[:, 0] / SPACING).astype(int)
    middle = (column >= (nx - 1) // 3) & (column <= 2 * (nx - 1) // 3)
    contraction = (displacement[edge["top"] & middle, 1].mean()
                   - displacement[edge["bottom"] & middle, 1].mean()) / height
    c11, c12, _ = isotropic_moduli(YOUNGS, poisson, plane, THICKNESS)
    assert youngs_2d == pytest.approx((c11 ** 2 - c12 ** 2) / c11, rel=0.01)
    assert -contraction / strain == pytest.approx(c12 / c11, rel=0.01)
    # Uniform there: every row contracts alike, so the free top and bottom carry no
    # spurious stress.
    expected = -c12 / c11 * strain * body.position[:, 1]
    offset = (displacement[middle, 1] - expected[middle]).mean()  # the bottom's y is free
    assert np.allclose(displacement[middle, 1] - offset, expected[middle],
                       atol=1e-3 * strain * height)


def test_edge_lines_give_their_axial_stiffness_inwards_and_nodes_carry_their_cells():
    body = build(f"youngs_modulus = {YOUNGS}\nthickness = {THICKNESS}\ndensity = 800.0")
    # Mass of the (nx-1) a x (ny-1) a rectangle, t deep.
    area = (NX - 1) * (NY - 1) * SPACING ** 2
    assert body.mass.sum() == pytest.approx(800.0 * THICKNESS * area, rel=1e-12)
    assert body.mass[0] == pytest.approx(0.25 * 800.0 * THICKNESS * SPACING ** 2)
    # Plane strain, nu = 1/4: k_d = 3 E t / (8 (1 - nu^2)), k_a = 2 k_d. Across m cells an
    # edge line of axial springs carries (1/2 - alpha) k_a, the next line (1 + alpha) k_a,
    # alpha = 5 m / (72 (m - 1)).
    diagonal = 3 * YOUNGS * THICKNESS / (8 * (1 - 0.25 ** 2))
    position = body.position / SPACING
    first, second = position[body.springs[:, 0]], position[body.springs[:, 1]]
    horizontal = np.isclose(first[:, 1], second[:, 1])
    vertical = np.isclose(first[:, 0], second[:, 0])
    assert np.allclose(body.stiffness[~(horizontal | vertical)], diagonal)
    for lines, mask, across in ((NY, horizontal, 1), (NX, vertical, 0)):
        cells = lines - 1
        alpha = 5 * cells / (72 * (cells - 1))
        line = np.round(first[mask, across]).astype(int)
        expected = np.select([(line == 0) | (line == lines - 1), (line == 1) | (line == lines - 2)],
                             [0.5 - alpha, 1.0 + alpha], 1.0)
        assert np.allclose(body.stiffness[mask], 2 * diagonal * expected)
        # Per column (row) of cells, the axial springs add up to whole cells.
        assert expected.sum() == pytest.approx(len(expected) * cells / lines)


def pure_bending_stiffness(nodes_across, vertical=False):
    """Moment / curvature of a lattice beam 15 nodes per node across long, under an end couple.

    The left end is held, the right end carries axial forces proportional to the distance
    from the mid-line; the curvature is read from the middle third, where the end effects
    have died away (pure bending is an exact equilibrium of the lattice there).
    """
    spacing = 0.01
    along = 15 * nodes_across
    shape = (nodes_across, along) if vertical else (along, nodes_across)
    body = build(f"youngs_modulus = {YOUNGS}\npoisson_ratio = 0.25\nthickness = {THICKNESS}"
                 f"\ndensity = 1000.0", nx=shape[0], ny=shape[1], spacing=spacing)
    axis = 1 if vertical else 0
    x, y = body.position[:, axis], body.position[:, 1 - axis]
    y = y - y.mean()
    column = np.round(x / spacing).astype(int)
    force = np.zeros_like(body.position)
    end = column == column.max()
    force[end, axis] = y[end] / (y[end] ** 2).sum()  # a unit couple
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    displacement, _ = static_displacement(matrix, force, column == 0)
    middle = np.arange(along // 3, 2 * along // 3)
    rotation = [np.polyfit(y[column == c], displacement[column == c, axis], 1)[0]
                for c in middle]
    return 1.0 / abs(np.polyfit(middle * spacing, rotation, 1)[0])


@pytest.mark.parametrize("nodes_across", [3, 4, 5, 8])
@pytest.mark.parametrize("vertical", [False, True], ids=["along_x", "along_y"])
def test_pure_bending_stiffness_is_exact(nodes_across, vertical):
    """D = E2 t h^3/12 with h = (n - 1) a for any n >= 3 (not 1 + 5/4 (a/h)^2 of it)."""
    depth = (nodes_across - 1) * 0.01
    exact = YOUNGS / (1 - 0.25 ** 2) * THICKNESS * depth ** 3 / 12
    assert pure_bending_stiffness(nodes_across, vertical) == pytest.approx(exact, rel=1e-6)


def test_one_cell_deep_is_nine_quarters_too_stiff_and_warns(caplog):
    """Two lines across: both carry all the axial stiffness at +-a/2, nothing to move inwards."""
    with caplog.at_level(logging.WARNING):
        stiffness = pure_bending_stiffness(2)
    assert "one cell deep" in caplog.text
    exact = YOUNGS / (1 - 0.25 ** 2) * THICKNESS * 0.01 ** 3 / 12
    assert stiffness == pytest.approx(9 / 4 * exact, rel=1e-6)


def test_unrepresentable_poisson_ratio_keeps_the_bending_modulus_and_warns(caplog):
    with caplog.at_level(logging.WARNING):
        body = build(f"youngs_modulus = {YOUNGS}\npoisson_ratio = 0.45\ndensity = 1100.0")
    assert "poisson_ratio 0.45 is not representable" in caplog.text
    assert "only 0.25" in caplog.text
    reaction, edge = affine_reactions(body, [[1e-4, 0.0], [0.0, 0.0]])
    c11 = reaction[edge["right"], 0].sum() / (1e-4 * (NY - 1) * SPACING)
    # E2 = (C11^2 - C12^2)/C11 = 8/9 C11 of the lattice equals E/(1 - nu^2).
    assert 8 / 9 * c11 == pytest.approx(YOUNGS / (1 - 0.45 ** 2), rel=0.01)


def test_damping_ratio_sets_dashpots_proportional_to_the_springs():
    body = build(f"youngs_modulus = {YOUNGS}\ndensity = 1000.0\ndamping_ratio = 0.2")
    diagonal = 3 * YOUNGS / (8 * (1 - 0.25 ** 2))
    omega_max = math.sqrt(4 * 3 * diagonal / (1000.0 * SPACING ** 2))
    assert body.axial_damping
    assert np.allclose(body.damping, 2 * 0.2 / omega_max * body.stiffness)
    # A rigid rotation is not damped: no dashpot force at all.
    centre = body.position.mean(axis=0)
    spin = np.column_stack([-(body.position[:, 1] - centre[1]), body.position[:, 0] - centre[0]])
    body.velocity[:] = spin
    body.fluid_force[:] = 0.0
    acceleration = body.acceleration_at(0.0, body.velocity, 1e-6)
    assert np.abs(acceleration).max() < 1e-9 * np.abs(spin).max() * omega_max


def test_highest_mode_of_a_free_patch_has_the_damping_ratio():
    """Modal check: with C = beta K every mode has zeta_n = beta omega_n / 2, and the
    patch's highest mode is the infinite lattice's omega_max within 2 %."""
    body = build(f"youngs_modulus = {YOUNGS}\ndensity = 1000.0\ndamping_ratio = 0.3", nx=12,
                 ny=12)
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness).toarray()
    inverse_root_mass = 1 / np.sqrt(np.repeat(body.mass, 2))
    omega = np.sqrt(np.abs(np.linalg.eigvalsh(matrix * np.outer(inverse_root_mass,
                                                                 inverse_root_mass))))
    damping = stiffness_matrix(body.position, body.springs, body.damping).toarray()
    beta = damping[np.nonzero(matrix)][0] / matrix[np.nonzero(matrix)][0]
    assert np.allclose(damping, beta * matrix)
    cell_mass = 1000.0 * SPACING ** 2
    axial = 3 * YOUNGS / (4 * (1 - 0.25 ** 2))
    omega_max = highest_lattice_frequency(axial, axial / 2, cell_mass)
    # Edge modes of the finite patch lie a little above the infinite lattice's top.
    assert omega.max() == pytest.approx(omega_max, rel=0.02)
    assert beta * omega.max() / 2 == pytest.approx(0.3, rel=0.02)


BAD = {
    "with_stiffness": ("youngs_modulus = 1e6\ndensity = 1000.0\nstiffness = 100.0",
                       r"body\[0\] 'patch'.stiffness cannot be combined with youngs_modulus"),
    "with_node_mass": ("youngs_modulus = 1e6\nnode_mass = 0.1",
                        r"node_mass cannot be combined with youngs_modulus"),
    "no_mass": ("youngs_modulus = 1e6", r"density \[kg/m\^3\] is needed with youngs_modulus"),
    "both_dampings": ("youngs_modulus = 1e6\ndensity = 1.0\ndamping = 1.0\ndamping_ratio = 0.1",
                      r"give damping \[N s/m\] or damping_ratio, not both"),
    "poisson_without_modulus": ("stiffness = 100.0\nnode_mass = 0.1\npoisson_ratio = 0.3",
                                r"poisson_ratio applies to a lattice body with youngs_modulus"),
    "poisson_out_of_range": ("youngs_modulus = 1e6\ndensity = 1.0\npoisson_ratio = 0.5",
                             r"poisson_ratio must be < 0.5, got 0.5"),
    "no_stiffness": ("node_mass = 0.1", r"missing key 'stiffness' \[N/m\] \(or give "
                                        r"youngs_modulus"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_materials_are_refused_with_one_line(name):
    material, pattern = BAD[name]
    with pytest.raises(CaseError, match=pattern) as info:
        MassSpringModel([build(material)])
    assert "\n" not in str(info.value)


def test_general_body_refuses_youngs_modulus():
    text = CASE.split("[[body]]")[0] + """
[[body]]
type = "general"
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 2], [2, 0]]
boundary = [0, 1, 2]
node_mass = 0.1
youngs_modulus = 1e6
"""
    with pytest.raises(CaseError, match=r"youngs_modulus applies to lattice bodies only"):
        build_bodies(schema.validate(config.load_text(text)))


def test_elastic_lattice_is_a_pure_function_of_its_table():
    spec = {"stiffness": None, "shear_stiffness": 0.0, "node_mass": 0.0, "density": 1000.0,
            "damping": 0.0, "damping_ratio": 0.0, "plane": "stress", "thickness": 2.0,
            "spacing": 0.1, "youngs_modulus": 8.0, "poisson_ratio": None}
    springs = np.array([[0, 1], [0, 2], [0, 3], [1, 2]])
    material = elastic_lattice("b", spec, (2, 2), springs)
    # Plane stress, nu = 1/3: k_d = 3 E t / 8 = 6, edge axial springs k_a / 2 = 6.
    assert np.allclose(material.stiffness, [6.0, 6.0, 6.0, 6.0])
    assert np.allclose(material.mass, 0.25 * 1000.0 * 2.0 * 0.01)
    assert material.properties["effective_poisson_ratio"] == pytest.approx(1 / 3)
