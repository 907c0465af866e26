"""Case sections of the solids: the shared solver settings and the bodies."""

import math

from parmps.config import Key, Section
from parmps.errors import CaseError

SECTIONS = {
    "solid": Section({
        "model": Key("str", "mass_spring", choices=("mass_spring",),
                     doc="the solid model every body uses (parmps.solids.MODELS)"),
        "substep": Key("float", 0.0, ge=0.0,
                       doc="fixed solid substep [s]; 0 chooses it from the stiffest node"),
        "safety": Key("float", 0.5, gt=0.0, le=1.0,
                      doc="automatic substep = safety x the Verlet stability limit"),
        "constraint_prediction": Key("str", "linear", choices=("linear", "quadratic"),
                                     doc="linear: the area multiplier of docs/design.md §1.5; "
                                         "quadratic: also predicts the area swept in a "
                                         "substep (rotating bodies)"),
    }, doc="mass-spring solver settings shared by every body"),
    "body": Section({
        "name": Key("str", "", doc="used in the output; default body<k>"),
        "type": Key("str", "lattice", choices=("lattice", "general"),
                    doc="\"lattice\": nx by ny nodes with springs generated; \"general\": "
                        "nodes, springs and boundary loop given"),
        "nx": Key("int", 0, ge=0, doc="lattice: nodes along x"),
        "ny": Key("int", 0, ge=0, doc="lattice: nodes along y"),
        "spacing": Key("float", 0.0, ge=0.0, doc="lattice: node spacing [m]"),
        "lower": Key("vec2", [0.0, 0.0], doc="lattice: position of the lower-left node"),
        "nodes": Key("points", [], doc="general: node positions [[x, y], ...]"),
        "springs": Key("pairs", [], doc="general: springs as node index pairs [[i, j], ...]"),
        "boundary": Key("ints", [], doc="general: the boundary loop, counter-clockwise"),
        "masses": Key("floats", [], gt=0.0, doc="general: one mass per node [kg]"),
        "spring_stiffness": Key("floats", [], gt=0.0,
                                doc="general: one stiffness per spring [N/m]"),
        "node_mass": Key("float", 0.0, ge=0.0, doc="mass of every node [kg]"),
        "density": Key("float", 0.0, ge=0.0,
                       doc="lattice: node mass = density x spacing^2 (per unit depth); "
                           "with youngs_modulus: density x thickness x spacing^2 x the "
                           "share of the cells the node touches"),
        "stiffness": Key("float", None, gt=0.0,
                         doc="structural (or every) spring [N/m]; a lattice may give "
                             "youngs_modulus instead"),
        "shear_stiffness": Key("float", 0.0, ge=0.0,
                               doc="lattice diagonal springs [N/m]; 0 means = stiffness"),
        "damping": Key("float", 0.0, ge=0.0, doc="b in -b (v_i - v_j) [N s/m]"),
        # Elastic material of a lattice body (parmps.solids.mass_spring.elastic).
        "youngs_modulus": Key("float", 0.0, ge=0.0,
                              doc="lattice: Young's modulus E [Pa]; sets the springs (and, "
                                  "with density, the node masses) instead of stiffness"),
        "poisson_ratio": Key("float", None, gt=-1.0, lt=0.5,
                             doc="with youngs_modulus: nu; the lattice represents only 1/4 "
                                 "(plane strain) or 1/3 (plane stress): another value keeps "
                                 "E/(1-nu^2) (plane strain) or E, with a warning; default: "
                                 "the representable one"),
        "thickness": Key("float", 1.0, gt=0.0,
                         doc="with youngs_modulus: out-of-plane depth t [m] of the slice"),
        "plane": Key("str", "strain", choices=("strain", "stress"),
                     doc="with youngs_modulus: plane strain (a slice of a long body) or "
                         "plane stress (a thin sheet)"),
        "damping_ratio": Key("float", 0.0, ge=0.0,
                             doc="with youngs_modulus: damping ratio of the lattice's highest "
                                 "mode, from dashpots along the springs (mode n gets "
                                 "zeta omega_n/omega_max)"),
        "volume_constraint": Key("bool", True, doc="keep the boundary polygon's area"),
        "gravity": Key("bool", True, doc="feel physics.gravity"),
        "velocity": Key("vec2", [0.0, 0.0], doc="initial velocity of every node [m/s]"),
        "pinned": Key("str", "none", choices=("none", "top", "bottom", "left", "right", "all"),
                      doc="a side whose nodes never move"),
        "pinned_ids": Key("ints", [], ge=0, doc="more nodes that never move"),
        "anchors": Key("points", [], doc="fixed points (e.g. on a rigid wall) that close the "
                                         "boundary polygon: the area kept is the one between "
                                         "the body and them; they are not particles"),
        "anchor_row": Key("str", "bottom", choices=("bottom", "top"),
                          doc="lattice with anchors: the loop runs through the anchors (in "
                              "order) and then this row (bottom: right to left; top: left "
                              "to right)"),
        "load": Key("tables", [], keys={
            "nodes": Key("str", choices=("top", "bottom", "left", "right", "all", "row",
                                         "column", "ids"),
                         doc="which nodes the force acts on: a side, all, a row or column "
                             "(index), or listed ids"),
            "index": Key("int", 0, ge=0, doc="the row or column (from 0 at bottom/left)"),
            "ids": Key("ints", [], ge=0, doc="the nodes, with nodes = \"ids\""),
            "force": Key("vec2", doc="force on each node of the set [N]"),
            "start": Key("float", 0.0, ge=0.0, doc="[s]"),
            "end": Key("float", math.inf, gt=0.0, doc="[s]; default: never ends"),
            "ramp": Key("float", 0.0, ge=0.0, doc="linear rise and fall time [s]"),
        }, doc="[[body.load]]: a force on a node set over a time window"),
    }, many=True, doc="a mass-spring solid: a lattice or general nodes and springs"),
}


def check_dimension_support(raw, dimension):
    """Bodies are 2D so far: a 3D case with a [[body]] is refused in one line."""
    if dimension != 2 and raw.get("body"):
        raise CaseError(f"[[body]]: solid bodies run in 2D cases only so far; this case is "
                        f"{dimension}D (domain.lower has {dimension} components)")


def check(case):
    if case["body"]:
        # Bodies are small: building them is the cheapest complete check.
        from parmps.solids.mass_spring.build import build_bodies
        build_bodies(case)
