"""3D elastic lattice bodies against beam and plate theory (validation/cantilever_3d/,
validation/kirchhoff_plate/, tests/test_elastic_3d.py).

Cantilever: a lattice ``[[body]]`` with an elastic material, square cross-section of
``nodes`` x ``nodes`` nodes (depth h = width b between the outer nodes), length L =
``slenderness`` h along x, clamped by pinning its left face, deflecting along -z. With
I = b h^3/12, A = b h (Euler-Bernoulli):

- tip load P (spread equally over the right face): w = P L^3 / (3 E I);
- own weight, q = rho g A: w = q L^4 / (8 E I);
- first natural frequency: omega_1 = 1.8751^2 sqrt(E I / (rho A L^4)).

Plate: a square lattice plate of side a (between the outer nodes), thickness t, clamped
on its four side faces, under a uniform pressure q on its top face; Kirchhoff: centre
deflection w = 0.00126 q a^4 / D, D = E t^3 / 12 (1 - nu^2) with the lattice's nu = 1/4.
The plate is solved on one quadrant with the symmetry planes through the centre (the
springs and loads lying in a symmetry plane halved, the normal displacement held there),
the same linear problem as the whole plate in a quarter of the unknowns.

Statics: parmps.solids.mass_spring.statics (sparse direct solve); the frequency: a sparse
generalised eigen solve of K and M (shift-invert about 0).
"""

import math

import numpy as np

from parmps import config, schema
from parmps.solids.mass_spring.build import build_bodies
from parmps.solids.mass_spring.elastic import elastic_lattice
from parmps.solids.mass_spring.lattice import lattice_geometry
from parmps.solids.mass_spring.statics import (body_static_displacement, lowest_frequencies,
                                               static_displacement, stiffness_matrix)
from parmps.tools.cantilever import FIRST_ROOT, tip_nodes

KIRCHHOFF_CLAMPED_SQUARE = 0.00126  # w D / (q a^4) at the centre (Timoshenko & Woinowsky-Krieger)
LATTICE_POISSON = 0.25

# A soft solid (rubber-like modulus, water-like density), 2 cm deep and wide.
DEPTH = 0.02
YOUNGS_MODULUS = 1.0e7
DENSITY = 1000.0
GRAVITY = 9.81
TIP_LOAD = 0.01  # total [N]

CASE = """title = "Clamped 3D lattice cantilever, {n} x {n} nodes across, L/h = {slenderness}"
[domain]
lower = [{x0}, {x0}, {x0}]
upper = [{x1}, {x1}, {x1}]
[physics]
gravity = [0.0, 0.0, {gravity!r}]
[time]
end = 1.0
[[body]]
name = "beam"
nx = {nx}
ny = {n}
nz = {n}
spacing = {spacing!r}
youngs_modulus = {youngs!r}
density = {density!r}
volume_constraint = false    # a bending beam keeps its volume only approximately
pinned = "left"              # clamped: the whole left face is held
{load}"""

LOAD = """[[body.load]]
nodes = "right"
force = [0.0, 0.0, {force!r}]
"""


def cantilever_case(nodes, slenderness, tip_load=0.0, gravity=0.0):
    """The case text of the cantilever with a tip load (total, N) and/or gravity."""
    spacing = DEPTH / (nodes - 1)
    nx = int(round(slenderness * (nodes - 1))) + 1
    length = (nx - 1) * spacing
    load = LOAD.format(force=-tip_load / nodes ** 2) if tip_load else ""
    return CASE.format(n=nodes, nx=nx, slenderness=slenderness, spacing=spacing,
                       youngs=YOUNGS_MODULUS, density=DENSITY, gravity=-gravity, load=load,
                       x0=-length, x1=2.0 * length)


def cantilever_body(nodes, slenderness, tip_load=0.0, gravity=0.0):
    text = cantilever_case(nodes, slenderness, tip_load, gravity)
    (body,) = build_bodies(schema.validate(config.load_text(text)))
    return body


def beam_theory(slenderness):
    """Euler-Bernoulli tip deflections (tip load, own weight) [m] and omega_1 [rad/s]."""
    length = slenderness * DEPTH
    bending = YOUNGS_MODULUS * DEPTH ** 4 / 12.0
    line_mass = DENSITY * DEPTH ** 2
    return {"tip_load": TIP_LOAD * length ** 3 / (3.0 * bending),
            "gravity": line_mass * GRAVITY * length ** 4 / (8.0 * bending),
            "omega": FIRST_ROOT ** 2 * math.sqrt(bending / (line_mass * length ** 4))}


def static_tip_deflection(nodes, slenderness, tip_load=0.0, gravity=0.0):
    """Downward deflection of the tip (mean over the right face's nodes) [m]."""
    body = cantilever_body(nodes, slenderness, tip_load, gravity)
    return -float(body_static_displacement(body)[tip_nodes(body), 2].mean())


def first_frequency(nodes, slenderness):
    """omega_1 [rad/s] of the lattice cantilever: sparse eigen solve of K and M."""
    body = cantilever_body(nodes, slenderness)
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    omega, _ = lowest_frequencies(matrix, body.mass, body.pinned)
    return float(omega[0])


