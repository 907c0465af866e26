"""Walls and fluid of any shape: a ``[[wall]]`` or ``[[fluid_block]]`` given as a surface
mesh or a primitive, laid on the case's one lattice.

The lattice is ``particles.origin + (i + 1/2) l0`` on every axis, the alignment of the
box path (parmps.geometry.scene): a tank whose corners lie on the lattice's lines
``origin + k l0`` has its particles on these same points, so a box given as a mesh
lays the tank's particles (its corners rounded: a point counts by its distance to the
surface, a tank's by its layer).

A wall's particles are the lattice points whose signed distance s into the wall's
material (away from the fluid) satisfies 0 <= s <= (wall_layers + dummy_layers) l0:
the points with s <= wall_layers l0 are wall particles, the rest dummies, as a tank's
layers at s = l0/2, 3l0/2, ... A fluid of a shape is the lattice points inside it
(s < 0 of its surface), clipped to ``lower``/``upper`` when given.
"""

import logging
import os

import numpy as np

from parmps.core.geometry import format_point
from parmps.core.particles import DUMMY, WALL
from parmps.geometry.domain import Domain
from parmps.errors import CaseError
from parmps.geometry.surfaces import (Box, Cylinder, LatticeBlock, MeshSurface,
                                      PolylineSurface, Sphere)

log = logging.getLogger(__name__)

# The keys each primitive needs, beside the ones every entry has.
SHAPE_KEYS = {"sphere": ("center", "radius"), "cylinder": ("center", "radius", "axis", "length"),
              "box": ("lower", "upper")}
# What a key left out reads as (parmps.geometry.settings declares these defaults).
UNSET = {"center": None, "radius": 0.0, "axis": "z", "length": 0.0, "lower": None,
         "upper": None}
# A mesh's extent this many times the domain's (or less than its inverse) is a unit
# mistake: millimetres given for metres.
UNIT_RATIO = 100.0
# Rounding of the lattice points' distances (a tank's points lie at (k + 1/2) l0).
_TOLERANCE = 1e-9


def needed_keys(shape, dimension):
    """The keys ``shape`` reads; in 2D a cylinder is a circle (no axis, no length)."""
    keys = SHAPE_KEYS[shape]
    if shape == "cylinder" and dimension == 2:
        keys = ("center", "radius")
    return keys


def check_shape_keys(label, spec, dimension, clip=False):
    """Refuse an entry with neither or both of mesh and shape, a shape missing a key it
    needs or given one it does not read. ``clip``: lower/upper are a clipping box."""
    if spec["mesh"] and spec["shape"]:
        raise CaseError(f"{label}: give mesh or shape, not both")
    if not spec["mesh"] and not spec["shape"]:
        raise CaseError(f"missing key '{label}.mesh' or '{label}.shape': a wall is a "
                        f"surface mesh (mesh = \"FILE\") or a shape (\"cylinder\", "
                        f"\"sphere\" or \"box\")")
    reads = ("lower", "upper") if clip else ()
    if spec["shape"]:
        needs = needed_keys(spec["shape"], dimension)
        for key in needs:
            if key in ("center", "lower", "upper") and spec[key] is None:
                raise CaseError(f"missing key '{label}.{key}': shape = \"{spec['shape']}\" "
                                f"needs {', '.join(needs)}")
            if key in ("radius", "length") and not spec[key] > 0:
                raise CaseError(f"missing key '{label}.{key}': shape = \"{spec['shape']}\" "
                                f"needs {key} > 0 (it reads {', '.join(needs)})")
        reads = reads + needs
    for key, unset in UNSET.items():
        if key in spec and spec[key] != unset and key not in reads:
            what = f"shape = \"{spec['shape']}\"" if spec["shape"] else "a mesh"
            raise CaseError(f"{label}.{key} does not apply to {what}"
                            + (f" (it reads {', '.join(reads)})" if reads else ""))


def shape_bounds(spec):
    """The bounding box (lower, upper) of a box, a block's clipping box or a primitive, or
    None (a mesh not yet read): for estimates before the scene is built."""
    if spec.get("lower") is not None:
        return np.asarray(spec["lower"], float), np.asarray(spec["upper"], float)
    if spec["shape"] == "cylinder":
        return Cylinder(spec["center"], spec["radius"], spec["axis"], spec["length"]).bounds()
    if spec["shape"] == "sphere":
        return Sphere(spec["center"], spec["radius"]).bounds()
    return None


