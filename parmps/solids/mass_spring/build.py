"""Build the mass-spring bodies of a case (``[[body]]`` tables) and check them.

Two kinds of body:

- ``type = "lattice"``: nx x ny (x nz in 3D) nodes at ``lower + (i, j[, k])
  spacing``, node index ``i + nx j (+ nx ny k)``, structural springs between
  neighbours along every axis (``stiffness``) and both diagonals of every square
  in every coordinate plane (``shear_stiffness``)
  (:mod:`parmps.solids.mass_spring.lattice`). Its boundary is derived: the
  counter-clockwise loop in 2D, the outward triangles of its surface in 3D.
- ``type = "general"`` (2D): ``nodes``, ``springs`` (index pairs) and a named
  ``boundary`` loop. A loop given clockwise is refused (not silently reversed),
  with a message saying to reverse it, so the node order the user sees in the
  output is the one they wrote.

Node sets (for ``pinned`` and ``[[body.load]]``): a side (the nodes at the
extreme coordinate: ``left``/``right`` along x, ``front``/``back`` along y in
3D, ``bottom``/``top`` along the last axis, y in 2D and z in 3D), ``all``, a 2D
lattice's ``row`` or ``column`` or a 3D lattice's ``layer`` (``index`` from 0
at the bottom/left), or listed ``ids``; ``pinned_outside`` = [lower, upper] also
pins every node on or outside that box (a plate clamped on its four edges).

Every problem is a one-line :class:`CaseError` naming the body and the key.
"""

import logging

import numpy as np

from parmps.core.geometry import outside_box
from parmps.errors import CaseError
from parmps.solids.mass_spring.body import Body, polygon_area
from parmps.solids.mass_spring.elastic import check_not_elastic, elastic_lattice, is_elastic
from parmps.solids.mass_spring.membrane import attach as attach_membrane
from parmps.solids.mass_spring.membrane import check_keys as check_membrane_keys
from parmps.solids.mass_spring.lattice import FACE_DIAGONAL, lattice_geometry  # noqa: F401
from parmps.solids.mass_spring.shell import check_keys as check_shell_keys, shell_body

log = logging.getLogger(__name__)

LATTICE_ONLY = ("nx", "ny", "nz", "spacing", "density", "shear_stiffness", "youngs_modulus")
GENERAL_ONLY = ("nodes", "springs", "boundary", "masses", "spring_stiffness")


def _label(k, spec):
    return f"body[{k}]" + (f" '{spec['name']}'" if spec["name"] else "")


