"""Case section of the probes: ``[[probe]]`` tables, one per probe (docs/design.md §5.1)."""

import re

import numpy as np

from parmps.config import ZERO, Key, PerDimension, Section
from parmps.core.settings import has_fluid, snap_to_lattice
from parmps.errors import CaseError
from parmps.solids.mass_spring.lattice import lattice_geometry

KINDS = ("pressure", "level", "force", "displacement")

# Which of the geometric keys each kind takes (the others must be left out).
_GEOMETRY = {"pressure": ("position", "normal"), "level": ("line",),
             "force": ("segment", "patch", "wall_box", "wall", "normal", "body"),
             "displacement": ("body", "nodes")}
_GEOMETRY_KEYS = ("position", "line", "segment", "patch", "wall_box", "wall", "normal", "body",
                  "nodes")

SECTIONS = {
    "probe": Section({
        "name": Key("str", doc="names /probes/<name> in result.h5 and OUTDIR/probes/<name>.csv"),
        "kind": Key("str", choices=KINDS,
                    doc="pressure: a Shepard average of the fluid's pressure around a point; "
                        "level: the water's height along a vertical line; force: the "
                        "fluid's force on a wall segment (2D), a rectangular wall patch (3D), "
                        "a wall box or a body; displacement: the "
                        "mean displacement of some of a body's nodes from their rest "
                        "positions"),
        "position": Key("vector", None, doc="pressure: the point [m]"),
        "normal": Key("vector", None,
                      doc="pressure or force on a wall: the wall's normal, pointing into the "
                          "fluid; the sample points move half a spacing along it, onto the "
                          "centre line of the first fluid layer"),
        "line": Key("points", [], doc="level: [[x, y_bottom], [x, y_top]] in 2D, "
                                      "[[x, y, z_bottom], [x, y, z_top]] in 3D: vertical [m]"),
        "reading": Key("str", "depth", choices=("depth", "crossing"),
                       doc="level: depth, the line's bottom plus the integral of the fluid "
                           "fill over the water column standing on it (a wave gauge: a jet "
                           "passing above does not count); crossing, the highest height at "
                           "which the fill falls through 0.5 (a jet's top reads as the level)"),
        "segment": Key("points", [], doc="force, 2D: the wall segment [[x0, y0], [x1, y1]] [m]"),
        "patch": Key("points", [],
                     doc="force, 3D: a rectangle of wall in a plane x, y or z = const, given "
                         "by two opposite corners [[x0, y0, z0], [x1, y1, z1]] [m]"),
        "wall_box": Key("int", -1, ge=-1,
                        doc="force: the index k of a fixed [[wall_box]] (0 for the first): "
                            "the fluid's force on all its faces (the pressure sampled on "
                            "them and the viscous force on its particles); -1: none"),
        "wall": Key("str", "", doc="force: the name of a fixed [[wall]] (of any shape): the "
                                   "fluid's force on all its surface (the pressure sampled "
                                   "on it and the viscous force on its particles)"),
        "body": Key("str", "", doc="force: the body's name (the sum over its nodes); "
                                   "displacement: the body whose nodes are followed"),
        "nodes": Key("ints", [], ge=0,
                     doc="displacement: node indices (i + nx j on a lattice) whose mean "
                         "displacement is sampled"),
        "interval": Key("float", 0.0, ge=0.0,
                        doc="simulated time between samples [s]; 0: every step"),
        "radius": Key("float", 2.0, ge=1.0, le=4.0,
                      doc="the sampling kernel's radius, in spacings l0"),
        "min_fill": Key("float", 0.5, gt=0.0, le=1.0,
                        doc="pressure: a point whose fluid fills less than this share of the "
                            "part of its support outside walls reads NaN (dry; 0.5: the "
                            "free surface, where the level probe draws it)"),
    }, many=True, doc="a probe sampled during the run (docs/design.md §5.1)"),
}


