"""The number-density source of the original MPS (Koshizuka & Oka 1996; docs/design.md).

``rhs_i = gamma rho / dt^2 (n*_i - n0) / n0`` with n* the number density at the
predicted positions and ``gamma`` a relaxation coefficient (below 1: the full
deviation corrected in one step makes the pressure noisy).
"""

from parmps.config import Key


class RelaxedSource:
    """A source with a pull back to n0 of relaxation gamma, ``[mps.<name>] relaxation``
    (each subclass's KEYS give its default)."""

    def __init__(self, settings, constants):
        self.relaxation = settings["relaxation"]
        self.constants = constants


class DensitySource(RelaxedSource):
    KEYS = {"relaxation": Key("float", 0.2, gt=0.0, le=1.0,
                              doc="gamma: fraction of the number-density deviation "
                                  "corrected per step")}

    def rhs(self, step):
        c = self.constants
        return (c.density / step.dt ** 2) * self.relaxation * \
            (step.number_density[step.unknown_index] - c.n0) / c.n0
