"""Mass-spring solids (issue 4): Verlet accuracy, conservation, the area
constraint, automatic substeps, and bad bodies refused with one line."""

import math
import pathlib

import numpy as np
import pytest

from parmps import config, schema, validation
from parmps.solids.mass_spring.build import build_bodies, lattice_geometry
from parmps.solids.mass_spring.lattice import AXIAL, FACE_DIAGONAL
from parmps.errors import CaseError
from parmps.solids.mass_spring.body import Body, area_gradient, polygon_area
from parmps.solids.mass_spring.model import MassSpringModel

ROOT = pathlib.Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def load_case(path):
    return schema.validate(config.load_text(pathlib.Path(path).read_text()))


def lattice_body(stiffness=1.0e3, mass=0.01, damping=0.0, constraint=True, n=7, seed=None,
                 speed=0.0):
    position, springs, _, boundary = lattice_geometry((n, n), 0.01, (0.0, 0.0))
    velocity = np.zeros_like(position)
    if seed is not None:
        velocity = speed * np.random.default_rng(seed).standard_normal(position.shape)
    return Body("lattice", position, velocity, mass, springs, stiffness, damping, boundary,
                volume_constraint=constraint)


def run(system, dt_outer, steps, record):
    out = []
    for step in range(steps):
        system.advance(step * dt_outer, dt_outer)
        out.append(record())
    return np.array(out)


# ---------------------------------------------------------------------------
# Geometry


def test_area_and_gradient_of_a_square():
    position = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    loop = np.arange(4)
    assert polygon_area(position, loop) == pytest.approx(2.0)
    assert polygon_area(position, loop[::-1]) == pytest.approx(-2.0)
    # Finite differences of the area agree with the analytic gradient.
    gradient = area_gradient(position, loop)
    h = 1e-7
    for node in range(4):
        for axis in range(2):
            moved = position.copy()
            moved[node, axis] += h
            numeric = (polygon_area(moved, loop) - polygon_area(position, loop)) / h
            assert gradient[node, axis] == pytest.approx(numeric, abs=1e-6)
    assert np.allclose(gradient.sum(axis=0), 0.0)


def test_lattice_boundary_is_counter_clockwise_and_complete():
    position, springs, kind, boundary = lattice_geometry((4, 3), 0.5, (1.0, 2.0))
    assert len(boundary) == 2 * (4 + 3) - 4
    assert len(set(boundary.tolist())) == len(boundary)
    assert polygon_area(position, boundary) == pytest.approx(1.5 * 1.0)
    # Structural: 3*3 + 4*2 = 17; shear: 2 per cell, 3*2 cells.
    assert (kind == AXIAL).sum() == 17 and (kind == FACE_DIAGONAL).sum() == 12
    assert len({tuple(sorted(s)) for s in springs.tolist()}) == len(springs)


# ---------------------------------------------------------------------------
# Two nodes on one spring


def two_node_system(substep):
    m1, m2, stiffness = 0.01, 0.03, 100.0
    rest = 0.1
    stretch = 0.01
    position = [[0.0, 0.0], [rest, 0.0]]
    body = Body("pair", position, np.zeros((2, 2)), [m1, m2], [[0, 1]], stiffness, 0.0,
                boundary=[], volume_constraint=False)
    # Stretch after construction so the rest length stays `rest`.
    body.position[1, 0] += stretch
    reduced = m1 * m2 / (m1 + m2)
    period = 2 * math.pi * math.sqrt(reduced / stiffness)
    return MassSpringModel([body], substep=substep), body, period


def test_two_node_spring_period_and_energy():
    _, _, period = two_node_system(0.0)
    system, body, _ = two_node_system(period / 1000)
    periods = 100
    outer = period / 20
    steps = int(round(periods * period / outer))
    energy0 = sum(body.energy())

    def record():
        return (body.position[1, 0] - body.position[0, 0] - body.rest_length[0],
                sum(body.energy()))

    samples = run(system, outer, steps, record)
    stretch, energy = samples[:, 0], samples[:, 1]
    time = outer * np.arange(1, steps + 1)
    # Upward zero crossings of the stretch, linearly interpolated.
    k = np.flatnonzero((stretch[:-1] < 0) & (stretch[1:] >= 0))
    crossing = time[k] + outer * (-stretch[k]) / (stretch[k + 1] - stretch[k])
    measured = (crossing[-1] - crossing[0]) / (len(crossing) - 1)
    assert abs(measured / period - 1) < 0.005
    drift = np.max(np.abs(energy - energy0)) / energy0
    assert drift < 1e-4


