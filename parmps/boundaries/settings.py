"""Case sections of the boundaries: tanks and wall boxes (fixed or moving), inlets, outlets."""

import math

import numpy as np

from parmps.config import (ZERO, Key, PerDimension, Section, check_ordered_box,
                           resolve_file_paths)
from parmps.core.timeseries import read_table
from parmps.errors import CaseError

# Prescribed motion of a tank or wall box (parmps.boundaries.walls): its wall and dummy
# particles translate together at `velocity` while move_start <= t < move_end.
# "Never stops" is the default move_end, infinity; a case file cannot write
# it (numbers must be finite), it leaves the key out.
MOTION_KEYS = {
    "velocity": Key("vector", ZERO,
                    doc="constant velocity of the whole geometry, walls and dummies [m/s]; "
                        "[0, 0]: fixed"),
    "move_start": Key("float", 0.0, ge=0.0, doc="time the motion starts [s]"),
    "move_end": Key("float", math.inf, gt=0.0,
                    doc="time the motion stops [s], > move_start; default: never stops"),
}

WALL_SECTIONS = ("tank", "wall_box")

SECTIONS = {
    "tank": Section({
        "lower": Key("vector", doc="inner lower corner (the wall surface)"),
        "upper": Key("vector", doc="inner upper corner; the side walls end at its height "
                                   "(y in 2D, z in 3D)"),
        "wall_layers": Key("int", 2, ge=1, le=10, doc="layers of wall particles (in the PPE)"),
        "dummy_layers": Key("int", 2, ge=0, le=10,
                            doc="layers of dummy particles behind the walls (number density "
                                "only)"),
        "open_top": Key("bool", True, doc="no wall along the top (false: a closed box)"),
        **MOTION_KEYS,
    }, many=True, doc="walls around a box (a floor and side walls; a roof unless open_top), "
                      "with dummy layers behind them; they may "
                      "translate at a constant velocity (see MOTION_KEYS)"),
    "wall_box": Section({
        "lower": Key("vector", doc="lower corner of the obstacle's surface [m]"),
        "upper": Key("vector", doc="upper corner of the obstacle's surface [m]"),
        "wall_layers": Key("int", 2, ge=1, le=10,
                           doc="layers of wall particles inside its surface (dummies fill "
                               "the rest)"),
        **MOTION_KEYS,
    }, many=True, doc="a solid rectangular obstacle: wall layers outside, dummies inside; "
                      "it may translate at a constant velocity (see MOTION_KEYS)"),
    "inlet": Section({
        "lower": Key("vector", doc="lower-left corner of the buffer zone"),
        "upper": Key("vector", doc="upper-right corner of the buffer zone"),
        "velocity": Key("vector", doc="the mean inflow velocity U0, along one axis [m/s]; "
                                      "with a table, only its direction is used"),
        "profile": Key("str", "uniform", choices=("uniform", "parabolic"),
                       doc="the speed across the opening: \"uniform\" (U0 everywhere) or "
                           "\"parabolic\", the fully developed laminar profile with mean "
                           "U0: a channel's 1.5 U0 (1 - (2r/h)^2) in 2D, a rectangular "
                           "duct's exact series in 3D, a pipe's 2 U0 (1 - (r/R)^2) with "
                           "shape = \"circle\""),
        "shape": Key("str", "box", choices=("box", "circle"),
                     doc="the opening: the box's whole cross-section, or (3D) the circle "
                         "of `radius` about the centre of that cross-section"),
        "radius": Key("float", 0.0, ge=0.0, doc="shape circle: the opening's radius [m]"),
        "ramp": Key("float", None, gt=0.0,
                    doc="start the mean as U0 (1 - cos(pi t / ramp)) / 2 for t < ramp, "
                        "then U0 (Turek & Hron's start) [s]; default: U0 from t = 0"),
        "table": Key("str", "",
                     doc="a text file of two columns, t [s] and the mean speed [m/s] along "
                         "`velocity`'s direction (>= 0), t increasing: interpolated "
                         "linearly, held constant past its ends; a relative path is from "
                         "the case file's directory"),
    }, many=True, doc="an inflow buffer zone: lattice lanes of inflow particles, each "
                      "moving at its share of the profile times the mean U0(t); a lane's "
                      "new particles enter at its upstream face, particles leaving its "
                      "downstream face become fluid"),
    "outlet": Section({
        "side": Key("str", choices=("left", "right", "front", "back", "bottom", "top"),
                    doc="the domain side through which fluid leaves and is removed: left "
                        "and right along x, front and back along y (3D only), bottom and top "
                        "along the vertical (y in 2D, z in 3D)"),
        "velocity": Key("vector", ZERO,
                        doc="[0, 0]: plain removal; else fluid within `buffer` layers of "
                            "the side becomes an outflow buffer moving at this velocity"),
        "buffer": Key("int", 4, ge=1, le=20, doc="outflow buffer depth, in particles"),
        "pressure": Key("str", "dirichlet", choices=("dirichlet", "fluid"),
                        doc="outflow buffer particles: P = 0 (the channel's pressure "
                            "reference) or pressure unknowns like fluid"),
    }, many=True, doc="an open side of the domain: fluid crossing it is removed"),
}


