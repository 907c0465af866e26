"""Solids in 3D (and the parts written once for any d): the lattice's geometry, the enclosed
volume and its gradient, the compiled kernels, the iterated volume multiplier, the 7x7x7
pair of validation/mass_spring_7x7x7 and 3D input refused in one line."""

import itertools
import pathlib
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest

from parmps import config, open_result, schema, validation
from parmps.errors import CaseError
from parmps.geometry.mesh import enclosed_volume
from parmps.solids.mass_spring.body import (Body, boundary_facets, damping_forces, spring_forces,
                                            volume_multiplier)
from parmps.solids.mass_spring.build import build_bodies
from parmps.solids.mass_spring.kernels import held_force_substeps, network_forces
from parmps.solids.mass_spring.lattice import AXIAL, FACE_DIAGONAL, lattice_geometry
from parmps.solids.mass_spring.model import MassSpringModel
from parmps.solids.mass_spring.surface import volume_gradient
from test_solid import load_case, run

ROOT = pathlib.Path(__file__).resolve().parents[1]


def perturbed_lattice(shape, seed, amplitude=0.2, spacing=0.1, lower=(1.0, -2.0, 0.5)):
    position, springs, kind, boundary = lattice_geometry(shape, spacing, lower)
    rng = np.random.default_rng(seed)
    position = position + amplitude * spacing * rng.uniform(-1, 1, position.shape)
    return position, springs, boundary_facets(boundary)


# ---------------------------------------------------------------------------
# The lattice


def test_3d_lattice_counts_match_hand_counts():
    position, springs, kind, triangles = lattice_geometry((3, 4, 5), 0.5, (1.0, 2.0, 3.0))
    assert position.shape == (60, 3)
    # Axial: 2*4*5 along x + 3*3*5 along y + 3*4*4 along z = 40 + 45 + 48.
    assert (kind == AXIAL).sum() == 133
    # Face diagonals, two per square: xy 2*3 squares x 5 layers, xz 2*4 x 4, yz 3*4 x 3.
    assert (kind == FACE_DIAGONAL).sum() == 2 * (30 + 32 + 36)
    # Surface: two triangles per face square, 2 * (2*3 + 2*4 + 3*4) squares.
    assert triangles.shape == (2 * 2 * 26, 3)
    assert len({tuple(sorted(s)) for s in springs.tolist()}) == len(springs)
    length = np.linalg.norm(position[springs[:, 0]] - position[springs[:, 1]], axis=1)
    assert np.allclose(length[kind == AXIAL], 0.5)
    assert np.allclose(length[kind == FACE_DIAGONAL], 0.5 * np.sqrt(2))
    # Node i + nx j + nx ny k sits at lower + (i, j, k) spacing.
    assert np.array_equal(position[1 + 3 * 2 + 12 * 4], [1.5, 3.0, 5.0])
    # The 7x7x7 body: 3*6*49 axial, 2*3*36*7 diagonal, 12*36 triangles.
    _, springs, kind, triangles = lattice_geometry((7, 7, 7), 0.01, (0.0, 0.0, 0.0))
    assert ((kind == AXIAL).sum(), (kind == FACE_DIAGONAL).sum(), len(triangles)) == (
        882, 1512, 432)


