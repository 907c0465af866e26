"""Case section of the fluid-solid coupling."""

from parmps.config import Key, Section
from parmps.coupling import SCHEMES
from parmps.core.settings import has_fluid
from parmps.errors import CaseError

# A lattice body's node spacing must match the particle spacing within this.
_SPACING_TOLERANCE = 1e-6

SECTIONS = {
    "coupling": Section({
        "scheme": Key("str", "implicit_pressure", choices=tuple(SCHEMES),
                      doc="how fluid and bodies exchange forces each step (parmps.coupling."
                          "SCHEMES): weak = one fluid step, then the bodies' substeps with "
                          "the fluid force held (unstable for bodies lighter than the "
                          "fluid); implicit_pressure = the same with the nodes as particles "
                          "of their own density in the pressure equation (the same answer "
                          "at density ratio 1, stable for light bodies)"),
    }),
}


def check(case):
    """In a fluid, a lattice body's nodes must sit l0 apart: they are particles of it."""
    if not has_fluid(case):
        return
    spacing = case["particles"]["spacing"]
    for k, spec in enumerate(case["body"]):
        if spec["type"] == "lattice" and \
                abs(spec["spacing"] - spacing) > _SPACING_TOLERANCE * spacing:
            name = spec["name"] or f"body{k}"
            raise CaseError(f"body[{k}] '{name}': spacing {spec['spacing']:g} must "
                            f"equal particles.spacing {spacing:g} in a case with fluid (its "
                            f"nodes are particles of the fluid)")
