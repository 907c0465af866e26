"""The case-file reference is generated from the schema: every key must carry its text."""

from parmps import schema
from parmps.config import Key, Section
from parmps.tools import casedoc


def test_every_key_of_the_schema_has_its_doc_text():
    missing = casedoc.undocumented(schema.SECTIONS)
    assert missing == [], f"keys without doc text: {', '.join(missing)}"


def test_a_key_without_doc_text_is_reported():
    sections = {"demo": Section({"documented": Key("float", 1.0, doc="a length [m]"),
                                 "bare": Key("int", 2),
                                 "nested": Key("tables", [], doc="items", keys={
                                     "inner": Key("str", "x")})}, many=True)}
    assert casedoc.undocumented(sections) == ["demo[].bare", "demo[].nested[].inner"]


def test_the_reference_lists_every_key_with_type_default_and_allowed_values():
    page = casedoc.markdown()
    for name, section in schema.SECTIONS.items():
        assert (f"## `[[{name}]]`" if section.many else f"## `[{name}]`") in page
    rows = [line for line in page.splitlines() if line.startswith("| `")]
    assert len(rows) == len(list(casedoc.walk(schema.SECTIONS)))
    # One row read back: [mps] re_laplacian is a float in l0, 3.1 by default in 2D and 2.3
    # in 3D, in (1, 5].
    (row,) = [r for r in rows if r.startswith("| `re_laplacian` |")]
    assert row.split(" | ")[1:5] == ["`float`", "l0", "`3.1 in 2D, 2.3 in 3D`", "> 1.0, ≤ 5.0"]


def test_any_type_string_is_rendered_as_it_is():
    # A kind the renderer has never seen (a dimension-generic vector, say) still gets a row.
    section = Section({"corner": Key("vector", [0.0, 0.0, 0.0], doc="a corner [m]"),
                       "mode": Key("str", "a", choices=("a", "b"), doc="which one")})
    text = casedoc.section_markdown("demo", section)
    assert "| `corner` | `vector` | m | `[0.0, 0.0, 0.0]` |  | a corner [m] |" in text
    assert '| `mode` | `str` |  | `"a"` | "a", "b" | which one |' in text


def test_units_are_read_from_the_doc_text_not_from_table_references():
    assert casedoc.unit(Key("float", 1.0, doc="rho [kg/m^3]")) == "kg/m^3"
    assert casedoc.unit(Key("float", 1.0, doc="radius, in l0")) == "l0"
    assert casedoc.unit(Key("str", "x", doc="settings in [mps.<name>]")) == ""
    assert casedoc.default(Key("vec2")) == "required"
    assert casedoc.default(Key("float", None, doc="optional")) == "unset"
