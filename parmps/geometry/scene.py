"""The scene: turn the case's fluid blocks, tanks, wall boxes and walls into particles.

Every rank builds the same global scene (it is cheap next to one time step) and
keeps the particles of its own slab, so global ids depend on the case alone and
never on the rank count. Particles sit on the lattice of spacing l0 at
``corner + (i + 1/2) l0``; a wall's first layer lies half a spacing outside the
surface it models, as the fluid's first layer lies half a spacing inside.
"""

import numpy as np
from scipy.spatial import cKDTree

from parmps.core.geometry import format_point
from parmps.core.neighbours import close_pairs
from parmps.core.particles import DUMMY, FLUID, WALL, Particles
from parmps.errors import CaseError
from parmps.geometry.domain import Domain
from parmps.geometry.walls import fluid_particles, surface_of, wall_particles

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


def fluid_block(block, spacing, name, case=None, walls=None):
    """A box of the lattice ``lower + (i + 1/2) l0``, or the inside of a mesh or shape on
    the case's lattice (parmps.geometry.walls), less what the walls of any shape take."""
    if block.get("shape") or block.get("mesh"):
        domain = Domain.from_case(case)
        position = fluid_particles(name, block, surface_of(name, block, domain),
                                   case["particles"]["origin"], spacing, domain)
        position = clear_of_walls(position, walls, case, spacing, every_wall=True)
    else:
        position, _ = _lattice(block["lower"], _counts(name, block, spacing), spacing)
        if case is not None and case.get("wall"):
            position = clear_of_walls(position, walls, case, spacing, every_wall=False)
    velocity = np.tile(np.asarray(block["velocity"], dtype=float), (len(position), 1))
    if block.get("velocity_gradient"):
        velocity += position @ np.asarray(block["velocity_gradient"], dtype=float).T
    return position, np.full(len(position), FLUID, np.int8), velocity




def build_walls(case, spacing):
    """Every tank, wall box and wall of any shape of the case, in that order: name ->
    (position, kind, velocity, its walls.Side or None). A wall of any shape leaves out its points
    within half a spacing of an earlier wall's particles (the earlier one stands there, a
    wall particle if either was)."""
    walls = {}
    domain = Domain.from_case(case)
    for k, spec in enumerate(case["tank"]):
        name = f"tank[{k}]"
        walls[name] = (*tank(spec, spacing, name, open_axes(spec, domain, spacing)), None)
    for k, spec in enumerate(case["wall_box"]):
        name = f"wall_box[{k}]"
        walls[name] = (*wall_box(spec, spacing, name), None)
    for k, spec in enumerate(case.get("wall", ())):
        name = f"wall[{k}]"
        label = f"{name} '{spec['name']}'" if spec["name"] else name
        surface = surface_of(label, spec, domain, wall=True)
        position, kind, velocity, side = wall_particles(label, spec, surface,
                                                        case["particles"]["origin"], spacing,
                                                        domain)
        if walls:
            earlier = np.concatenate([w[0] for w in walls.values()])
            distance, nearest = cKDTree(earlier).query(position, distance_upper_bound=
                                                       0.5 * spacing)
            taken = np.isfinite(distance)
            if taken.any():
                _promote(walls, nearest[taken & (kind == WALL)])
                position, kind, velocity = position[~taken], kind[~taken], velocity[~taken]
        walls[name] = (position, kind, velocity, side)
    return walls


def _promote(walls, indices):
    """Make the earlier walls' particles ``indices`` (into their concatenation) walls."""
    start = 0
    for position, kind, _, _ in walls.values():
        mine = indices[(indices >= start) & (indices < start + len(position))] - start
        kind[mine] = WALL
        start += len(position)


# The water's first layer lies a whole spacing from a wall's first layer, as in a tank.
CLEARANCE = 1.0 - 1e-6


def clear_of_walls(position, walls, case, spacing, every_wall):
    """``position`` less the points in a wall of any shape's material or closer than a
    spacing to its particles (``every_wall``: to any wall's, tanks' and wall boxes' too)."""
    keep = np.ones(len(position), bool)
    near = [w[0] for w in walls.values() if every_wall or w[3] is not None]
    for entry in walls.values():
        if entry[3] is not None:
            keep &= ~entry[3].material(position)
    if near and len(position):
        points = np.concatenate(near)
        if len(points):
            keep &= ~_too_close(position, points, case["particles"]["origin"], spacing)
    return position[keep]


def _too_close(position, points, origin, spacing):
    """Which of ``position`` lie closer than CLEARANCE spacings to any of ``points``. Two
    points of the lattice ``origin + (i + 1/2) l0`` are that close only when they are the
    same point: those are matched by their indices (a k-d tree of the walls' points took a
    second for a million fluid points); the others are searched in a k-d tree."""
    def lattice_index(p):
        index = (p - np.asarray(origin, float)) / spacing - 0.5
        nearest = np.rint(index).astype(np.int64)
        return nearest, np.all(np.abs(index - nearest) < 1e-6, axis=1)

    (fluid, fluid_on), (wall, wall_on) = lattice_index(position), lattice_index(points)
    close = np.zeros(len(position), bool)
    if fluid_on.any() and wall_on.any():
        low = np.minimum(fluid[fluid_on].min(axis=0), wall[wall_on].min(axis=0))
        span = np.maximum(fluid[fluid_on].max(axis=0), wall[wall_on].max(axis=0)) - low + 1
        keys = np.ravel_multi_index(tuple((wall[wall_on] - low).T), span)
        close[fluid_on] = np.isin(np.ravel_multi_index(tuple((fluid[fluid_on] - low).T), span),
                                  keys)
    for mine, theirs in ((fluid_on, ~wall_on), (~fluid_on, np.ones(len(points), bool))):
        if mine.any() and theirs.any():
            distance, _ = cKDTree(points[theirs]).query(position[mine], distance_upper_bound=
                                                        CLEARANCE * spacing)
            close[mine] |= np.isfinite(distance)
    return close


