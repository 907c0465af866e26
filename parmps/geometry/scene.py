"""Geometry: turn the case's fluid blocks, tanks and wall boxes into particles.

Every rank builds the same global scene (it is cheap next to one time step) and
keeps the particles of its own slab, so global ids depend on the case alone and
never on the rank count. Particles sit on the lattice of spacing l0 at
``corner + (i + 1/2) l0``; a wall's first layer lies half a spacing outside the
surface it models, as the fluid's first layer lies half a spacing inside.
"""

import numpy as np

from parmps.core.geometry import format_point, outside_box
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


def _lattice(lower, counts, spacing, first=None):
    """Lattice points corner + (i + 1/2) l0 for each axis's i in [first, first + count).

    Returns the points (n, d) and their integer lattice indices (n, d), x varying
    fastest, then y, then z (in 2D the order of the former meshgrid(indexing="xy")).
    """
    first = [0] * len(counts) if first is None else first
    axes = [np.arange(f, f + n) for f, n in zip(first, counts)]
    grids = np.meshgrid(*axes[::-1], indexing="ij")
    index = np.column_stack([g.ravel() for g in grids[::-1]])
    position = np.column_stack([lower[a] + (index[:, a] + 0.5) * spacing
                                for a in range(len(counts))])
    return position, index


def lattice_points(lower, counts, spacing):
    """The points ``lower + (i + 1/2) l0`` of a lattice with ``counts`` points per axis."""
    return _lattice(lower, counts, spacing)[0]


def _counts(name, spec, spacing):
    """Lattice spacings along each axis of the box ``spec`` (lower, upper)."""
    return [lattice_count(f"{name} {AXIS_EXTENT[a]}", spec["upper"][a] - spec["lower"][a],
                          spacing) for a in range(len(spec["lower"]))]


# What a box's extent along each axis is called in messages.
AXIS_EXTENT = ("width", "height", "depth")


def fluid_block(block, spacing, name):
    position, _ = _lattice(block["lower"], _counts(name, block, spacing), spacing)
    velocity = np.tile(np.asarray(block["velocity"], dtype=float), (len(position), 1))
    return position, np.full(len(position), FLUID, np.int8), velocity


def tank(spec, spacing, name):
    """Walls on every side of the inner box but the top (the last axis's upper side)
    when ``open_top``: a floor and side walls, with dummy layers behind them."""
    counts = _counts(name, spec, spacing)
    layers = spec["wall_layers"] + spec["dummy_layers"]
    top = counts[-1] + (0 if spec["open_top"] else layers)
    position, index = _lattice(spec["lower"], [n + 2 * layers for n in counts[:-1]]
                               + [top + layers], spacing, first=[-layers] * len(counts))
    # Distance in layers from the inner box (Chebyshev), 0 inside it.
    beyond = [np.maximum(-index[:, a], index[:, a] - (n - 1)) for a, n in enumerate(counts)]
    if spec["open_top"]:
        beyond[-1] = -index[:, -1]
    depth = np.maximum.reduce([*beyond, np.zeros(len(index), index.dtype)])
    keep = depth > 0
    kind = np.where(depth[keep] <= spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position[keep], kind, np.zeros((int(keep.sum()), len(counts)))


def wall_box(spec, spacing, name):
    """A filled box: its outer wall_layers are wall particles, the core is dummy."""
    counts = _counts(name, spec, spacing)
    position, index = _lattice(spec["lower"], counts, spacing)
    depth = np.minimum.reduce([np.minimum(index[:, a], n - 1 - index[:, a])
                               for a, n in enumerate(counts)])
    kind = np.where(depth < spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position, kind, np.zeros((len(position), len(counts)))


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
            position, kind, velocity = builder(spec, spacing, name)
            if section == "fluid_block" and solids is not None:
                # A closed shell's nodes take the place of the water at its surface.
                keep = ~solids.displaces(position, spacing)
                position, kind, velocity = position[keep], kind[keep], velocity[keep]
            add(name, position, kind, velocity)
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
        raise CaseError(f"{sources[origin[first]]} puts {int(outside.sum())} particles outside "
                        f"the domain {format_point(lower, 'g', '[]')}-"
                        f"{format_point(upper, 'g', '[]')}, "
                        f"e.g. at {format_point(particles.position[first])} (walls and dummy "
                        f"layers included); enlarge domain.lower/domain.upper or move the "
                        f"geometry")


def check_overlaps(particles, origin, sources, spacing):
    """Refuse two particles closer than half a spacing: overlapping geometry."""
    i, j = close_pairs(particles.position, 0.5 * spacing)
    if len(i):
        a, b = sorted((sources[origin[i[0]]], sources[origin[j[0]]]))
        what = f"{a} overlaps {b}" if a != b else f"{a} overlaps itself"
        raise CaseError(f"{what}: {len(i)} pairs of particles closer than half a spacing, "
                        f"e.g. near {format_point(particles.position[i[0]])}")
