"""Case section of the output."""

from parmps.config import Key, Section

SECTIONS = {
    "output": Section({
        "frames": Key("bool", True, doc="write particle frames (diagnostics are always written)"),
    }),
}


def check(case):
    pass