def surface_of(label, spec, domain, wall=False):
    """The surface of a ``[[wall]]`` (``wall``) or shaped ``[[fluid_block]]``: a primitive,
    or the checked mesh of its file (a wall's may be open)."""
    dimension = domain.dimension
    if spec["shape"] == "sphere":
        return Sphere(spec["center"], spec["radius"])
    if spec["shape"] == "cylinder":
        return Cylinder(spec["center"], spec["radius"], spec["axis"], spec["length"])
    if spec["shape"] == "box":
        return Box(spec["lower"], spec["upper"])
    return _mesh_surface(label, spec, dimension, domain, wall)


def _mesh_surface(label, spec, dimension, domain, wall):
    from parmps.geometry.mesh import check_closed_surface, check_wall_surface, read_mesh

    source = f"{label}.mesh '{spec['mesh']}'"
    if not os.path.isfile(spec["mesh"]):
        raise CaseError(f"{source}: no such file (a relative path is from the case file's "
                        f"directory)")
    if dimension == 2:
        return _polyline_surface(source, label, spec, domain, wall)
    vertices, triangles = read_mesh(spec["mesh"], source)
    is_open = False
    if wall:
        is_open = check_wall_surface(source, vertices, triangles)
        _check_fluid_side(label, spec, is_open)
    else:
        check_closed_surface(source, vertices, triangles, single=False)
    if spec.get("lower") is None:  # a clipped fill may come from a larger surface
        check_inside_domain(source, vertices, domain)
    log.debug("%s: %d vertices, %d triangles%s", source, len(vertices), len(triangles),
              ", open" if is_open else "")
    return MeshSurface(vertices, triangles, open=is_open)


def _polyline_surface(source, label, spec, domain, wall):
    """A 2D wall's or fluid's curve from its mesh file's line cells, checked."""
    from parmps.geometry.mesh import check_polyline, read_polyline

    vertices, segments = read_polyline(spec["mesh"], source)
    is_open = check_polyline(source, vertices, segments)
    if wall:
        _check_fluid_side(label, spec, is_open)
    elif is_open:
        raise CaseError(f"{source}: a fluid's curve must be closed, and this one has ends")
    if spec.get("lower") is None:
        check_inside_domain(source, vertices, domain)
    return PolylineSurface(vertices, segments, open=is_open)


def _check_fluid_side(label, spec, is_open):
    """An open surface's fluid is on the side its triangles face; a closed one's is given."""
    if is_open and spec["fluid"]:
        raise CaseError(f"{label}.fluid does not apply to an open surface (its mesh has a "
                        f"rim): the fluid lies on the side its triangles face; leave out "
                        f"fluid, or close the surface")
    if not is_open and not spec["fluid"]:
        raise CaseError(f"missing key '{label}.fluid': which side of the closed surface the "
                        f"fluid is on, \"inside\" (a vessel) or \"outside\" (an obstacle)")


def fluid_outside(spec, surface):
    """Whether a wall's fluid lies outside its surface, on the side its normals point to:
    an obstacle, or an open surface."""
    return spec["fluid"] == "outside" or getattr(surface, "open", False)


def check_inside_domain(source, vertices, domain):
    """Refuse a mesh whose bounding box leaves the domain along an axis that is not
    periodic (along a periodic one it is cut at the faces), saying both boxes (and the
    likely cause when the sizes differ by a unit's factor)."""
    lower, upper = domain.lower, domain.upper
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    bounded = [a for a in range(domain.dimension) if a not in domain.periodic]
    if np.all(low[bounded] >= lower[bounded]) and np.all(high[bounded] <= upper[bounded]):
        return
    ratio = float(np.ptp(vertices, axis=0).max() / (upper - lower).max())
    hint = ""
    if ratio > UNIT_RATIO or ratio < 1.0 / UNIT_RATIO:
        hint = (f"; it is {ratio:.3g} times the domain's size: a file in millimetres for a "
                f"case in metres?")
    raise CaseError(f"{source}: the mesh lies outside the domain: its bounding box "
                    f"{format_point(low, '.6g', '[]')}-{format_point(high, '.6g', '[]')} "
                    f"against the domain's {format_point(lower, 'g', '[]')}-"
                    f"{format_point(upper, 'g', '[]')}{hint}")


