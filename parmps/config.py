"""The machinery of case files: TOML, validated strictly against a schema.

A case is a TOML document whose tables are sections. Every key has a type, a
range and usually a default; unknown keys, wrong types and values out of range
raise :class:`CaseError` with one line naming the key. The sections themselves
are declared by the components that read them (``parmps/<component>/settings.py``)
and assembled in :mod:`parmps.case`; this module knows none of them.
"""

import difflib
import math
import tomllib

from parmps.errors import CaseError

REQUIRED = object()


class Key:
    """One entry of a section: its type, default and allowed range.

    kind is one of "float", "int", "bool", "str", "vector" (d floats, d the
    case's dimension), "vec2" (two floats, whatever the dimension),
    "floats" (a list of floats), "ints" (a list of ints), "strs" (a list of strings, each
    one of ``choices`` when given), "options" (a table of
    scalars passed through, e.g. PETSc options), "points" (a list of [x, y]),
    "pairs" (a list of [i, j] integer pairs) or "tables" (an array of tables,
    ``[[section.key]]``, each checked against the sub-schema ``keys``) or "table"
    (one sub-table ``[section.key]`` checked against ``keys``, e.g. a scheme's settings).
    """

    def __init__(self, kind, default=REQUIRED, *, gt=None, ge=None, lt=None, le=None,
                 choices=None, keys=None, doc=""):
        self.kind = kind
        self.default = default
        self.gt, self.ge, self.lt, self.le = gt, ge, lt, le
        self.choices = choices
        self.keys = keys
        self.doc = doc

    def check(self, name, value, dimension=2):
        if self.kind == "table":
            return _validate_table(name, self.keys, value, dimension=dimension)
        if self.kind == "tables":
            if isinstance(value, dict):
                value = [value]
            if not isinstance(value, list):
                raise CaseError(f"{name} must be an array of tables ([[{name}]]), "
                                f"got {_type_name(value)}")
            return [_validate_table(f"{name}[{k}]", self.keys, item, dimension=dimension)
                    for k, item in enumerate(value)]
        value = _coerce(name, self.kind, value, dimension)
        for item in (value if self.kind in ("vector", "vec2", "floats", "ints") else [value]):
            self._check_range(name, item)
        if self.kind == "strs":
            self._check_strs(name, value)
        elif self.choices is not None and value not in self.choices:
            raise CaseError(f"{name} must be one of {', '.join(map(repr, self.choices))}, "
                            f"got {value!r}")
        return value

    def _check_strs(self, name, value):
        for k, item in enumerate(value):
            if self.choices is not None and item not in self.choices:
                raise CaseError(f"{name}[{k}] must be one of "
                                f"{', '.join(map(repr, self.choices))}, got {item!r}")
            if item in value[:k]:
                raise CaseError(f"{name} names {item!r} twice")

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


class DimensionDefault:
    """A default that depends on the case's dimension: called with d, it gives the value."""

    def __call__(self, dimension):
        raise NotImplementedError

    def __repr__(self):
        return f"{self(2)} in 2D, {self(3)} in 3D"


class PerDimension(DimensionDefault):
    """A vector default that depends on the case's dimension: ``PerDimension(last)`` is
    d - 1 zeros followed by ``last`` (a zero vector, or gravity along -z in 3D, -y in 2D)."""

    def __init__(self, last=0.0):
        self.last = float(last)

    def __call__(self, dimension):
        return [0.0] * (dimension - 1) + [self.last]


class ByDimension(DimensionDefault):
    """A scalar default measured for each dimension: ``ByDimension(in_2d, in_3d)``."""

    def __init__(self, in_2d, in_3d):
        self.values = {2: in_2d, 3: in_3d}

    def __call__(self, dimension):
        return self.values[dimension]


# The zero vector of the case's dimension: the default of velocities.
ZERO = PerDimension(0.0)

# Components' names, for messages.
AXES = "xyz"


class Section:
    """A TOML table (many=False) or an array of tables (many=True).

    ``replaced`` maps keys that earlier versions accepted to a sentence saying
    what replaced them, so an old case gets that sentence instead of "unknown key".
    """

    def __init__(self, keys, *, many=False, required=False, doc="", replaced=None):
        self.keys = keys
        self.many = many
        self.required = required
        self.doc = doc
        self.replaced = dict(replaced or {})


def _type_name(value):
    return {bool: "boolean", int: "integer", float: "number", str: "string",
            list: "array", dict: "table"}.get(type(value), type(value).__name__)


