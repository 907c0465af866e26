"""A clamped elastic lattice cantilever against Euler-Bernoulli beam theory.

Shared by tests/test_cantilever.py and scripts/verify_cantilever.py. The beam is
a lattice ``[[body]]`` with an elastic material (parmps.solids.mass_spring.elastic),
``ny`` nodes through its depth h and ``slenderness`` = L/h, clamped by pinning
its left column; L and h are the distances between the outer nodes, the extent
of the material the lattice represents (docs/elastic_lattice.md). Per unit depth
t = 1 m, with E2 the plane modulus (E/(1 - nu^2) in plane strain):

- tip load P (spread equally over the right column): w = P L^3 / (3 E2 I);
- own weight, q = rho g h: w = q L^4 / (8 E2 I);
- first natural frequency: omega_1 = 1.8751^2 sqrt(E2 I / (rho h L^4)),

with I = h^3/12. ``node_cells=True`` builds instead the lattice of explicit
springs (edge springs not halved, the same k_a = 2 k_d = 3 E2/4) with every node
carrying a full cell, rho a^2, read as a beam of depth h = ny a: the other
reading of a lattice, kept for comparison. Statics: a direct linear solve of the body's springs
(parmps.solids.mass_spring.statics); the frequency: the time integrator
(MassSpringModel) released from the static shape under its own weight, timed by
the zero crossings of the tip's deflection.
"""

import math

import numpy as np

from parmps import config, schema
from parmps.solids.mass_spring.model import MassSpringModel
from parmps.solids.mass_spring.statics import (body_static_displacement, lowest_frequencies,
                                               stiffness_matrix)

FIRST_ROOT = 1.8751040687119611  # cos(bL) cosh(bL) = -1, clamped-free beam

# A soft solid (rubber-like modulus, water-like density) 2 cm deep.
DEPTH = 0.02
YOUNGS_MODULUS = 1.0e7
DENSITY = 1000.0
GRAVITY = 9.81
TIP_LOAD = 1.0  # total [N] per metre of depth

CASE = """title = "Clamped elastic lattice cantilever, {ny} nodes deep, L/h = {slenderness}"
[domain]
lower = [{x0}, {y0}]
upper = [{x1}, {y1}]
[physics]
gravity = [0.0, {gravity}]
[time]
end = 1.0
[[body]]
name = "beam"
nx = {nx}
ny = {ny}
spacing = {spacing!r}
{material}
volume_constraint = false    # a bending beam keeps its area only approximately
pinned = "left"              # clamped: the whole left column is held
{load}"""

LOAD = """[[body.load]]
nodes = "right"
force = [0.0, {force!r}]
"""


def case_text(ny, slenderness, tip_load=0.0, gravity=0.0, node_cells=False):
    """A solid-only case: the cantilever with a tip load (total, N) and/or gravity."""
    cells = ny if node_cells else ny - 1
    spacing = DEPTH / cells
    nx = slenderness * cells + 1
    length = (nx - 1) * spacing
    if node_cells:
        diagonal = 3.0 * YOUNGS_MODULUS / (8.0 * (1.0 - 0.25 ** 2))
        material = (f"stiffness = {2.0 * diagonal!r}\nshear_stiffness = {diagonal!r}\n"
                    f"node_mass = {DENSITY * spacing ** 2!r}")
    else:
        material = f"youngs_modulus = {YOUNGS_MODULUS!r}\ndensity = {DENSITY!r}"
    load = LOAD.format(force=-tip_load / ny) if tip_load else ""
    return CASE.format(ny=ny, nx=nx, slenderness=slenderness, spacing=spacing,
                       material=material, gravity=-gravity, load=load,
                       x0=-0.5 * length, y0=-length, x1=2.0 * length, y1=length + DEPTH)


def build_system(ny, slenderness, tip_load=0.0, gravity=0.0, node_cells=False):
    text = case_text(ny, slenderness, tip_load, gravity, node_cells)
    return MassSpringModel.from_case(schema.validate(config.load_text(text)))


def beam_theory(slenderness):
    """Euler-Bernoulli tip deflections (tip load, own weight) [m] and omega_1 [rad/s]."""
    length = slenderness * DEPTH
    plane_modulus = YOUNGS_MODULUS / (1.0 - 0.25 ** 2)  # plane strain, the lattice's nu
    bending = plane_modulus * DEPTH ** 3 / 12.0
    line_mass = DENSITY * DEPTH
    return {"tip_load": TIP_LOAD * length ** 3 / (3.0 * bending),
            "gravity": line_mass * GRAVITY * length ** 4 / (8.0 * bending),
            "omega": FIRST_ROOT ** 2 * math.sqrt(bending / (line_mass * length ** 4))}


def tip_nodes(body):
    return np.flatnonzero(np.isclose(body.position[:, 0], body.position[:, 0].max()))


def static_tip_deflection(ny, slenderness, tip_load=0.0, gravity=0.0, node_cells=False):
    """Downward deflection of the tip's mid-depth (mean of the right column) [m]."""
    body = build_system(ny, slenderness, tip_load, gravity, node_cells).bodies[0]
    displacement = body_static_displacement(body)
    return -float(displacement[tip_nodes(body), 1].mean())


def first_frequency(ny, slenderness, periods=3.0, samples_per_period=200):
    """omega_1 [rad/s] measured with the time integrator, and the substeps it took.

    The beam starts at rest in its static shape under its own weight (almost
    all first mode) and swings free (no gravity, no damping); the period is
    read from the zero crossings of the tip's deflection.
    """
    body = build_system(ny, slenderness, gravity=GRAVITY).bodies[0]
    shape = body_static_displacement(body)
    system = build_system(ny, slenderness)
    body = system.bodies[0]
    rest = body.position.copy()
    # A small amplitude (tip at 1e-3 h) keeps the springs in their linear range.
    tip = tip_nodes(body)
    body.position += shape * (1e-3 * DEPTH / abs(shape[tip, 1].mean()))
    estimate = beam_theory(slenderness)["omega"]
    dt = 2.0 * math.pi / estimate / samples_per_period
    steps = int(periods * samples_per_period)
    times = dt * np.arange(steps + 1)
    deflection = np.empty(steps + 1)
    deflection[0] = (body.position[tip, 1] - rest[tip, 1]).mean()
    substeps = 0
    for step in range(steps):
        substeps += system.advance(times[step], dt)[body.name]
        deflection[step + 1] = (body.position[tip, 1] - rest[tip, 1]).mean()
    sign = np.signbit(deflection)
    k = np.flatnonzero(sign[1:] != sign[:-1])
    crossings = times[k] + dt * deflection[k] / (deflection[k] - deflection[k + 1])
    if len(crossings) < 3:
        raise RuntimeError(f"only {len(crossings)} zero crossings in {periods} periods")
    # A straight line through all crossings, so no single one (shifted by the
    # small higher-mode content) sets the period.
    half_period = np.polyfit(np.arange(len(crossings)), crossings, 1)[0]
    return math.pi / half_period, substeps


def lattice_first_frequency(ny, slenderness, node_cells=False):
    """omega_1 of the lattice itself: the lowest eigenvalue of K phi = omega^2 M phi (sparse)."""
    body = build_system(ny, slenderness, node_cells=node_cells).bodies[0]
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    omega, _ = lowest_frequencies(matrix, body.mass, body.pinned)
    return float(omega[0])
