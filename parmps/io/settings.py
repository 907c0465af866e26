"""Case section of the output."""

from parmps.config import Key, Section

SECTIONS = {
    "output": Section({
        "frames": Key("bool", True, doc="write particle frames (diagnostics are always written)"),
        "checkpoint_interval": Key("float", 900.0, ge=0.0,
                                   doc="wall seconds between checkpoints (0: only at the end "
                                       "and on an interruption)"),
    }),
}


def check(case):
    pass
