"""Case section of the time loop."""

from parmps.config import Key, Section
from parmps.errors import CaseError

SECTIONS = {
    "time": Section({
        "end": Key("float", gt=0.0, doc="end time [s]"),
        "dt_max": Key("float", 1.0e-3, gt=0.0, doc="largest step [s]"),
        "fixed_dt": Key("float", 0.0, ge=0.0, doc="a fixed step [s]; 0 means adaptive"),
        # 0.5: with the default scheme (density source, corrected gradient) the dam breaks
        # of cases/ run to the end at 0.5 on 1, 2 and 3 ranks, the 5 mm one with one step
        # redone at half its dt at the impact on the far wall (time.retries).
        "cfl": Key("float", 0.5, gt=0.0, le=1.0, doc="C_cfl: dt <= C_cfl l0 / |u|max"),
        "retries": Key("int", 3, ge=0, le=20,
                       doc="a step that fails its checks (Courant, a wall, NaN) is redone "
                           "with half its dt up to this many times; 0: stop at once "
                           "(never with time.fixed_dt)"),
        "viscous_number": Key("float", 0.2, gt=0.0, le=1.0, doc="dt <= C l0^2 / nu"),
        "output_interval": Key("float", 0.05, gt=0.0, doc="time between frames [s]"),
        "max_steps": Key("int", 0, ge=0, doc="stop after this many steps; 0 means no limit"),
    }, required=True),
}


def check(case):
    time = case["time"]
    if time["fixed_dt"] > 0 and time["fixed_dt"] > time["end"]:
        raise CaseError(f"time.fixed_dt ({time['fixed_dt']}) exceeds time.end ({time['end']})")
