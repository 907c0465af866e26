"""Build the mass-spring bodies of a case (``[[body]]`` tables) and check them.

Two kinds of body:

- ``type = "lattice"``: nx x ny nodes at ``lower + (i, j) spacing``, node index
  ``i + nx j`` (row by row from the bottom-left), structural springs between
  horizontal and vertical neighbours (``stiffness``) and both diagonals of every
  cell (``shear_stiffness``). Its boundary loop is derived, counter-clockwise.
- ``type = "general"``: ``nodes``, ``springs`` (index pairs) and a named
  ``boundary`` loop. A loop given clockwise is refused (not silently reversed),
  with a message saying to reverse it, so the node order the user sees in the
  output is the one they wrote.

Node sets (for ``pinned`` and ``[[body.load]]``): a side (``top``, ``bottom``,
``left``, ``right``: the nodes at the extreme coordinate), ``all``, a lattice
``row`` or ``column`` (``index`` from 0 at the bottom/left), or listed ``ids``.

Every problem is a one-line :class:`CaseError` naming the body and the key.
"""

import logging

import numpy as np

from parmps.core.geometry import outside_box
from parmps.errors import CaseError
from parmps.solids.mass_spring.body import Body, polygon_area
from parmps.solids.mass_spring.elastic import check_not_elastic, elastic_lattice, is_elastic
from parmps.solids.mass_spring.lattice import FACE_DIAGONAL, lattice_geometry  # noqa: F401

log = logging.getLogger(__name__)

LATTICE_ONLY = ("nx", "ny", "spacing", "density", "shear_stiffness", "youngs_modulus")
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
    """Node masks of the four sides: nodes at the extreme coordinate (within rounding)."""
    extent = max(float(np.ptp(position, axis=0).max()), 1e-300)
    tol = 1e-9 * extent
    x, y = position[:, 0], position[:, 1]
    return {"bottom": y <= y.min() + tol, "top": y >= y.max() - tol,
            "left": x <= x.min() + tol, "right": x >= x.max() - tol,
            "all": np.ones(len(position), bool)}


def node_set(label, what, position, index=0, ids=(), shape=None):
    """Indices of the nodes a pinned side or a load names."""
    n = len(position)
    if what in ("row", "column"):
        if shape is None:
            raise CaseError(f"{label}.nodes = \"{what}\" needs a lattice body; use "
                            f"\"ids\" for a general body")
        nx, ny = shape
        count = ny if what == "row" else nx
        if index >= count:
            raise CaseError(f"{label}.index {index} is not a {what} of the {nx}x{ny} lattice "
                            f"(0..{count - 1})")
        grid = np.arange(nx * ny).reshape(ny, nx)
        return grid[index, :] if what == "row" else grid[:, index]
    if what == "ids":
        ids = np.asarray(ids, dtype=np.int64)
        if not len(ids):
            raise CaseError(f"{label}.ids is empty: list the nodes for nodes = \"ids\"")
        bad = ids[(ids < 0) | (ids >= n)]
        if len(bad):
            raise CaseError(f"{label}.ids names node {int(bad[0])}, but the body has "
                            f"{n} nodes (0..{n - 1})")
        return np.unique(ids)
    return np.flatnonzero(_sides(position)[what])


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


def _lattice(label, spec):
    for key in GENERAL_ONLY:
        if spec[key]:
            raise CaseError(f"{label}.{key} applies to general bodies only "
                            f"(set type = \"general\")")
    nx, ny, spacing = spec["nx"], spec["ny"], spec["spacing"]
    for key, value in (("nx", nx), ("ny", ny)):
        if value < 2:
            raise CaseError(f"{label}.{key} must be >= 2 for a lattice body, got {value}")
    if not spacing > 0:
        raise CaseError(f"{label}.spacing must be > 0 for a lattice body, got {spacing}")
    position, springs, kind, boundary = lattice_geometry((nx, ny), spacing, spec["lower"])
    shear = kind == FACE_DIAGONAL
    if is_elastic(spec):
        # Springs, masses and dashpots come from the material, in build_body.
        return position, springs, None, None, boundary, (nx, ny)
    check_not_elastic(label, spec)
    if spec["node_mass"] > 0 and spec["density"] > 0:
        raise CaseError(f"{label}: give node_mass or density, not both")
    if spec["node_mass"] > 0:
        mass = spec["node_mass"]
    elif spec["density"] > 0:
        # Per unit depth: each node carries one lattice cell's worth of material.
        mass = spec["density"] * spacing ** 2
    else:
        raise CaseError(f"{label}: node mass must be > 0: set node_mass [kg] or density "
                        f"[kg/m^3]")
    if spec["stiffness"] is None:
        raise CaseError(f"{label}: missing key 'stiffness' [N/m] (or give youngs_modulus [Pa])")
    shear_stiffness = spec["shear_stiffness"] or spec["stiffness"]
    stiffness = np.where(shear, shear_stiffness, spec["stiffness"])
    return position, springs, stiffness, np.full(len(position), mass), boundary, (nx, ny)


