"""The case-file reference, generated from the schema (:data:`parmps.schema.SECTIONS`).

Every :class:`parmps.config.Key` carries its type, default, allowed values and its
meaning (``doc``); this module walks the sections, sub-tables included, and writes
them as one Markdown page, so the reference cannot drift from what the code checks.
A key's unit is written in its ``doc`` as a trailing bracket (``"rho [kg/m^3]"``)
or as "in l0"; the page shows it in a column of its own.

The type column shows ``Key.kind`` as it is, whatever the kind (a new vector type
needs no change here).
"""

import re

from parmps.config import REQUIRED

# A unit in brackets: letters, digits, ^ / * and spaces, but no '.' or '<' (those
# are references to other tables, such as [mps.<name>]).
_UNIT = re.compile(r"\[([A-Za-z0-9^/*·_ -]+)\]")
_IN_SPACING = re.compile(r"\bin (l0|units of l0)\b")


def walk(sections):
    """Every key of ``sections`` (name -> Section) as (dotted name, Key, Section),
    the keys of ``table`` and ``tables`` keys included (as ``section.key.sub``)."""
    for name, section in sections.items():
        prefix = f"{name}[]" if section.many else name
        yield from _walk_keys(prefix, section.keys, section)


def _walk_keys(prefix, keys, section):
    for key_name, key in keys.items():
        dotted = f"{prefix}.{key_name}"
        yield dotted, key, section
        if key.kind in ("table", "tables") and key.keys:
            sub = f"{dotted}[]" if key.kind == "tables" else dotted
            yield from _walk_keys(sub, key.keys, section)


def undocumented(sections):
    """Dotted names of the keys whose ``doc`` is empty (a table's keys are judged, and
    so is the table key itself)."""
    return [name for name, key, _ in walk(sections) if not (key.doc or "").strip()]


def unit(key):
    """The unit named in a key's doc ("" when it names none)."""
    doc = key.doc or ""
    match = _UNIT.search(doc)
    if match:
        return match.group(1).strip()
    if _IN_SPACING.search(doc):
        return "l0"
    return ""


def _toml(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return str(value)


def default(key):
    """The default as TOML text, "required" for a key without one."""
    if key.kind == "table":
        return "(table)"
    if key.default is REQUIRED:
        return "required"
    if key.default is None:
        return "unset"
    return _toml(key.default)


def allowed(key):
    """The allowed values: the choices, or the range the key checks."""
    if key.choices is not None:
        return ", ".join(_toml(choice) for choice in key.choices)
    bounds = [(key.gt, ">"), (key.ge, "≥"), (key.lt, "<"), (key.le, "≤")]
    return ", ".join(f"{symbol} {_toml(bound)}" for bound, symbol in bounds
                     if bound is not None)


def _cell(text):
    return " ".join(str(text).split()).replace("|", "\\|")


def _row(name, key):
    cells = (f"`{name}`", f"`{key.kind}`", _cell(unit(key)), f"`{_cell(default(key))}`",
             _cell(allowed(key)), _cell(key.doc))
    return "| " + " | ".join(cells) + " |"


HEADER = ("| key | type | unit | default | allowed | meaning |\n"
          "| --- | --- | --- | --- | --- | --- |")


def section_markdown(name, section):
    """One section: its heading, how it is written in TOML, its doc and its table of keys."""
    form = f"[[{name}]]" if section.many else f"[{name}]"
    lines = [f"## `{form}`", ""]
    if section.doc:
        lines += [_cell(section.doc), ""]
    notes = ["an array of tables: repeat it for each item" if section.many else "",
             "required" if section.required else ""]
    notes = [note for note in notes if note]
    if notes:
        lines += [f"*{'; '.join(notes)}.*", ""]
    prefix = f"{name}[]" if section.many else name
    lines.append(HEADER)
    for dotted, key, _ in _walk_keys(prefix, section.keys, section):
        lines.append(_row(dotted[len(prefix) + 1:], key))
    if section.replaced:
        lines += ["", "Keys of earlier versions, refused with this message:", ""]
        lines += [f"- `{old}`: {_cell(new)}" for old, new in section.replaced.items()]
    return "\n".join(lines) + "\n"


INTRO = """# Case-file reference

This page is generated from the schema (`parmps.schema.SECTIONS`) when the documentation
is built: it lists every section and key a case file may hold, with its type, unit,
default, allowed values and meaning. A key without a default is required; one whose default
is "unset" is optional and has no value unless given (what its absence means is in its
text). Keys of a
sub-table are written `key.sub` (a table `[section.key]`) or `key[].sub` (an array of
tables `[[section.key]]`). Units are SI; `l0` is the particle spacing
(`particles.spacing`). A case may also hold a top-level `title` string.

Check a case without running it: `python -m parmps CASE.toml --check`.
"""


def markdown(sections=None):
    """The whole reference page as Markdown."""
    if sections is None:
        from parmps import schema
        sections = schema.SECTIONS
    parts = [INTRO]
    parts += [section_markdown(name, section) for name, section in sections.items()]
    return "\n".join(parts)
