"""What a fluid step holds at once: the search's pair list goes before the matrix.

The step's largest allocations are the search's pair list (the Laplacian's radius plus
the skin) and the pressure matrix. The sums at the predicted positions run over sub-lists
cut from the search's list (within the number density's and the Laplacian's radii; one
list when the two radii are the same, as in 3D by default), so the search's list is let go
once the source has read it, before the matrix is assembled, unless the shift reads it
after the correction (docs/performance.md, memory in 3D). And where the step's arrays come
from: the heap, unless the environment's glibc malloc settings say otherwise
(docs/performance.md, "The heap that never shrinks").
"""

import os
import subprocess
import sys
import weakref

import numpy as np
import pytest

from conftest import CASES, NoHalo, OneRank, case_of
from parmps.core.neighbours import pairs_within
from parmps.fluid import projection
from parmps.fluid.projection import FluidSolver
from parmps.geometry import scene


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
    expected_indptr, expected_cols = pairs_within(indptr, cols, seen["position"],
                                                  c.re_laplacian, n)
    assert np.array_equal(seen["indptr"], expected_indptr)
    assert np.array_equal(seen["cols"], expected_cols)
    # In 32 bits: the sub-list is alive at the step's peak, the solver's set-up.
    assert seen["cols"].dtype == np.int32
    assert len(seen["cols"]) < 0.7 * len(cols)


def test_the_search_list_goes_with_the_shift_too(monkeypatch):
    # The shift reads the wider sub-list, cut at the predicted positions.
    _, seen, _, _ = _one_step(monkeypatch, "hydrostatic.toml", ['mps.shifting="fickian"'])
    assert not seen["search_alive"]


# A fresh interpreter: where a large array lives once PETSc's libraries are loaded, before
# the solver's start-up (argument "loaded") or after it ("started"); glibc only (the
# [heap] mapping of /proc/self/maps). One array a process: a block freed into the heap
# would serve the next one from there, mapped or not.
_WHERE_ARRAYS_LIVE = """
import sys
import numpy as np
from parmps.fluid import ppe

petsc4py = ppe.import_petsc4py()
petsc4py.init([])
from petsc4py import PETSc  # its libraries' constructors run here
if sys.argv[1] == "started":
    ppe._petsc()
array = np.ones(8_000_000)  # 64 MB, above the threshold below
for line in open("/proc/self/maps"):
    if line.rstrip().endswith("[heap]"):
        low, high = (int(part, 16) for part in line.split()[0].split("-"))
        if low <= array.ctypes.data < high:
            print("heap")
            break
else:
    print("mapped")
"""


def _where_arrays_live(moment, **environment):
    env = {name: value for name, value in os.environ.items() if not name.startswith("MALLOC_")}
    result = subprocess.run([sys.executable, "-c", _WHERE_ARRAYS_LIVE, moment],
                            capture_output=True, text=True, timeout=120,
                            env=dict(env, **environment))
    assert result.returncode == 0, result.stderr
    return result.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_environments_malloc_settings_hold_once_petsc_is_loaded():
    """Debian's PETSc loads SuperLU_DIST, whose CombBLAS sets glibc's malloc never to map
    a block nor trim the heap, over the environment's settings. The code keeps that (the
    faster step) unless the environment says otherwise: then its settings are applied again
    when the solver starts (docs/performance.md, "The heap that never shrinks")."""
    threshold = {"MALLOC_MMAP_THRESHOLD_": str(32 * 2 ** 20)}
    if _where_arrays_live("loaded", **threshold) == "mapped":
        pytest.skip("this PETSc's libraries leave glibc's malloc as the environment set it")
    assert _where_arrays_live("started", **threshold) == "mapped"
    assert _where_arrays_live("started") == "heap"
