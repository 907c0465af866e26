"""The elastic gate at rest under its water column: a lattice gate's static deflection against
Euler-Bernoulli in plane stress and in plane strain (validation/elastic_gate_3d/).

A 2D gate is a slice of a plate; whether that slice bends with D = E t^3/12 (plane stress, a
narrow strip free to contract sideways) or with E t^3/12(1 - nu^2) (plane strain, a wide plate
in cylindrical bending) is an assumption of the 2D case. A 3D gate spanning the tank's width,
its side edges free, settles it: its static deflection under the same load, read at
mid-width, sits between the two, and the fraction

    f = (1 - w_3D / w_stress) / nu^2    (0: plane stress, 1: plane strain)

says where. The lattice's own Poisson ratio is the one the comparison can make (1/4 for the
cubic lattice, docs/elastic_lattice.md), so both beam figures use it.

The load is the still water column of height h against the gate's face towards the water:
p = rho g (h - z) on each node of that face, times its share of the face, a^(d-1) (half of
that on the face's edges), normal to the face. A point load F at distance s from the clamp of
a cantilever of free length L moves the free end by F s^2 (3 L - s) / 6 D (per unit width).
"""

import numpy as np

from parmps.solids.mass_spring.statics import static_displacement, stiffness_matrix

WATER_DENSITY = 1000.0
GRAVITY = 9.81


def face_loads(position, spacing, water_height, density=WATER_DENSITY, gravity=GRAVITY):
    """Forces (n, d) of the still water column on a gate's face towards the water (the nodes
    at the smallest x, the water on the -x side), along +x: p(z) times each node's share of
    the face. The vertical axis is the last one."""
    position = np.asarray(position, float)
    d = position.shape[1]
    face = np.isclose(position[:, 0], position[:, 0].min(), atol=1e-9 * spacing)
    share = np.full(len(position), spacing ** (d - 1))
    for axis in range(1, d):
        # Half a share on the face's outermost lines (the tributary area stops at the edge).
        coordinate = position[:, axis]
        edge = np.isclose(coordinate, coordinate[face].min()) | np.isclose(
            coordinate, coordinate[face].max())
        share = np.where(edge, 0.5 * share, share)
    pressure = density * gravity * np.clip(water_height - position[:, -1], 0.0, None)
    force = np.zeros_like(position)
    force[face, 0] = pressure[face] * share[face]
    return force


def lattice_spacing(body):
    """The lattice's spacing: its shortest spring's rest length."""
    ends = body.position[body.springs]
    return float(np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1).min())


def lattice_deflection(body, water_height):
    """Static displacement (n, d) of a lattice gate under its water column (linear springs, the
    volume constraint left out: at rest it moves the gate by a second-order amount)."""
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    force = face_loads(body.position, lattice_spacing(body), water_height)
    displacement, _ = static_displacement(matrix, force, body.pinned)
    return displacement


def beam_tip(body, water_height, rigidity, width):
    """Euler-Bernoulli free-end deflection [m] of the gate's free length under the same node
    loads as :func:`lattice_deflection`, summed across the width and spread over ``width``,
    for a bending stiffness ``rigidity`` D per unit width."""
    position = body.position
    vertical = position[:, -1]
    free = ~body.pinned
    clamp = vertical[body.pinned].min()  # the lowest pinned row is the clamp line
    length = clamp - vertical[free].min()
    force = face_loads(position, lattice_spacing(body), water_height)[:, 0]
    # Loads on pinned nodes go to the support; a free node's load bends the beam.
    distance = clamp - vertical[free]
    load = force[free] / width
    return float(np.sum(load * distance ** 2 * (3.0 * length - distance)) / (6.0 * rigidity))


def gate_convention(body, water_height, youngs_modulus, poisson_ratio, probe_nodes):
    """The lattice gate's static free-end deflection at ``probe_nodes`` against the beam in
    plane stress and in plane strain (``poisson_ratio``: the lattice's own). A dict:
    ``lattice``, ``plane_stress``, ``plane_strain`` [m], ``fraction`` f (see the module) and
    ``across`` (the free row's deflection from one side edge to the other, 3D)."""
    position = body.position
    thickness = np.ptp(position[:, 0])
    # The width the loads were summed over (between the outer nodes); 1 for a 2D slice.
    width = float(np.prod(np.ptp(position[:, 1:-1], axis=0)))
    displacement = lattice_deflection(body, water_height)
    lattice = float(displacement[probe_nodes, 0].mean())
    stress = beam_tip(body, water_height, youngs_modulus * thickness ** 3 / 12.0, width)
    strain = stress * (1.0 - poisson_ratio ** 2)
    # The free row's deflection along the width (one value in 2D).
    tip = np.isclose(position[:, -1], position[:, -1].min())
    _, line = np.unique(np.round(position[tip, 1:-1] / lattice_spacing(body)).astype(int),
                        axis=0, return_inverse=True)
    across = np.bincount(line.ravel(), displacement[tip, 0]) / np.bincount(line.ravel())
    return {"lattice": lattice, "plane_stress": stress, "plane_strain": strain,
            "fraction": (1.0 - lattice / stress) / poisson_ratio ** 2, "across": across}