def _coerce(name, kind, value, dimension=2):
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
    if kind in ("vector", "vec2", "floats", "ints"):
        if not isinstance(value, list):
            raise CaseError(f"{name} must be an array, got {_type_name(value)} {value!r}")
        if kind == "vec2" and len(value) != 2:
            raise CaseError(f"{name} must have 2 components [x, y], got {len(value)}")
        if kind == "vector" and len(value) != dimension:
            components = ", ".join(AXES[:dimension])
            raise CaseError(f"{name} has {len(value)} components but the case is {dimension}D "
                            f"(domain.lower has {dimension}): give [{components}]")
        item_kind = "int" if kind == "ints" else "float"
        return [_coerce(f"{name}[{k}]", item_kind, v) for k, v in enumerate(value)]
    if kind == "strs":
        if not isinstance(value, list):
            raise CaseError(f"{name} must be an array of strings, got {_type_name(value)} "
                            f"{value!r}")
        return [_coerce(f"{name}[{k}]", "str", v) for k, v in enumerate(value)]
    if kind in ("points", "pairs"):
        if not isinstance(value, list):
            raise CaseError(f"{name} must be an array, got {_type_name(value)} {value!r}")
        item_kind = "vector" if kind == "points" else "ints"
        items = [_coerce(f"{name}[{k}]", item_kind, v, dimension) for k, v in enumerate(value)]
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


def _validate_table(name, keys, raw, replaced=None, dimension=2):
    if not isinstance(raw, dict):
        raise CaseError(f"{name} must be a table, got {_type_name(raw)}")
    for key in raw:
        if replaced and key in replaced:
            raise CaseError(f"{name}.{key} is no longer a key: {replaced[key]}")
        if key not in keys:
            raise _unknown(name, key, keys)
    out = {}
    for key, spec in keys.items():
        full = f"{name}.{key}"
        if key in raw:
            out[key] = spec.check(full, raw[key], dimension)
        elif spec.kind == "table":
            out[key] = _validate_table(full, spec.keys, {}, dimension=dimension)
        elif spec.default is REQUIRED:
            raise CaseError(f"missing key '{full}'")
        elif isinstance(spec.default, DimensionDefault):
            out[key] = spec.default(dimension)
        else:
            # Copy list defaults so no two cases share one mutable object.
            out[key] = list(spec.default) if isinstance(spec.default, list) else spec.default
    return out


def validate_sections(raw, sections, dimension=2):
    """Check a parsed case against ``sections`` (name -> Section); fill in every default.

    ``title`` is the one free top-level string. Every "vector" key must have
    ``dimension`` components. Returns a plain nested dict.
    """
    if not isinstance(raw, dict):
        raise CaseError("the case must be a TOML table")
    for key in raw:
        if key != "title" and key not in sections:
            raise _unknown("", key, list(sections) + ["title"])
    title = raw.get("title", "")
    if not isinstance(title, str):
        raise CaseError(f"title must be a string, got {_type_name(title)}")
    case = {"title": title}
    for name, section in sections.items():
        if name not in raw:
            if section.required:
                raise CaseError(f"missing section [{name}]")
            case[name] = [] if section.many else _validate_table(name, section.keys, {},
                                                                 dimension=dimension)
            continue
        value = raw[name]
        if section.many:
            if isinstance(value, dict):
                value = [value]
            if not isinstance(value, list):
                raise CaseError(f"{name} must be an array of tables ([[{name}]]), "
                                f"got {_type_name(value)}")
            case[name] = [_validate_table(f"{name}[{k}]", section.keys, item, section.replaced,
                                          dimension)
                          for k, item in enumerate(value)]
        else:
            case[name] = _validate_table(name, section.keys, value, section.replaced, dimension)
    return case


def check_ordered_box(name, box):
    """Refuse a box whose ``upper`` does not exceed its ``lower`` on every axis."""
    for axis, label in enumerate("xyz"[:len(box["lower"])]):
        if not box["upper"][axis] > box["lower"][axis]:
            raise CaseError(f"{name}.upper.{label} ({box['upper'][axis]}) must exceed "
                            f"{name}.lower.{label} ({box['lower'][axis]})")


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


def resolve_file_paths(raw, case_file, sections, key):
    """Make the relative paths under ``key`` of the entries of ``sections`` of a parsed case
    absolute, from the directory of ``case_file`` (a stored case then finds its files from
    anywhere); returns whether any changed."""
    import os

    base = os.path.dirname(os.path.abspath(case_file))
    changed = False
    for section in sections:
        entries = raw.get(section, [])
        for entry in entries if isinstance(entries, list) else [entries]:
            path = entry.get(key) if isinstance(entry, dict) else None
            if isinstance(path, str) and path and not os.path.isabs(path):
                entry[key] = os.path.normpath(os.path.join(base, path))
                changed = True
    return changed


def load_text(text, source="case"):
    """Parse TOML text; a syntax error becomes a one-line CaseError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{source}: not valid TOML: {exc}") from None
