"""Geometry: turn the case's fluid blocks, tanks and wall boxes into particles.

Every rank builds the same global scene (it is cheap next to one time step) and
keeps the particles of its own slab, so global ids depend on the case alone and
never on the rank count. Particles sit on the lattice of spacing l0 at
``corner + (i + 1/2) l0``; a wall's first layer lies half a spacing outside the
surface it models, as the fluid's first layer lies half a spacing inside.
"""

import numpy as np

from parmps.core.geometry import outside_box
from parmps.errors import CaseError
from parmps.core.neighbours import close_pairs
from parmps.core.particles import DUMMY, FLUID, WALL, Particles

# Coordinates that should land on the lattice may be off by rounding only.
_LATTICE_TOLERANCE = 1e-6


def lattice_count(name, extent, spacing):
    """How many lattice spacings fit ``extent``; refuse an extent that is not a whole number."""
    count = extent / spacing
    rounded = int(round(count))
    if abs(count - rounded) > _LATTICE_TOLERANCE * max(1.0, count) or rounded < 1:
        raise CaseError(f"{name}: extent {extent:g} is not a whole number of "
                        f"particles.spacing {spacing:g} ({count:.4f} spacings)")
    return rounded


def _lattice(lower, nx, ny, spacing, i0=0, j0=0):
    """Lattice points corner + (i + 1/2, j + 1/2) l0 for i in [i0, i0+nx), j in [j0, j0+ny)."""
    i = np.arange(i0, i0 + nx)
    j = np.arange(j0, j0 + ny)
    ii, jj = np.meshgrid(i, j, indexing="xy")
    x = lower[0] + (ii.ravel() + 0.5) * spacing
    y = lower[1] + (jj.ravel() + 0.5) * spacing
    return np.column_stack([x, y]), ii.ravel(), jj.ravel()


def fluid_block(block, spacing, name):
    lower = block["lower"]
    nx = lattice_count(f"{name} width", block["upper"][0] - lower[0], spacing)
    ny = lattice_count(f"{name} height", block["upper"][1] - lower[1], spacing)
    position, _, _ = _lattice(lower, nx, ny, spacing)
    velocity = np.tile(np.asarray(block["velocity"], dtype=float), (len(position), 1))
    return position, np.full(len(position), FLUID, np.int8), velocity


