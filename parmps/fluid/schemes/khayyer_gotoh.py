"""Khayyer & Gotoh's stabilised pressure schemes: HS, HL, ECS (docs/schemes.md).

Pair loops in the style of :mod:`parmps.core.pairs` (rows are the owned
particles, columns owned or ghost, distances evaluated on the fly), written for
any dimension d = ``position.shape[1]``, plus thin numpy functions that turn
their sums into pressure-equation terms.

Sign convention: parmps solves ``A p = b`` with ``A = -<lap> + shift`` (symmetric
positive definite), so every ``*_source`` here returns ``b``, the right-hand side
of ``-<lap p>_i = b_i``: positive where the fluid is being compressed.

Sources:

- HS: Khayyer & Gotoh (2009), "Modified moving particle semi-implicit methods
  for the prediction of 2D wave impact pressure", Coastal Engineering 56,
  419-440: the source is the time derivative of the number density taken
  analytically along the particles' (predicted) velocities.
- HL: Khayyer & Gotoh (2010), "A higher order Laplacian model for enhancement
  and stabilization of pressure calculation by the MPS method", Applied Ocean
  Research 32, 124-131: in 2D <lap phi>_i = 1/n0 sum_j phi_ij
  (w''(r_ij) - w'(r_ij)/r_ij), which for w = re/r - 1 is 3 re/(n0 r_ij^3).
- ECS: Khayyer & Gotoh (2011), "Enhancement of stability and accuracy of the
  moving particle semi-implicit method", J. Comput. Phys. 230, 3093-3118.

The equation numbers of these papers could not be checked here; OpenMps
(src/OpenMps/Computer.hpp, MPS_HS/MPS_HL/MPS_ECS) implements the same
formulas and was read alongside.
"""

import numba
import numpy as np

from parmps.core.pairs import pair_component, pair_distance2


@numba.njit(cache=True)
def number_density_rate(indptr, cols, position, velocity, radius, n_rows):
    """Dn_i/Dt = sum_j dw(r_ij)/dr dr_ij/dt = -re sum_j (r_ij . u_ij) / |r_ij|^3.

    The exact time derivative of n_i = sum_j w(r_ij) with w = re/r - 1, at the
    given positions and velocities (r_ij = r_j - r_i, u_ij = u_j - u_i), over
    every neighbour within ``radius`` = re, dummies included: they count in the
    number density (Khayyer & Gotoh 2009, the HS source).
    """
    dimension = position.shape[1]
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            r2 = pair_distance2(position, i, j, dimension)
            if r2 <= 0.0 or r2 >= radius * radius:
                continue
            approach = 0.0
            for k in range(dimension):
                approach += pair_component(position, i, j, k) * (velocity[j, k] - velocity[i, k])
            total += approach / (r2 * np.sqrt(r2))
        out[i] = -radius * total
    return out


@numba.njit(cache=True)
def higher_order_laplacian_sum(indptr, cols, position, field, include, radius, n_rows):
    """sum_j (phi_j - phi_i) re / |r_ij|^3 over neighbours j within ``radius`` with include[j].

    Times the HL coefficient (``higher_order_laplacian_coefficient``) this is
    Khayyer & Gotoh's (2010) higher-order Laplacian of a scalar field; with
    ``include`` = "carries a pressure" it is minus the action of the matrix that
    ``laplacian.poisson_rows(..., inverse_cube=True)`` builds, for rows whose
    neighbours are all unknowns.
    """
    dimension = position.shape[1]
    out = np.zeros(n_rows)
    for i in range(n_rows):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if not include[j]:
                continue
            r2 = pair_distance2(position, i, j, dimension)
            if r2 <= 0.0 or r2 >= radius * radius:
                continue
            total += (field[j] - field[i]) * radius / (r2 * np.sqrt(r2))
        out[i] = total
    return out


