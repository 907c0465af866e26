"""Case sections of the geometry: the fluid blocks, and the walls of any shape."""

from parmps.boundaries.settings import MOTION_KEYS
from parmps.config import ZERO, Key, Section, check_ordered_box, resolve_file_paths
from parmps.errors import CaseError
from parmps.geometry.walls import check_shape_keys

# A surface given as a mesh file or as a primitive; which keys a shape reads:
# parmps.geometry.walls.SHAPE_KEYS.
SURFACE_KEYS = {
    "mesh": Key("str", "", doc="a closed surface mesh file (STL, OBJ, PLY, Gmsh .msh, VTK, "
                               "... read by meshio; a relative path is from the case "
                               "file's directory), 3D only"),
    "center": Key("vector", None, doc="shape sphere and cylinder: the centre [m]"),
    "radius": Key("float", 0.0, ge=0.0, doc="shape sphere and cylinder: the radius [m]"),
    "axis": Key("str", "z", choices=("x", "y", "z"),
                doc="shape cylinder in 3D: the axis it lies along"),
    "length": Key("float", 0.0, ge=0.0,
                  doc="shape cylinder in 3D: its length along the axis, flat ends [m]"),
}

SECTIONS = {
    "fluid_block": Section({
        "lower": Key("vector", None, doc="lower corner of the block [m]; with a mesh or "
                                         "shape, of the box the fill is clipped to"),
        "upper": Key("vector", None, doc="upper corner of the block [m] (or of the clip)"),
        "velocity": Key("vector", ZERO, doc="initial velocity of its particles [m/s]"),
        "velocity_gradient": Key("points", [],
                                 doc="d rows du_i/dx_j [1/s]: the initial velocity is "
                                     "velocity + G x (x from the origin of coordinates), "
                                     "e.g. [[0, 1, 0], [0, 0, 0], [0, 0, 0]] a simple shear "
                                     "u = y along x; [] none"),
        "shape": Key("str", "", choices=("", "cylinder", "sphere"),
                     doc="fill a cylinder (a circle in 2D) or a sphere instead of the box"),
        **SURFACE_KEYS,
    }, many=True, doc="fluid particles on the l0 lattice: a box (lower, upper), or the "
                      "inside of a closed mesh or shape (on the lattice origin + "
                      "(i + 1/2) l0, clipped to lower/upper when given); fluid points in "
                      "a [[wall]]'s material or closer than l0 to its particles are left "
                      "out"),
    "wall": Section({
        "name": Key("str", "", doc="the wall's name, for probes and messages"),
        "shape": Key("str", "", choices=("", "cylinder", "sphere", "box"),
                     doc="a cylinder (a circle in 2D: center, radius; in 3D also axis and "
                         "length), a sphere (center, radius) or a box (lower, upper)"),
        **SURFACE_KEYS,
        "lower": Key("vector", None, doc="shape box: its lower corner [m]"),
        "upper": Key("vector", None, doc="shape box: its upper corner [m]"),
        "fluid": Key("str", "", choices=("", "inside", "outside"),
                     doc="which side of a closed surface the fluid is on: \"outside\" an "
                         "obstacle, \"inside\" a vessel; the wall and dummy layers lie on "
                         "the other side. Needed for a shape and a closed mesh; an open "
                         "mesh (one with a rim) has its fluid on the side its triangles "
                         "face, and its walls end at the rim"),
        "wall_layers": Key("int", 2, ge=1, le=10, doc="layers of wall particles (in the "
                                                      "PPE), nearest the surface"),
        "dummy_layers": Key("int", 2, ge=0, le=10,
                            doc="layers of dummy particles behind them (number density "
                                "only)"),
        **MOTION_KEYS,
    }, many=True, doc="a wall of any shape, from a surface mesh or a primitive: wall and "
                      "dummy particles on the lattice points within (wall_layers + "
                      "dummy_layers) l0 of the surface on the side away from the fluid; "
                      "it may translate at a constant velocity (see MOTION_KEYS)"),
}


def check(case):
    dimension = case["dimension"]
    for k, block in enumerate(case["fluid_block"]):
        label = f"fluid_block[{k}]"
        if block["shape"] or block["mesh"]:
            check_shape_keys(label, block, dimension, clip=True)
        else:
            for key in ("lower", "upper"):
                if block[key] is None:
                    raise CaseError(f"missing key '{label}.{key}': a fluid block is a box "
                                    f"(lower, upper), or give mesh or shape")
            for key in ("center", "radius", "length"):
                if block[key] != SURFACE_KEYS[key].default:
                    raise CaseError(f"{label}.{key} applies to a fluid block with "
                                    f"shape = \"cylinder\" or \"sphere\" only")
        if block["velocity_gradient"] and len(block["velocity_gradient"]) != dimension:
            raise CaseError(f"{label}.velocity_gradient has {len(block['velocity_gradient'])} "
                            f"rows but the case is {dimension}D: give {dimension} rows du_i/dx_j")
        if (block["lower"] is None) != (block["upper"] is None):
            raise CaseError(f"{label}: give both lower and upper, or neither")
        if block["lower"] is not None:
            check_ordered_box(label, block)
    names = set()
    for k, wall in enumerate(case["wall"]):
        label = f"wall[{k}]"
        check_shape_keys(label, wall, dimension)
        if wall["shape"] and not wall["fluid"]:
            raise CaseError(f"missing key '{label}.fluid': which side of the shape the fluid "
                            f"is on, \"inside\" (a vessel) or \"outside\" (an obstacle)")
        if wall["shape"] == "box":
            check_ordered_box(label, wall)
        if wall["name"]:
            if wall["name"] in names:
                raise CaseError(f"{label}.name '{wall['name']}' names another wall too")
            names.add(wall["name"])
        if not wall["move_end"] > wall["move_start"]:
            raise CaseError(f"{label}.move_end ({wall['move_end']}) must exceed "
                            f"{label}.move_start ({wall['move_start']})")


def resolve_paths(raw, case_file):
    """Make the meshes' relative paths of a parsed case absolute, from the directory of
    ``case_file``; returns whether any changed."""
    return resolve_file_paths(raw, case_file, SECTIONS, "mesh")