def tank(spec, spacing, name):
    """Walls on the left, right and bottom of the inner rectangle (and the top if closed)."""
    lower = spec["lower"]
    nx = lattice_count(f"{name} width", spec["upper"][0] - lower[0], spacing)
    ny = lattice_count(f"{name} height", spec["upper"][1] - lower[1], spacing)
    layers = spec["wall_layers"] + spec["dummy_layers"]
    top = ny + (0 if spec["open_top"] else layers)
    position, ii, jj = _lattice(lower, nx + 2 * layers, top + layers, spacing,
                                i0=-layers, j0=-layers)
    # Distance in layers from the inner rectangle (Chebyshev), 0 inside it.
    depth = np.maximum.reduce([-ii, ii - (nx - 1), -jj, jj - (ny - 1) if not spec["open_top"]
                               else np.full_like(jj, -1), np.zeros_like(ii)])
    keep = depth > 0
    kind = np.where(depth[keep] <= spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position[keep], kind, np.zeros((int(keep.sum()), 2))


def wall_box(spec, spacing, name):
    """A filled rectangle: its outer wall_layers are wall particles, the core is dummy."""
    lower = spec["lower"]
    nx = lattice_count(f"{name} width", spec["upper"][0] - lower[0], spacing)
    ny = lattice_count(f"{name} height", spec["upper"][1] - lower[1], spacing)
    position, ii, jj = _lattice(lower, nx, ny, spacing)
    depth = np.minimum.reduce([ii, nx - 1 - ii, jj, ny - 1 - jj])
    kind = np.where(depth < spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position, kind, np.zeros((len(position), 2))


BUILDERS = {"fluid_block": fluid_block, "tank": tank, "wall_box": wall_box}


def build(case, solids=None, open_boundaries=None):
    """All particles of the case, ids 0..N-1 in the order of the case's geometry entries.

    Then the node particles of ``solids`` (a SolidModel; in body order) and last
    the inflow buffers of ``open_boundaries`` (ids from N, see parmps.boundaries.open).
    Returns the Particles and, for each particle, the index into ``sources`` (the
    names of the geometry entries) that made it.
    """
    spacing = case["particles"]["spacing"]
    positions, kinds, velocities, origin, sources = [], [], [], [], []
    body_index, node_index, ids = [], [], []

    def add(name, position, kind, velocity, body=None, node=None, id_=None):
        positions.append(position)
        kinds.append(kind)
        velocities.append(velocity)
        body_index.append(np.full(len(position), -1, np.int32) if body is None else body)
        node_index.append(np.full(len(position), -1, np.int32) if node is None else node)
        ids.append(id_)
        origin.append(np.full(len(position), len(sources), np.int32))
        sources.append(name)

    for section, builder in BUILDERS.items():
        for k, spec in enumerate(case[section]):
            name = f"{section}[{k}]"
            add(name, *builder(spec, spacing, name))
    if solids is not None:
        nodes = solids.node_particles()
        for k, body in enumerate(solids.bodies):
            mine = nodes.body == k
            add(f"body[{k}] '{body.name}'", nodes.position[mine], nodes.kind[mine],
                nodes.velocity[mine], nodes.body[mine], nodes.node[mine])
    count = sum(len(p) for p in positions)
    if open_boundaries is not None:
        for name, buffer in open_boundaries.initial_particles(count):
            add(name, buffer.position, buffer.kind, buffer.velocity, id_=buffer.id)
    if not positions or not any(len(p) for p in positions):
        raise CaseError("the case has no particles: add a [[fluid_block]]")
    position = np.concatenate(positions)
    start = np.cumsum([0] + [len(p) for p in positions])
    particles = Particles({
        "id": np.concatenate([np.arange(start[k], start[k + 1], dtype=np.int64)
                              if i is None else i for k, i in enumerate(ids)]),
        "kind": np.concatenate(kinds),
        "position": position,
        "velocity": np.concatenate(velocities),
        "body": np.concatenate(body_index),
        "node": np.concatenate(node_index),
    })
    origin = np.concatenate(origin)
    check_inside_domain(case, particles, origin, sources)
    check_overlaps(particles, origin, sources, spacing)
    return particles, origin, sources


def check_inside_domain(case, particles, origin, sources):
    lower = np.asarray(case["domain"]["lower"])
    upper = np.asarray(case["domain"]["upper"])
    outside = outside_box(particles.position, lower, upper)
    if outside.any():
        first = int(np.flatnonzero(outside)[0])
        x, y = particles.position[first]
        raise CaseError(f"{sources[origin[first]]} puts {int(outside.sum())} particles outside "
                        f"the domain [{lower[0]:g}, {lower[1]:g}]-[{upper[0]:g}, {upper[1]:g}], "
                        f"e.g. at ({x:.6g}, {y:.6g}) (walls and dummy layers included); "
                        f"enlarge domain.lower/domain.upper or move the geometry")


def check_overlaps(particles, origin, sources, spacing):
    """Refuse two particles closer than half a spacing: overlapping geometry."""
    i, j = close_pairs(particles.position, 0.5 * spacing)
    if len(i):
        a, b = sorted((sources[origin[i[0]]], sources[origin[j[0]]]))
        what = f"{a} overlaps {b}" if a != b else f"{a} overlaps itself"
        x, y = particles.position[i[0]]
        raise CaseError(f"{what}: {len(i)} pairs of particles closer than half a spacing, "
                        f"e.g. near ({x:.6g}, {y:.6g})")