def wall_particles(label, spec, surface, origin, spacing, domain):
    """The wall and dummy particles of a ``[[wall]]``: (position, kind, velocity, its
    :class:`Side`)."""
    depth = (spec["wall_layers"] + spec["dummy_layers"]) * spacing
    low, high = surface.bounds()
    reach = depth + spacing
    lattice = LatticeBlock.covering(origin, spacing, np.asarray(low) - reach,
                                    np.asarray(high) + reach)
    signed = surface.lattice_distance(lattice, reach)
    # Into the material: inside the surface when the fluid is outside it.
    into = -signed if fluid_outside(spec, surface) else signed
    band = (into >= 0.0) & (into <= depth * (1.0 + _TOLERANCE))
    position = lattice.points(band)
    kind = np.where(lattice.values(into, band) <= spec["wall_layers"] * spacing
                    * (1.0 + _TOLERANCE), WALL, DUMMY).astype(np.int8)
    # Along a periodic axis the wall is cut at the faces: its images continue it.
    within = in_period(position, domain)
    position, kind = position[within], kind[within]
    _check_room(label, spec, position, domain, spacing)
    return position, kind, np.zeros_like(position), Side(spec, surface, lattice, signed)


def in_period(position, domain):
    """Which rows of ``position`` lie in [lower, upper) along every periodic axis."""
    keep = np.ones(len(position), bool)
    for axis in domain.periodic:
        keep &= (position[:, axis] >= domain.lower[axis]) & \
                (position[:, axis] < domain.upper[axis])
    return keep


def _check_room(label, spec, position, domain, spacing):
    lower, upper = domain.lower, domain.upper
    outside = domain.outside(position)
    if outside.any():
        first = position[np.flatnonzero(outside)[0]]
        layers = spec["wall_layers"] + spec["dummy_layers"]
        raise CaseError(
            f"{label}: no room for its {spec['wall_layers']} wall and {spec['dummy_layers']} "
            f"dummy layers ({layers} x {spacing:g} m) inside the domain "
            f"{format_point(lower, 'g', '[]')}-{format_point(upper, 'g', '[]')}: "
            f"{int(outside.sum())} of its particles fall outside, e.g. at "
            f"{format_point(first)}; enlarge domain.lower/domain.upper or move the wall")


def fluid_particles(label, spec, surface, origin, spacing, domain):
    """The lattice points inside the surface of a shaped ``[[fluid_block]]``, clipped to
    its lower/upper when given and to the period along a periodic axis; (n, d)."""
    low, high = surface.bounds()
    if spec["lower"] is not None:
        low, high = np.maximum(low, spec["lower"]), np.minimum(high, spec["upper"])
    lattice = LatticeBlock.covering(origin, spacing, low, high)
    if min(lattice.shape, default=0) == 0:
        raise CaseError(f"{label}: its lower/upper leave no part of its shape to fill")
    position = lattice.points(surface.lattice_distance(lattice, 0.0) < 0.0)
    return position[in_period(position, domain)]


class Side:
    """Which side of a ``[[wall]]`` points are on: its signed distance on the lattice block
    its particles were laid from, and the surface for points off that lattice."""

    def __init__(self, spec, surface, lattice, signed):
        self.spec, self.surface, self.lattice, self.signed = spec, surface, lattice, signed

    def material(self, points):
        """Which of ``points`` lie in the wall's material (s >= 0), at any depth: the water
        of a block that covers an obstacle is not kept inside it."""
        lattice, outside = self.lattice, fluid_outside(self.spec, self.surface)
        # Into the material is outside the surface for a vessel, inside for an obstacle.
        into = np.full(len(points), -np.inf if outside else np.inf)
        index = (points - lattice.origin) / lattice.spacing - 0.5 - lattice.low
        nearest = np.rint(index).astype(np.int64)
        inside_block = np.all((nearest >= 0) & (nearest < lattice.shape), axis=1)
        on_lattice = inside_block & np.all(np.abs(index - nearest) < 1e-6, axis=1)
        signed = self.signed[tuple(nearest[on_lattice].T)]
        into[on_lattice] = -signed if outside else signed
        # Off the lattice but within the block: ask the surface.
        off = inside_block & ~on_lattice
        if off.any():
            signed = _signed_at(self.surface, points[off])
            into[off] = -signed if outside else signed
        return into >= 0.0


