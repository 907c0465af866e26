"""Domain decompositions: distribute, halo, refresh, migration, rebalance, refusals, aborts.

The checks live in tests/mpi/decomposition_worker.py. They run here on one rank
in-process, and under ``mpirun -n 2`` and ``mpirun -n 3 --oversubscribe`` once
per rank count (one job runs every check; each check is reported as its own
test). Every mpirun has a timeout, so a deadlock fails instead of hanging.
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


@pytest.fixture(scope="module", params=[2, 3], ids=lambda n: f"{n}ranks")
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
