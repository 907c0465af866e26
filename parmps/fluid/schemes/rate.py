"""Khayyer & Gotoh's number-density-rate sources: HS (2009) and HS + ECS (2011).

HS: ``b_i = s rho/(n0 dt) (Dn/Dt)*_i``, the time derivative of the number
density taken analytically along the predicted velocities at the predicted
positions, in place of the standard source's difference quotient. ECS adds
``rho/(n0 dt) (|e_i| (Dn/Dt)^k_i + |(Dn/Dt)^k_i| e_i)``, e_i = (n^k_i - n0)/n0,
both at the start of the step: a pull back to n0 that acts only while the
deviation grows. Exact forms, their sources and what each makes true:
docs/schemes.md (HS, ECS).

``s`` is the normalisation: 1 in the papers ("paper"). On a lattice the rate of
a uniform expansion is (n0 + N)/(d n0) times -n0 div u (N the neighbour count),
so with the standard Laplacian the published source asks 1.67 times the
correction at 2.3 l0; "lattice" sets s = d n0/(n0 + N), which makes the rate
of a linear velocity field on the initial lattice exactly -n0 div u.
"""

from parmps.config import Key
from parmps.fluid.schemes.khayyer_gotoh import error_compensating_source, number_density_rate

RATE_NORMALISATIONS = ("paper", "lattice")


def rate_scale(normalisation, constants):
    """s of the module docstring for the case's constants."""
    if normalisation == "paper":
        return 1.0
    return constants.dimension * constants.n0 / (constants.n0 + constants.neighbour_count0)


class DensityRateSource:
    KEYS = {"normalisation": Key("str", "paper", choices=RATE_NORMALISATIONS,
                                 doc="\"paper\": rho/(n0 dt) Dn/Dt as published; \"lattice\": "
                                     "times d n0/(n0 + N), exact for a linear velocity field")}

    def __init__(self, settings, constants):
        self.constants = constants
        self.scale = rate_scale(settings["normalisation"], constants)

    def rhs(self, step):
        c = self.constants
        rate = number_density_rate(step.near_indptr, step.near_cols, step.position_star,
                                   step.velocity_star, c.re_number_density, step.n_owned)
        return (self.scale * c.density / (c.n0 * step.dt)) * rate[step.unknown_index]


class CompensatedRateSource(DensityRateSource):
    def rhs(self, step):
        c = self.constants
        index = step.unknown_index
        current_density = step.number_density_at(step.position, c.re_number_density)
        current_rate = number_density_rate(step.indptr, step.cols, step.position,
                                           step.velocity, c.re_number_density, step.n_owned)
        compensation = error_compensating_source(current_density[index],
                                                 self.scale * current_rate[index],
                                                 c.density, c.n0, step.dt)
        return super().rhs(step) + compensation
