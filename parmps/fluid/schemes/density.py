"""The number-density source of the original MPS (Koshizuka & Oka 1996; docs/design.md §1.4).

``rhs_i = gamma rho / dt^2 (n*_i - n0) / n0`` with n* the density measure at the
predicted positions and ``gamma`` a relaxation coefficient (below 1: the full
deviation corrected in one step makes the pressure noisy).

The measure is the case's choice, ``[mps.<source>] kernel``:

- ``"smooth"``: sum_j W(r_ij) over the neighbours and the particle itself, W
  Wendland's C2 function on the number density's radius, against its value in
  the lattice. Why: the MPS weight re/r - 1 is singular, so its sum depends on how
  the neighbours are arranged as well as on how many there are. A square lattice
  and a hexagonal one of the same density differ by 1.7 % in n (re = 2.3 l0), and
  a fluid that has lost its initial lattice holds n = n0 only by spreading out:
  the still tank's column rose by 1.1 % (docs/design.md §1.4). The smooth sum reads
  the two lattices within 0.3 % and follows the area a disordered fluid takes.
- ``"mps"``: the MPS number density n (the original scheme).
"""

from parmps.config import Key
from parmps.core import lattice
from parmps.core.density import smooth_density

DENSITY_KERNELS = ("smooth", "mps")


def kernel_key(default):
    return Key("str", default, choices=DENSITY_KERNELS,
               doc="how the density error is measured: \"smooth\" (Wendland C2 sum, self "
                   "included) or \"mps\" (the number density n, weight re/r - 1)")


class RelaxedSource:
    """A source with a pull back to the lattice density of relaxation gamma,
    ``[mps.<name>] relaxation`` (each subclass's KEYS give its default)."""

    def __init__(self, settings, constants):
        self.relaxation = settings["relaxation"]
        self.constants = constants


class MeasuredSource(RelaxedSource):
    """A relaxed source whose density error is measured as ``[mps.<name>] kernel`` says
    (each subclass's KEYS give its default, with :func:`kernel_key`)."""

    def __init__(self, settings, constants):
        super().__init__(settings, constants)
        self.kernel = settings["kernel"]
        if self.kernel == "smooth":
            self.smooth0 = lattice.smooth_reference(constants.spacing,
                                                    constants.re_number_density,
                                                    constants.dimension)

    def density_error(self, step, predicted):
        """(measure - its lattice value) / lattice value of the unknown rows, at the
        predicted positions (``predicted``) or at the start of the step."""
        c = self.constants
        index = step.unknown_index
        if predicted:
            # The sub-list within the number density's radius was cut at the prediction.
            position, indptr, cols = step.position_star, step.near_indptr, step.near_cols
        else:
            position, indptr, cols = step.position, step.indptr, step.cols
        if self.kernel == "smooth":
            measure = smooth_density(indptr, cols, position, c.re_number_density,
                                     step.n_owned)
            return (measure[index] - self.smooth0) / self.smooth0
        number_density = (step.number_density if predicted
                          else step.number_density_at(position, c.re_number_density))
        return (number_density[index] - c.n0) / c.n0


class DensitySource(MeasuredSource):
    KEYS = {"relaxation": Key("float", 0.2, gt=0.0, le=1.0,
                              doc="gamma: fraction of the density deviation corrected per step"),
            "kernel": kernel_key("smooth")}

    def rhs(self, step):
        c = self.constants
        error = self.density_error(step, predicted=True)
        return (c.density / step.dt ** 2) * self.relaxation * error
