"""The scripts, plot scripts and the docs' configuration import the installed package
(scripts/setup installs it, editable, into the venv): none of them edits ``sys.path``."""

import re

from conftest import ROOT

# Where study, plot and set-up code lives outside the package.
FOLDERS = ("scripts", "validation", "docs", "tests")


def test_no_file_outside_the_package_edits_sys_path():
    edits = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"\bsys\.path\.(insert|append)\(", line):
                    edits.append(f"{path.relative_to(ROOT)}:{number}")
    assert edits == []