def test_two_node_spring_at_the_automatic_substep():
    # The automatic substep is chosen for stability (safety 0.5 of the limit),
    # not accuracy: the period then follows Verlet's omega_h = 2 asin(omega h / 2).
    system, body, period = two_node_system(0.0)
    h = system.stable_substep()
    omega = 2 * math.pi / period
    assert omega * h < 2
    expected = 2 * math.pi / (2 * math.asin(omega * h / 2) / h)
    energy0 = sum(body.energy())
    samples = run(system, h, int(100 * period / h),
                  lambda: (body.position[1, 0] - body.position[0, 0] - body.rest_length[0],
                           sum(body.energy())))
    stretch = samples[:, 0]
    k = np.flatnonzero((stretch[:-1] < 0) & (stretch[1:] >= 0))
    crossing = h * (k + 1) + h * (-stretch[k]) / (stretch[k + 1] - stretch[k])
    measured = (crossing[-1] - crossing[0]) / (len(crossing) - 1)
    assert measured == pytest.approx(expected, rel=2e-3)
    assert np.max(np.abs(samples[:, 1] / energy0 - 1)) < 0.5


# ---------------------------------------------------------------------------
# Momentum and the constraint


@pytest.mark.parametrize("constraint", [False, True])
def test_momentum_conserved_without_external_force(constraint):
    body = lattice_body(damping=0.05, constraint=constraint, seed=1, speed=0.2)
    body.gravity = np.zeros(2)
    system = MassSpringModel([body])
    p0 = body.momentum()
    scale = float(np.sum(body.mass * np.linalg.norm(body.velocity, axis=1)))
    momentum = run(system, 1e-3, 200, body.momentum)
    assert np.max(np.abs(momentum - p0)) < 1e-13 * scale
    if constraint:
        assert abs(body.volume_error()) < 1e-6
    else:
        assert abs(body.volume_error()) > 1e-4  # the random kick does change the area


def run_case(path, dt_outer=None):
    case = load_case(path)
    system = MassSpringModel.from_case(case)
    body = system.bodies[0]
    dt = dt_outer or case["time"]["fixed_dt"]
    steps = int(round(case["time"]["end"] / dt))
    errors = run(system, dt, steps, body.volume_error)
    return dt * np.arange(1, steps + 1), errors, case


def test_7x7_case_keeps_its_area_with_the_constraint():
    check = validation.load("mass_spring_7x7")
    time, errors, case = run_case(check.case_path)
    assert np.all(np.isfinite(errors))
    assert np.max(np.abs(errors)) < check.tolerance["volume_error"]


def test_7x7_case_loses_area_without_the_constraint():
    check = validation.load("mass_spring_7x7")
    time, errors, case = run_case(check.other_cases["unconstrained"])
    load = case["body"][0]["load"][0]
    loaded = (time > load["start"] + load["ramp"]) & (time < load["end"])
    # Percent level while pressed, and the constrained case is not.
    low, high = check.tolerance["unconstrained_volume_error"]
    assert low < np.max(np.abs(errors[loaded])) < high


# ---------------------------------------------------------------------------
# Stiffness sweep: stable at any stiffness, substeps ~ sqrt(k)


def test_stiffness_sweep_stable_and_substeps_grow_like_sqrt_k():
    stiffnesses = 10.0 ** np.arange(1, 8)
    dt_outer = 0.05
    counts = []
    for stiffness in stiffnesses:
        # Random node velocities put energy into every mode, the stiffest included.
        body = lattice_body(stiffness=stiffness, seed=2, speed=0.05)
        system = MassSpringModel([body])
        energy0 = sum(body.energy())
        energy = run(system, dt_outer, 4, lambda: sum(body.energy()))
        assert np.all(np.isfinite(energy))
        assert np.all(np.abs(energy / energy0 - 1) < 0.1), f"k = {stiffness:g}: {energy}"
        counts.append(system.last_substep_counts[body.name])
    slope = np.polyfit(np.log(stiffnesses), np.log(counts), 1)[0]
    assert 0.45 < slope < 0.55, (counts, slope)


