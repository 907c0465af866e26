"""Cell membranes (parmps/solids/mass_spring/membrane.py): the WLC-POW and dihedral forces
against finite differences of their energies, the area and volume kept under load, a
small stretch, and a membrane that tears stopping the run in one line."""

import math

import numpy as np
import pytest

from parmps.errors import RunFailure
from parmps.solids.mass_spring import membrane, membrane_kernels
from parmps.solids.mass_spring.shell import icosphere, red_blood_cell

MU = 6.3e-6       # [N/m]
KAPPA = 2.4e-19   # [J]


def _perturbed(vertices, scale=0.05, seed=1):
    rng = np.random.default_rng(seed)
    edge = np.linalg.norm(vertices[1] - vertices[0])
    return vertices + scale * edge * rng.standard_normal(vertices.shape)


def _membrane(vertices, triangles, kappa=KAPPA, area=True, volume=True, drag=0.0):
    return membrane.Membrane(vertices, triangles, MU, 2.2, 2.0, kappa, area, volume, drag, 0.0)


def _forces(m, position, bending):
    force = np.zeros_like(position)
    velocity = np.zeros_like(position)
    if bending:
        membrane_kernels.bending_forces(position, m.quads, m.rest_cosine, m.rest_sine, m.kb,
                                        force)
    else:
        membrane_kernels.edge_forces(position, velocity, m.edges, m.max_length, m.kp,
                                     m.kbt_over_p, m.exponent, 0.0, 1.0, force)
    return force


def _energy(m, position, bending):
    if bending:
        return membrane.bending_energy(position, m.quads, m.rest_angle, m.kb)
    e = m.edges
    length = np.linalg.norm(position[e[:, 0]] - position[e[:, 1]], axis=1)
    return float(membrane.wlc_pow_energy(length, m.max_length, m.kbt_over_p, m.kp,
                                         m.exponent).sum())


def test_the_wlc_pow_tension_is_its_energys_derivative_and_vanishes_at_rest():
    kbt_p, lmax, kp = membrane.wlc_parameters(np.array([1e-6]), MU, 2.2, 2.0)
    length = np.linspace(0.5e-6, 2.0e-6, 7)
    h = 1e-13
    numeric = (membrane.wlc_pow_energy(length + h, lmax, kbt_p, kp, 2.0)
               - membrane.wlc_pow_energy(length - h, lmax, kbt_p, kp, 2.0)) / (2 * h)
    tension = membrane.wlc_pow_tension(length, lmax, kbt_p, kp, 2.0)
    assert np.allclose(numeric, tension, rtol=1e-6, atol=1e-9 * np.abs(tension).max())
    assert abs(membrane.wlc_pow_tension(np.array([1e-6]), lmax, kbt_p, kp, 2.0)[0]) < 1e-20
    # The compiled law is the same.
    assert math.isclose(membrane_kernels.wlc_pow_tension(1.7e-6, lmax[0], kbt_p, kp[0], 2.0),
                        membrane.wlc_pow_tension(1.7e-6, lmax[0], kbt_p, kp[0], 2.0),
                        rel_tol=1e-12)


def test_the_linearised_net_has_the_shear_modulus_asked_for():
    """sqrt(3)/4 dT/dl at rest (Fedosov et al. 2010's mu0) is the modulus given."""
    rest = np.array([0.3e-6])
    kbt_p, lmax, kp = membrane.wlc_parameters(rest, MU, 2.2, 2.0)
    h = 1e-12
    slope = (membrane.wlc_pow_tension(rest + h, lmax, kbt_p, kp, 2.0)
             - membrane.wlc_pow_tension(rest - h, lmax, kbt_p, kp, 2.0)) / (2 * h)
    assert math.isclose(math.sqrt(3.0) / 4.0 * slope[0], MU, rel_tol=1e-5)