def _segments_cross(a, b, c, d, scale):
    """For segment arrays ab and cd, whether they touch or cross (``scale``: the loop's size)."""
    def orient(p, q, r):
        return ((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    scale = max(scale, 1e-300)
    tol = 1e-12 * scale ** 2
    o1, o2 = orient(a, b, c), orient(a, b, d)
    o3, o4 = orient(c, d, a), orient(c, d, b)
    proper = (o1 * o2 < -tol ** 2) & (o3 * o4 < -tol ** 2)

    def on_segment(p, q, r, o):
        return ((np.abs(o) <= tol)
                & (np.minimum(p[..., 0], q[..., 0]) - 1e-12 * scale <= r[..., 0])
                & (r[..., 0] <= np.maximum(p[..., 0], q[..., 0]) + 1e-12 * scale)
                & (np.minimum(p[..., 1], q[..., 1]) - 1e-12 * scale <= r[..., 1])
                & (r[..., 1] <= np.maximum(p[..., 1], q[..., 1]) + 1e-12 * scale))

    touching = (on_segment(a, b, c, o1) | on_segment(a, b, d, o2)
                | on_segment(c, d, a, o3) | on_segment(c, d, b, o4))
    return proper | touching


def check_boundary(label, position, loop):
    """Refuse a loop that is not a simple counter-clockwise polygon of existing nodes."""
    n = len(position)
    loop = np.asarray(loop, dtype=np.int64)
    if len(loop) < 3:
        raise CaseError(f"{label}.boundary must list at least 3 nodes, got {len(loop)}")
    bad = loop[(loop < 0) | (loop >= n)]
    if len(bad):
        raise CaseError(f"{label}.boundary names node {int(bad[0])}, but the body has "
                        f"{n} nodes (0..{n - 1})")
    values, counts = np.unique(loop, return_counts=True)
    if counts.max() > 1:
        raise CaseError(f"{label}.boundary is not a simple polygon: node "
                        f"{int(values[counts > 1][0])} appears twice")
    start = position[loop]
    end = np.roll(start, -1, axis=0)
    m = len(loop)
    first, second = np.triu_indices(m, k=2)
    # Edges k and k+1 share a node, and so do the last and the first.
    keep = ~((first == 0) & (second == m - 1))
    first, second = first[keep], second[keep]
    crossing = _segments_cross(start[first], end[first], start[second], end[second],
                               scale=float(np.ptp(start, axis=0).max()))
    if crossing.any():
        e, f = int(first[crossing][0]), int(second[crossing][0])
        raise CaseError(f"{label}.boundary is not a simple polygon: edge "
                        f"{int(loop[e])}-{int(loop[(e + 1) % m])} meets edge "
                        f"{int(loop[f])}-{int(loop[(f + 1) % m])}")
    area = polygon_area(position, loop)
    if area < 0:
        raise CaseError(f"{label}.boundary is ordered clockwise (area {area:.6g}); list it "
                        f"counter-clockwise (reverse it): parmps refuses rather than "
                        f"reorder it")
    if area == 0:
        raise CaseError(f"{label}.boundary encloses no area")


def _sides(position):
    """Node masks of the sides: nodes at the extreme coordinate (within rounding)."""
    extent = max(float(np.ptp(position, axis=0).max()), 1e-300)
    tol = 1e-9 * extent
    d = position.shape[1]
    axes = {"left": 0, "right": 0, "bottom": d - 1, "top": d - 1}
    if d == 3:
        axes.update(front=1, back=1)
    sides = {"all": np.ones(len(position), bool)}
    for name, axis in axes.items():
        x = position[:, axis]
        low = name in ("left", "bottom", "front")
        sides[name] = x <= x.min() + tol if low else x >= x.max() - tol
    return sides


# The lattice words of a node set: (the lattice axis the index runs along,
# the dimension the word belongs to). A row is the nodes of one j.
LATTICE_SETS = {"row": (1, 2), "column": (0, 2), "layer": (2, 3)}


def _lattice_set(label, what, index, shape):
    """The nodes of a lattice's row, column or layer ``index``."""
    if shape is None:
        raise CaseError(f"{label}.nodes = \"{what}\" needs a lattice body; use "
                        f"\"ids\" for a general body")
    axis, dimension = LATTICE_SETS[what]
    if len(shape) != dimension:
        words = ", ".join(w for w, (_, e) in LATTICE_SETS.items() if e == len(shape))
        raise CaseError(f"{label}.nodes = \"{what}\" names a set of a {dimension}D lattice; "
                        f"this body is {len(shape)}D (use {words}, a side or ids)")
    count = shape[axis]
    size = "x".join(str(n) for n in shape)
    if index >= count:
        raise CaseError(f"{label}.index {index} is not a {what} of the {size} lattice "
                        f"(0..{count - 1})")
    grid = np.arange(int(np.prod(shape))).reshape(shape[::-1])
    return np.take(grid, index, axis=len(shape) - 1 - axis).ravel()


def node_set(label, what, position, index=0, ids=(), shape=None):
    """Indices of the nodes a pinned side or a load names."""
    n = len(position)
    if what in LATTICE_SETS:
        return _lattice_set(label, what, index, shape)
    if what == "ids":
        ids = np.asarray(ids, dtype=np.int64)
        if not len(ids):
            raise CaseError(f"{label}.ids is empty: list the nodes for nodes = \"ids\"")
        bad = ids[(ids < 0) | (ids >= n)]
        if len(bad):
            raise CaseError(f"{label}.ids names node {int(bad[0])}, but the body has "
                            f"{n} nodes (0..{n - 1})")
        return np.unique(ids)
    sides = _sides(position)
    if what not in sides:
        raise CaseError(f"{label}: \"{what}\" names a side of a 3D body (along y); in 2D "
                        f"the sides are left, right, bottom and top")
    return np.flatnonzero(sides[what])


def pinned_nodes(label, spec, position, shape):
    """The mask of the nodes that never move: ``pinned`` (a side), ``pinned_ids`` and the
    nodes on or outside the box ``pinned_outside``."""
    pinned = np.zeros(len(position), bool)
    if spec["pinned"] != "none":
        pinned[node_set(f"{label}.pinned", spec["pinned"], position, shape=shape)] = True
    if spec["pinned_ids"]:
        pinned[node_set(f"{label}.pinned_ids", "ids", position, ids=spec["pinned_ids"])] = True
    if spec["pinned_outside"]:
        pinned |= not_inside_box(f"{label}.pinned_outside", spec["pinned_outside"], position)
    return pinned


def not_inside_box(label, box, position):
    """The nodes on or outside the box ``box`` = [lower, upper] (within rounding): a plate
    clamped along the box's sides, its margin beyond them held too."""
    if len(box) != 2 or not np.all(np.asarray(box[0]) < np.asarray(box[1])):
        raise CaseError(f"{label} must be two points [lower, upper] with lower < upper on "
                        f"every axis, got {box}")
    tol = 1e-9 * max(float(np.ptp(position, axis=0).max()), 1e-300)
    pinned = outside_box(position, np.add(box[0], tol), np.subtract(box[1], tol))
    if not pinned.any() or pinned.all():
        which = "every node" if not pinned.any() else "no node"
        raise CaseError(f"{label} = {box} holds {which} of the body strictly inside: it pins "
                        f"{'none' if not pinned.any() else 'all'} of them")
    return pinned


def _check_springs(label, springs, n):
    if not len(springs):
        raise CaseError(f"{label} has no springs")
    bad = (springs < 0) | (springs >= n)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        node = int(springs[row][bad[row]][0])
        raise CaseError(f"{label}.springs[{row}] = [{springs[row, 0]}, {springs[row, 1]}] names "
                        f"node {node}, but the body has {n} nodes (0..{n - 1})")
    same = springs[:, 0] == springs[:, 1]
    if same.any():
        row = int(np.flatnonzero(same)[0])
        raise CaseError(f"{label}.springs[{row}] joins node {springs[row, 0]} to itself")


def _lattice_shape(label, spec, dimension):
    """(nx, ny) or (nx, ny, nz), checked."""
    names = ("nx", "ny", "nz")[:dimension]
    if dimension == 2 and spec["nz"]:
        raise CaseError(f"{label}.nz applies to 3D cases only (this case is 2D)")
    for key in names:
        if spec[key] < 2:
            raise CaseError(f"{label}.{key} must be >= 2 for a lattice body, got {spec[key]}")
    return tuple(spec[key] for key in names)


def _lattice(label, spec, dimension):
    for key in GENERAL_ONLY:
        if spec[key]:
            raise CaseError(f"{label}.{key} applies to general bodies only "
                            f"(set type = \"general\")")
    shape, spacing = _lattice_shape(label, spec, dimension), spec["spacing"]
    if not spacing > 0:
        raise CaseError(f"{label}.spacing must be > 0 for a lattice body, got {spacing}")
    position, springs, kind, boundary = lattice_geometry(shape, spacing, spec["lower"])
    shear = kind == FACE_DIAGONAL
    if is_elastic(spec):
        # Springs, masses and dashpots come from the material, in build_body.
        return position, springs, None, None, boundary, shape
    check_not_elastic(label, spec)
    if spec["node_mass"] > 0 and spec["density"] > 0:
        raise CaseError(f"{label}: give node_mass or density, not both")
    if spec["node_mass"] > 0:
        mass = spec["node_mass"]
    elif spec["density"] > 0:
        # Each node carries one lattice cell's worth of material (2D: per unit depth).
        mass = spec["density"] * spacing ** dimension
    else:
        raise CaseError(f"{label}: node mass must be > 0: set node_mass [kg] or density "
                        f"[kg/m^3]")
    if spec["stiffness"] is None:
        raise CaseError(f"{label}: missing key 'stiffness' [N/m] (or give youngs_modulus [Pa])")
    shear_stiffness = spec["shear_stiffness"] or spec["stiffness"]
    stiffness = np.where(shear, shear_stiffness, spec["stiffness"])
    return position, springs, stiffness, np.full(len(position), mass), boundary, shape


def _general(label, spec, dimension):
    if dimension != 2:
        raise CaseError(f"{label}.type = \"general\" runs in 2D cases only so far (its "
                        f"boundary is a node loop); in 3D use type = \"lattice\"")
    for key in LATTICE_ONLY:
        if spec[key]:
            raise CaseError(f"{label}.{key} applies to lattice bodies only")
    check_not_elastic(label, spec)
    position = np.asarray(spec["nodes"], dtype=float).reshape(-1, 2)
    n = len(position)
    if n < 2:
        raise CaseError(f"{label}.nodes must list at least 2 nodes, got {n}")
    springs = np.asarray(spec["springs"], dtype=np.int64).reshape(-1, 2)
    _check_springs(label, springs, n)
    if spec["spring_stiffness"]:
        if len(spec["spring_stiffness"]) != len(springs):
            raise CaseError(f"{label}.spring_stiffness has {len(spec['spring_stiffness'])} "
                            f"values for {len(springs)} springs")
        stiffness = np.asarray(spec["spring_stiffness"], dtype=float)
    elif spec["stiffness"] is None:
        raise CaseError(f"{label}: missing key 'stiffness' [N/m] (or spring_stiffness)")
    else:
        stiffness = np.full(len(springs), spec["stiffness"])
    if spec["masses"] and spec["node_mass"] > 0:
        raise CaseError(f"{label}: give node_mass or masses, not both")
    if spec["masses"]:
        if len(spec["masses"]) != n:
            raise CaseError(f"{label}.masses has {len(spec['masses'])} values for {n} nodes")
        mass = np.asarray(spec["masses"], dtype=float)
    elif spec["node_mass"] > 0:
        mass = np.full(n, spec["node_mass"])
    else:
        raise CaseError(f"{label}: node mass must be > 0: set node_mass or masses [kg]")
    boundary = np.asarray(spec["boundary"], dtype=np.int64)
    if not len(boundary):
        raise CaseError(f"{label}.boundary is missing: name the boundary loop of nodes, "
                        f"counter-clockwise")
    return position, springs, stiffness, mass, boundary, None


def _anchored_boundary(label, spec, boundary, shape, n, count):
    """The loop through the anchors (nodes n, n+1, ...) and one row of the body.

    A lattice closes over its bottom row (right to left) or its top row (left
    to right); a general body names the anchors in its own boundary list.
    """
    anchor_ids = np.arange(n, n + count)
    if shape is None:
        if not np.isin(anchor_ids, boundary).all():
            raise CaseError(f"{label}.boundary must name every anchor (nodes {n}..{n + count - 1}"
                            f" after the {n} nodes)")
        return boundary
    nx, ny = shape
    grid = np.arange(nx * ny).reshape(ny, nx)
    row = grid[0, ::-1] if spec["anchor_row"] == "bottom" else grid[-1, :]
    return np.concatenate([anchor_ids, row])


def _closed_boundary(label, spec, position, boundary, shape):
    """(anchors (a, d), the boundary through them, the material's own outline), checked.

    A 2D loop is checked as a simple counter-clockwise polygon; a 3D lattice's
    surface is outward by construction (lattice.py).
    """
    n, d = position.shape
    anchors = np.asarray(spec["anchors"], dtype=float).reshape(-1, d)
    if d != 2:
        if len(anchors):
            raise CaseError(f"{label}.anchors close a 2D boundary loop; they apply to 2D "
                            f"cases only")
        return anchors, boundary, boundary
    outline = boundary[boundary < n]
    if len(anchors):
        boundary = _anchored_boundary(label, spec, boundary, shape, n, len(anchors))
    check_boundary(label, np.concatenate([position, anchors]), boundary)
    return anchors, boundary, outline


def _check_placement(label, position, springs, domain):
    """Refuse zero-length springs and nodes outside the domain."""
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    short = ~np.any(separation != 0.0, axis=1)
    if short.any():
        row = int(np.flatnonzero(short)[0])
        raise CaseError(f"{label}.springs[{row}] has zero rest length: nodes "
                        f"{springs[row, 0]} and {springs[row, 1]} coincide")
    if domain is not None:
        lower, upper = np.asarray(domain["lower"]), np.asarray(domain["upper"])
        # Along a periodic axis a body may lie across the seam.
        bounded = [a for a in range(len(lower))
                   if "xyz"[a] not in domain.get("periodic", ())]
        outside = outside_box(position[:, bounded], lower[bounded], upper[bounded])
        if outside.any():
            at = ", ".join(f"{x:.6g}" for x in position[np.flatnonzero(outside)[0]])
            raise CaseError(f"{label} has {int(outside.sum())} nodes outside the domain, "
                            f"e.g. at ({at})")


def _loads(label, spec, position, shape):
    """(nodes, force, start, end, ramp) of every [[body.load]], checked."""
    loads = []
    for l, load in enumerate(spec["load"]):
        where = f"{label}.load[{l}]"
        if not load["end"] > load["start"]:
            raise CaseError(f"{where}.end ({load['end']}) must exceed start ({load['start']})")
        if 2 * load["ramp"] > load["end"] - load["start"]:
            raise CaseError(f"{where}.ramp ({load['ramp']}) must be at most half the window "
                            f"end - start ({load['end'] - load['start']:g})")
        nodes = node_set(where, load["nodes"], position, load["index"], load["ids"], shape)
        if load["within"] > 0:
            # A contact patch: every node within the distance of the set's centre.
            centre = position[nodes].mean(axis=0)
            nodes = np.flatnonzero(np.linalg.norm(position - centre, axis=1)
                                   <= load["within"])
        force = np.asarray(load["force"], dtype=float)
        if load["total"]:
            force = force / len(nodes)
        loads.append((nodes, force, load["start"], load["end"], load["ramp"]))
    return loads


def build_body(k, spec, gravity, domain=None):
    """One :class:`Body` from a validated ``[[body]]`` table; the case's dimension is
    that of ``gravity``."""
    label = _label(k, spec)
    name = spec["name"] or f"body{k}"
    dimension = len(gravity)
    builder = {"lattice": _lattice, "general": _general, "shell": shell_body}[spec["type"]]
    if spec["type"] != "shell":
        check_shell_keys(label, spec)
    check_membrane_keys(label, spec)
    cell = spec.get("membrane", "springs") != "springs"   # a cell membrane, any law
    # A membrane replaces the shell's springs (membrane.attach): build it with placeholders.
    shell_spec = dict(spec, stiffness=1.0, bending_stiffness=0.0) if cell else spec
    position, springs, stiffness, mass, boundary, shape = builder(label, shell_spec, dimension)
    damping, axial_damping = spec["damping"], False
    if shape is not None and is_elastic(spec):
        stiffness, mass, damping, axial_damping, _ = elastic_lattice(label, spec, shape, springs)
    n = len(position)
    anchors, boundary, outline = _closed_boundary(label, spec, position, boundary, shape)
    _check_placement(label, np.concatenate([position, anchors]), springs, domain)
    pinned = pinned_nodes(label, spec, position, shape)
    loads = _loads(label, spec, position, shape)
    velocity = np.tile(np.asarray(spec["velocity"], dtype=float), (n, 1))
    if len(anchors):
        # Anchors follow the material nodes: pinned, at rest, without springs.
        a = len(anchors)
        position = np.concatenate([position, anchors])
        velocity = np.concatenate([velocity, np.zeros((a, dimension))])
        mass = np.concatenate([np.broadcast_to(mass, (n,)), np.full(a, np.mean(mass))])
        pinned = np.concatenate([pinned, np.ones(a, bool)])
    body = Body(name, position, velocity, mass, springs, stiffness, damping, boundary,
                volume_constraint=spec["volume_constraint"], pinned=pinned,
                gravity=gravity if spec["gravity"] else np.zeros(dimension), loads=loads,
                anchors=len(anchors), outline=outline, axial_damping=axial_damping,
                encloses_fluid=spec["type"] == "shell")
    if body.rest_volume <= 0.0:
        raise CaseError(f"{label}: its boundary encloses no volume ({body.rest_volume:.6g})")
    if cell:
        attach_membrane(body, label, spec)
    log.debug("body %s: %d nodes, %d springs, volume %.6g, %d pinned, %d loads", name, n,
              len(springs), body.rest_volume, int(pinned.sum()), len(loads))
    return body


def build_bodies(case):
    """Every ``[[body]]`` of a validated case, as
    :class:`~parmps.solids.mass_spring.body.Body` objects."""
    dimension = case.get("dimension", 2)
    gravity = case.get("physics", {}).get("gravity", [0.0] * (dimension - 1) + [-9.81])
    bodies = [build_body(k, spec, gravity, case.get("domain"))
              for k, spec in enumerate(case.get("body", []))]
    names = [body.name for body in bodies]
    for k, name in enumerate(names):
        if name in names[:k]:
            raise CaseError(f"body[{k}].name '{name}' is used twice; body names must differ")
    return bodies
