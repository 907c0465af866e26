"""The mixed source on a still column's lattice: the hydrostatic field solves the rows.

One step of the solver on the still tank's initial lattice (cases/hydrostatic.toml and
cases/hydrostatic_3d.toml, at rest), with a pressure solver that returns P = rho g (H - z),
z the last axis, zero half a spacing above the
top row and linear into the walls, instead of solving: A P - b is each row's residual,
which the density term has to balance with a density error of gamma^-1 dt^2/rho times it.
With the body force's share of u* taken as the flux of the Laplacian's dummy pairs
(``[mps.mixed] body_force = "laplacian"``) the rows beside the floor read zero (the matrix's
compressibility and a pair beyond the two dummy layers left); in the divergence with the
walls at rest (``"divergence"``) the first fluid row reads -0.47 rho g/l0 and the second
wall layer +0.70 (docs/design.md §1.4); in 3D, at its Laplacian radius of 2.3 l0, -0.48 and
+0.90.
"""

import numpy as np
import pytest

from conftest import CASES, NoHalo, OneRank, case_of
from parmps.geometry import scene
from parmps.core.particles import DUMMY, FLUID, WALL
from parmps.fluid.projection import FluidSolver


class _Hydrostatic:
    """Returns the field it is given (one value per particle) in the rows' order and keeps
    the system it was asked to solve."""

    index_dtype = np.dtype(np.int64)

    def __init__(self, field):
        self.field = field
        self.fluid = None

    def setup_due(self):
        return True

    def solve(self, owned, other, rhs, guess, step_number, ids):
        self.system = (*owned, rhs)
        # Row r is the particle row_order.order[r] (the search's cell order).
        self.rows = self.fluid.row_order.order
        self.pressure = self.field[self.rows]
        return self.pressure, 0, 0.0


def _residual(name, body_force):
    case = case_of(CASES / name, 'mps.source="mixed"', f'mps.mixed.body_force="{body_force}"')
    particles, _, _ = scene.build(case)
    kind, position = particles.kind, particles.position
    spacing = case["particles"]["spacing"]
    fluid = kind == FLUID
    surface = position[fluid, -1].max() + 0.5 * spacing
    floor = position[fluid, -1].min() - 0.5 * spacing
    g, density = -case["physics"]["gravity"][-1], case["fluid"]["density"]
    solver = _Hydrostatic(density * g * (surface - position[:, -1]))
    solver.fluid = FluidSolver(case, OneRank(), NoHalo(), solver)
    solver.fluid.step(particles, 1e-3, 0)
    indptr, columns, values, rhs = solver.system
    rows = solver.rows
    assert np.array_equal(np.sort(rows), np.flatnonzero(kind != DUMMY))
    applied = np.add.reduceat(values * solver.pressure[columns], indptr[:-1])
    height = (position[rows, -1] - floor) / spacing
    # Columns three spacings or more inside the side walls: the floor's rows alone.
    low, high = position[fluid, :-1].min(axis=0), position[fluid, :-1].max(axis=0)
    horizontal = position[rows, :-1]
    middle = np.all((horizontal > low + 3 * spacing) & (horizontal < high - 3 * spacing), axis=1)
    return (applied - rhs) / (density * g / spacing), kind[rows], height, middle


# The divergence's residuals in the first fluid row and the second wall layer, at each case's
# default Laplacian radius (3.1 l0 in 2D, 2.3 in 3D).
DIVERGENCE_RESIDUALS = {"hydrostatic.toml": (-0.47, 0.70), "hydrostatic_3d.toml": (-0.48, 0.90)}


@pytest.mark.parametrize("name", ["hydrostatic.toml", "hydrostatic_3d.toml"])
@pytest.mark.parametrize("body_force", ["laplacian", "divergence"])
def test_the_hydrostatic_field_solves_the_rows_beside_the_floor(name, body_force):
    residual, kind, height, middle = _residual(name, body_force)
    first_row = (kind == FLUID) & (height < 1.0) & middle
    deep_wall = (kind == WALL) & (height > -2.0) & (height < -1.0) & middle
    beside_floor = (height < 3.0) & (height > -2.0)
    if body_force == "laplacian":
        assert np.abs(residual[beside_floor]).max() < 0.015
    else:
        first, deep = DIVERGENCE_RESIDUALS[name]
        assert residual[first_row].mean() == pytest.approx(first, abs=0.03)
        assert residual[deep_wall].mean() == pytest.approx(deep, abs=0.03)