def test_fixed_substep_above_the_limit_is_refused_with_the_limit():
    body = lattice_body(stiffness=1e5)
    limit = body.stability_limit()
    MassSpringModel([body], substep=0.9 * limit)
    with pytest.raises(CaseError, match=f"stability limit.*{limit:.6g}"):
        MassSpringModel([lattice_body(stiffness=1e5)], substep=1.1 * limit)


def _dense_highest_frequency(body):
    """sqrt of the largest eigenvalue of M^-1 K, K assembled spring by spring (dense)."""
    n, d = body.position.shape
    stiffness_matrix = np.zeros((d * n, d * n))
    for (i, j), k, length in zip(body.springs, body.stiffness, body.rest_length):
        e = (body.position[i] - body.position[j]) / length
        block = k * np.outer(e, e)
        for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            stiffness_matrix[d * a:d * a + d, d * b:d * b + d] += sign * block
    root = 1.0 / np.sqrt(np.repeat(body.mass, d))
    return math.sqrt(np.linalg.eigvalsh(root[:, None] * stiffness_matrix * root[None, :]).max())


@pytest.mark.parametrize("shape", [(4, 4), (3, 3, 3), (12, 12, 12)])
def test_limit_is_the_true_highest_frequency_and_the_node_bound_lies_above_it(shape):
    # 2/omega of the linearised network, to 1e-6 (Lanczos for the 12^3 body's 5,184 dofs,
    # a dense solve for the small ones), with node masses that differ: the node bound
    # (kept for the damping rate) is an upper bound of the same omega, 1.3-2 times it.
    from parmps.solids.mass_spring.body import stiffest_frequency
    position, springs, _, boundary = lattice_geometry(shape, 0.01, (0.0,) * len(shape))
    mass = 0.01 * (1.0 + np.random.default_rng(1).random(len(position)))
    stiffness = 1e3 * (1.0 + np.random.default_rng(2).random(len(springs)))
    body = Body("lattice", position, np.zeros_like(position), mass, springs, stiffness, 0.0,
                boundary)
    omega_true = _dense_highest_frequency(body) if len(position) <= 400 else None
    limit = body.stability_limit()
    if omega_true is not None:
        assert limit == pytest.approx(2 / omega_true, rel=1e-6)
    omega_bound, _ = stiffest_frequency(body.mass, body.springs, body.stiffness)
    assert 1.2 < omega_bound * limit / 2 < 2.5


def test_a_large_lattice_is_stable_at_its_automatic_substep():
    # The 12^3 lattice (Lanczos's limit) with random velocities in every mode, the stiffest
    # included, no damping and no constraint. At the automatic substep (half the limit) the
    # energy read at the full steps sits 6.5 % above its start (Verlet's modified energy:
    # the offset goes as (omega h)^2, 1.5 % at a quarter of the limit) and stays there:
    # within 1 % from 500 to 4000 substeps. At 1.05 times the limit the stiffest mode grows
    # and the energy runs away.
    position, springs, _, boundary = lattice_geometry((12, 12, 12), 0.01, (0.0,) * 3)
    velocity = 0.01 * np.random.default_rng(3).standard_normal(position.shape)
    energy0 = 0.5 * 0.01 * float(np.sum(velocity ** 2))

    def energies(factor, blocks):
        body = Body("lattice", position, velocity, 0.01, springs, 1e3, 0.0, boundary,
                    volume_constraint=False)
        h = factor * body.stability_limit()
        out = []
        for _ in range(blocks):
            assert body.advance(0.0, 500 * h, h) == 500
            out.append(sum(body.energy()) / energy0)
        return np.array(out)

    stable = energies(0.5, 8)
    assert np.all(np.abs(stable - 1) < 0.1), stable
    assert np.ptp(stable) < 0.01, stable
    assert not np.all(energies(1.05, 1) < 10)