def lattice_sums(spacing, radius, dimension=2):
    """Sums over a particle's neighbours on the full square/cubic lattice of spacing l0.

    Returns ``(n0, count, inverse_distance_sum, inverse_cube_sum)``: n0 = sum w,
    count = neighbours within ``radius``, sum re/r (= n0 + count) and sum re/r^3
    (the HL weight; times the coefficient, the diagonal of an interior row).
    """
    reach = int(np.ceil(radius / spacing)) + 1
    axes = [np.arange(-reach, reach + 1) * spacing] * dimension
    offsets = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dimension)
    distance = np.sqrt((offsets ** 2).sum(axis=1))
    distance = distance[(distance > 0.0) & (distance < radius)]
    n0 = float((radius / distance - 1.0).sum())
    return (n0, len(distance), float((radius / distance).sum()),
            float((radius / distance ** 3).sum()))


HL_NORMALISATIONS = ("paper", "projection", "lattice")


def higher_order_laplacian_coefficient(spacing, radius, normalisation="paper", dimension=2):
    """The factor c in <lap phi>_i = c sum_j phi_ij re/|r_ij|^3 (docs/schemes.md, HL).

    - "paper": (5 - d)/n0, Khayyer & Gotoh (2010) in 2D (3/n0) and OpenMps in 2D
      and 3D. On a lattice it is c_q times the true Laplacian of a quadratic
      field, c_q = (5 - d)(n0 + N)/(2 d n0): 2.13 at re = 2.1 l0, 1.86 at 3.1 l0
      (OpenMps issue #30 reports the same 2.126), 1.5 in the continuum limit.
    - "projection": 2/n0. With the HS source and the standard MPS gradient this
      makes the projection consistent on a lattice: the corrected velocities of a
      quadratic pressure field have zero HS rate. Equal to "paper" in 3D only.
    - "lattice": 2d / sum_j re/|r_ij| over the initial lattice, so that the
      operator is exact for quadratic fields on it (the role lambda0 plays in the
      standard Laplacian).

    ``n0`` is the lattice number density at ``radius``.
    """
    n0, _, inverse_distance_sum, _ = lattice_sums(spacing, radius, dimension)
    if normalisation == "paper":
        return (5.0 - dimension) / n0
    if normalisation == "projection":
        return 2.0 / n0
    if normalisation == "lattice":
        return 2.0 * dimension / inverse_distance_sum
    raise ValueError(f"unknown HL normalisation {normalisation!r}; "
                     f"expected one of {', '.join(HL_NORMALISATIONS)}")


def higher_order_source(rate, density, n0, dt):
    """HS right-hand side b_i = rho/(n0 dt) Dn_i/Dt, from ``number_density_rate`` at (r*, u*).

    Khayyer & Gotoh (2009): <lap p>_i = -rho/(n0 dt) (Dn/Dt)*_i, i.e. the
    standard source rho/dt^2 (n* - n0)/n0 with the difference quotient replaced
    by the analytic derivative along the predicted velocities.
    """
    return (density / (n0 * dt)) * np.asarray(rate)


def error_compensating_source(number_density, rate, density, n0, dt):
    """ECS right-hand side, to be added to the HS one (Khayyer & Gotoh 2011).

    With e_i = (n_i^k - n0)/n0 and the rate (Dn/Dt)_i^k, both at the start of
    the step (positions r^k, velocities u^k):

        b_i = |e_i| rho/(n0 dt) (Dn/Dt)_i^k + |dt/n0 (Dn/Dt)_i^k| rho/dt^2 e_i
            = rho/(n0 dt) (|e_i| (Dn/Dt)_i^k + |(Dn/Dt)_i^k| e_i),

    the paper's dynamic coefficients alpha = |e| and beta = |dt/n0 Dn/Dt|. It
    is 2 rho/(n0 dt) |e_i| (Dn/Dt)_i^k where the deviation is growing (same
    signs: more pressure while compressing further, less while expanding
    further) and zero where it is already shrinking, at n = n0 or at a standstill.
    """
    deviation = (np.asarray(number_density) - n0) / n0
    rate = np.asarray(rate)
    return (density / (n0 * dt)) * (np.abs(deviation) * rate + np.abs(rate) * deviation)
