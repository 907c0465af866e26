"""Domain decompositions: distribute, halo, refresh, migration, rebalance, refusals, aborts.

The checks live in tests/mpi/decomposition_worker.py. They run here on one rank
in-process, and under ``mpirun -n 2``, ``-n 3`` and ``-n 4`` (oversubscribed)
once per rank count (one job runs every check; each check is reported as its
own test). Every mpirun has a timeout, so a deadlock fails instead of hanging.
"""

import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from parmps.parallel.mpi import run_mpirun

WORKER = Path(__file__).parent / "mpi" / "decomposition_worker.py"
TIMEOUT = 60


def _load_worker():
    spec = importlib.util.spec_from_file_location("decomposition_worker", WORKER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


worker = _load_worker()
CHECK_NAMES = list(worker.CHECKS)


@pytest.mark.parametrize("name", CHECK_NAMES)
def test_one_rank(name):
    from mpi4py import MPI
    if MPI.COMM_WORLD.size != 1:
        pytest.skip("in-process checks run on one rank")
    results = worker.run_checks(MPI.COMM_WORLD, [name])
    assert results[name] is None, results[name]


@pytest.fixture(scope="module", params=[2, 3, 4], ids=lambda n: f"{n}ranks")
def mpi_results(request, tmp_path_factory):
    ranks = request.param
    out = tmp_path_factory.mktemp(f"decomposition{ranks}") / "results.json"
    result = run_mpirun(ranks, [sys.executable, WORKER, "checks", out], timeout=TIMEOUT)
    if result.returncode != 0 or not out.exists():
        pytest.fail(f"mpirun -n {ranks} worker failed with status {result.returncode}:\n"
                    f"{result.stderr[-3000:]}")
    return json.loads(out.read_text())


@pytest.mark.mpi
@pytest.mark.parametrize("name", CHECK_NAMES)
def test_mpi(mpi_results, name):
    assert name in mpi_results, f"check {name} did not run"
    assert mpi_results[name] is None, mpi_results[name]


# On eight ranks the blocks are a 2 x 2 x 2 grid in 3D and 4 x 2 in 2D: every kind of
# neighbour (faces, edges, corners) and three levels of nested cuts. (The slabs' scenes hold
# at most six slabs, and some 2D scenes are sized for four ranks.)
EIGHT_RANK_CHECKS = [f"blocks3d:{name}" for name in ("halo", "refresh", "migrate",
                                                     "lazy_migration", "rebalance_projection",
                                                     "empty_rank")] \
    + [f"blocks:{name}" for name in ("halo", "refresh", "migrate", "lazy_migration")]


@pytest.mark.mpi
def test_blocks_on_eight_ranks(tmp_path):
    out = tmp_path / "results.json"
    result = run_mpirun(8, [sys.executable, WORKER, "checks", out] + EIGHT_RANK_CHECKS,
                        timeout=120)
    assert result.returncode == 0 and out.exists(), result.stderr[-3000:]
    results = json.loads(out.read_text())
    assert sorted(results) == sorted(EIGHT_RANK_CHECKS)
    failed = {name: message for name, message in results.items() if message}
    assert not failed, failed


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_exception_on_one_rank_aborts_the_job(ranks):
    start = time.monotonic()
    result = run_mpirun(ranks, [sys.executable, WORKER, "abort"], timeout=30)
    elapsed = time.monotonic() - start
    assert result.returncode != 0
    assert elapsed < 30
    assert f"rank {ranks - 1}/{ranks}" in result.stderr
    assert "boom on purpose" in result.stderr


def test_a_part_with_extra_work_gets_that_much_less_of_the_particles():
    from parmps.parallel.balance import part_targets
    # 100 units of particle work over 4 parts, the first carrying 20 more: 30 each in all.
    np.testing.assert_allclose(part_targets(100.0, 4, [20.0, 0, 0, 0]), [10.0, 40.0, 70.0])
    # Without extra work (or none given), equal shares.
    np.testing.assert_allclose(part_targets(100.0, 4, np.zeros(4)), [25.0, 50.0, 75.0])
    np.testing.assert_allclose(part_targets(100.0, 4), [25.0, 50.0, 75.0])
    # Extra work beyond the mean: that part takes no particles, the others share them.
    np.testing.assert_allclose(part_targets(100.0, 3, [0.0, 500.0, 0.0]), [50.0, 50.0])


def test_pack_round_trip():
    from parmps.parallel.exchange import pack, unpack_new
    rng = np.random.default_rng(0)
    arrays = [rng.normal(size=7), rng.integers(0, 9, size=(7, 3)).astype(np.int64),
              (rng.normal(size=(7, 2)) > 0), np.arange(7, dtype=np.int8),
              rng.normal(size=(7, 2, 2)).astype(np.float32)]
    index = np.array([5, 0, 3])
    out = unpack_new(pack(arrays, index), arrays)
    for original, copy in zip(arrays, out):
        assert copy.dtype == original.dtype
        np.testing.assert_array_equal(copy, original[index])
    empty = unpack_new(pack(arrays, index[:0]), arrays)
    assert [len(a) for a in empty] == [0] * len(arrays)


# --- the interface, the registry and the choice of decomposition (no MPI job) ----------------

def _case(lower, upper, **parallel):
    """A validated case with the given domain (2D or 3D)."""
    from parmps import schema
    return schema.validate({"domain": {"lower": list(lower), "upper": list(upper)},
                            "particles": {"spacing": 1.0}, "time": {"end": 1.0},
                            "parallel": parallel})


def test_every_registered_decomposition_implements_the_interface():
    from mpi4py import MPI
    from parmps.parallel import DECOMPOSITIONS, create_decomposition, decomposition_class
    from parmps.parallel.base import Decomposition
    assert set(DECOMPOSITIONS) >= {"slabs", "blocks"}
    for name in DECOMPOSITIONS:
        cls = decomposition_class(name)
        assert issubclass(cls, Decomposition) and cls.name == name
        assert not cls.__abstractmethods__, (name, cls.__abstractmethods__)
        for dimension in (2, 3):
            made = create_decomposition(MPI.COMM_WORLD, _case([0.0] * dimension,
                                                              [30.0] * dimension), name)
            assert made.neighbours == [] and made.describe()
            lower, upper = made.box(0)
            assert lower.shape == upper.shape == (dimension,)
            assert np.all(made.owner(np.zeros((5, dimension))) == 0)
            with pytest.raises(ValueError, match="shape"):
                made.owner(np.zeros(5))  # x alone is not a position


def test_a_dry_wall_weighs_as_a_dummy():
    """The balance weighs each particle by its kind's work, and a dry wall (no water within
    two search radii: no pair list, P = 0) as the dummy it then costs as."""
    from mpi4py import MPI
    from parmps.core.particles import DUMMY, FLUID, WALL, Particles
    from parmps.parallel import create_decomposition
    made = create_decomposition(MPI.COMM_WORLD, _case([0.0, 0.0], [30.0, 30.0],
                                                      wall_weight=0.7, dummy_weight=0.2),
                                "slabs")
    kind = np.array([FLUID, WALL, WALL, DUMMY, DUMMY])
    particles = Particles({"id": np.arange(5), "kind": kind, "position": np.zeros((5, 2)),
                           "dry": np.array([0, 0, 1, 0, 1])})
    np.testing.assert_allclose(made.weights(particles), [1.0, 0.7, 0.2, 0.2, 0.2])
    np.testing.assert_allclose(made.loads(particles), [2.3])


@pytest.mark.parametrize("name", ["slabs", "blocks"])
def test_only_a_cut_blind_to_dry_walls_makes_the_first_check_special(name):
    """A scene's particles carry no dry flag: the first load check after their cut
    rebalances above FIRST_CUT_TOLERANCE. A checkpoint's carry the dry flags its cut
    weighed: after it the first check is like any other (the imbalance tolerance)."""
    from mpi4py import MPI
    from parmps.core.particles import FLUID, WALL, Particles
    from parmps.parallel import create_decomposition
    from parmps.parallel.base import FIRST_CUT_TOLERANCE
    excess = 2 * (FIRST_CUT_TOLERANCE - 1.0)
    loads = np.array([1.0 + excess, 1.0 - excess])
    position = np.column_stack([np.linspace(1.0, 29.0, 6), np.full(6, 5.0)])
    for dry, expected in ((np.array([0, 0, 0, 0, 1, 1]), None),
                          (np.zeros(6), "weighed the walls before they were known dry")):
        made = create_decomposition(MPI.COMM_WORLD, _case([0.0, 0.0], [30.0, 30.0]), name)
        assert FIRST_CUT_TOLERANCE < loads.max() / loads.mean() < made.imbalance_tolerance
        scene = Particles({"id": np.arange(6), "kind": np.array([FLUID] * 4 + [WALL] * 2),
                           "position": position, "dry": dry.astype(np.int8)})
        made.distribute(scene)
        reason = made._rebalance_reason(loads, step=1)
        assert (reason is None) if expected is None else (expected in reason), reason
        assert made._rebalance_reason(loads, step=2) is None  # only the first is special


@pytest.mark.parametrize("ranks, lower, upper, expected", [
    (4, [0, 0], [30, 30], (2, 2)),        # square: the balanced grid
    (4, [0, 0], [120, 30], (4, 1)),       # a channel: Dims_create's 2 x 2 would cost more
    (4, [0, 0], [30, 120], (1, 4)),
    (8, [0, 0, 0], [30, 30, 30], (2, 2, 2)),
    (6, [0, 0], [30, 10], (6, 1)),        # 10 m holds two blocks across y, 6 x 1 is cheaper
    (12, [0, 0], [40, 10], (6, 2)),       # 40 m holds only ten slabs
])
def test_the_grid_follows_the_domain(ranks, lower, upper, expected):
    from parmps.parallel.grid import choose_grid
    assert choose_grid(ranks, lower, upper, 3.7, 3.7) == expected


def test_no_grid_fits_more_ranks_than_the_halo_allows():
    from parmps.parallel.grid import choose_grid, factorisations
    assert sorted(factorisations(6, 2)) == [(1, 6), (2, 3), (3, 2), (6, 1)]
    assert len(factorisations(8, 3)) == 10
    assert choose_grid(7, [0, 0], [20, 20], 3.7, 3.7) is None  # 7 is prime, 5 fit per axis
    assert choose_grid(2, [0, 0], [5, 5], 3.7, 3.7) is None


@pytest.mark.parametrize("ranks, upper, expected", [
    (1, [30, 30], "slabs"),
    (2, [30, 30], "slabs"),
    (3, [30, 10], "slabs"),
    (6, [30, 30], "blocks"),               # 3 x 2 saves over a quarter of the ghosts
    (8, [30, 30], "blocks"),               # 30 m holds six slabs
    (8, [30, 30, 30], "blocks"),
])
def test_auto_chooses_and_says_why(ranks, upper, expected):
    from parmps.parallel import choose_decomposition
    name, why = choose_decomposition(ranks, _case([0.0] * len(upper), upper))
    assert name == expected and why


def test_a_grid_that_does_not_fit_is_refused_in_one_line():
    from mpi4py import MPI
    from parmps.errors import CaseError
    from parmps.parallel import create_decomposition
    with pytest.raises(CaseError, match="product must be the rank count"):
        create_decomposition(MPI.COMM_WORLD, _case([0, 0], [30, 30], decomposition="blocks",
                                                   grid=[2, 2]))
    made = create_decomposition(MPI.COMM_WORLD, _case([0, 0], [30, 30],
                                                      decomposition="blocks", grid=[1, 1]))
    assert made.grid == (1, 1)


def test_a_decomposition_is_given_its_domain_halo_and_balance_not_a_case():
    """The decomposition's arguments are objects (the Devito distributor's way): built
    from them alone it cuts as the one the case makes."""
    from mpi4py import MPI
    from parmps.geometry.domain import Domain
    from parmps.parallel import create_decomposition, decomposition_class
    from parmps.parallel.base import Balance, Halo
    case = _case([0.0, 0.0], [30.0, 30.0])
    from_case = create_decomposition(MPI.COMM_WORLD, case, "slabs")
    domain = Domain([0.0, 0.0], [30.0, 30.0])
    halo = Halo(from_case.reach, from_case.margin, from_case.halo_width, from_case.min_width)
    balance = Balance(0.5, 0.25, 20, 1.2)
    made = decomposition_class("slabs")(MPI.COMM_WORLD, domain, halo, balance)
    assert made.halo_width == from_case.halo_width
    np.testing.assert_array_equal(made.box(0)[0], from_case.box(0)[0])
    assert made.rebalance_interval == 20 and made.imbalance_tolerance == 1.2
    from parmps.core.particles import DUMMY, FLUID, WALL
    np.testing.assert_allclose(made.kind_weight[[FLUID, WALL, DUMMY]], [1.0, 0.5, 0.25])