def open_axes(spec, domain, spacing):
    """The periodic axes along which a tank's inner box spans the whole period: it has no
    walls across them (its floor and sides continue through the seam instead)."""
    return tuple(a for a in domain.periodic
                 if domain.spans(spec["lower"], spec["upper"], a, 1e-6 * spacing))


def tank(spec, spacing, name, open_axes=()):
    """Walls on every side of the inner box but the top (the last axis's upper side)
    when ``open_top`` and the sides across ``open_axes`` (periodic axes it spans): a
    floor and side walls, with dummy layers behind them."""
    counts = _counts(name, spec, spacing)
    layers = spec["wall_layers"] + spec["dummy_layers"]
    below = [0 if a in open_axes else layers for a in range(len(counts))]
    above = list(below)
    if spec["open_top"]:
        above[-1] = 0
    position, index = _lattice(spec["lower"], [n + b + a for n, b, a in
                                               zip(counts, below, above)],
                               spacing, first=[-b for b in below])
    # Distance in layers from the inner box (Chebyshev), 0 inside it.
    beyond = [np.maximum(-index[:, a], index[:, a] - (n - 1)) for a, n in enumerate(counts)]
    if spec["open_top"]:
        beyond[-1] = -index[:, -1]
    depth = np.maximum.reduce([*beyond, np.zeros(len(index), index.dtype)])
    keep = depth > 0
    kind = np.where(depth[keep] <= spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position[keep], kind, np.zeros((int(keep.sum()), len(counts)))


def tank_material(spec, spacing, domain, shift=0.0):
    """The material of a tank's walls as boxes ``(lower, upper, (axis, side))``: its sides
    along every axis but the periodic ones it spans (:func:`open_axes`), the top only when
    closed; each as thick as its wall and dummy layers, ``shift`` the tank's travel."""
    inner_lower = np.add(spec["lower"], shift)
    inner_upper = np.add(spec["upper"], shift)
    thick = (spec["wall_layers"] + spec["dummy_layers"]) * spacing
    d = len(inner_lower)
    walled = [a for a in range(d) if a not in open_axes(spec, domain, spacing)]
    outer_lower, outer_upper = inner_lower.copy(), inner_upper.copy()
    outer_lower[walled] -= thick
    outer_upper[walled] += thick
    if spec["open_top"]:
        outer_upper[-1] = inner_upper[-1]
    boxes = []
    for axis in walled:
        for side in (0, 1):
            if side == 1 and axis == d - 1 and spec["open_top"]:
                continue
            lower, upper = outer_lower.copy(), outer_upper.copy()
            if side == 0:
                upper[axis] = inner_lower[axis]
            else:
                lower[axis] = inner_upper[axis]
                upper[axis] = inner_upper[axis] + thick
            boxes.append((lower, upper, (axis, side)))
    return boxes


def wall_box(spec, spacing, name):
    """A filled box: its outer wall_layers are wall particles, the core is dummy."""
    counts = _counts(name, spec, spacing)
    position, index = _lattice(spec["lower"], counts, spacing)
    depth = np.minimum.reduce([np.minimum(index[:, a], n - 1 - index[:, a])
                               for a, n in enumerate(counts)])
    kind = np.where(depth < spec["wall_layers"], WALL, DUMMY).astype(np.int8)
    return position, kind, np.zeros((len(position), len(counts)))


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

    # The walls first, since the water keeps clear of them; then numbered in the order
    # of the sections, the fluid blocks first.
    walls = build_walls(case, spacing)
    for k, spec in enumerate(case["fluid_block"]):
        name = f"fluid_block[{k}]"
        position, kind, velocity = fluid_block(spec, spacing, name, case, walls)
        if solids is not None:
            # A closed shell's nodes take the place of the water at its surface.
            keep = ~solids.displaces(position, spacing, Domain.from_case(case))
            position, kind, velocity = position[keep], kind[keep], velocity[keep]
        add(name, position, kind, velocity)
    for name, (position, kind, velocity, _) in walls.items():
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
    # A body given across a periodic seam: its node particles inside the period.
    particles.position[:] = Domain.from_case(case).wrapped(particles.position)
    check_inside_domain(case, particles, origin, sources)
    check_overlaps(particles, origin, sources, spacing)
    return particles, origin, sources


def check_inside_domain(case, particles, origin, sources):
    domain = Domain.from_case(case)
    lower, upper = domain.lower, domain.upper
    outside = domain.outside(particles.position)
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
