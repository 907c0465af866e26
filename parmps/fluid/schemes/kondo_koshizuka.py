"""Kondo & Koshizuka's (2011) stabilised source term (docs/schemes.md, KK).

Kondo, M. & Koshizuka, S. (2011), "Improvement of stability in moving particle
semi-implicit method", Int. J. Numer. Meth. Fluids 65, 638-654. The paper's
text could not be read here, so its exact equation could not be checked; the
two forms below are the readings docs/schemes.md discusses, both written as
the right-hand side b of parmps's ``-<lap p>_i + (rho c/dt^2) p_i = b_i``
(positive where the fluid is being compressed):

- ``source_term``: a main term from the change of number density over the
  explicit stage, (n*_i - n^k_i)/n0, plus a weak pull back to n0,
  gamma (n^k_i - n0)/n0; both over dt^2. The form as it is usually quoted.
- ``second_difference_source_term``: the main term as the second time
  difference n*_i - 2 n^k_i + n^{k-1}_i, the literal reading of "second time
  derivative of the number density"; it needs n^{k-1}, carried per particle.

n^k is the number density at the start of the step (positions r^k), n* at the
predicted positions, n^{k-1} at the start of the previous step. For a number
density that does not change, both reduce to the standard source with
relaxation gamma: rho/dt^2 gamma (n - n0)/n0.
"""

import numpy as np

from parmps.config import Key
from parmps.fluid.schemes.density import RelaxedSource


def source_term(number_density_current, number_density_predicted, n0, density, dt, relaxation):
    """b_i = rho/dt^2 [(n*_i - n^k_i) + gamma (n^k_i - n0)] / n0."""
    current = np.asarray(number_density_current)
    predicted = np.asarray(number_density_predicted)
    return (density / dt ** 2) * ((predicted - current) + relaxation * (current - n0)) / n0


def second_difference_source_term(number_density_previous, number_density_current,
                                  number_density_predicted, n0, density, dt, relaxation):
    """b_i = rho/dt^2 [(n*_i - 2 n^k_i + n^{k-1}_i) + gamma (n^k_i - n0)] / n0.

    Differs from :func:`source_term` by rho/dt^2 (n^k_i - n^{k-1}_i)/n0: it asks
    the pressure to stop the acceleration of the number density, not its rate.
    """
    previous = np.asarray(number_density_previous)
    current = np.asarray(number_density_current)
    predicted = np.asarray(number_density_predicted)
    return (density / dt ** 2) * ((predicted - 2.0 * current + previous)
                                  + relaxation * (current - n0)) / n0


class DensityAccelerationSource(RelaxedSource):
    """The second-difference reading, registered as ``density_acceleration``.

    n^{k-1} is the number density one step back along the current velocities,
    at r^k - dt u^k: the step moves every fluid particle by exactly dt u^{k}
    (the corrected velocity), so with a constant dt this is the previous step's
    start, and with a changing dt it is still the backward point of a central
    second difference over dt. That needs no state carried between steps, so
    the scheme survives migration and restart unchanged.
    """

    KEYS = {"relaxation": Key("float", 0.01, gt=0.0, le=1.0,
                              doc="gamma of the pull back to n0")}

    def rhs(self, step):
        c = self.constants
        index = step.unknown_index
        current = step.number_density_at(step.position, c.re_number_density)
        previous = step.number_density_at(step.position - step.dt * step.velocity,
                                          c.re_number_density)
        return second_difference_source_term(previous[index], current[index],
                                             step.number_density[index], c.n0, c.density,
                                             step.dt, self.relaxation)