def check(case):
    for k, outlet in enumerate(case["outlet"]):
        if case["dimension"] == 2 and outlet["side"] in ("front", "back"):
            raise CaseError(f"outlet[{k}].side '{outlet['side']}' is a side of a 3D domain; "
                            f"a 2D one has left, right, bottom and top")
    check_not_periodic(case)
    for kind in (*WALL_SECTIONS, "inlet"):
        for k, item in enumerate(case[kind]):
            check_ordered_box(f"{kind}[{k}]", item)
    for k, inlet in enumerate(case["inlet"]):
        check_inlet(f"inlet[{k}]", inlet, case["dimension"])
    for kind in WALL_SECTIONS:
        for k, item in enumerate(case[kind]):
            if not item["move_end"] > item["move_start"]:
                raise CaseError(f"{kind}[{k}].move_end ({item['move_end']}) must exceed "
                                f"{kind}[{k}].move_start ({item['move_start']})")
    time = case["time"]
    if time["fixed_dt"] > 0:
        # A wall's speed is known now: a fixed step too long for it is a case error.
        for kind in (*WALL_SECTIONS, "wall"):
            for k, item in enumerate(case.get(kind, ())):
                speed = math.hypot(*item["velocity"])
                if speed * time["fixed_dt"] > time["cfl"] * case["particles"]["spacing"]:
                    raise CaseError(
                        f"{kind}[{k}].velocity: a wall moving at {speed:g} m/s needs "
                        f"dt <= time.cfl x spacing / speed = "
                        f"{time['cfl'] * case['particles']['spacing'] / speed:.4g} s, but "
                        f"time.fixed_dt is {time['fixed_dt']:g} s")


def check_not_periodic(case):
    """Refuse an outlet on a side, or an inlet whose flow runs along an axis, the domain
    repeats along (``domain.periodic``): a periodic axis has no open side."""
    periodic = case["domain"].get("periodic", ())
    dimension = case["dimension"]
    for k, outlet in enumerate(case["outlet"]):
        axis = {"left": 0, "right": 0, "front": 1, "back": 1,
                "bottom": dimension - 1, "top": dimension - 1}[outlet["side"]]
        if "xyz"[axis] in periodic:
            raise CaseError(f"outlet[{k}].side '{outlet['side']}' is a face of the periodic "
                            f"axis {'xyz'[axis]!r} (domain.periodic): a periodic axis has no "
                            f"open side")
    for k, inlet in enumerate(case["inlet"]):
        along = [a for a, v in enumerate(inlet["velocity"]) if v != 0.0]
        if along and "xyz"[along[0]] in periodic:
            raise CaseError(f"inlet[{k}].velocity runs along the periodic axis "
                            f"{'xyz'[along[0]]!r} (domain.periodic): a periodic axis has no "
                            f"open side; drive the flow with a body force "
                            f"(physics.gravity) instead")


def check_inlet(name, inlet, dimension):
    """The profile's, the ramp's and the table's keys of one inlet (the table is read)."""
    if inlet["shape"] == "circle":
        if dimension == 2:
            raise CaseError(f"{name}.shape \"circle\" is an opening of a 3D case; a 2D "
                            f"opening is the box's side")
        if not inlet["radius"] > 0.0:
            raise CaseError(f"{name}.radius must be > 0 with shape = \"circle\"")
        widths = [u - l for l, u in zip(inlet["lower"], inlet["upper"])]
        across = [w for a, w in enumerate(widths) if inlet["velocity"][a] == 0.0]
        if len(across) == dimension - 1 and 2.0 * inlet["radius"] > min(across) * (1 + 1e-12):
            raise CaseError(f"{name}.radius {inlet['radius']:g}: the circle must fit in the "
                            f"box's cross-section ({' x '.join(f'{w:g}' for w in across)})")
    elif inlet["radius"] != 0.0:
        raise CaseError(f"{name}.radius is only read with shape = \"circle\"")
    if inlet["table"]:
        if inlet["ramp"] is not None:
            raise CaseError(f"{name}: give ramp or table, not both (a table starts as it "
                            f"gives)")
        table = inflow_table(name, inlet)
        if np.any(table[:, 1] < 0.0):
            raise CaseError(f"{name}.table: the mean speeds must be >= 0 (an inlet cannot "
                            f"run backwards); {inlet['table']} has {table[:, 1].min():g}")


def inflow_table(name, inlet):
    """The inlet's table (rows t, mean speed), checked."""
    return read_table(inlet["table"], f"{name}.table")


def resolve_paths(raw, case_file):
    """Make the inlets' relative table paths of a parsed case absolute, from the directory of
    ``case_file``; returns whether any changed."""
    return resolve_file_paths(raw, case_file, ("inlet",), "table")