def _signed_at(surface, points):
    """The surface's signed distance at ``points`` (lattice points or not); for a mesh
    only its sign, -1 inside and +1 outside."""
    if hasattr(surface, "signed_distance"):
        return surface.signed_distance(points)
    if surface.open:
        return surface.open_signed_distance(points)
    from parmps.geometry.mesh import points_inside

    return np.where(points_inside(points, surface.vertices, surface.triangles), -1.0, 1.0)


def probed_walls(case):
    """name -> (points, lengths (2D) or areas (3D), unit normals into the fluid) on the
    surface of every named ``[[wall]]`` a force probe reads, about half a spacing apart."""
    wanted = {probe["wall"] for probe in case["probe"] if probe.get("wall")}
    out = {}
    for k, spec in enumerate(case["wall"]):
        if spec["name"] in wanted:
            label = f"wall[{k}] '{spec['name']}'"
            surface = surface_of(label, spec, Domain.from_case(case), wall=True)
            points, weights, outward = surface.samples(0.5 * case["particles"]["spacing"])
            into = outward if fluid_outside(spec, surface) else -outward
            out[spec["name"]] = (points, weights, into)
    return out


class MaterialDepth:
    """How deep points lie in the material of each ``[[wall]]`` of a case (the run-time
    guard's test for walls of any shape; a tank's and a wall box's are boxes).

    A primitive answers exactly; a mesh by interpolating, multilinearly, its signed distance
    on the lattice block about it (computed once, within ``reach`` of the surface: deeper
    points read ``reach``)."""

    def __init__(self, case):
        spacing = case["particles"]["spacing"]
        domain = Domain.from_case(case)
        self.walls = []
        for k, spec in enumerate(case.get("wall", ())):
            label = f"wall[{k}] '{spec['name']}'" if spec["name"] else f"wall[{k}]"
            surface = surface_of(label, spec, domain, wall=True)
            reach = (spec["wall_layers"] + spec["dummy_layers"] + 2) * spacing
            grid = None
            if not hasattr(surface, "signed_distance"):
                low, high = surface.bounds()
                lattice = LatticeBlock.covering(case["particles"]["origin"], spacing,
                                                np.asarray(low) - reach,
                                                np.asarray(high) + reach)
                grid = (lattice, np.clip(surface.lattice_distance(lattice, reach),
                                         -reach, reach))
            self.walls.append((label, spec, surface, grid, reach))

    def __bool__(self):
        return bool(self.walls)

    def depth(self, points, shifts):
        """(depth into the deepest wall's material [m], that wall's index) of each point;
        ``shifts``: each wall's displacement from where it was built."""
        deepest = np.full(len(points), -np.inf)
        which = np.full(len(points), -1, np.int64)
        for k, (_, spec, surface, grid, reach) in enumerate(self.walls):
            at = points - np.asarray(shifts[k], dtype=float)
            signed = (surface.signed_distance(at) if grid is None
                      else _interpolate(*grid, at, reach))
            into = -signed if fluid_outside(spec, surface) else signed
            deeper = into > deepest
            deepest[deeper], which[deeper] = into[deeper], k
        return deepest, which

    def label(self, k):
        return self.walls[k][0]


def _interpolate(lattice, values, points, reach):
    """Multilinear interpolation of ``values`` (on the block's points) at ``points``;
    points off the block read +reach (outside the surface, beyond its band)."""
    index = (points - lattice.corner) / lattice.spacing
    shape = np.array(lattice.shape)
    first = np.floor(index).astype(np.int64)
    inside = np.all((first >= 0) & (first < shape - 1), axis=1)
    out = np.full(len(points), reach)
    if not inside.any():
        return out
    first, fraction = first[inside], index[inside] - first[inside]
    total = np.zeros(len(first))
    d = len(shape)
    for corner in range(2 ** d):
        bits = np.array([(corner >> a) & 1 for a in range(d)])
        weight = np.prod(np.where(bits, fraction, 1.0 - fraction), axis=1)
        total += weight * values[tuple((first + bits).T)]
    out[inside] = total
    return out