def snap_to_faces(case):
    """With particles.snap the walls' faces lie on the lattice's lines: a probe on a wall
    (one with a normal) moves along its normal onto the face as built, and a patch or
    segment onto those lines, in place."""
    for probe in case["probe"]:
        if probe["normal"] is not None and probe["position"] is not None:
            snapped = snap_to_lattice(probe["position"], case)
            normal = np.abs(np.asarray(probe["normal"], float))
            along = normal > 1e-12 * normal.max()
            probe["position"] = [s if a else p for s, p, a in
                                 zip(snapped, probe["position"], along)]
        for key in ("segment", "patch"):
            probe[key] = [snap_to_lattice(point, case) for point in probe[key]]


def check(case):
    if case["particles"]["snap"] and case["particles"]["spacing"] is not None:
        snap_to_faces(case)
    names = set()
    for k, probe in enumerate(case["probe"]):
        label = f"probe[{k}]"
        name = probe["name"]
        if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", name):
            raise CaseError(f"{label}.name must be letters, digits, '_', '-' or '.' (it names "
                            f"a file and an HDF5 group), got {name!r}")
        if name in names:
            raise CaseError(f"{label}.name '{name}' is used by an earlier probe")
        names.add(name)
        label = f"{label} '{name}'"
        kind = probe["kind"]
        if not probe["body"] and not has_fluid(case):
            raise CaseError(f"{label} samples the fluid, but the case has no fluid or walls")
        for key in _GEOMETRY_KEYS:
            given = probe[key] not in (None, [], "", -1)
            if given and key not in _GEOMETRY[kind]:
                raise CaseError(f"{label}.{key} is not a key of a {kind} probe (it takes "
                                f"{', '.join(_GEOMETRY[kind])})")
        if kind != "level" and probe["reading"] != "depth":
            raise CaseError(f"{label}.reading is a key of a level probe only")
        if probe["normal"] is not None and not any(probe["normal"]):
            raise CaseError(f"{label}.normal must not be zero")
        if kind == "pressure":
            if probe["position"] is None:
                raise CaseError(f"missing key '{label}.position': a pressure probe needs "
                                f"its point")
            _inside(case, f"{label}.position", probe["position"])
        elif kind == "level":
            line = probe["line"]
            form = _LINE_FORM[case["dimension"]]
            if len(line) != 2:
                raise CaseError(f"missing key '{label}.line': a level probe needs "
                                f"{form}" if not line else
                                f"{label}.line must have 2 points, got {len(line)}")
            if line[0][:-1] != line[1][:-1] or not line[1][-1] > line[0][-1]:
                raise CaseError(f"{label}.line must be vertical and run upwards "
                                f"({form}), got {line}")
            for point in line:
                _inside(case, f"{label}.line", point)
        elif kind == "displacement":
            _check_displacement(case, label, probe)
        else:
            _check_force(case, label, probe)


def _check_displacement(case, label, probe):
    bodies = {spec["name"] or f"body{k}": spec for k, spec in enumerate(case["body"])}
    if probe["body"] not in bodies:
        raise CaseError(f"missing key '{label}.body': a displacement probe needs a body of the "
                        f"case ({', '.join(bodies) or 'it has none'})" if not probe["body"]
                        else f"{label}.body '{probe['body']}' is not a body of the case "
                             f"({', '.join(bodies) or 'it has none'})")
    if not probe["nodes"]:
        raise CaseError(f"missing key '{label}.nodes': a displacement probe needs the node "
                        f"indices it follows")
    count = len(rest_positions(bodies[probe["body"]]))
    if max(probe["nodes"]) >= count:
        raise CaseError(f"{label}.nodes has {max(probe['nodes'])}, but body "
                        f"'{probe['body']}' has {count} nodes")


def rest_positions(body):
    """A body's node positions as the case builds them (n, d): a lattice's i + nx j
    (+ nx ny k), d the number of components of its ``lower``."""
    if body["type"] == "lattice":
        shape = [body[key] for key in ("nx", "ny", "nz")[:len(body["lower"])]]
        return lattice_geometry(shape, body["spacing"], body["lower"]).position
    return np.asarray(body["nodes"], dtype=float).reshape(-1, 2)


# How a level probe's line is written, by dimension.
_LINE_FORM = {2: "[[x, y_bottom], [x, y_top]]", 3: "[[x, y, z_bottom], [x, y, z_top]]"}