def test_3d_surface_is_closed_and_outward():
    position, _, _, triangles = lattice_geometry((3, 4, 5), 0.5, (0.0, 0.0, 0.0))
    # Closed and consistently oriented: every directed edge once, and its reverse once.
    edges = [(t[a], t[(a + 1) % 3]) for t in triangles.tolist() for a in range(3)]
    assert len(set(edges)) == len(edges)
    assert set(edges) == {(b, a) for a, b in edges}
    # Outward: each normal points away from the box's centre, off the face's plane.
    corners = position[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    outward = corners.mean(axis=1) - position.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", normal, outward) > 0)
    assert np.allclose(normal.sum(axis=0), 0.0)
    # Only surface nodes carry triangles: the 2*3*1 interior nodes do not.
    assert len(np.unique(triangles)) == 60 - 1 * 2 * 3


# ---------------------------------------------------------------------------
# The enclosed volume and its gradient


def test_unit_cube_volume_is_exact():
    for lower in ((0.0, 0.0, 0.0), (3.0, -5.0, 7.0)):
        position, _, _, triangles = lattice_geometry((2, 2, 2), 1.0, lower)
        assert enclosed_volume(position, triangles) == 1.0
        assert enclosed_volume(position, triangles[:, ::-1]) == -1.0
    position, _, _, triangles = lattice_geometry((4, 5, 6), 0.5, (0.25, 0.5, -1.0))
    assert enclosed_volume(position, triangles) == 1.5 * 2.0 * 2.5


def test_volume_is_that_of_the_rotated_and_moved_body():
    position, _, facets = perturbed_lattice((4, 3, 5), seed=4)
    volume = enclosed_volume(position, facets)
    rotation, _ = np.linalg.qr(np.random.default_rng(5).standard_normal((3, 3)))
    rotation *= np.sign(np.linalg.det(rotation))
    moved = position @ rotation.T + [100.0, -50.0, 20.0]
    assert enclosed_volume(moved, facets) == pytest.approx(volume, rel=1e-12)


@pytest.mark.parametrize("shape", [(5, 4), (4, 3, 5), (2, 2, 2)])
def test_volume_gradient_matches_finite_differences(shape):
    position, _, facets = perturbed_lattice(shape, seed=len(shape),
                                            lower=(1.0, -2.0, 0.5)[:len(shape)])
    gradient = volume_gradient(position, facets)
    h = 1e-6
    numeric = np.zeros_like(position)
    for node, axis in itertools.product(range(len(position)), range(position.shape[1])):
        up, down = position.copy(), position.copy()
        up[node, axis] += h
        down[node, axis] -= h
        numeric[node, axis] = (enclosed_volume(up, facets)
                               - enclosed_volume(down, facets)) / (2 * h)
    assert np.abs(numeric - gradient).max() < 1e-7 * np.abs(gradient).max()
    # Interior nodes get none; a translation changes nothing; V is homogeneous of
    # degree d, so sum x.gradV = d V (Euler).
    interior = np.setdiff1d(np.arange(len(position)), facets)
    assert np.all(gradient[interior] == 0.0)
    assert np.allclose(gradient.sum(axis=0), 0.0, atol=1e-14)
    d = position.shape[1]
    assert np.sum(position * gradient) == pytest.approx(d * enclosed_volume(position, facets),
                                                        rel=1e-10)


def test_2d_facets_give_the_polygon_area_and_its_gradient():
    position, _, facets = perturbed_lattice((5, 4), seed=7, lower=(0.3, 0.1))
    x, y = position[facets[:, 0]].T
    u, v = position[facets[:, 1]].T
    assert enclosed_volume(position, facets) == pytest.approx(0.5 * np.sum(x * v - u * y),
                                                              rel=1e-13)
    loop = facets[:, 0]
    after, before = np.roll(loop, -1), np.roll(loop, 1)
    expected = 0.5 * np.column_stack([position[after, 1] - position[before, 1],
                                      position[before, 0] - position[after, 0]])
    assert np.allclose(volume_gradient(position, facets)[loop], expected, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------
# The compiled kernels in 3D


def body_3d(constraint=True, seed=1, speed=0.3, damping=0.2, n=4):
    position, springs, _, triangles = lattice_geometry((n, n, n), 0.01, (0.0, 0.0, 0.0))
    velocity = speed * np.random.default_rng(seed).standard_normal(position.shape)
    return Body("cube", position, velocity, 0.01, springs, 1000.0, damping, triangles,
                volume_constraint=constraint)


@pytest.mark.parametrize("axial", [False, True], ids=["relative", "axial"])
def test_compiled_network_forces_match_the_numpy_forms_in_3d(axial):
    body = body_3d()
    rng = np.random.default_rng(2)
    position = body.position + 1e-3 * rng.standard_normal(body.position.shape)
    stiffness = body.stiffness * (1.0 + rng.random(len(body.springs)))
    if axial:
        separation = position[body.springs[:, 0]] - position[body.springs[:, 1]]
        relative = body.velocity[body.springs[:, 0]] - body.velocity[body.springs[:, 1]]
        rate = (body.damping * np.einsum("ij,ij->i", relative, separation)
                / np.einsum("ij,ij->i", separation, separation))
        dashpots = np.zeros_like(position)
        np.add.at(dashpots, body.springs[:, 0], -rate[:, None] * separation)
        np.add.at(dashpots, body.springs[:, 1], rate[:, None] * separation)
    else:
        dashpots = damping_forces(body.velocity, body.springs, body.damping)
    expected = spring_forces(position, body.springs, body.rest_length, stiffness) + dashpots
    force = np.zeros_like(position)
    network_forces(position, body.velocity, body.springs, body.rest_length, stiffness,
                   body.damping, axial, force)
    assert np.allclose(force, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_held_force_substeps_match_the_numpy_loop_in_3d():
    body = body_3d(constraint=False)
    external = np.linspace(-1e-3, 1e-3, body.position.size).reshape(body.position.shape)
    h = 0.5 * body.stability_limit()
    position, velocity = body.position.copy(), body.velocity.copy()
    inverse_mass = body.inverse_mass[:, None]

    def acceleration(x, v):
        return inverse_mass * (spring_forces(x, body.springs, body.rest_length, body.stiffness)
                               + damping_forces(v, body.springs, body.damping) + external)

    a = acceleration(position, velocity)
    compiled = (position.copy(), velocity.copy(), a.copy())
    held_force_substeps(*compiled, body.inverse_mass, body.springs, body.rest_length,
                        body.stiffness, body.damping, False, external, h, 30,
                        np.zeros(len(position)), np.zeros_like(position))
    for _ in range(30):
        velocity += 0.5 * h * a
        position += h * velocity
        a = acceleration(position, velocity)
        velocity += 0.5 * h * a
    assert np.allclose(compiled[0], position, rtol=0, atol=1e-14)
    assert np.allclose(compiled[1], velocity, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_compiled_substeps_with_loads_and_constraint_match_the_numpy_loop(d):
    """kernels.body_substeps against Body.acceleration_at's substeps (compiled = False)."""
    def body():
        position, springs, _, boundary = lattice_geometry((4,) * d, 0.01, (0.0,) * d)
        velocity = 0.2 * np.random.default_rng(6).standard_normal(position.shape)
        top = np.flatnonzero(position[:, -1] == position[:, -1].max())
        side = np.flatnonzero(position[:, 0] == 0.0)
        loads = [(top, -0.3 * np.eye(d)[-1], 0.0, 0.02, 0.005),
                 (side, 0.1 * np.eye(d)[0], 0.004, 1.0, 0.0)]
        b = Body("block", position, velocity, 0.01, springs, 1000.0, 0.2, boundary,
                 pinned=position[:, -1] == 0.0, gravity=-9.81 * np.eye(d)[-1], loads=loads)
        b.fluid_force[:] = np.linspace(-1e-3, 1e-3, b.position.size).reshape(b.position.shape)
        b.constraint_iterations, b.constraint_tolerance = 8, 1e-12
        return b
    compiled, numpy_form = body(), body()
    numpy_form.compiled = False
    h = 0.5 * compiled.stability_limit()
    steps = []
    for step in range(6):
        compiled.advance(step * 10 * h, 10 * h, h)
        numpy_form.advance(step * 10 * h, 10 * h, h)
        steps.append((compiled.newton_steps, numpy_form.newton_steps))
    assert np.allclose(compiled.position, numpy_form.position, rtol=0, atol=1e-15)
    assert np.allclose(compiled.velocity, numpy_form.velocity, rtol=1e-9, atol=1e-12)
    assert compiled.multiplier == pytest.approx(numpy_form.multiplier, rel=1e-6)
    # The same steps, but for a residual within round-off of the tolerance.
    assert all(abs(a - b) <= 1 for a, b in steps) and max(a for a, _ in steps) >= 1
    assert abs(compiled.volume_error()) < 1e-11


# ---------------------------------------------------------------------------
# The multiplier, iterated


@pytest.mark.parametrize("shape", [(6, 5), (4, 4, 4)])
def test_newton_steps_put_the_next_position_on_the_rest_volume(shape):
    position, _, facets = perturbed_lattice(shape, seed=8, amplitude=0.1, spacing=0.01,
                                            lower=(0.0, 0.0, 0.0)[:len(shape)])
    rng = np.random.default_rng(9)
    velocity = rng.standard_normal(position.shape)
    force = rng.standard_normal(position.shape)
    inverse_mass = np.full(len(position), 100.0)
    rest = enclosed_volume(position, facets) * 1.001
    dt = 2e-4

    def next_volume(iterations):
        multiplier, gradient, steps = volume_multiplier(
            position, facets, rest, velocity, inverse_mass, force, dt, 1e-13, iterations)
        step = dt * velocity + dt ** 2 * inverse_mass[:, None] * (force - gradient * multiplier)
        return enclosed_volume(position + step, facets) / rest - 1.0, steps

    linear, none = next_volume(0)
    iterated, steps = next_volume(8)
    assert none == 0 and 1 <= steps <= 3
    assert abs(linear) > 1e-9 and abs(iterated) < 1e-12


def test_momentum_is_conserved_with_the_constraint_in_3d():
    body = body_3d(seed=3)
    system = MassSpringModel([body])
    p0 = body.momentum()
    scale = float(np.sum(body.mass * np.linalg.norm(body.velocity, axis=1)))
    momentum = run(system, 1e-3, 50, body.momentum)
    errors = run(system, 1e-3, 50, body.volume_error)
    assert np.max(np.abs(momentum - p0)) < 1e-13 * scale
    assert np.max(np.abs(errors)) < 1e-11 and body.newton_steps >= 1


# ---------------------------------------------------------------------------
# The 7x7x7 pair (validation/mass_spring_7x7x7)


def run_case(path):
    case = load_case(path)
    system = MassSpringModel.from_case(case)
    body = system.bodies[0]
    dt = case["time"]["fixed_dt"]
    steps = int(round(case["time"]["end"] / dt))
    errors = run(system, dt, steps, body.volume_error)
    return dt * np.arange(1, steps + 1), errors, case, body


def test_7x7x7_case_keeps_its_volume_with_the_constraint():
    check = validation.load("mass_spring_7x7x7")
    time, errors, case, body = run_case(check.case_path)
    assert body.dimension == 3 and body.n_nodes == 343 and len(body.facets) == 432
    assert np.all(np.isfinite(errors))
    assert np.max(np.abs(errors)) < check.tolerance["volume_error"]
    # It was pressed: the top moved down while the load acted, and came back.
    assert body.position[:, 2].max() == pytest.approx(0.06, abs=1e-3)


def test_7x7x7_case_loses_volume_without_the_constraint():
    check = validation.load("mass_spring_7x7x7")
    time, errors, case, _ = run_case(check.other_cases["unconstrained"])
    load = case["body"][0]["load"][0]
    loaded = (time > load["start"] + load["ramp"]) & (time < load["end"])
    low, high = check.tolerance["unconstrained_volume_error"]
    assert low < np.max(np.abs(errors[loaded])) < high


# ---------------------------------------------------------------------------
# 3D input


BASE_3D = """
[domain]
lower = [-1.0, -1.0, -1.0]
upper = [1.0, 1.0, 1.0]
[time]
end = 0.01
[[body]]
name = "b"
nx = 3
ny = 4
nz = 5
spacing = 0.01
node_mass = 0.01
stiffness = 100.0
"""


def build(text):
    return build_bodies(schema.validate(config.load_text(text)))


def test_3d_node_sets():
    (body,) = build(BASE_3D + """
pinned = "front"
[[body.load]]
nodes = "layer"
index = 4
force = [0.0, 0.0, -1.0]
[[body.load]]
nodes = "top"
force = [1.0, 0.0, 0.0]
""")
    assert body.gravity.tolist() == [0.0, 0.0, -9.81]
    assert np.flatnonzero(body.pinned).tolist() == [i + 12 * k for k in range(5) for i in range(3)]
    layer, top = body.load_field
    assert np.array_equal(np.flatnonzero(layer[:, 2]), np.arange(48, 60))
    assert np.array_equal(np.flatnonzero(top[:, 0]), np.arange(48, 60))
    assert body.rest_volume == pytest.approx(0.02 * 0.03 * 0.04)


def test_pinned_outside_holds_the_nodes_on_or_outside_the_box():
    """A plate clamped along a box's sides: the nodes strictly inside move, the rest (its
    faces included, within rounding) are pinned, on top of ``pinned``."""
    (body,) = build(BASE_3D + "pinned_outside = [[0.0, 0.0, -1.0], [0.02, 0.03, 1.0]]\n"
                    "pinned = \"bottom\"\n")
    position = body.position
    free = ((position[:, 0] > 0.005) & (position[:, 0] < 0.015) & (position[:, 1] > 0.005)
            & (position[:, 1] < 0.025) & (position[:, 2] > 0.005))
    assert np.count_nonzero(free) == 2 * 4
    assert np.array_equal(~body.pinned, free)


@pytest.mark.parametrize("box, pattern", [
    ("[[0.0, 0.0, -1.0]]", r"must be two points \[lower, upper\] with lower < "
                           r"upper on every axis"),
    ("[[0.02, 0.0, -1.0], [0.0, 0.03, 1.0]]", r"with lower < upper on every axis"),
    ("[[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]", r"holds every node of the body strictly inside: "
                                              r"it pins none of them"),
    ("[[0.0, 0.0, 0.0], [0.01, 0.01, 0.01]]", r"holds no node of the body strictly inside"),
])
def test_a_bad_pinned_outside_box_is_refused_in_one_line(box, pattern):
    with pytest.raises(CaseError, match=r"body\[0\] 'b'.pinned_outside.*" + pattern) as info:
        build(BASE_3D + f"pinned_outside = {box}\n")
    assert "\n" not in str(info.value)


BAD_3D = {
    "wrong_components": ("lower = [0.0, 0.0]", r"body\[0\].lower has 2 components but the "
                                               r"case is 3D"),
    "row_in_3d": ("[[body.load]]\nnodes = \"row\"\nforce = [0.0, 0.0, 1.0]",
                  r"load\[0\].nodes = \"row\" names a set of a 2D lattice; this body is 3D"),
    "general_in_3d": ("type = \"general\"",
                      r"(applies to lattice bodies only|runs in 2D cases only)"),
    "anchors_in_3d": ("anchors = [[0.0, 0.0, -0.01]]", r"anchors .* apply to 2D cases only"),
    "nz_too_small": ("nz = 1", r"body\[0\] 'b'.nz must be >= 2"),
}


@pytest.mark.parametrize("name", sorted(BAD_3D))
def test_bad_3d_bodies_are_refused_with_one_line(name):
    extra, pattern = BAD_3D[name]
    text = BASE_3D.replace("nz = 5\n", "") + ("" if name == "nz_too_small" else "nz = 5\n")
    with pytest.raises(CaseError, match=pattern) as info:
        build(text + extra + "\n")
    assert "\n" not in str(info.value)


def test_2d_words_and_keys_refused_in_their_wrong_dimension():
    base = BASE_3D.replace("[-1.0, -1.0, -1.0]", "[-1.0, -1.0]").replace(
        "[1.0, 1.0, 1.0]", "[1.0, 1.0]")
    with pytest.raises(CaseError, match=r"nz applies to 3D cases only"):
        build(base)
    with pytest.raises(CaseError, match=r"\"front\" names a side of a 3D body"):
        build(base.replace("nz = 5\n", "pinned = \"front\"\n"))
    with pytest.raises(CaseError, match=r"\"layer\" names a set of a 3D lattice"):
        build(base.replace("nz = 5\n", "") + "[[body.load]]\nnodes = \"layer\"\n"
              "force = [0.0, 1.0]\n")


def cli(*args):
    return subprocess.run([sys.executable, "-m", "parmps", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_3d_solid_only_run_writes_nodes_surface_and_series(tmp_path):
    out = tmp_path / "out"
    result = cli(ROOT / "cases" / "mass_spring_7x7x7.toml", "-o", out, "--end-time", "0.02")
    assert result.returncode == 0, result.stderr
    with open_result(out) as run_result:
        body = run_result.bodies["block"]
        steps = len(run_result.diagnostics["step"])
        assert body.volume_error.shape == (steps,) and body.centroid.shape == (steps, 3)
        assert body.fluid_force.shape == (steps, 3) and body.newton_steps.shape == (steps,)
        assert body.surface.shape == (432, 3) and body.springs.shape == (2394, 2)
        nodes = run_result.frames[-1].bodies["block"]
        assert nodes["position"].shape == (343, 3) and nodes["velocity"].shape == (343, 3)
        assert np.max(np.abs(body.volume_error)) < 1e-8
    xdmf = ElementTree.parse(out / "result.xdmf").getroot()
    types = {t.get("TopologyType") for t in xdmf.iter("Topology")}
    assert {"Polyline", "Triangle"} <= types
    triangles = [t for t in xdmf.iter("Topology") if t.get("TopologyType") == "Triangle"]
    assert triangles[0].find("DataItem").text.endswith(":/solids/block/surface")
    assert {g.get("GeometryType") for g in xdmf.iter("Geometry")} == {"XYZ"}


@pytest.mark.parametrize("n", [2, 3], ids=["2d", "3d"])
def test_the_first_substep_from_rest_keeps_the_volume(n):
    """A body at rest under a sudden load: its first substep drifts h^2/2 a, not the
    h^2 a of the Verlet loop's later ones, and the multiplier predicts exactly that."""
    shape = (5,) * n
    position, springs, _, boundary = lattice_geometry(shape, 0.01, (0.0,) * n)
    facets = boundary_facets(boundary)
    body = Body("block", position, np.zeros_like(position), 0.01, springs, 1000.0, 0.0,
                boundary, volume_constraint=True)
    body.constraint_iterations, body.constraint_tolerance = 8, 1e-13
    # A strong push on the top layer, held over the step.
    top = position[:, -1] > position[:, -1].max() - 1e-9
    body.fluid_force[top, -1] = -5.0
    body.advance(0.0, 1e-3, 1e-3)
    assert abs(enclosed_volume(body.position, facets) / body.rest_volume - 1.0) < 1e-11