# ---------------------------------------------------------------------------
# Loads and pinned nodes


def test_load_window_and_pinned_side():
    case = load_case(CASES / "mass_spring_7x7.toml")
    system = MassSpringModel.from_case(case)
    body = system.bodies[0]
    bottom = body.position[:, 1] == body.position[:, 1].min()
    top = body.position[:, 1] == body.position[:, 1].max()
    start = body.position.copy()
    run(system, 1e-3, 300, lambda: 0)
    assert np.array_equal(body.position[bottom], start[bottom])
    assert np.all(body.position[~bottom, 1] < start[~bottom, 1] + 1e-12)
    assert np.any(body.position[top, 1] < start[top, 1] - 1e-4)
    factor = body.external_force(0.3)[top, 1]
    assert np.allclose(factor, -0.5)
    assert np.allclose(body.external_force(0.6), 0.0)


def test_general_body_from_case():
    text = (CASES / "mass_spring_7x7.toml").read_text().split("[[body]]")[0] + """
[[body]]
name = "triangle"
type = "general"
nodes = [[0.0, 0.0], [0.02, 0.0], [0.01, 0.02], [0.01, 0.007]]
springs = [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]]
boundary = [0, 1, 2]
masses = [0.01, 0.01, 0.01, 0.02]
stiffness = 500.0
pinned_ids = [0]
[[body.load]]
nodes = "ids"
ids = [2]
force = [0.1, 0.0]
end = 0.1
"""
    case = schema.validate(config.load_text(text))
    (body,) = build_bodies(case)
    assert body.name == "triangle" and body.n_nodes == 4 and len(body.springs) == 6
    assert body.rest_volume == pytest.approx(0.5 * 0.02 * 0.02)
    system = MassSpringModel([body], constraint_prediction="linear")
    errors = run(system, 1e-3, 100, body.volume_error)
    assert np.array_equal(body.position[0], [0.0, 0.0])
    # The body swings about its pinned node: the linear prediction of §1.5
    # leaves the area swept per substep (dt Omega)^2; the Newton steps on the
    # multiplier (the default, and what "quadratic" now means) do not.
    assert 1e-6 < np.max(np.abs(errors)) < 1e-3
    for prediction in ("iterated", "quadratic"):
        case["solid"]["constraint_prediction"] = prediction
        system = MassSpringModel.from_case(case)
        body = system.bodies[0]
        errors = run(system, 1e-3, 100, body.volume_error)
        assert np.max(np.abs(errors)) < 1e-10


# ---------------------------------------------------------------------------
# Bad input: one line naming the problem


BASE = """
[domain]
lower = [-1.0, -1.0]
upper = [1.0, 1.0]
[particles]
spacing = 0.01
[time]
end = 0.01
"""

GENERAL = """
[[body]]
name = "b"
type = "general"
node_mass = 0.01
stiffness = 100.0
"""

BAD_BODIES = {
    "missing_node": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 5]]
boundary = [0, 1, 2]
""", r"springs\[1\] = \[1, 5\] names node 5, but the body has 3 nodes"),
    "zero_mass": ("""
[[body]]
nx = 3
ny = 3
spacing = 0.01
node_mass = 0.0
stiffness = 100.0
""", "node mass must be > 0"),
    "negative_mass": (GENERAL.replace("node_mass = 0.01", "masses = [0.01, -0.01, 0.01]")
                      + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 2]]
boundary = [0, 1, 2]
""", r"body\[0\].masses must be > 0.0, got -0.01"),
    "zero_stiffness": ("""
[[body]]
nx = 3
ny = 3
spacing = 0.01
node_mass = 0.01
stiffness = 0.0
""", r"body\[0\].stiffness must be > 0.0, got 0.0"),
    "negative_stiffness": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 2]]
