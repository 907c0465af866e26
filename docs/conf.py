"""Sphinx configuration of parmps's documentation (built by ``scripts/docs``).

Two pages are generated from the code when the build starts, into ``_generated/`` (ignored by
git): the case-file reference from the schema (:mod:`parmps.tools.casedoc`) and the API page,
one section per public module of the package.
"""

import os
import pkgutil
import re

import parmps  # scripts/setup installs it (editable) into the venv scripts/docs uses

project = "parmps"
author = "the parmps developers"
release = version = parmps.__version__
copyright = "2026, the parmps developers"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "README.md"]
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
html_theme = "alabaster"
html_theme_options = {"fixed_sidebar": True}
html_static_path = []
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": True}
# The physics modules keep their numba kernels and Debian's MPI stack; none of them
# starts anything at import, so autodoc imports them as they are.
nitpicky = False


def public_modules():
    """Every module of the package whose dotted name has no part starting with '_'."""
    names = ["parmps"]
    for info in pkgutil.walk_packages(parmps.__path__, "parmps."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def api_page():
    lines = ["# API", "",
             "Every public module of the package, from its docstrings. The entry points a user "
             "needs are {func}`parmps.open_result` (reading results), "
             "{mod}`parmps.validation` (validations and benchmarks) and {mod}`parmps.cli` "
             "(the command line).", ""]
    for name in public_modules():
        lines += [f"## `{name}`", "", "```{eval-rst}", f".. automodule:: {name}", "```", ""]
    return "\n".join(lines)


def write_generated(app):
    from parmps.tools import casedoc
    directory = os.path.join(app.srcdir, "_generated")
    os.makedirs(directory, exist_ok=True)
    for name, text in (("case_reference.md", casedoc.markdown()), ("api.md", api_page())):
        path = os.path.join(directory, name)
        # Rewrite only on change, so Sphinx rebuilds only what changed.
        old = open(path).read() if os.path.exists(path) else None
        if old != text:
            with open(path, "w") as handle:
                handle.write(text)


_LITERAL = re.compile(r"(``.*?``)")


def plain_bars(app, what, name, obj, options, lines):
    """The docstrings write |x| for a length or an absolute value, which reStructuredText
    reads as a substitution: escape bars outside inline literals."""
    for k, line in enumerate(lines):
        parts = _LITERAL.split(line)
        lines[k] = "".join(part if part.startswith("``") else part.replace("|", "\\|")
                           for part in parts)


def setup(app):
    app.connect("builder-inited", write_generated)
    app.connect("autodoc-process-docstring", plain_bars)
