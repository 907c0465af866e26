"""Closed triangle meshes for shell bodies (issue 24 item 3).

A shell is a closed, outward-oriented triangle mesh: its vertices are the body's
nodes, its edges carry springs, a bending spring joins the two vertices opposite
each edge, and its triangles are the facets whose enclosed volume Hong et al.'s
constraint keeps. The meshes themselves are made, read and checked by
:mod:`parmps.geometry.shapes` and :mod:`parmps.geometry.mesh` (their names are
re-exported here for the shell's callers); this module turns a ``[[body]]`` table
into one and keeps a shell's nodes clear of the fluid: :func:`displaced_by_shell`
the fluid's points a shell's nodes take the place of (docs/shells.md, A shell in a
fluid).
"""

import logging

import numpy as np

from parmps.config import ZERO, Key
from parmps.core.geometry import surface_distance
from parmps.errors import CaseError
from parmps.geometry.mesh import (check_closed_surface, edge_lengths, edges_and_bending,
                                 enclosed_volume, node_areas, read_mesh, triangle_areas)
from parmps.geometry.shapes import RBC_DIAMETER, capsule, icosphere, red_blood_cell

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------
# The fluid beside a shell


def fluid_clearance(vertices, triangles, spacing):
    """How far from a shell's surface the fluid's lattice points are left out [m].

    The shell's nodes are particles of the fluid: each stands for a particle's volume
    l0^d. Leaving out the points within c of the surface, on both sides, removes a layer
    2 c thick, about 2 c A / l0^3 points on a surface of area A; it holds as many nodes as
    the layer held points when 2 c = l0^3 / a, a = A / nodes the mean area per node. On
    a mesh of edges l0 (a = (sqrt 3 / 2) l0^2) that is c = 0.58 l0. A finer mesh clears
    more, a coarser one no less than half a spacing (closer points overlap a node).
    """
    area = float(triangle_areas(vertices, triangles).sum())
    per_node = area / len(np.unique(triangles))
    return max(0.5 * spacing, 0.5 * spacing ** 3 / per_node)


# The longest mean edge, in particle spacings, of a shell in a fluid. Its nodes stand for
# the fluid they displace: at a mean edge of 1.41 l0 the capsule of cases/capsule_3d.toml
# has 114 nodes where the layer within half a spacing of it held 178 lattice points, and
# before the coupling held the water to its side it let 4 particles through there and 36 at
# 1.91 l0 (validation/capsule_3d/README.md).
MAX_EDGE_IN_FLUID = 1.25


def check_shell_in_fluid(label, vertices, triangles, spacing):
    """Refuse a shell whose nodes lie too far apart to hold the water, in one line."""
    mean = float(edge_lengths(vertices, triangles).mean())
    if mean > MAX_EDGE_IN_FLUID * spacing:
        raise CaseError(f"{label}: its mean edge {mean:.4g} m is {mean / spacing:.2f} "
                        f"particle spacings; in a fluid a shell's nodes are particles of "
                        f"it, standing for the water they displace, and must lie at most "
                        f"{MAX_EDGE_IN_FLUID} spacings apart on average: refine the shell "
                        f"(spacing or refinement)")


def displaced_by_shell(points, vertices, triangles, spacing):
    """Which of ``points`` (k, 3) lie within :func:`fluid_clearance` of the shell."""
    clearance = fluid_clearance(vertices, triangles, spacing)
    return surface_distance(points, vertices, triangles, clearance) < clearance


# --------------------------------------------------------------------------
# A shell body from its [[body]] table


SHAPES = ("sphere", "capsule", "red_blood_cell", "file")

# The [[body]] keys of type = "shell" (parmps.solids.settings adds them). A shell
# also reads spacing (target edge length), stiffness (edge springs), node_mass,
# damping, pinned, load and volume_constraint.
KEYS = {
    "shape": Key("str", "sphere", choices=SHAPES,
                 doc="shell: a generated sphere, capsule or red_blood_cell (Evans & Fung "
                     "1972), or a closed triangle mesh file"),
    "radius": Key("float", 0.0, ge=0.0, doc="shell sphere and capsule: radius [m]"),
    "length": Key("float", 0.0, ge=0.0,
                  doc="shell capsule: length of its cylinder [m] (total radius+length+radius)"),
    "diameter": Key("float", 0.0, ge=0.0,
                    doc="shell red_blood_cell: diameter [m]; 0 means Evans & Fung's 7.82 um"),
    "axis": Key("str", "z", choices=("x", "y", "z"),
                doc="shell capsule and red_blood_cell: the axis of symmetry"),
    "center": Key("vector", ZERO, doc="shell: centre of a generated shape; added to a mesh "
                                      "file's coordinates"),
    "mesh": Key("str", "", doc="shell with shape = \"file\": a closed surface mesh (STL, OBJ, "
                               "Gmsh .msh, VTK, ... read by meshio; a relative path is from "
                               "the working directory)"),
    "geodesic_base": Key("str", "octahedron", choices=("octahedron", "icosahedron"),
                         doc="shell red_blood_cell: the geodesic sphere mapped onto the cell "
                             "(the octahedron's grid runs along x and y; the icosahedron's "
                             "does not)"),
    "refinement": Key("int", 0, ge=0,
                      doc="shell: geodesic frequency n (each base edge cut n times; 2^k is k "
                          "midpoint subdivisions) instead of spacing"),
    "bending_stiffness": Key("float", 0.0, ge=0.0,
                             doc="shell: spring joining the two vertices opposite each edge "
                                 "[N/m]; 0: no bending springs"),
    "surface_density": Key("float", 0.0, ge=0.0,
                           doc="shell: mass per area [kg/m^2]; a node gets a third of its "
                               "triangles' area (instead of node_mass)"),
}