# The key naming a force probe's piece of wall, by dimension.
_WALL_PIECE = {2: "segment", 3: "patch"}


def _check_force(case, label, probe):
    piece = _WALL_PIECE[case["dimension"]]
    other = _WALL_PIECE[5 - case["dimension"]]
    if probe[other]:
        raise CaseError(f"{label}.{other} is for a {5 - case['dimension']}D case; "
                        f"this one is {case['dimension']}D: give {piece}")
    given = [key for key in (piece, "wall_box", "wall", "body")
             if probe[key] not in ([], "", -1)]
    if len(given) != 1:
        raise CaseError(f"{label} needs exactly one of '{piece}', 'wall_box', 'wall' and "
                        f"'body'" + (f" (it has {', '.join(given)})" if given else ""))
    if probe["wall_box"] >= 0:
        _check_wall_box(case, label, probe)
        return
    if probe["wall"]:
        _check_wall(case, label, probe)
        return
    if probe["body"]:
        body = probe["body"]
        bodies = [spec["name"] or f"body{k}" for k, spec in enumerate(case["body"])]
        if body not in bodies:
            raise CaseError(f"{label}.body '{body}' is not a body of the case "
                            f"({', '.join(bodies) or 'it has none'})")
        if probe["normal"] is not None:
            raise CaseError(f"{label}.normal is not a key of a force probe on a body")
        return
    corners = probe[piece]
    if len(corners) != 2:
        raise CaseError(f"{label}.{piece} must have 2 points, got {len(corners)}")
    a, b = (np.asarray(point, float) for point in corners)
    length = float(np.linalg.norm(b - a))
    if piece == "patch" and np.count_nonzero(b != a) != 2:
        raise CaseError(f"{label}.patch must be a rectangle in a plane x, y or z = const "
                        f"(two opposite corners that differ in two coordinates), got {corners}")
    if length == 0.0:
        raise CaseError(f"{label}.{piece} has zero length")
    if probe["normal"] is None:
        raise CaseError(f"missing key '{label}.normal': a force probe on a {piece} needs "
                        f"the wall's normal, pointing into the fluid")
    normal = np.asarray(probe["normal"], float)
    # In 3D the patch spans two axes; its normal must lie along the third.
    spans = np.diag(b - a) if piece == "patch" else (b - a)[None, :]
    if np.any(np.abs(spans @ normal) > 1e-9 * length * np.linalg.norm(normal)):
        raise CaseError(f"{label}.normal {probe['normal']} is not perpendicular to its "
                        f"{piece}")
    for point in corners:
        _inside(case, f"{label}.{piece}", point)


def _check_wall_box(case, label, probe):
    boxes = case["wall_box"]
    k = probe["wall_box"]
    if k >= len(boxes):
        raise CaseError(f"{label}.wall_box is {k}, but the case has {len(boxes)} "
                        f"[[wall_box]] (the first is 0)")
    if any(boxes[k]["velocity"]):
        raise CaseError(f"{label}.wall_box {k} moves: a force probe follows fixed walls only")
    if probe["normal"] is not None:
        raise CaseError(f"{label}.normal is not a key of a force probe on a wall box (each "
                        f"face's normal points out of the box)")


def _check_wall(case, label, probe):
    walls = {spec["name"]: spec for spec in case["wall"] if spec["name"]}
    if probe["wall"] not in walls:
        raise CaseError(f"{label}.wall '{probe['wall']}' is not the name of a [[wall]] of the "
                        f"case ({', '.join(walls) or 'it has no named wall'})")
    if any(walls[probe["wall"]]["velocity"]):
        raise CaseError(f"{label}.wall '{probe['wall']}' moves: a force probe follows fixed "
                        f"walls only")
    if probe["normal"] is not None:
        raise CaseError(f"{label}.normal is not a key of a force probe on a wall (the "
                        f"normals are its surface's, pointing into the fluid)")


def _inside(case, name, point):
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    if not all(lower[a] <= point[a] <= upper[a] for a in range(len(lower))):
        raise CaseError(f"{name} {point} lies outside the domain {lower}..{upper}")