def _general(label, spec):
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


def build_body(k, spec, gravity, domain=None):
    """One :class:`Body` from a validated ``[[body]]`` table."""
    label = _label(k, spec)
    name = spec["name"] or f"body{k}"
    builder = _lattice if spec["type"] == "lattice" else _general
    position, springs, stiffness, mass, boundary, shape = builder(label, spec)
    damping, axial_damping = spec["damping"], False
    if shape is not None and is_elastic(spec):
        stiffness, mass, damping, axial_damping, _ = elastic_lattice(label, spec, shape, springs)
    n = len(position)
    anchors = np.asarray(spec["anchors"], dtype=float).reshape(-1, 2)
    outline = boundary[boundary < n]
    if len(anchors):
        boundary = _anchored_boundary(label, spec, boundary, shape, n, len(anchors))
    check_boundary(label, np.concatenate([position, anchors]), boundary)
    separation = position[springs[:, 0]] - position[springs[:, 1]]
    short = np.hypot(separation[:, 0], separation[:, 1]) == 0
    if short.any():
        row = int(np.flatnonzero(short)[0])
        raise CaseError(f"{label}.springs[{row}] has zero rest length: nodes "
                        f"{springs[row, 0]} and {springs[row, 1]} coincide")
    if domain is not None:
        lower, upper = np.asarray(domain["lower"]), np.asarray(domain["upper"])
        every = np.concatenate([position, anchors])
        outside = outside_box(every, lower, upper)
        if outside.any():
            x, y = every[np.flatnonzero(outside)[0]]
            raise CaseError(f"{label} has {int(outside.sum())} nodes outside the domain, "
                            f"e.g. at ({x:.6g}, {y:.6g})")
    pinned = np.zeros(n, bool)
    if spec["pinned"] != "none":
        pinned[node_set(f"{label}.pinned", spec["pinned"], position, shape=shape)] = True
    if spec["pinned_ids"]:
        pinned[node_set(f"{label}.pinned_ids", "ids", position, ids=spec["pinned_ids"])] = True
    loads = []
    for l, load in enumerate(spec["load"]):
        where = f"{label}.load[{l}]"
        if not load["end"] > load["start"]:
            raise CaseError(f"{where}.end ({load['end']}) must exceed start ({load['start']})")
        if 2 * load["ramp"] > load["end"] - load["start"]:
            raise CaseError(f"{where}.ramp ({load['ramp']}) must be at most half the window "
                            f"end - start ({load['end'] - load['start']:g})")
        nodes = node_set(where, load["nodes"], position, load["index"], load["ids"], shape)
        loads.append((nodes, np.asarray(load["force"]), load["start"], load["end"],
                      load["ramp"]))
    velocity = np.tile(np.asarray(spec["velocity"], dtype=float), (n, 1))
    if len(anchors):
        # Anchors follow the material nodes: pinned, at rest, without springs.
        a = len(anchors)
        position = np.concatenate([position, anchors])
        velocity = np.concatenate([velocity, np.zeros((a, 2))])
        mass = np.concatenate([np.broadcast_to(mass, (n,)), np.full(a, np.mean(mass))])
        pinned = np.concatenate([pinned, np.ones(a, bool)])
    body = Body(name, position, velocity, mass, springs, stiffness, damping, boundary,
                volume_constraint=spec["volume_constraint"], pinned=pinned,
                gravity=gravity if spec["gravity"] else (0.0, 0.0), loads=loads,
                anchors=len(anchors), outline=outline, axial_damping=axial_damping)
    log.debug("body %s: %d nodes, %d springs, area %.6g, %d pinned, %d loads", name, n,
              len(springs), body.rest_volume, int(pinned.sum()), len(loads))
    return body


def build_bodies(case):
    """Every ``[[body]]`` of a validated case, as :class:`~parmps.solids.mass_spring.body.Body` objects."""
    gravity = case.get("physics", {}).get("gravity", (0.0, -9.81))
    bodies = [build_body(k, spec, gravity, case.get("domain"))
              for k, spec in enumerate(case.get("body", []))]
    names = [body.name for body in bodies]
    for k, name in enumerate(names):
        if name in names[:k]:
            raise CaseError(f"body[{k}].name '{name}' is used twice; body names must differ")
    return bodies
