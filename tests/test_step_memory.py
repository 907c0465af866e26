"""What a fluid step holds at once: the search's pair list goes before the matrix.

The step's largest allocations are the search's pair list (the Laplacian's radius plus
the skin) and the pressure matrix. The sums at the predicted positions run over sub-lists
cut from the search's list (within the number density's and the Laplacian's radii; one
list when the two radii are the same, as in 3D by default), so the search's list is let go
once the source has read it, before the matrix is assembled, unless the shift reads it
after the correction (docs/performance.md, memory in 3D).
"""

import weakref

import numpy as np
import pytest

from conftest import CASES, NoHalo, OneRank, case_of
from parmps.core import kernels, scene
from parmps.fluid import projection
from parmps.fluid.projection import FluidSolver


class _Quiet:
    """A pressure solver that returns P = 0 and records nothing: the step's lists are the
    subject here, not its answer."""

    index_dtype = np.dtype(np.int64)

    def setup_due(self):
        return True

    def solve(self, owned, other, rhs, guess, step_number, ids):
        return np.zeros(len(rhs)), 0, 0.0


def _one_step(monkeypatch, name, overrides=()):
    """One step of ``name``'s first lattice; returns what the matrix's assembly was given
    and whether the search's list was alive then."""
    case = case_of(CASES / name, *overrides)
    particles, _, _ = scene.build(case)
    fluid = FluidSolver(case, OneRank(), NoHalo(), _Quiet())
    search = {}

    def searched(*args, **kwargs):
        indptr, cols, order = pair_list(*args, **kwargs)
        # The list is a view of the search's buffer: the buffer lives as long as any view.
        search["buffer"] = weakref.ref(cols.base if cols.base is not None else cols)
        search["pairs"] = (indptr, cols.copy())
        return indptr, cols, order

    pair_list = projection.pair_list
    monkeypatch.setattr(projection, "pair_list", searched)
    seen = {}
    rows = fluid.laplacian.rows

    def assembling(indptr, cols, position, *args, **kwargs):
        seen.update(search_alive=search["buffer"]() is not None, indptr=indptr, cols=cols,
                    position=position.copy())
        return rows(indptr, cols, position, *args, **kwargs)

    monkeypatch.setattr(fluid.laplacian, "rows", assembling)
    fluid.step(particles, 1e-3, 0)
    return fluid, seen, search["pairs"], particles.n_owned


@pytest.mark.parametrize("name", ["hydrostatic.toml", "hydrostatic_3d.toml"])
def test_the_matrix_is_assembled_without_the_search_list_over_its_sub_list(monkeypatch, name):
    fluid, seen, (indptr, cols), n = _one_step(monkeypatch, name)
    assert not seen["search_alive"]
    c = fluid.constants
    # The matrix's pairs: those of the search's list within the Laplacian's radius at the
    # predicted positions, in the same order.
    expected_indptr, expected_cols = kernels.pairs_within(indptr, cols, seen["position"],
                                                          c.re_laplacian, n)
    assert np.array_equal(seen["indptr"], expected_indptr)
    assert np.array_equal(seen["cols"], expected_cols)
    # In 32 bits: the sub-list is alive at the step's peak, the solver's set-up.
    assert seen["cols"].dtype == np.int32
    assert len(seen["cols"]) < 0.7 * len(cols)


def test_the_search_list_stays_while_the_shift_reads_it(monkeypatch):
    _, seen, _, _ = _one_step(monkeypatch, "hydrostatic.toml", ['mps.shifting="fickian"'])
    assert seen["search_alive"]