def _irregular_patch(n=12, spacing=0.3e-6, seed=2):
    """A planar triangular lattice patch, its nodes moved by up to a fifth of the spacing:
    (nodes (N, 3), edges (E, 2), its area, triangles (T, 3))."""
    j, i = np.divmod(np.arange(n * n), n)
    nodes = np.column_stack([(i + 0.5 * j) * spacing, j * spacing * math.sqrt(3) / 2,
                             np.zeros(n * n)])
    nodes[:, :2] += 0.2 * spacing * np.random.default_rng(seed).uniform(-1, 1, (n * n, 2))
    corner = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    triangles = np.concatenate([np.column_stack([corner, corner + 1, corner + n]),
                                np.column_stack([corner + 1, corner + n + 1, corner + n])])
    pairs = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    a, b, c = (nodes[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    return nodes, np.unique(pairs, axis=0), area, triangles


def test_an_irregular_net_sheared_a_little_stores_the_energy_of_the_modulus_asked_for():
    """kBT/p from the net's area and lengths (wlc_parameters): a small uniform shear g of an
    irregular stress-free net, averaged over the directions 0 and 45 degrees (which average
    cos^2 over all), stores 2 mu0 g^2 A; the mean length alone would miss it."""
    nodes, edges, area, _ = _irregular_patch()
    rest = np.linalg.norm(nodes[edges[:, 0]] - nodes[edges[:, 1]], axis=1)
    kbt_p, lmax, kp = membrane.wlc_parameters(rest, MU, 2.2, 2.0, area)
    g = 1e-4
    stored = []
    for angle in (0.0, math.pi / 4):
        c, s = math.cos(2 * angle), math.sin(2 * angle)
        strain = np.array([[1 + g * c, g * s, 0], [g * s, 1 - g * c, 0], [0, 0, 1]])
        moved = nodes @ strain.T
        length = np.linalg.norm(moved[edges[:, 0]] - moved[edges[:, 1]], axis=1)
        stored.append(np.sum(membrane.wlc_pow_energy(length, lmax, kbt_p, kp, 2.0)
                             - membrane.wlc_pow_energy(rest, lmax, kbt_p, kp, 2.0)))
    assert np.mean(stored) / (2 * g ** 2 * area) == pytest.approx(MU, rel=1e-3)
    mean_only = membrane.wlc_parameters(rest, MU, 2.2, 2.0)[0]
    assert abs(mean_only / kbt_p - 1) > 0.01


@pytest.mark.parametrize("law, area_modulus", [("skalak", MU * (1 + 2 * 4.0)),
                                                 ("neo_hookean", 3 * MU)])
def test_a_triangle_law_sheared_or_dilated_a_little_has_its_moduli(law, area_modulus):
    """An irregular planar net of triangles: a small pure shear g stores 2 G g^2 A, a small
    dilation e stores 2 K e^2 A, K = G (1 + 2C) (Skalak, C = 4) or 3 G (neo-Hookean)."""
    nodes, _, area, triangles = _irregular_patch()
    inverse = membrane.rest_frames(nodes, triangles)
    rest = 0.5 * np.linalg.norm(np.cross(nodes[triangles[:, 1]] - nodes[triangles[:, 0]],
                                         nodes[triangles[:, 2]] - nodes[triangles[:, 0]]),
                                axis=1)
    code = membrane.TRIANGLE_LAWS[law]

    def energy(strain):
        return membrane.triangle_law_energy(nodes @ strain.T, triangles, inverse, rest, code,
                                            MU, 4.0)

    assert energy(np.eye(3)) == pytest.approx(0.0, abs=1e-30)
    g = 1e-4
    for angle in (0.0, 0.3):
        c, s = math.cos(2 * angle), math.sin(2 * angle)
        shear = np.array([[1 + g * c, g * s, 0], [g * s, 1 - g * c, 0], [0, 0, 1]])
        assert energy(shear) / (2 * g ** 2 * area) == pytest.approx(MU, rel=1e-3)
    dilation = np.diag([1 + g, 1 + g, 1.0])
    assert energy(dilation) / (2 * g ** 2 * area) == pytest.approx(area_modulus, rel=1e-3)


@pytest.mark.parametrize("law", ["skalak", "neo_hookean"])
def test_triangle_law_forces_are_minus_the_gradient_of_their_energy(law):
    vertices, triangles = red_blood_cell(frequency=4)
    m = membrane.Membrane(vertices, triangles, MU, 2.2, 2.0, 0.0, True, True, 0.0, 0.0,
                          law=law, skalak_c=10.0)
    position = _perturbed(vertices, 0.15)
    force = np.zeros_like(position)
    membrane_kernels.triangle_forces(position, m.triangles, m.rest_inverse, m.rest_area,
                                     m.law, m.modulus, m.dilation, force)
    assert membrane.membrane_energy(vertices, m) == pytest.approx(0.0, abs=1e-30)
    h = 1e-4 * np.linalg.norm(vertices[1] - vertices[0])
    for node in np.random.default_rng(4).choice(len(position), 12, replace=False):
        for axis in range(3):
            up, down = position.copy(), position.copy()
            up[node, axis] += h
            down[node, axis] -= h
            numeric = -(membrane.membrane_energy(up, m)
                        - membrane.membrane_energy(down, m)) / (2 * h)
            assert numeric == pytest.approx(force[node, axis], rel=1e-5,
                                            abs=1e-7 * np.abs(force).max())


@pytest.mark.parametrize("bending", [False, True], ids=["edges", "bending"])
def test_membrane_forces_are_minus_the_gradient_of_their_energy(bending):
    vertices, triangles = red_blood_cell(frequency=4)
    m = _membrane(vertices, triangles)
    position = _perturbed(vertices, 0.08)
    force = _forces(m, position, bending)
    rng = np.random.default_rng(3)
    h = 1e-4 * np.linalg.norm(vertices[1] - vertices[0])
    for node in rng.choice(len(position), 12, replace=False):
        for axis in range(3):
            up, down = position.copy(), position.copy()
            up[node, axis] += h
            down[node, axis] -= h
            numeric = -(_energy(m, up, bending) - _energy(m, down, bending)) / (2 * h)
            assert numeric == pytest.approx(force[node, axis], rel=1e-5,
                                            abs=1e-7 * np.abs(force).max())


def test_the_area_and_volume_gradients_are_those_of_finite_differences():
    vertices, triangles = icosphere(1e-6, frequency=3)
    position = _perturbed(vertices)
    gradients = np.empty((2,) + position.shape)
    area, volume = membrane_kernels.area_volume(position, triangles, gradients, True)
    assert area == pytest.approx(membrane.triangle_area_total(position, triangles), rel=1e-12)
    h = 1e-12
    for node, axis in [(0, 0), (5, 1), (17, 2)]:
        up, down = position.copy(), position.copy()
        up[node, axis] += h
        down[node, axis] -= h
        empty = np.empty((2, 0, 3))
        a1, v1 = membrane_kernels.area_volume(up, triangles, empty, False)
        a0, v0 = membrane_kernels.area_volume(down, triangles, empty, False)
        assert gradients[0, node, axis] == pytest.approx((a1 - a0) / (2 * h), rel=1e-5)
        assert gradients[1, node, axis] == pytest.approx((v1 - v0) / (2 * h), rel=1e-5)


def test_the_local_area_force_is_minus_the_gradient_of_its_energy():
    vertices, triangles = red_blood_cell(frequency=4)
    m = membrane.Membrane(vertices, triangles, MU, 2.2, 2.0, 0.0, True, True, 0.0, 0.0,
                          local_area_modulus=MU)
    position = _perturbed(vertices, 0.08)
    force = np.zeros_like(position)
    membrane_kernels.local_area_forces(position, m.triangles, m.rest_area, m.local_modulus,
                                       force)

    def energy(x):
        a, b, c = (x[triangles[:, k]] for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        return 0.5 * MU * np.sum((area - m.rest_area) ** 2 / m.rest_area)

    h = 1e-4 * np.linalg.norm(vertices[1] - vertices[0])
    for node in (0, 7, 40, 65):
        for axis in range(3):
            up, down = position.copy(), position.copy()
            up[node, axis] += h
            down[node, axis] -= h
            numeric = -(energy(up) - energy(down)) / (2 * h)
            assert numeric == pytest.approx(force[node, axis], rel=1e-5,
                                            abs=1e-7 * np.abs(force).max())


CELL = """membrane = "wlc"
shear_modulus = 6.3e-6
bending_modulus = 2.4e-19
local_area_modulus = 6.3e-6
drag_rate = 2.0e4"""


def _case(body, end=2.0e-3, dt=1.0e-4, cell=CELL):
    from parmps import config, schema
    text = f"""title = "membrane test"
[domain]
lower = [-1.0e-5, -1.0e-5, -1.0e-5]
upper = [1.0e-5, 1.0e-5, 1.0e-5]
[physics]
gravity = [0.0, 0.0, 0.0]
[time]
end = {end}
fixed_dt = {dt}
output_interval = {dt}
[[body]]
name = "cell"
type = "shell"
node_mass = 1.0e-17
{cell}
{body}
"""
    return schema.validate(config.load_text(text, "membrane test"))


PULL = """
[[body.load]]
nodes = "right"
within = {within}
total = true
force = [{force}, 0.0, 0.0]
ramp = 5.0e-4
[[body.load]]
nodes = "left"
within = {within}
total = true
force = [-{force}, 0.0, 0.0]
ramp = 5.0e-4
"""


def _run(case, steps):
    from parmps.solids.mass_spring.model import MassSpringModel
    model = MassSpringModel.from_case(case)
    dt, body = case["time"]["fixed_dt"], model.bodies[0]
    worst = 0.0
    for step in range(steps):
        model.advance(step * dt, dt)
        model.check(step, (step + 1) * dt)
        worst = max(worst, abs(body.membrane.area_error(body.position)),
                    abs(body.volume_error()))
    return model, body, worst


def test_the_area_and_volume_of_a_small_pulled_shell_are_kept_within_1e_8():
    case = _case('shape = "capsule"\nradius = 1.0e-6\nlength = 2.0e-6\naxis = "x"\n'
                 'refinement = 3\n' + PULL.format(within=0.6e-6, force=5.0e-11))
    _, body, worst = _run(case, 20)
    assert np.ptp(body.position[:, 0]) > 4.05e-6       # it did stretch
    assert worst <= 1e-8
    assert body.energy()[1] > 0.0                       # the membrane's, stretched


def test_a_sphere_cannot_keep_both_its_area_and_its_volume():
    from parmps.errors import CaseError
    from parmps.solids.mass_spring.model import MassSpringModel
    with pytest.raises(CaseError, match="area_constraint = false"):
        MassSpringModel.from_case(_case('shape = "sphere"\nradius = 2.0e-6\nrefinement = 4'))


@pytest.mark.parametrize("law", ["wlc", "skalak"])
def test_a_coarse_cell_pulled_by_16_pn_comes_to_rest_longer_and_narrower(law):
    case = _case('shape = "red_blood_cell"\nrefinement = 8\n'
                 + PULL.format(within=1.0e-6, force=1.6e-11), end=4.0e-3)
    case["body"][0]["membrane"] = law
    model, body, worst = _run(case, 40)
    axial, transverse = np.ptp(body.position[:, 0]), np.ptp(body.position[:, 1])
    assert np.abs(body.velocity).max() < 1e-4        # at rest [m/s]
    assert 7.9e-6 < axial < 10.1e-6 and 5.58e-6 < transverse < 7.82e-6
    assert worst <= 1e-8


def test_a_membrane_stretched_past_its_chains_stops_the_run_naming_body_node_and_key():
    case = _case('shape = "red_blood_cell"\nrefinement = 6\nmaximum_extension = 1.3\n'
                 + PULL.format(within=1.0e-6, force=2.0e-9).replace("5.0e-4", "1.0e-4"))
    with pytest.raises(RunFailure, match=r"body 'cell'.*node \d+.*maximum_extension"):
        _run(case, 20)


def test_the_icosahedral_cell_is_closed_and_the_octahedral_cells_shape():
    from parmps.geometry.mesh import check_closed_surface, triangle_areas
    from parmps.geometry.mesh import enclosed_volume
    vertices, triangles = red_blood_cell(frequency=6, base="icosahedron")
    check_closed_surface("icosahedral cell", vertices, triangles)
    assert len(vertices) == 10 * 6 ** 2 + 2
    fine = red_blood_cell(frequency=24)
    assert triangle_areas(vertices, triangles).sum() == pytest.approx(
        triangle_areas(*fine).sum(), rel=0.02)
    assert enclosed_volume(vertices, triangles) == pytest.approx(enclosed_volume(*fine),
                                                                 rel=0.03)


def test_a_membrane_folded_over_stops_the_run_naming_the_node_and_the_settings():
    vertices, triangles = red_blood_cell(frequency=6, base="icosahedron")
    m = _membrane(vertices, triangles)
    m.check("cell", vertices)                      # at rest: nothing to say
    folded = vertices.copy()
    # The node nearest the top face's centre, slid past its neighbours: its triangles on
    # that side turn over.
    top = np.flatnonzero(vertices[:, 2] > 0)
    node = int(top[np.argmin(np.hypot(vertices[top, 0], vertices[top, 1]))])
    edge = np.linalg.norm(vertices[triangles[0, 0]] - vertices[triangles[0, 1]])
    folded[node, 0] += 3.0 * edge
    with pytest.raises(RunFailure, match=r"body 'cell': its membrane folded over at node "
                                         r"\d+ .*bending_modulus.*solid.safety"):
        m.check("cell", folded)


def test_a_membrane_pressed_through_itself_stops_the_run_though_no_triangle_folded():
    """The top face's dimple pushed smoothly through the bottom face: every dihedral turns
    little (the fold check is silent), but edges of the top face pierce the bottom's."""
    vertices, triangles = red_blood_cell(frequency=8, base="icosahedron")
    m = _membrane(vertices, triangles)
    m.check("cell", vertices)                      # at rest: nothing to say
    assert membrane_kernels.first_crossing(vertices, m.edges, m.triangles,
                                           1.0e-6) == (-1, -1)
    pressed = vertices.copy()
    rho2 = vertices[:, 0] ** 2 + vertices[:, 1] ** 2
    top = vertices[:, 2] > 0
    depth = 2.0 * vertices[top, 2][np.argmin(rho2[top])]      # twice the half-thickness
    pressed[top, 2] -= 1.5 * depth * np.exp(-rho2[top] / (1.5e-6) ** 2)
    turn = np.abs(membrane.dihedral_angles(pressed, m.quads) - m.rest_angle)
    assert turn.max() < membrane.FOLD_LIMIT
    with pytest.raises(RunFailure, match=r"body 'cell': its membrane passed through itself: "
                                         r"the edge at node \d+ crosses the triangle at node "
                                         r"\d+: raise bending_modulus.*solid.safety"):
        m.check("cell", pressed)


@pytest.mark.parametrize("law, key, message", [
    ("wlc", "skalak_c = 5.0", r"'cell'\.skalak_c applies to membrane = \"skalak\" only"),
    ("skalak", "maximum_extension = 1.5",
     r"'cell'\.maximum_extension applies to membrane = \"wlc\" only, not \"skalak\""),
    ("springs", "", r"'cell'\.drag_rate applies to a cell membrane only"),
])
def test_a_membrane_key_of_another_law_is_refused_naming_it(law, key, message):
    from parmps.errors import CaseError
    cell = CELL.replace('"wlc"', f'"{law}"')
    if law == "springs":
        cell = "stiffness = 1.0e-6\ndrag_rate = 1.0"
    with pytest.raises(CaseError, match=message):
        _case(f'shape = "red_blood_cell"\nrefinement = 4\n{key}\n', cell=cell)


def _verlet_growth(m, vertices, mass, h, steps, seed=5):
    """How much a tiny random displacement of ``m``'s rest shape grows over ``steps``
    substeps of h of the run's own compiled scheme (no drag, loads or constraints)."""
    n = len(vertices)
    rng = np.random.default_rng(seed)
    start = 1e-6 * float(m.rest_length.mean()) * rng.standard_normal((n, 3))
    position, velocity = vertices + start, np.zeros((n, 3))
    acceleration = m.elastic_force(position) / mass[:, None]
    none = np.zeros(0)
    membrane_kernels.membrane_substeps(
        position, velocity, acceleration, mass, 1.0 / mass, np.zeros((n, 3)),
        np.zeros((0, n, 3)), none, none, none, 0.0, h, steps, m.edges, m.max_length, m.kp,
        m.kbt_over_p, m.exponent, 0.0, membrane.EXTENSION_LIMIT, m.quads, m.rest_cosine,
        m.rest_sine, m.kb, m.rest_area, m.local_modulus, 0.0, m.triangle_law(), m.triangles,
        m.rest, np.array([False, False]), 1e-12, 0, np.zeros(n), np.zeros((n, 3)))
    return np.abs(position - vertices).max() / np.abs(start).max()


@pytest.mark.parametrize("law", ["wlc", "neo_hookean"])
def test_the_substep_limit_is_the_membranes_own_verlet_limit(law):
    """The limit 2/omega from Membrane.highest_frequency is where the run's scheme turns
    unstable: 3 % below it a small disturbance stays small, 3 % above it it explodes (a
    stand-in of springs is 1.2 times too stiff for the chains, 0.9 for the sheet)."""
    vertices, triangles = red_blood_cell(frequency=6, base="icosahedron")
    m = membrane.Membrane(vertices, triangles, MU, 2.2, 2.0, KAPPA, False, False, 0.0, 0.0,
                          local_area_modulus=MU if law == "wlc" else 0.0, law=law)
    mass = np.full(len(vertices), 1e-17)
    limit = 2.0 / m.highest_frequency(vertices, mass)
    assert _verlet_growth(m, vertices, mass, 0.97 * limit, 3000) < 10.0
    assert _verlet_growth(m, vertices, mass, 1.03 * limit, 3000) > 1e3