spring_stiffness = [100.0, -5.0]
boundary = [0, 1, 2]
""", r"body\[0\].spring_stiffness must be > 0.0, got -5.0"),
    "self_intersecting": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [0.1, 0.1]]
springs = [[0, 1], [1, 2], [2, 3], [3, 0]]
boundary = [0, 1, 2, 3]
""", "boundary is not a simple polygon: edge 1-2 meets edge 3-0"),
    "repeated_node": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 2]]
boundary = [0, 1, 2, 1]
""", "not a simple polygon: node 1 appears twice"),
    "clockwise": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
springs = [[0, 1], [1, 2]]
boundary = [0, 2, 1]
""", "ordered clockwise.*counter-clockwise \\(reverse it\\)"),
    "no_springs": (GENERAL + """
nodes = [[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]
boundary = [0, 1, 2]
""", r"body\[0\] 'b' has no springs"),
    "lattice_without_springs": ("""
[[body]]
nx = 1
ny = 1
spacing = 0.01
node_mass = 0.01
stiffness = 100.0
""", r"nx must be >= 2"),
    "substep_too_long": ("""
[solid]
substep = 0.01
[[body]]
nx = 3
ny = 3
spacing = 0.01
node_mass = 0.01
stiffness = 1000.0
""", r"solid.substep \(0.01 s\) is above the stability limit of body 'body0' \(0.00"),
    "unknown_load_key": ("""
[[body]]
nx = 3
ny = 3
spacing = 0.01
node_mass = 0.01
stiffness = 1000.0
[[body.load]]
nodes = "top"
forse = [0.0, -1.0]
""", r"unknown key 'body\[0\].load\[0\].forse' \(did you mean 'force'\?\)"),
}


def check_bad(text):
    case = schema.validate(config.load_text(text))
    MassSpringModel.from_case(case)


@pytest.mark.parametrize("name", sorted(BAD_BODIES))
def test_bad_bodies_are_refused_with_one_line(name):
    body, pattern = BAD_BODIES[name]
    with pytest.raises(CaseError, match=pattern) as info:
        check_bad(BASE + body)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("axial", [False, True], ids=["relative", "axial"])
def test_compiled_network_forces_match_the_numpy_forms(axial):
    """parmps.solids.mass_spring.kernels against the numpy statement of the same forces."""
    from parmps.solids.mass_spring.body import damping_forces, spring_forces
    from parmps.solids.mass_spring.elastic import axial_damping_forces
    from parmps.solids.mass_spring.kernels import network_forces
    body = lattice_body(damping=0.3, seed=1, speed=0.5)
    rng = np.random.default_rng(2)
    position = body.position + 1e-3 * rng.standard_normal(body.position.shape)
    stiffness = body.stiffness * (1.0 + rng.random(len(body.springs)))
    expected = spring_forces(position, body.springs, body.rest_length, stiffness) + (
        axial_damping_forces(position, body.velocity, body.springs, body.damping) if axial
        else damping_forces(body.velocity, body.springs, body.damping))
    force = np.zeros_like(position)
    network_forces(position, body.velocity, body.springs, body.rest_length, stiffness,
                   body.damping, axial, force)
    assert np.allclose(force, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_held_force_substeps_match_the_general_loop():
    """The compiled loop (no area constraint, no windowed load) against the general one."""
    def body(gravity):
        b = lattice_body(damping=0.05, constraint=False, seed=3, speed=0.2)
        b.gravity = np.asarray(gravity)
        b.fluid_force[:] = np.linspace(-1e-3, 1e-3, 2 * b.n_nodes).reshape(-1, 2)
        return b
    compiled, general = body((0.0, -9.81)), body((0.0, -9.81))
    # A zero-force window load sends the general body down the Python loop.
    general.load_field = np.zeros((1, general.n_nodes, 2))
    general.load_start, general.load_end = np.zeros(1), np.ones(1)
    general.load_ramp = np.zeros(1)
    h = 0.5 * compiled.stability_limit()
    for step in range(5):
        assert compiled.advance(step * 20 * h, 20 * h, h) == 20
        general.advance(step * 20 * h, 20 * h, h)
    assert np.allclose(compiled.position, general.position, rtol=0, atol=1e-13)
    assert np.allclose(compiled.velocity, general.velocity, rtol=1e-10, atol=1e-12)
