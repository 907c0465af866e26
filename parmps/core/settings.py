"""Case sections of the scene: the domain, the particle lattice, gravity, fluid blocks."""

from parmps.config import Key, Section, check_ordered_box
from parmps.errors import CaseError

# Sections whose entries are particles on the lattice and so need particles.spacing.
PARTICLE_SECTIONS = ("fluid_block", "tank", "wall_box", "inlet", "outlet")

SECTIONS = {
    "domain": Section({
        "lower": Key("vec2", doc="lower-left corner; every particle must start inside"),
        "upper": Key("vec2", doc="upper-right corner"),
        "escaped_fluid": Key("str", "remove", choices=("remove", "stop"),
                             doc="a fluid particle outside the box after a step: \"remove\" "
                                 "drops it and the run goes on (spray thrown over a wall), "
                                 "counted in the diagnostics' n_escaped; \"stop\" stops the "
                                 "run. Any other particle outside always stops it"),
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
    }),
    "physics": Section({
        "gravity": Key("vec2", [0.0, -9.81], doc="[m/s^2]"),
    }),
    "fluid_block": Section({
        "lower": Key("vec2", doc="lower-left corner of the block [m]"),
        "upper": Key("vec2", doc="upper-right corner of the block [m]"),
        "velocity": Key("vec2", [0.0, 0.0], doc="initial velocity of its particles [m/s]"),
    }, many=True, doc="a rectangle filled with fluid particles on the l0 lattice"),
}


def check_dimension(raw):
    """The case's dimension, from the number of components of domain.lower (before validation).

    Only 2D exists so far; a 3D domain is refused with a sentence that says so
    rather than a complaint about a vector's length.
    """
    lower = raw.get("domain", {}).get("lower") if isinstance(raw.get("domain"), dict) else None
    if isinstance(lower, list) and len(lower) == 3:
        raise CaseError("domain.lower has 3 components: parmps runs 2D cases only so far "
                        "(3D is planned); give [x, y]")
    return 2


def check(case):
    particle_sections = [name for name in PARTICLE_SECTIONS if case.get(name)]
    if case["particles"]["spacing"] is None and particle_sections:
        raise CaseError(f"missing key 'particles.spacing': the case has "
                        f"[[{particle_sections[0]}]] particles, which need a spacing")
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    for axis, label in enumerate("xy"):
        if not upper[axis] > lower[axis]:
            raise CaseError(f"domain.upper.{label} ({upper[axis]}) must exceed "
                            f"domain.lower.{label} ({lower[axis]})")
    for k, block in enumerate(case["fluid_block"]):
        check_ordered_box(f"fluid_block[{k}]", block)


def search_radius(case):
    """The pair-search radius [m]: the Laplacian's radius plus a skin. It is also the
    halo's reach, so the decomposition and the fluid step take it from here."""
    spacing = case["particles"]["spacing"]
    return case["mps"]["re_laplacian"] * spacing + case["parallel"]["halo_skin"] * spacing


# The geometry that makes a case a fluid case; bodies alone run without a fluid.
FLUID_GEOMETRY = ("fluid_block", "tank", "wall_box")


def has_fluid(case):
    """Whether the case has fluid or wall particles (else it is bodies alone)."""
    return any(case.get(name) for name in FLUID_GEOMETRY)
