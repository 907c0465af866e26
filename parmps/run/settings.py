"""Case section of the time loop."""

from parmps.config import Key, Section
from parmps.errors import CaseError

SECTIONS = {
    "time": Section({
        "end": Key("float", gt=0.0, doc="end time [s]"),
        "dt_max": Key("float", 1.0e-3, gt=0.0, doc="largest step [s]"),
        "fixed_dt": Key("float", 0.0, ge=0.0, doc="a fixed step [s]; 0 means adaptive"),
        # 0.3: the peer dam break (cases/dam_break_2d_peer.toml, l0 = 5 mm) runs to 0.5 s
        # with the default pressure scheme at 0.3 and blows up at 0.4 (step 172, 32 m/s);
        # the original scheme was stable at 0.4.
        "cfl": Key("float", 0.4, gt=0.0, le=1.0, doc="C_cfl: dt <= C_cfl l0 / |u|max"),
        "viscous_number": Key("float", 0.2, gt=0.0, le=1.0, doc="dt <= C l0^2 / nu"),
        "output_interval": Key("float", 0.05, gt=0.0, doc="time between frames [s]"),
        "max_steps": Key("int", 0, ge=0, doc="stop after this many steps; 0 means no limit"),
    }, required=True),
}


def check(case):
    time = case["time"]
    if time["fixed_dt"] > 0 and time["fixed_dt"] > time["end"]:
        raise CaseError(f"time.fixed_dt ({time['fixed_dt']}) exceeds time.end ({time['end']})")
