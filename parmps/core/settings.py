"""Case sections of the scene: the domain, the particle lattice, gravity (the fluid blocks
and the walls of any shape are parmps.geometry.settings's)."""

from parmps.config import ZERO, Key, PerDimension, Section
from parmps.errors import CaseError

# Sections whose entries are particles on the lattice and so need particles.spacing.
PARTICLE_SECTIONS = ("fluid_block", "tank", "wall_box", "wall", "inlet", "outlet")

SECTIONS = {
    "domain": Section({
        "lower": Key("vector", doc="lower-left corner; every particle must start inside"),
        "upper": Key("vector", doc="upper-right corner"),
        "escaped_fluid": Key("str", "remove", choices=("remove", "stop"),
                             doc="a fluid particle outside the box after a step: \"remove\" "
                                 "drops it and the run goes on (spray thrown over a wall), "
                                 "counted in the diagnostics' n_escaped; \"stop\" stops the "
                                 "run. Any other particle outside always stops it"),
        "periodic": Key("strs", [], choices=("x", "y", "z"),
                        doc="axes along which the domain is periodic (e.g. [\"x\"]): its "
                            "extent along each is the period; particles leaving one face "
                            "enter at the other, neighbours are found across it, and walls "
                            "that reach a periodic face continue across it. The period must "
                            "be a whole number of spacings and the lattice must line up with "
                            "the faces (domain.lower on particles.origin's lines)"),
        "max_escaped_fraction": Key("float", 0.01, ge=0.0, le=1.0,
                                    doc="with escaped_fluid = \"remove\", the run stops once "
                                        "more than this fraction of the fluid particles at "
                                        "t = 0 has left: a flood is a leak or an unstable run, "
                                        "not spray"),
    }, required=True, doc="the box that holds the particles; fluid leaving it is removed or "
                          "stops the run (escaped_fluid)"),
    "particles": Section({
        "spacing": Key("float", None, gt=0.0,
                       doc="initial particle spacing l0 [m]; needed by any case with fluid "
                           "or walls, not by a solid-only case"),
        "snap": Key("bool", False,
                    doc="false: every box (fluid block, tank, wall box, inlet) must span a "
                        "whole number of spacings; true: each box's corners move to the "
                        "nearest lines origin + k l0 of one lattice, so a geometry given in "
                        "metres (a benchmark's) runs at any spacing, each face within half a "
                        "spacing of where it was given; probes with a normal move onto the "
                        "face as built"),
        "origin": Key("vector", ZERO, doc="a point of the lattice's lines [m]: the boxes' "
                                          "corners with snap, and the lattice that walls "
                                          "and fluid of a mesh or shape are laid on "
                                          "(origin + (i + 1/2) l0)"),
    }),
    "physics": Section({
        "gravity": Key("vector", PerDimension(-9.81), doc="[m/s^2]"),
    }),
}


# The dimensions a case may have.
DIMENSIONS = (2, 3)


def check_dimension(raw):
    """The case's dimension, from the number of components of domain.lower (before validation).

    [x, y] makes a 2D case, [x, y, z] a 3D one (z up); every other vector of the
    case must then have as many components (:class:`parmps.config.Key` "vector").
    """
    lower = raw.get("domain", {}).get("lower") if isinstance(raw.get("domain"), dict) else None
    if isinstance(lower, list) and len(lower) in DIMENSIONS:
        return len(lower)
    if isinstance(lower, list):
        raise CaseError(f"domain.lower has {len(lower)} components: give [x, y] for a 2D case "
                        f"or [x, y, z] for a 3D one")
    return 2


def check(case):
    particle_sections = [name for name in PARTICLE_SECTIONS if case.get(name)]
    if case["particles"]["spacing"] is None and particle_sections:
        raise CaseError(f"missing key 'particles.spacing': the case has "
                        f"[[{particle_sections[0]}]] particles, which need a spacing")
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    for k, name in enumerate(case["domain"]["periodic"]):
        if name not in "xyz"[:len(lower)]:
            raise CaseError(f"domain.periodic[{k}] names axis {name!r}, which a "
                            f"{len(lower)}D case does not have")
    for axis, label in enumerate("xyz"[:len(lower)]):
        if not upper[axis] > lower[axis]:
            raise CaseError(f"domain.upper.{label} ({upper[axis]}) must exceed "
                            f"domain.lower.{label} ({lower[axis]})")
    if case["particles"]["snap"] and case["particles"]["spacing"] is not None:
        snap_boxes(case)


# The sections whose entries are boxes of particles (lower, upper corners).
BOX_SECTIONS = ("fluid_block", "tank", "wall_box", "inlet")


def snap_to_lattice(value, case):
    """``value`` (a coordinate vector) moved to the nearest lattice lines origin + k l0."""
    spacing = case["particles"]["spacing"]
    origin = case["particles"]["origin"]
    return [o + round((v - o) / spacing) * spacing for v, o in zip(value, origin)]


def snap_boxes(case):
    """With particles.snap: every box's corners on the lattice's lines, in place. Two boxes
    that touched still touch, and each face moves by at most half a spacing."""
    for name in BOX_SECTIONS:
        for box in case.get(name, ()):
            if box["lower"] is None:  # a fluid block of a shape and no clipping box
                continue
            box["lower"] = snap_to_lattice(box["lower"], case)
            box["upper"] = snap_to_lattice(box["upper"], case)


def search_radius(case):
    """The pair-search radius [m]: the Laplacian's radius plus a skin. It is also the
    halo's reach, so the decomposition and the fluid step take it from here."""
    spacing = case["particles"]["spacing"]
    return case["mps"]["re_laplacian"] * spacing + case["parallel"]["halo_skin"] * spacing


# The geometry that makes a case a fluid case; bodies alone run without a fluid.
FLUID_GEOMETRY = ("fluid_block", "tank", "wall_box", "wall")


def has_fluid(case):
    """Whether the case has fluid or wall particles (else it is bodies alone)."""
    return any(case.get(name) for name in FLUID_GEOMETRY)
