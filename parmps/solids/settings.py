"""Case sections of the solids: the shared solver settings and the bodies."""

import logging
import math

from parmps.config import ZERO, Key, Section
from parmps.core.settings import has_fluid
from parmps.solids.mass_spring.membrane import KEYS as MEMBRANE_KEYS
from parmps.solids.mass_spring.shell import KEYS as SHELL_KEYS
from parmps.solids.mass_spring.shell import check_shell_in_fluid

# The sides of a body a node set may name: x, y (3D only) and the last axis.
SIDES = ("left", "right", "front", "back", "bottom", "top")

SECTIONS = {
    "solid": Section({
        "model": Key("str", "mass_spring", choices=("mass_spring",),
                     doc="the solid model every body uses (parmps.solids.MODELS)"),
        "substep": Key("float", 0.0, ge=0.0,
                       doc="fixed solid substep [s]; 0 chooses it from the stiffest node"),
        "safety": Key("float", 0.5, gt=0.0, le=1.0,
                      doc="automatic substep = safety x the Verlet stability limit"),
        "constraint_prediction": Key("str", "iterated",
                                     choices=("iterated", "linear", "quadratic"),
                                     doc="iterated: the volume multiplier of docs/design.md "
                                         "§1.5, then Newton steps on it until the next "
                                         "substep's volume is within constraint_tolerance; "
                                         "linear: the single solve alone; quadratic: the "
                                         "earlier name of iterated, which it now means"),
        "constraint_tolerance": Key("float", 1e-12, gt=0.0, lt=1e-6,
                                    doc="iterated: largest relative volume error predicted "
                                        "for the next substep"),
    }, doc="mass-spring solver settings shared by every body"),
    "body": Section({
        "name": Key("str", "", doc="used in the output; default body<k>"),
        "type": Key("str", "lattice", choices=("lattice", "general", "shell"),
                    doc="\"lattice\": nx by ny (by nz) nodes with springs generated; "
                        "\"general\" (2D): nodes, springs and boundary loop given; "
                        "\"shell\" (3D): a closed triangle mesh (docs/shells.md)"),
        "nx": Key("int", 0, ge=0, doc="lattice: nodes along x"),
        "ny": Key("int", 0, ge=0, doc="lattice: nodes along y"),
        "nz": Key("int", 0, ge=0, doc="3D lattice: nodes along z"),
        "spacing": Key("float", 0.0, ge=0.0, doc="lattice: node spacing [m]; shell: target "
                                                 "edge length [m]"),
        "lower": Key("vector", ZERO, doc="lattice: position of the node with the smallest "
                                         "coordinates"),
        "nodes": Key("points", [], doc="general: node positions [[x, y], ...]"),
        "springs": Key("pairs", [], doc="general: springs as node index pairs [[i, j], ...]"),
        "boundary": Key("ints", [], doc="general: the boundary loop, counter-clockwise"),
        "masses": Key("floats", [], gt=0.0, doc="general: one mass per node [kg]"),
        "spring_stiffness": Key("floats", [], gt=0.0,
                                doc="general: one stiffness per spring [N/m]"),
        "node_mass": Key("float", 0.0, ge=0.0, doc="mass of every node [kg]"),
        "density": Key("float", 0.0, ge=0.0,
                       doc="lattice: node mass = density x spacing^d (2D: per unit depth); "
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
        "volume_constraint": Key("bool", True, doc="keep the volume the boundary encloses "
                                                   "(the polygon's area in 2D)"),
        "gravity": Key("bool", True, doc="feel physics.gravity"),
        "velocity": Key("vector", ZERO, doc="initial velocity of every node [m/s]"),
        "pinned": Key("str", "none", choices=("none",) + SIDES + ("all",),
                      doc="a side whose nodes never move (front/back: the y sides of a 3D "
                          "body; top/bottom: the last axis, y in 2D, z in 3D)"),
        "pinned_ids": Key("ints", [], ge=0, doc="more nodes that never move"),
        "pinned_outside": Key("points", [], doc="a box [lower, upper]: the nodes on or "
                                                "outside it never move (a plate clamped "
                                                "along the box's sides) [m]"),
        "anchors": Key("points", [], doc="fixed points (e.g. on a rigid wall) that close the "
                                         "boundary polygon: the area kept is the one between "
                                         "the body and them; they are not particles"),
        "anchor_row": Key("str", "bottom", choices=("bottom", "top"),
                          doc="lattice with anchors: the loop runs through the anchors (in "
                              "order) and then this row (bottom: right to left; top: left "
                              "to right)"),
        "load": Key("tables", [], keys={
            "nodes": Key("str", choices=SIDES + ("all", "row", "column", "layer", "ids"),
                         doc="which nodes the force acts on: a side, all, a 2D lattice's row "
                             "or column or a 3D lattice's layer (index), or listed ids"),
            "index": Key("int", 0, ge=0, doc="the row, column or layer (from 0 at "
                                             "bottom/left; a layer: nodes k = index along z)"),
            "ids": Key("ints", [], ge=0, doc="the nodes, with nodes = \"ids\""),
            "force": Key("vector", doc="force on each node of the set [N]"),
            "start": Key("float", 0.0, ge=0.0, doc="[s]"),
            "end": Key("float", math.inf, gt=0.0, doc="[s]; default: never ends"),
            "ramp": Key("float", 0.0, ge=0.0, doc="linear rise and fall time [s]"),
            "within": Key("float", 0.0, ge=0.0,
                          doc="a contact patch: the nodes within this distance [m] of the "
                              "centre of the set named (e.g. a shell's right side) instead"),
            "total": Key("bool", False, doc="force is the set's total, spread evenly over "
                                            "its nodes, not each node's"),
        }, doc="[[body.load]]: a force on a node set over a time window"),
        **SHELL_KEYS,
        **MEMBRANE_KEYS,
    }, many=True, doc="a mass-spring solid: a lattice or general nodes and springs"),
}


def check(case):
    if case["body"]:
        # Bodies are small: building them is the cheapest complete check. Its warnings (a
        # Poisson ratio the lattice cannot represent, a body one cell deep) come again when
        # the run builds the bodies: only that build says them.
        from parmps.solids.mass_spring.build import build_bodies
        quiet = logging.getLogger("parmps.solids")
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            bodies = build_bodies(case)
        finally:
            quiet.setLevel(level)
        if has_fluid(case):
            for k, body in enumerate(bodies):
                if body.encloses_fluid:
                    check_shell_in_fluid(f"body[{k}] '{body.name}'", body.position,
                                         body.facets, case["particles"]["spacing"])