# Keys of the other body types, refused on a shell.
OTHER_KEYS = {"nx": 0, "ny": 0, "nz": 0, "density": 0.0, "shear_stiffness": 0.0,
              "youngs_modulus": 0.0, "nodes": [], "springs": [], "boundary": [],
              "masses": [], "spring_stiffness": [], "anchors": [], "poisson_ratio": None,
              "damping_ratio": 0.0, "plane": "strain", "thickness": 1.0}


def check_keys(label, spec):
    """Refuse shell keys on another body type, and other types' keys on a shell."""
    if spec["type"] == "shell":
        for key, unset in OTHER_KEYS.items():
            if spec.get(key, unset) != unset:
                raise CaseError(f"{label}.{key} does not apply to a shell body")
        return
    for key, value in KEYS.items():
        if key in spec and spec[key] != (value.default(len(spec["center"]))
                                         if callable(value.default) else value.default):
            raise CaseError(f"{label}.{key} applies to shell bodies only (type = \"shell\")")


def _oriented(mesh, axis, center):
    """A mesh made along z turned to ``axis`` by a cyclic permutation (a rotation,
    so the triangles stay outward), then moved to ``center``."""
    vertices, triangles = mesh
    turn = {"z": [0, 1, 2], "x": [2, 0, 1], "y": [1, 2, 0]}[axis]
    return vertices[:, turn] + np.asarray(center, dtype=float), triangles


# The keys each shape reads, beside center; the others must keep their defaults.
SHAPE_KEYS = {"sphere": ("radius", "spacing", "refinement"),
              "capsule": ("radius", "length", "axis", "spacing", "refinement"),
              "red_blood_cell": ("diameter", "axis", "spacing", "refinement", "geodesic_base"),
              "file": ("mesh",)}
UNSET = {"radius": 0.0, "length": 0.0, "diameter": 0.0, "axis": "z", "mesh": "",
         "spacing": 0.0, "refinement": 0, "geodesic_base": "octahedron"}


def _check_shape_keys(label, spec):
    shape = spec["shape"]
    for key, unset in UNSET.items():
        if spec[key] != unset and key not in SHAPE_KEYS[shape]:
            raise CaseError(f"{label}.{key} does not apply to shape = \"{shape}\" (it reads "
                            f"{', '.join(SHAPE_KEYS[shape])} and center)")
    if spec["spacing"] and spec["refinement"]:
        raise CaseError(f"{label}: give spacing (a target edge length) or refinement, not both")


def shell_mesh(label, spec):
    """(vertices, triangles) of a ``type = "shell"`` body, checked; ``label`` names
    the body in messages."""
    _check_shape_keys(label, spec)
    shape, h = spec["shape"], spec["spacing"] or None
    frequency = spec["refinement"] or None
    if shape == "file":
        if not spec["mesh"]:
            raise CaseError(f"{label}: shape = \"file\" needs mesh = \"path\" (STL, OBJ, "
                            f"Gmsh .msh, VTK, ...)")
        source = f"{label}.mesh '{spec['mesh']}'"
        vertices, triangles = read_mesh(spec["mesh"], source)
        mesh = (vertices + np.asarray(spec["center"], dtype=float), triangles)
    else:
        if shape in ("sphere", "capsule") and not spec["radius"] > 0:
            raise CaseError(f"{label}.radius must be > 0 for shape = \"{shape}\"")
        try:
            if shape == "sphere":
                made = icosphere(spec["radius"], frequency, h)
            elif shape == "capsule":
                made = capsule(spec["radius"], spec["length"], h, frequency)
            else:
                made = red_blood_cell(spec["diameter"] or RBC_DIAMETER, h, frequency,
                                      base=spec.get("geodesic_base", "octahedron"))
        except CaseError as exc:  # the generators name themselves, not the body
            raise CaseError(f"{label}: {exc}") from None
        mesh = _oriented(made, spec["axis"], spec["center"])
        source = f"{label} ({shape} generator)"
    check_closed_surface(source, *mesh)
    return mesh


def shell_body(label, spec, dimension):
    """What build.py needs of a shell: (position, springs, stiffness, mass, facets, None).

    Springs: every edge (``stiffness``), then, with ``bending_stiffness``, one across
    every edge between the vertices opposite it. The facets are the triangles.
    """
    if dimension != 3:
        raise CaseError(f"{label}.type = \"shell\" is a closed surface in 3D; this case is "
                        f"{dimension}D")
    check_keys(label, spec)
    vertices, triangles = shell_mesh(label, spec)
    edges, bending = edges_and_bending(triangles)
    if spec["stiffness"] is None:
        raise CaseError(f"{label}: missing key 'stiffness' [N/m] (the edge springs)")
    springs, stiffness = edges, np.full(len(edges), spec["stiffness"])
    if spec["bending_stiffness"] > 0:
        springs = np.concatenate([edges, bending])
        stiffness = np.concatenate([stiffness, np.full(len(bending),
                                                       spec["bending_stiffness"])])
    if spec["node_mass"] > 0 and spec["surface_density"] > 0:
        raise CaseError(f"{label}: give node_mass or surface_density, not both")
    if spec["node_mass"] > 0:
        mass = np.full(len(vertices), spec["node_mass"])
    elif spec["surface_density"] > 0:
        mass = spec["surface_density"] * node_areas(vertices, triangles)
    else:
        raise CaseError(f"{label}: node mass must be > 0: set node_mass [kg] or "
                        f"surface_density [kg/m^2]")
    log.debug("%s: %d nodes, %d triangles, %d springs (%d bending), volume %.6g", label,
             len(vertices), len(triangles), len(springs), len(springs) - len(edges),
             enclosed_volume(vertices, triangles))
    return vertices, springs, stiffness, mass, triangles, None