def cantilever_errors(nodes, slenderness):
    """Relative errors against Euler-Bernoulli: tip load, own weight, omega_1."""
    theory = beam_theory(slenderness)
    return {"tip_load": static_tip_deflection(nodes, slenderness, tip_load=TIP_LOAD)
            / theory["tip_load"] - 1.0,
            "gravity": static_tip_deflection(nodes, slenderness, gravity=GRAVITY)
            / theory["gravity"] - 1.0,
            "omega": first_frequency(nodes, slenderness) / theory["omega"] - 1.0}


def plate_spec(spacing):
    """The [[body]] table of the plate's material (as schema.validate leaves it)."""
    return {"stiffness": None, "shear_stiffness": 0.0, "node_mass": 0.0, "density": DENSITY,
            "damping": 0.0, "damping_ratio": 0.0, "plane": "strain", "thickness": 1.0,
            "spacing": spacing, "youngs_modulus": YOUNGS_MODULUS, "poisson_ratio": None}


def quadrant(shape, springs, stiffness):
    """The springs of the quadrant i, j <= centre of a plate lattice, with those lying in a
    symmetry plane (i = centre or j = centre) halved: the other half belongs to the
    mirrored quadrant. Returns the quadrant's node indices (into the whole plate), its
    springs (renumbered) and their stiffness."""
    nx, ny, nz = shape
    centre = ((nx - 1) // 2, (ny - 1) // 2)
    i, j = np.arange(nx * ny * nz) % nx, (np.arange(nx * ny * nz) // nx) % ny
    inside = (i <= centre[0]) & (j <= centre[1])
    kept = inside[springs].all(axis=1)
    springs, stiffness = springs[kept], stiffness[kept].copy()
    for coordinate, middle in ((i, centre[0]), (j, centre[1])):
        stiffness[(coordinate[springs] == middle).all(axis=1)] *= 0.5
    nodes = np.flatnonzero(inside)
    number = np.full(len(inside), -1)
    number[nodes] = np.arange(len(nodes))
    return nodes, number[springs], stiffness


def clamped_plate(cells, thickness_nodes, pressure=1000.0):
    """Centre deflection [m] of the clamped square lattice plate, ``cells`` spacings wide
    (even), ``thickness_nodes`` nodes through the thickness DEPTH, and Kirchhoff's: a dict,
    see :func:`clamped_plate_deflection`."""
    spacing = DEPTH / (thickness_nodes - 1)
    return clamped_plate_deflection((cells + 1, cells + 1, thickness_nodes), spacing,
                                    plate_spec(spacing), pressure)


def clamped_plate_deflection(shape, spacing, spec, pressure):
    """The lattice plate ``shape`` = (n, n, nt) (n odd) of material ``spec`` (a validated
    [[body]] table), clamped on its four side faces, under ``pressure`` q on its top face.

    Returns a dict: ``deflection`` (mean over the centre's nodes through the thickness,
    downward), ``expected`` = 0.00126 q a^4 / D with D = E t^3/12(1 - nu^2), nu = 1/4,
    ``error``, ``side`` a, ``thickness`` t, ``nodes`` (of the quadrant solved).
    """
    geometry = lattice_geometry(shape, spacing, (0.0, 0.0, 0.0))
    material = elastic_lattice("plate", spec, shape, geometry.springs)
    nodes, springs, stiffness = quadrant(shape, geometry.springs, material.stiffness)
    position = geometry.position[nodes]
    index = np.rint(position / spacing).astype(int)
    centre = (shape[0] - 1) // 2
    on_plane = [(index[:, axis] == centre).astype(float) for axis in (0, 1)]
    force = np.zeros_like(position)
    top = index[:, 2] == shape[2] - 1
    # q a^2 per top node; half of it on a symmetry plane, a quarter on both.
    force[top, 2] = -pressure * spacing ** 2 * 0.5 ** (on_plane[0] + on_plane[1])[top]
    fixed = np.zeros_like(position, bool)
    fixed[(index[:, 0] == 0) | (index[:, 1] == 0)] = True  # the clamped side faces
    fixed[:, 0] |= on_plane[0] > 0
    fixed[:, 1] |= on_plane[1] > 0
    matrix = stiffness_matrix(position, springs, stiffness)
    displacement, _ = static_displacement(matrix, force, fixed)
    middle = (on_plane[0] > 0) & (on_plane[1] > 0)
    side, thickness = (shape[0] - 1) * spacing, (shape[2] - 1) * spacing
    rigidity = spec["youngs_modulus"] * thickness ** 3 / (12.0 * (1.0 - LATTICE_POISSON ** 2))
    expected = KIRCHHOFF_CLAMPED_SQUARE * pressure * side ** 4 / rigidity
    deflection = -float(displacement[middle, 2].mean())
    return {"deflection": deflection, "expected": expected,
            "error": deflection / expected - 1.0, "side": side, "thickness": thickness,
            "nodes": len(position)}
