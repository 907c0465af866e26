"""Case section of the run-time checks: ``[[check]]`` tables (parmps.checks)."""

import re

from parmps.checks import CHECKS
from parmps.config import Key, Section
from parmps.core.settings import has_fluid
from parmps.errors import CaseError

SECTIONS = {
    "check": Section({
        "kind": Key("str", choices=tuple(CHECKS),
                    doc="body_crossing: fluid particles whose path crossed a thin lattice "
                        "body's mid-line (mid-surface in 3D) or a closed shell's surface, "
                        "counted every step; wall_crossing: fluid particles that crossed a "
                        "wall's surface into its material"),
        "body": Key("str", "", doc="body_crossing: the body's name"),
        "wall": Key("str", "", doc="wall_crossing: the name of a [[wall]] (of any shape): "
                                   "fluid particles that went into its material, across its "
                                   "surface, within a step"),
        "name": Key("str", "", doc="names /checks/<name> in result.h5; default "
                                   "<kind>_<body> (<kind>_<wall>)"),
    }, many=True, doc="a count of what must not happen, recorded every step"),
}


def check(case):
    names = set()
    bodies = {spec["name"] or f"body{k}": spec for k, spec in enumerate(case["body"])}
    walls = [spec["name"] for spec in case["wall"] if spec["name"]]
    for k, spec in enumerate(case["check"]):
        label = f"check[{k}]"
        if spec["kind"] == "wall_crossing":
            _check_wall(case, label, spec, walls)
            target = spec["wall"]
        else:
            _check_body(case, label, spec, bodies)
            target = spec["body"]
        spec["name"] = spec["name"] or f"{spec['kind']}_{target}"
        if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", spec["name"]):
            raise CaseError(f"{label}.name must be letters, digits, '_', '-' or '.' (it names "
                            f"an HDF5 group), got {spec['name']!r}")
        if spec["name"] in names:
            raise CaseError(f"{label}.name '{spec['name']}' is used by an earlier check")
        names.add(spec["name"])


def _check_wall(case, label, spec, walls):
    if spec["body"]:
        raise CaseError(f"{label}.body is not a key of a wall_crossing check (give wall)")
    if spec["wall"] not in walls:
        raise CaseError(f"missing key '{label}.wall': a wall_crossing check needs a named "
                        f"[[wall]] ({', '.join(walls) or 'the case has none'})"
                        if not spec["wall"] else
                        f"{label}.wall '{spec['wall']}' is not the name of a [[wall]] of the "
                        f"case ({', '.join(walls) or 'it has no named wall'})")


def _check_body(case, label, spec, bodies):
    if spec["wall"]:
        raise CaseError(f"{label}.wall is a key of a wall_crossing check only")
    if not spec["body"]:
        raise CaseError(f"missing key '{label}.body': a {spec['kind']} check needs a body")
    if spec["body"] not in bodies:
        raise CaseError(f"{label}.body '{spec['body']}' is not a body of the case "
                        f"({', '.join(bodies) or 'it has none'})")
    body = bodies[spec["body"]]
    if spec["kind"] == "body_crossing":
        counts = [body[key] for key in ("nx", "ny", "nz")[:case["dimension"]]]
        if body["type"] != "shell" and (body["type"] != "lattice" or min(counts) < 2):
            least = " x ".join(["2"] * case["dimension"])
            raise CaseError(f"{label}.body '{spec['body']}' must be a shell or a lattice of "
                            f"at least {least} nodes: its mid-line (mid-surface in 3D) is "
                            f"the mean through its thinnest direction")
        if not has_fluid(case):
            raise CaseError(f"{label} counts fluid particles, but the case has no fluid")
