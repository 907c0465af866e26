"""The constants of the MPS scheme for a case: radii, reference densities, material."""

from dataclasses import dataclass

from parmps.core import lattice
from parmps.core.settings import search_radius


@dataclass(frozen=True)
class MPSConstants:
    """Radii in metres, lattice reference values and the fluid's material
    (docs/design.md §1)."""

    dimension: int
    spacing: float
    re_number_density: float
    re_laplacian: float
    search_radius: float  # re_laplacian plus the skin: the pair list and the halo reach
    n0: float
    n0_laplacian: float
    lambda0: float
    neighbour_count0: int
    density: float
    viscosity: float

    @property
    def laplacian_coefficient(self):
        """2d / (lambda0 n0) of the Laplacian radius."""
        return 2.0 * self.dimension / (self.lambda0 * self.n0_laplacian)

    @classmethod
    def from_case(cls, case):
        spacing = case["particles"]["spacing"]
        mps = case["mps"]
        re_number_density = mps["re_number_density"] * spacing
        re_laplacian = mps["re_laplacian"] * spacing
        dimension = case.get("dimension", 2)
        n0, _ = lattice.reference_values(spacing, re_number_density, dimension)
        n0_laplacian, lambda0 = lattice.reference_values(spacing, re_laplacian, dimension)
        return cls(
            dimension=dimension, spacing=spacing,
            re_number_density=re_number_density, re_laplacian=re_laplacian,
            search_radius=search_radius(case), n0=n0, n0_laplacian=n0_laplacian,
            lambda0=lambda0,
            neighbour_count0=lattice.neighbour_count_reference(spacing, re_number_density,
                                                               dimension),
            density=case["fluid"]["density"], viscosity=case["fluid"]["viscosity"])

