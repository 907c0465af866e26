"""Case files: TOML, validated strictly against a schema before anything runs.

A case is a TOML document whose tables are the sections of ``SCHEMA``. Every key
has a type, a range and usually a default; unknown keys, wrong types and values
out of range raise :class:`CaseError` with one line naming the key. The result
of :func:`validate` is a plain nested dict with every default filled in.
"""

import difflib
import math
import tomllib

from parmps.errors import CaseError

REQUIRED = object()


class Key:
    """One entry of a section: its type, default and allowed range.

    kind is one of "float", "int", "bool", "str", "vec2" (two floats),
    "floats" (a list of floats), "ints" (a list of ints), "options" (a table of
    scalars passed through, e.g. PETSc options), "points" (a list of [x, y]),
    "pairs" (a list of [i, j] integer pairs) or "tables" (an array of tables,
    ``[[section.key]]``, each checked against the sub-schema ``keys``).
    """

    def __init__(self, kind, default=REQUIRED, *, gt=None, ge=None, lt=None, le=None,
                 choices=None, keys=None, doc=""):
        self.kind = kind
        self.default = default
        self.gt, self.ge, self.lt, self.le = gt, ge, lt, le
        self.choices = choices
        self.keys = keys
        self.doc = doc

    def check(self, name, value):
        if self.kind == "tables":
            if isinstance(value, dict):
                value = [value]
            if not isinstance(value, list):
                raise CaseError(f"{name} must be an array of tables ([[{name}]]), "
                                f"got {_type_name(value)}")
            return [_validate_table(f"{name}[{k}]", self.keys, item)
                    for k, item in enumerate(value)]
        value = _coerce(name, self.kind, value)
        for item in (value if self.kind in ("vec2", "floats", "ints") else [value]):
            self._check_range(name, item)
        if self.choices is not None and value not in self.choices:
            raise CaseError(f"{name} must be one of {', '.join(map(repr, self.choices))}, "
                            f"got {value!r}")
        return value

    def _check_range(self, name, value):
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return
        if self.gt is not None and not value > self.gt:
            raise CaseError(f"{name} must be > {self.gt}, got {value}")
        if self.ge is not None and not value >= self.ge:
            raise CaseError(f"{name} must be >= {self.ge}, got {value}")
        if self.lt is not None and not value < self.lt:
            raise CaseError(f"{name} must be < {self.lt}, got {value}")
        if self.le is not None and not value <= self.le:
            raise CaseError(f"{name} must be <= {self.le}, got {value}")


class Section:
    """A TOML table (many=False) or an array of tables (many=True)."""

    def __init__(self, keys, *, many=False, required=False, doc=""):
        self.keys = keys
        self.many = many
        self.required = required
        self.doc = doc


def _type_name(value):
    return {bool: "boolean", int: "integer", float: "number", str: "string",
            list: "array", dict: "table"}.get(type(value), type(value).__name__)


