"""Case section of the probes: ``[[probe]]`` tables, one per probe (docs/design.md §5.1)."""

import math
import re

import numpy as np

from parmps.config import Key, Section
from parmps.core.settings import has_fluid
from parmps.errors import CaseError

KINDS = ("pressure", "level", "force", "displacement")

# Which of the geometric keys each kind takes (the others must be left out).
_GEOMETRY = {"pressure": ("position", "normal"), "level": ("line",),
             "force": ("segment", "normal", "body"), "displacement": ("body", "nodes")}
_GEOMETRY_KEYS = ("position", "line", "segment", "normal", "body", "nodes")

SECTIONS = {
    "probe": Section({
        "name": Key("str", doc="names /probes/<name> in result.h5 and OUTDIR/probes/<name>.csv"),
        "kind": Key("str", choices=KINDS,
                    doc="pressure: a Shepard average of the fluid's pressure around a point; "
                        "level: the water's height along a vertical line; force: the "
                        "fluid's force on a wall segment or on a body; displacement: the "
                        "mean displacement of some of a body's nodes from their rest "
                        "positions"),
        "position": Key("vec2", None, doc="pressure: the point [m]"),
        "normal": Key("vec2", None,
                      doc="pressure or force on a wall: the wall's normal, pointing into the "
                          "fluid; the sample points move half a spacing along it, onto the "
                          "centre line of the first fluid layer"),
        "line": Key("points", [], doc="level: [[x, y_bottom], [x, y_top]], vertical [m]"),
        "reading": Key("str", "depth", choices=("depth", "crossing"),
                       doc="level: depth, y_bottom plus the integral of the fluid fill over "
                           "the water column standing on the line's bottom (a wave gauge: a "
                           "jet passing above does not count); crossing, the highest height "
                           "at which the fill falls through 0.5 (a jet's top reads as the "
                           "level)"),
        "segment": Key("points", [], doc="force: the wall segment [[x0, y0], [x1, y1]] [m]"),
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
                        doc="pressure: a point whose fluid weights sum to less than this "
                            "fraction of a full lattice's reads NaN (DualSPHysics's kclimit)"),
    }, many=True, doc="a probe sampled during the run (docs/design.md §5.1)"),
}


def check(case):
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
            given = probe[key] not in (None, [], "")
            if given and key not in _GEOMETRY[kind]:
                raise CaseError(f"{label}.{key} is not a key of a {kind} probe (it takes "
                                f"{', '.join(_GEOMETRY[kind])})")
        if kind != "level" and probe["reading"] != "depth":
            raise CaseError(f"{label}.reading is a key of a level probe only")
        if probe["normal"] is not None and math.hypot(*probe["normal"]) == 0.0:
            raise CaseError(f"{label}.normal must not be zero")
        if kind == "pressure":
            if probe["position"] is None:
                raise CaseError(f"missing key '{label}.position': a pressure probe needs "
                                f"its point")
            _inside(case, f"{label}.position", probe["position"])
        elif kind == "level":
            line = probe["line"]
            if len(line) != 2:
                raise CaseError(f"missing key '{label}.line': a level probe needs "
                                f"[[x, y_bottom], [x, y_top]]" if not line else
                                f"{label}.line must have 2 points, got {len(line)}")
            # Vertical: along the last axis, the gravity axis of every case.
            if line[0][:-1] != line[1][:-1] or not line[1][-1] > line[0][-1]:
                raise CaseError(f"{label}.line must be vertical and run upwards "
                                f"([[x, y_bottom], [x, y_top]]), got {line}")
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
    """A body's node positions as the case builds them (n, 2): a lattice's i + nx j."""
    if body["type"] == "lattice":
        i, j = np.meshgrid(np.arange(body["nx"]), np.arange(body["ny"]))
        return np.asarray(body["lower"]) + body["spacing"] * np.column_stack(
            [i.ravel(), j.ravel()]).astype(float)
    return np.asarray(body["nodes"], dtype=float).reshape(-1, 2)


def _check_force(case, label, probe):
    segment, body = probe["segment"], probe["body"]
    if bool(segment) == bool(body):
        raise CaseError(f"{label} needs exactly one of 'segment' and 'body'")
    if body:
        bodies = [spec["name"] or f"body{k}" for k, spec in enumerate(case["body"])]
        if body not in bodies:
            raise CaseError(f"{label}.body '{body}' is not a body of the case "
                            f"({', '.join(bodies) or 'it has none'})")
        if probe["normal"] is not None:
            raise CaseError(f"{label}.normal is not a key of a force probe on a body")
        return
    if len(segment) != 2:
        raise CaseError(f"{label}.segment must have 2 points, got {len(segment)}")
    (x0, y0), (x1, y1) = segment
    length = math.hypot(x1 - x0, y1 - y0)
    if length == 0.0:
        raise CaseError(f"{label}.segment has zero length")
    if probe["normal"] is None:
        raise CaseError(f"missing key '{label}.normal': a force probe on a segment needs "
                        f"the wall's normal, pointing into the fluid")
    nx, ny = probe["normal"]
    if abs(nx * (x1 - x0) + ny * (y1 - y0)) > 1e-9 * length * math.hypot(nx, ny):
        raise CaseError(f"{label}.normal {probe['normal']} is not perpendicular to its "
                        f"segment")
    for point in segment:
        _inside(case, f"{label}.segment", point)


def _inside(case, name, point):
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    if not all(lower[a] <= point[a] <= upper[a] for a in range(2)):
        raise CaseError(f"{name} {point} lies outside the domain {lower}..{upper}")