def _coerce(name, kind, value):
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(f"{name} must be a number, got {_type_name(value)} {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise CaseError(f"{name} must be finite, got {value}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise CaseError(f"{name} must be an integer, got {_type_name(value)} {value!r}")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise CaseError(f"{name} must be true or false, got {_type_name(value)} {value!r}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise CaseError(f"{name} must be a string, got {_type_name(value)} {value!r}")
        return value
    if kind in ("vec2", "floats", "ints"):
        if not isinstance(value, list):
            raise CaseError(f"{name} must be an array, got {_type_name(value)} {value!r}")
        if kind == "vec2" and len(value) != 2:
            raise CaseError(f"{name} must have 2 components [x, y], got {len(value)}")
        item_kind = "int" if kind == "ints" else "float"
        return [_coerce(f"{name}[{k}]", item_kind, v) for k, v in enumerate(value)]
    if kind in ("points", "pairs"):
        if not isinstance(value, list):
            raise CaseError(f"{name} must be an array, got {_type_name(value)} {value!r}")
        item_kind = "vec2" if kind == "points" else "ints"
        items = [_coerce(f"{name}[{k}]", item_kind, v) for k, v in enumerate(value)]
        if kind == "pairs":
            for k, item in enumerate(items):
                if len(item) != 2:
                    raise CaseError(f"{name}[{k}] must be a pair [i, j], got {len(item)} entries")
        return items
    if kind == "options":
        if not isinstance(value, dict):
            raise CaseError(f"{name} must be a table, got {_type_name(value)} {value!r}")
        out = {}
        for k, v in value.items():
            if not isinstance(v, (str, int, float, bool)):
                raise CaseError(f"{name}.{k} must be a string, number or boolean, "
                                f"got {_type_name(v)}")
            out[k] = v
        return out
    raise AssertionError(f"unknown key kind {kind}")


def _unknown(name, key, valid):
    close = difflib.get_close_matches(key, list(valid), n=1, cutoff=0.5)
    hint = f" (did you mean '{close[0]}'?)" if close else \
        f" (valid: {', '.join(sorted(valid))})"
    where = f"{name}.{key}" if name else key
    return CaseError(f"unknown key '{where}'{hint}")


def _validate_table(name, keys, raw):
    if not isinstance(raw, dict):
        raise CaseError(f"{name} must be a table, got {_type_name(raw)}")
    for key in raw:
        if key not in keys:
            raise _unknown(name, key, keys)
    out = {}
    for key, spec in keys.items():
        full = f"{name}.{key}"
        if key in raw:
            out[key] = spec.check(full, raw[key])
        elif spec.default is REQUIRED:
            raise CaseError(f"missing key '{full}'")
        else:
            # Copy list defaults so no two cases share one mutable object.
            out[key] = list(spec.default) if isinstance(spec.default, list) else spec.default
    return out


VEC_ZERO = (0.0, 0.0)

# Prescribed motion of a tank or wall box (parmps.boundaries.walls): its wall and dummy
# particles translate together at `velocity` while move_start <= t < move_end.
# "Never stops" is the default move_end, infinity; a case file cannot write
# it (numbers must be finite), it leaves the key out.
MOTION_KEYS = {
    "velocity": Key("vec2", [0.0, 0.0],
                    doc="constant velocity of the whole geometry, walls and dummies [m/s]; "
                        "[0, 0]: fixed"),
    "move_start": Key("float", 0.0, ge=0.0, doc="time the motion starts [s]"),
    "move_end": Key("float", math.inf, gt=0.0,
                    doc="time the motion stops [s], > move_start; default: never stops"),
}

SCHEMA = {
    "title": None,  # a free string, checked below
    "domain": Section({
        "lower": Key("vec2", doc="lower-left corner; every particle must lie inside"),
        "upper": Key("vec2", doc="upper-right corner"),
    }, required=True, doc="the box that holds every particle for the whole run"),
    "particles": Section({
        "spacing": Key("float", None, gt=0.0,
                       doc="initial particle spacing l0 [m]; needed by any case with fluid "
                           "or walls, not by a solid-only case"),
    }),
    "fluid": Section({
        "density": Key("float", 1000.0, gt=0.0, doc="rho [kg/m^3]"),
        "viscosity": Key("float", 1.0e-6, ge=0.0, doc="kinematic viscosity nu [m^2/s]"),
    }),
    "physics": Section({
        "gravity": Key("vec2", [0.0, -9.81], doc="[m/s^2]"),
    }),
    "mps": Section({
        "re_number_density": Key("float", 2.3, gt=1.0, le=5.0,
                                 doc="radius for number density and gradient, in l0"),
        "re_laplacian": Key("float", 3.1, gt=1.0, le=5.0, doc="radius for the Laplacian, in l0"),
        "surface_threshold": Key("float", 0.97, gt=0.0, lt=1.0,
                                 doc="beta: n* < beta n0 marks a free-surface particle"),
        "neighbour_threshold": Key("float", 0.0, ge=0.0, lt=1.0,
                                   doc="also surface if neighbour count < this times the "
                                       "full-lattice count (0 disables)"),
        "relaxation": Key("float", 0.2, gt=0.0, le=1.0, doc="gamma in the PPE source term"),
        "source_term": Key("str", "density", choices=("density", "mixed"),
                           doc="PPE source: number-density deviation, or the mixed "
                               "divergence + density term (Tanaka & Masunaga 2010)"),
        "mixed_relaxation": Key("float", 0.01, gt=0.0, le=1.0,
                                doc="gamma of the density term in the mixed source"),
        "compressibility": Key("float", 0.45e-9, ge=0.0, doc="c_comp [1/Pa]"),
        "clamp_negative_pressure": Key("bool", True),
        "gradient_correction": Key("bool", False,
                                   doc="multiply the pressure gradient by the inverse of its "
                                       "moment matrix (Khayyer & Gotoh 2011), which corrects its "
                                       "normalisation on a disordered arrangement"),
        "gradient_correction_limit": Key("float", 0.7, gt=0.0, le=1.0,
                                         doc="rows whose moment matrix (the identity on the "
                                             "full lattice) has an eigenvalue below this keep "
                                             "the plain gradient"),
        "collision": Key("bool", True),
        "collision_distance": Key("float", 0.5, gt=0.0, lt=1.0, doc="in l0"),
        "restitution": Key("float", 0.2, ge=0.0, le=1.0),
    }),
    "time": Section({
        "end": Key("float", gt=0.0, doc="end time [s]"),
        "dt_max": Key("float", 1.0e-3, gt=0.0, doc="largest step [s]"),
        "fixed_dt": Key("float", 0.0, ge=0.0, doc="a fixed step [s]; 0 means adaptive"),
        "cfl": Key("float", 0.2, gt=0.0, le=1.0, doc="C_cfl: dt <= C_cfl l0 / |u|max"),
        "viscous_number": Key("float", 0.2, gt=0.0, le=1.0, doc="dt <= C l0^2 / nu"),
        "output_interval": Key("float", 0.05, gt=0.0, doc="time between frames [s]"),
        "max_steps": Key("int", 0, ge=0, doc="stop after this many steps; 0 means no limit"),
    }, required=True),
    "pressure": Section({
        "rtol": Key("float", 1.0e-8, gt=0.0, lt=1.0),
        "max_iterations": Key("int", 1000, gt=0),
        "reuse_preconditioner": Key("int", 4, ge=0,
                                    doc="steps a preconditioner set-up is reused for "
                                        "(0: set up every step)"),
        "ksp_type": Key("str", "cg"),
        "pc_type": Key("str", "gamg"),
        "options": Key("options", {}, doc="more PETSc options, without the pressure_ prefix"),
    }),
    "fluid_block": Section({
        "lower": Key("vec2"),
        "upper": Key("vec2"),
        "velocity": Key("vec2", [0.0, 0.0]),
    }, many=True, doc="a rectangle filled with fluid particles on the l0 lattice"),
    "tank": Section({
        "lower": Key("vec2", doc="inner lower-left corner (the wall surface)"),
        "upper": Key("vec2", doc="inner upper-right corner; the side walls end at its y"),
        "wall_layers": Key("int", 2, ge=1, le=10),
        "dummy_layers": Key("int", 2, ge=0, le=10),
        "open_top": Key("bool", True),
        **MOTION_KEYS,
    }, many=True, doc="walls around a rectangle, with dummy layers behind them; they may "
                      "translate at a constant velocity (see MOTION_KEYS)"),
    "wall_box": Section({
        "lower": Key("vec2"),
        "upper": Key("vec2"),
        "wall_layers": Key("int", 2, ge=1, le=10),
        **MOTION_KEYS,
    }, many=True, doc="a solid rectangular obstacle: wall layers outside, dummies inside; "
                      "it may translate at a constant velocity (see MOTION_KEYS)"),
    "solid": Section({
        "substep": Key("float", 0.0, ge=0.0,
                       doc="fixed solid substep [s]; 0 chooses it from the stiffest node"),
        "safety": Key("float", 0.5, gt=0.0, le=1.0,
                      doc="automatic substep = safety x the Verlet stability limit"),
        "constraint_prediction": Key("str", "linear", choices=("linear", "quadratic"),
                                     doc="linear: the area multiplier of DESIGN.md 1.5; "
                                         "quadratic: also predicts the area swept in a "
                                         "substep (rotating bodies)"),
    }, doc="mass-spring solver settings shared by every body"),
    "body": Section({
        "name": Key("str", "", doc="used in the output; default body<k>"),
        "type": Key("str", "lattice", choices=("lattice", "general")),
        "nx": Key("int", 0, ge=0, doc="lattice: nodes along x"),
        "ny": Key("int", 0, ge=0, doc="lattice: nodes along y"),
        "spacing": Key("float", 0.0, ge=0.0, doc="lattice: node spacing [m]"),
        "lower": Key("vec2", [0.0, 0.0], doc="lattice: position of the lower-left node"),
        "nodes": Key("points", [], doc="general: node positions [[x, y], ...]"),
        "springs": Key("pairs", [], doc="general: springs as node index pairs [[i, j], ...]"),
        "boundary": Key("ints", [], doc="general: the boundary loop, counter-clockwise"),
        "masses": Key("floats", [], gt=0.0, doc="general: one mass per node [kg]"),
        "spring_stiffness": Key("floats", [], gt=0.0,
                                doc="general: one stiffness per spring [N/m]"),
        "node_mass": Key("float", 0.0, ge=0.0, doc="mass of every node [kg]"),
        "density": Key("float", 0.0, ge=0.0,
                       doc="lattice: node mass = density x spacing^2 (per unit depth); "
                           "with youngs_modulus: density x thickness x spacing^2 x the "
                           "share of the cells the node touches"),
        "stiffness": Key("float", None, gt=0.0,
                         doc="structural (or every) spring [N/m]; a lattice may give "
                             "youngs_modulus instead"),
        "shear_stiffness": Key("float", 0.0, ge=0.0,
                               doc="lattice diagonal springs [N/m]; 0 means = stiffness"),
        "damping": Key("float", 0.0, ge=0.0, doc="b in -b (v_i - v_j) [N s/m]"),
        # Elastic material of a lattice body (parmps.solids.mass_spring.elastic).
        "youngs_modulus": Key("float", 0.0, ge=0.0,
                              doc="lattice: Young's modulus E [Pa]; sets the springs (and, "
                                  "with density, the node masses) instead of stiffness"),
        "poisson_ratio": Key("float", None, gt=-1.0, lt=0.5,
                             doc="with youngs_modulus: nu; the lattice represents only 1/4 "
                                 "(plane strain) or 1/3 (plane stress): another value keeps "
                                 "E/(1-nu^2) (plane strain) or E, with a warning; default: "
                                 "the representable one"),
        "thickness": Key("float", 1.0, gt=0.0,
                         doc="with youngs_modulus: out-of-plane depth t [m] of the slice"),
        "plane": Key("str", "strain", choices=("strain", "stress"),
                     doc="with youngs_modulus: plane strain (a slice of a long body) or "
                         "plane stress (a thin sheet)"),
        "damping_ratio": Key("float", 0.0, ge=0.0,
                             doc="with youngs_modulus: damping ratio of the lattice's highest "
                                 "mode, from dashpots along the springs (mode n gets "
                                 "zeta omega_n/omega_max)"),
        "volume_constraint": Key("bool", True, doc="keep the boundary polygon's area"),
        "gravity": Key("bool", True, doc="feel physics.gravity"),
        "velocity": Key("vec2", [0.0, 0.0], doc="initial velocity of every node [m/s]"),
        "pinned": Key("str", "none", choices=("none", "top", "bottom", "left", "right", "all"),
                      doc="a side whose nodes never move"),
        "pinned_ids": Key("ints", [], ge=0, doc="more nodes that never move"),
        "anchors": Key("points", [], doc="fixed points (e.g. on a rigid wall) that close the "
                                         "boundary polygon: the area kept is the one between "
                                         "the body and them; they are not particles"),
        "anchor_row": Key("str", "bottom", choices=("bottom", "top"),
                          doc="lattice with anchors: the loop runs through the anchors (in "
                              "order) and then this row (bottom: right to left; top: left "
                              "to right)"),
        "load": Key("tables", [], keys={
            "nodes": Key("str", choices=("top", "bottom", "left", "right", "all", "row",
                                         "column", "ids")),
            "index": Key("int", 0, ge=0, doc="the row or column (from 0 at bottom/left)"),
            "ids": Key("ints", [], ge=0, doc="the nodes, with nodes = \"ids\""),
            "force": Key("vec2", doc="force on each node of the set [N]"),
            "start": Key("float", 0.0, ge=0.0, doc="[s]"),
            "end": Key("float", math.inf, gt=0.0, doc="[s]; default: never ends"),
            "ramp": Key("float", 0.0, ge=0.0, doc="linear rise and fall time [s]"),
        }, doc="[[body.load]]: a force on a node set over a time window"),
    }, many=True, doc="a mass-spring solid: a lattice or general nodes and springs"),
    "inlet": Section({
        "lower": Key("vec2", doc="lower-left corner of the buffer zone"),
        "upper": Key("vec2", doc="upper-right corner of the buffer zone"),
        "velocity": Key("vec2", doc="uniform inflow velocity U0, along x or y [m/s]"),
    }, many=True, doc="an inflow buffer zone: lattice columns of inflow particles moving at "
                      "U0; new columns enter at its upstream face, particles leaving its "
                      "downstream face become fluid"),
    "outlet": Section({
        "side": Key("str", choices=("left", "right", "bottom", "top"),
                    doc="the domain side through which fluid leaves and is removed"),
        "velocity": Key("vec2", [0.0, 0.0],
                        doc="[0, 0]: plain removal; else fluid within `buffer` layers of "
                            "the side becomes an outflow buffer moving at this velocity"),
        "buffer": Key("int", 4, ge=1, le=20, doc="outflow buffer depth, in particles"),
        "pressure": Key("str", "dirichlet", choices=("dirichlet", "fluid"),
                        doc="outflow buffer particles: P = 0 (the channel's pressure "
                            "reference) or pressure unknowns like fluid"),
    }, many=True, doc="an open side of the domain: fluid crossing it is removed"),
    "output": Section({
        "frames": Key("bool", True, doc="write particle frames (diagnostics are always written)"),
    }),
    "parallel": Section({
        "halo_skin": Key("float", 0.6, ge=0.0, le=5.0,
                         doc="extra halo width and neighbour-list skin, in l0"),
        "rebalance_interval": Key("int", 20, gt=0, doc="steps between load-balance checks"),
        "imbalance_tolerance": Key("float", 1.10, gt=1.0,
                                   doc="rebalance when max/mean particles exceeds this"),
        "migration_margin": Key("float", 0.5, ge=0.0, le=5.0,
                                doc="particles migrate once one is this far (in l0) outside "
                                    "its slab; halo and slabs widen by it (0: every step)"),
    }),
}


def validate(raw):
    """Check a parsed case against SCHEMA; return it with every default filled in."""
    if not isinstance(raw, dict):
        raise CaseError("the case must be a TOML table")
    for key in raw:
        if key not in SCHEMA:
            raise _unknown("", key, SCHEMA)
    case = {}
    title = raw.get("title", "")
    if not isinstance(title, str):
        raise CaseError(f"title must be a string, got {_type_name(title)}")
    case["title"] = title
    for name, section in SCHEMA.items():
        if section is None:
            continue
        if name not in raw:
            if section.required:
                raise CaseError(f"missing section [{name}]")
            case[name] = [] if section.many else _validate_table(name, section.keys, {})
            continue
        value = raw[name]
        if section.many:
            if isinstance(value, dict):
                value = [value]
            if not isinstance(value, list):
                raise CaseError(f"{name} must be an array of tables ([[{name}]]), "
                                f"got {_type_name(value)}")
            case[name] = [_validate_table(f"{name}[{k}]", section.keys, item)
                          for k, item in enumerate(value)]
        else:
            case[name] = _validate_table(name, section.keys, value)
    _check_consistency(case)
    return case


def _check_consistency(case):
    particle_sections = [name for name in ("fluid_block", "tank", "wall_box", "inlet", "outlet")
                         if case.get(name)]
    if case["particles"]["spacing"] is None and particle_sections:
        raise CaseError(f"missing key 'particles.spacing': the case has "
                        f"[[{particle_sections[0]}]] particles, which need a spacing")
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    for axis, label in enumerate("xy"):
        if not upper[axis] > lower[axis]:
            raise CaseError(f"domain.upper.{label} ({upper[axis]}) must exceed "
                            f"domain.lower.{label} ({lower[axis]})")
    for kind in ("fluid_block", "tank", "wall_box", "inlet"):
        for k, item in enumerate(case[kind]):
            for axis, label in enumerate("xy"):
                if not item["upper"][axis] > item["lower"][axis]:
                    raise CaseError(f"{kind}[{k}].upper.{label} ({item['upper'][axis]}) must "
                                    f"exceed {kind}[{k}].lower.{label} ({item['lower'][axis]})")
    for kind in ("tank", "wall_box"):
        for k, item in enumerate(case[kind]):
            if not item["move_end"] > item["move_start"]:
                raise CaseError(f"{kind}[{k}].move_end ({item['move_end']}) must exceed "
                                f"{kind}[{k}].move_start ({item['move_start']})")
    mps = case["mps"]
    if mps["re_laplacian"] < mps["re_number_density"]:
        raise CaseError(f"mps.re_laplacian ({mps['re_laplacian']}) must be >= "
                        f"mps.re_number_density ({mps['re_number_density']})")
    time = case["time"]
    if time["fixed_dt"] > 0 and time["fixed_dt"] > time["end"]:
        raise CaseError(f"time.fixed_dt ({time['fixed_dt']}) exceeds time.end ({time['end']})")
    if time["fixed_dt"] > 0:
        # A wall's speed is known now: a fixed step too long for it is a case error.
        for kind in ("tank", "wall_box"):
            for k, item in enumerate(case[kind]):
                speed = math.hypot(*item["velocity"])
                if speed * time["fixed_dt"] > time["cfl"] * case["particles"]["spacing"]:
                    raise CaseError(
                        f"{kind}[{k}].velocity: a wall moving at {speed:g} m/s needs "
                        f"dt <= time.cfl x spacing / speed = "
                        f"{time['cfl'] * case['particles']['spacing'] / speed:.4g} s, but "
                        f"time.fixed_dt is {time['fixed_dt']:g} s")
    if case["body"]:
        # Bodies are small: building them is the cheapest complete check.
        from parmps.solids.mass_spring.build import build_bodies
        build_bodies(case)


def parse_value(text):
    """A command-line value read as a TOML value; a bare word stays a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_override(raw, assignment):
    """Apply one ``--set SECTION.KEY=VALUE`` (``SECTION.N.KEY`` for arrays of tables)."""
    if "=" not in assignment:
        raise CaseError(f"--set {assignment}: expected SECTION.KEY=VALUE")
    path, text = assignment.split("=", 1)
    parts = path.strip().split(".")
    if len(parts) < 2 or not all(parts):
        raise CaseError(f"--set {assignment}: expected SECTION.KEY=VALUE")
    node = raw
    for depth, part in enumerate(parts[:-1]):
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise CaseError(f"--set {path}: '{part}' is not an index of "
                                f"{'.'.join(parts[:depth])} (it has {len(node)} entries)")
            node = node[int(part)]
            continue
        if part not in node:
            node[part] = {}
        node = node[part]
        if isinstance(node, list) and depth == len(parts) - 2:
            raise CaseError(f"--set {path}: {'.'.join(parts[:depth + 1])} is an array of "
                            f"tables; name the entry, e.g. {parts[0]}.0.{parts[-1]}")
    if not isinstance(node, dict):
        raise CaseError(f"--set {path}: {'.'.join(parts[:-1])} is not a table")
    node[parts[-1]] = parse_value(text.strip())
    return raw


def load_text(text, source="case"):
    """Parse TOML text; a syntax error becomes a one-line CaseError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{source}: not valid TOML: {exc}") from None
