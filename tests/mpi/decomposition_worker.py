"""Checks of the domain decompositions (parmps.parallel), run on every rank of a job.

Usage: mpirun -n N python tests/mpi/decomposition_worker.py checks RESULT.json
       mpirun -n N python tests/mpi/decomposition_worker.py abort

``checks`` runs every check in CHECKS; each one asserts collectively (all ranks
pass or fail together), and rank 0 writes {check name: null or the failure} to
RESULT.json. An unexpected exception aborts the whole job. ``abort`` raises on
the last rank while the others wait in a barrier: the job must end, not hang.

Most checks run once per set-up (``SETUPS``: slabs in 2D, blocks in 2D, blocks
in 3D on synthetic positions) and know a
decomposition only through its interface: ``owner``, ``box``, ``neighbours``.
Their brute-force answers come from the global scene, which every rank holds.

The checks also run on one rank inside pytest (tests/test_decomposition.py).
"""

import json
import sys

import numpy as np
from mpi4py import MPI

from parmps import config, schema
from parmps.parallel import create_decomposition
from parmps.parallel.exchange import by_id_blocks
from parmps.errors import CaseError
from parmps.core.particles import DUMMY, FLUID, WALL, Particles
from parmps.parallel.mpi import abort_on_exception, agree, assert_all

SPACING = 1.0
# The checks' Laplacian radius, set in every case whatever the dimension's default (2.3 l0 in
# 3D): the halo is it plus the default halo_skin.
RE_LAPLACIAN = 3.1
HALO = (RE_LAPLACIAN + 0.6) * SPACING

# name -> (decomposition, dimension, the domain's extent across x (y, and z in 3D)).
# The blocks' domains are square enough for the rank grid to cut y (and z).
SETUPS = {"slabs": ("slabs", 2, 10.0), "blocks": ("blocks", 2, 30.0),
          "blocks3d": ("blocks", 3, 24.0)}


def make_case(lower_x, upper_x, setup="slabs", **parallel):
    """A case whose halo is HALO (any dimension); strict migration (no margin) unless asked."""
    name, dimension, across = SETUPS[setup]
    parallel.setdefault("migration_margin", 0.0)
    parallel["decomposition"] = name
    return schema.validate({
        "domain": {"lower": [lower_x] + [0.0] * (dimension - 1),
                   "upper": [upper_x] + [across] * (dimension - 1)},
        "particles": {"spacing": SPACING},
        "mps": {"re_laplacian": RE_LAPLACIAN},
        "time": {"end": 1.0},
        "parallel": parallel,
    })


def build_decomposition(comm, case):
    return create_decomposition(comm, case, case["parallel"]["decomposition"])


def scene(position, kind=None):
    """A global scene with ids 0..N-1 whose velocity and pressure encode the id."""
    n, d = position.shape
    ids = np.arange(n, dtype=np.int64)
    return Particles({
        "id": ids,
        "kind": np.full(n, FLUID, np.int8) if kind is None else kind,
        "position": position,
        "velocity": _encoded_velocity(ids, d),
        "pressure": ids * 0.25,
    })


def _encoded_velocity(ids, dimension):
    return np.column_stack([ids * (1.0 - 3.0 * k) for k in range(dimension)])


def lattice(nx, ny, x0=0.0):
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    return np.column_stack([x0 + (i.ravel() + 0.5) * SPACING, (j.ravel() + 0.5) * SPACING])


def random_scene(n, x_max, seed=1, setup="slabs"):
    _, dimension, across = SETUPS[setup]
    rng = np.random.default_rng(seed)
    return scene(np.column_stack([rng.uniform(0.0, x_max, n)]
                                 + [rng.uniform(0.0, across, n) for _ in range(dimension - 1)]))


def all_ids(comm, particles):
    """Every rank's owned ids, concatenated in rank order (the same on every rank)."""
    return np.concatenate(comm.allgather(particles.id[:particles.n_owned]))


def check_ownership(comm, decomposition, particles, n_total, what):
    ids = all_ids(comm, particles)
    assert_all(comm, np.array_equal(np.sort(ids), np.arange(n_total)),
               lambda: f"{what}: global ids are not exactly 0..{n_total - 1}: "
                       f"{len(ids)} ids, {len(np.unique(ids))} distinct")
    position = particles.position[:particles.n_owned]
    lo, hi = decomposition.box(comm.rank)
    assert_all(comm, np.all((position >= lo) & (position < hi)),
               lambda: f"{what}: owned positions outside this rank's box [{lo}, {hi})")
    assert_all(comm, np.all(decomposition.owner(position) == comm.rank),
               f"{what}: owner() disagrees with the box")
    own = particles.id[:particles.n_owned]
    assert_all(comm, np.all(np.diff(own) > 0), f"{what}: owned ids not ascending")
    assert_all(comm, np.allclose(particles.velocity[:particles.n_owned],
                                 _encoded_velocity(own, position.shape[1])),
               f"{what}: velocity did not travel with its particle")


# --- the checks ---------------------------------------------------------------------------------

def check_distribute_counts(comm):
    """Known lattices give known per-rank counts and edges between columns."""
    expected = {1: [120], 2: [60, 60], 3: [40, 40, 40]}
    decomposition = create_decomposition(comm, make_case(0.0, 24.0), "slabs")
    mine = decomposition.distribute(scene(lattice(24, 5)))
    if comm.size in expected:
        counts = list(decomposition.counts(mine))
        assert_all(comm, counts == expected[comm.size],
                   f"24x5 lattice: counts {counts}, expected {expected[comm.size]}")
        edges = {1: [], 2: [12.0], 3: [8.0, 16.0]}[comm.size]
        assert_all(comm, np.allclose(decomposition.interior_edges, edges),
                   f"24x5 lattice: edges {decomposition.interior_edges}, expected {edges}")
    check_ownership(comm, decomposition, mine, 120, "24x5 lattice")
    # 25 columns of 4: the edges go to the column gap nearest each quantile.
    expected = {1: [100], 2: [48, 52], 3: [32, 36, 32]}
    decomposition = create_decomposition(comm, make_case(0.0, 25.0), "slabs")
    mine = decomposition.distribute(scene(lattice(25, 4)))
    if comm.size in expected:
        counts = list(decomposition.counts(mine))
        assert_all(comm, counts == expected[comm.size],
                   f"25x4 lattice: counts {counts}, expected {expected[comm.size]}")
    check_ownership(comm, decomposition, mine, 100, "25x4 lattice")


def check_block_counts(comm):
    """A square lattice splits into equal blocks; a 2 x 2 grid on four ranks."""
    for dimension in (2, 3):
        n = 24
        axes = np.meshgrid(*[np.arange(n) + 0.5] * dimension, indexing="ij")
        position = np.column_stack([a.ravel() for a in axes]) * SPACING
        case = make_case(0.0, 24.0, "blocks" if dimension == 2 else "blocks3d")
        case["domain"]["upper"] = [24.0] * dimension
        blocks = build_decomposition(comm, case)
        mine = blocks.distribute(scene(position))
        expected_grid = {1: (1,), 2: (2, 1), 3: (3, 1), 4: (2, 2)}.get(comm.size)
        if expected_grid is not None:
            grid = expected_grid + (1,) * (dimension - len(expected_grid))
            assert_all(comm, blocks.grid == grid, f"{dimension}D: grid {blocks.grid}, "
                                                  f"expected {grid}")
            counts = list(blocks.counts(mine))
            assert_all(comm, counts == [n ** dimension // comm.size] * comm.size,
                       f"{dimension}D {n}^d lattice: counts {counts}")
        check_ownership(comm, blocks, mine, n ** dimension, f"{dimension}D lattice")


def _expected_ghosts(decomposition, global_position, rank):
    """Ghost ids of ``rank`` by brute force: every other rank's particles within the halo
    width of this rank's box, by owner rank, then by id."""
    owner = decomposition.owner(global_position)
    lo, hi = decomposition.box(rank)
    h = decomposition.halo_width
    near = np.all((global_position > lo - h) & (global_position < hi + h), axis=1)
    ids = np.flatnonzero(near & (owner != rank))
    return ids[np.lexsort((ids, owner[ids]))]


def check_halo(comm, setup):
    """Ghosts are exactly the other ranks' particles within the halo width of this rank's
    box (corners included), in a fixed order, and every neighbour within re is there."""
    global_scene = random_scene(1500 * SETUPS[setup][1] ** 2 // 4, 30.0, seed=2, setup=setup)
    # Some particles exactly at the halo distance and on lattice-like repeated x.
    global_scene.position[:40, 0] = np.repeat(np.linspace(5.0, 25.0, 10), 4)
    decomposition = build_decomposition(comm, make_case(0.0, 30.0, setup))
    mine = decomposition.distribute(global_scene)
    halo = decomposition.build_halo(mine)
    n = halo.n_owned
    expected = _expected_ghosts(decomposition, global_scene.position, comm.rank)
    assert_all(comm, n == mine.n_owned and halo.n_ghost == decomposition.n_ghost,
               "build_halo changed n_owned or miscounted ghosts")
    assert_all(comm, np.array_equal(halo.id[n:], expected),
               lambda: f"ghost ids {halo.id[n:][:10]}... ({halo.n_ghost}) != brute force "
                       f"{expected[:10]}... ({len(expected)})")
    for name in ("position", "velocity", "pressure", "kind"):
        assert_all(comm, np.array_equal(halo.arrays[name][n:],
                                        global_scene.arrays[name][halo.id[n:]]),
                   f"ghost field {name} differs from its owner's")
    # Completeness: every particle within re_laplacian of an owned one is here.
    radius = RE_LAPLACIAN * SPACING
    local = set(halo.id.tolist())
    position = global_scene.position
    missing = 0
    for start in range(0, n, 256):
        block = halo.position[start:min(start + 256, n)]
        d2 = ((block[:, None, :] - position[None, :, :]) ** 2).sum(axis=2)
        near = np.unique(np.nonzero(d2 < radius * radius)[1])
        missing += sum(1 for j in near.tolist() if j not in local)
    assert_all(comm, missing == 0, f"{missing} neighbours within re of owned particles "
                                   f"are neither owned nor ghosts")
    # A second build_halo from the halo'd Particles drops the old ghosts first.
    again = decomposition.build_halo(halo)
    assert_all(comm, np.array_equal(again.id, halo.id), "build_halo is not idempotent")
    # Ghosts come from neighbours only; with a cut along two axes some come across a corner.
    owner = decomposition.owner(global_scene.position)
    sources = set(owner[halo.id[n:]].tolist())
    assert_all(comm, sources <= set(decomposition.neighbours),
               f"ghosts from {sorted(sources)}, neighbours {decomposition.neighbours}")
    grid = getattr(decomposition, "grid", (comm.size,))
    if sum(g > 1 for g in grid) >= 2:
        mine_box = np.array(decomposition.box(comm.rank))
        diagonal = [r for r in sources if np.sum(np.any(
            np.array(decomposition.box(r)) != mine_box, axis=0)) >= 2]
        assert_all(comm, len(diagonal) > 0, f"no ghosts across a corner (grid {grid})")


def check_refresh(comm, setup):
    """refresh() copies the owners' current values into the ghosts, in place, any dtype/shape."""
    decomposition = build_decomposition(comm, make_case(0.0, 30.0, setup))
    halo = decomposition.build_halo(decomposition.distribute(
        random_scene(1500, 30.0, seed=3, setup=setup)))
    n, ids = halo.n_owned, halo.id
    total = len(halo)
    values = np.full(total, np.nan)
    rows = np.full(total, -1, np.int64)
    block = np.full((total, 3), np.nan, np.float32)
    small = np.zeros(total, np.int8)
    flags = np.zeros(total, bool)
    pair = np.full((total, 2), np.nan)
    values[:n] = ids[:n] * 1.5 + 1.0
    rows[:n] = ids[:n] + 1000
    block[:n] = np.column_stack([ids[:n], ids[:n] + 1, ids[:n] + 2]).astype(np.float32)
    small[:n] = (ids[:n] % 100).astype(np.int8)
    flags[:n] = ids[:n] % 2 == 1
    pair[:n] = np.column_stack([ids[:n] * 3.0, ids[:n] * 4.0])
    column = pair[:, 1]  # a non-contiguous view, refreshed in place
    returned = decomposition.refresh([values, rows, block, small, flags, column])
    g = ids[n:]
    assert_all(comm, isinstance(returned, list) and returned[0] is values,
               "refresh did not return its argument")
    assert_all(comm, np.array_equal(values[n:], g * 1.5 + 1.0), "float ghosts not refreshed")
    assert_all(comm, np.array_equal(rows[n:], g + 1000), "int64 ghosts not refreshed")
    assert_all(comm, np.array_equal(block[n:], np.column_stack([g, g + 1, g + 2])
                                    .astype(np.float32)), "N x 3 float32 ghosts not refreshed")
    assert_all(comm, np.array_equal(small[n:], (g % 100).astype(np.int8)), "int8 ghosts")
    assert_all(comm, np.array_equal(flags[n:], g % 2 == 1), "bool ghosts not refreshed")
    assert_all(comm, np.array_equal(pair[n:, 1], g * 4.0) and np.all(np.isnan(pair[n:, 0])),
               "a non-contiguous column was not refreshed in place (or touched its neighbour)")
    # A single array and a whole Particles.
    values[n:] = -1.0
    decomposition.refresh(values)
    assert_all(comm, np.array_equal(values[n:], g * 1.5 + 1.0), "single-array refresh")
    halo.position[:n] += 0.125
    halo.pressure[:n] = -halo.id[:n]
    decomposition.refresh(halo)
    owner_x = np.concatenate(comm.allgather(halo.position[:n]))
    owner_id = np.concatenate(comm.allgather(halo.id[:n]))
    lookup = np.empty_like(owner_x)
    lookup[owner_id] = owner_x
    assert_all(comm, np.array_equal(halo.position[n:], lookup[g]), "Particles refresh: position")
    assert_all(comm, np.array_equal(halo.pressure[n:], -g.astype(float)),
               "Particles refresh: pressure")
    # Wrong length is refused.
    failed = False
    try:
        decomposition.refresh([values[:n]])
    except ValueError:
        failed = True
    assert_all(comm, failed or len(g) == 0 and comm.size == 1,
               "refresh accepted an array of the wrong length")


def _moved(position, ids, decomposition, pattern):
    """A deterministic motion of every particle (the same on every rank)."""
    position = position.copy()
    d = position.shape[1]
    lower, upper = decomposition.lower, decomposition.upper
    if pattern == "small":
        step = np.where(ids % 3 == 0, 0.7, np.where(ids % 3 == 1, -0.45, 0.0))
        position += step[:, None] * (1.0 - 0.5 * np.arange(d))
    else:  # jumps over several regions, and particles exactly on the boxes' corners
        span = upper - lower
        mirror = ids % 4 == 0
        position[mirror] = upper + lower - position[mirror]
        position[ids % 4 == 1] += 0.5 * span
        on_corner = np.flatnonzero(ids % 37 == 0)
        for i in on_corner:
            lo, _ = decomposition.box(int(ids[i] % decomposition.size))
            position[i] = np.where(np.isfinite(lo), lo, position[i])
    return position


def check_migrate(comm, setup):
    """Migration keeps every id exactly once and delivers each to its new owner."""
    for pattern in ("small", "far"):
        global_scene = random_scene(2000, 30.0, seed=4, setup=setup)
        decomposition = build_decomposition(comm, make_case(0.0, 30.0, setup))
        mine = decomposition.distribute(global_scene)
        halo = decomposition.build_halo(mine)
        new = _moved(global_scene.position, global_scene.id, decomposition, pattern)
        halo.position[:] = new[halo.id]
        migrated = decomposition.migrate(halo)
        assert_all(comm, migrated.n_ghost == 0, "migrate kept ghosts")
        check_ownership(comm, decomposition, migrated, 2000, f"migrate ({pattern})")
        expected = np.flatnonzero(decomposition.owner(new) == comm.rank)
        assert_all(comm, np.array_equal(migrated.id, expected),
                   f"migrate ({pattern}): owned ids differ from the brute-force owners")
        assert_all(comm, np.array_equal(migrated.position, new[migrated.id]),
                   f"migrate ({pattern}): positions corrupted")


def _boxes(decomposition):
    return np.array([decomposition.box(r) for r in range(decomposition.size)])


def check_rebalance(comm, setup):
    """A skewed load comes back within the tolerance at once; a balanced one is left alone."""
    tolerance = 1.10
    global_scene = random_scene(6000, 60.0, seed=5, setup=setup)
    decomposition = build_decomposition(
        comm, make_case(0.0, 60.0, setup, rebalance_interval=4))
    mine = decomposition.distribute(global_scene)
    mine.position[:, 0] = 60.0 * (mine.position[:, 0] / 60.0) ** 3
    if SETUPS[setup][1] > 2:  # skewed along z too
        mine.position[:, 2] = SETUPS[setup][2] * (mine.position[:, 2] / SETUPS[setup][2]) ** 2
    mine = decomposition.migrate(mine)
    before = decomposition.imbalance(mine)
    if comm.size > 1:
        assert_all(comm, before > 1.5, f"the skewed scene is not imbalanced ({before:.3f})")
    # Over the tolerance: rebalanced even between periodic checks.
    balanced = decomposition.rebalance(decomposition.build_halo(mine), step=6)
    after = decomposition.imbalance(balanced)
    assert_all(comm, balanced.n_ghost == 0, "rebalance returned ghosts")
    assert_all(comm, after <= tolerance, f"imbalance {after:.4f} after rebalancing "
                                         f"(was {before:.3f})")
    assert_all(comm, decomposition.rebalance_count == (1 if comm.size > 1 else 0),
               f"{decomposition.rebalance_count} rebalances, expected one")
    check_ownership(comm, decomposition, balanced, 6000, "rebalance")
    boxes = _boxes(decomposition)
    again = decomposition.rebalance(balanced, step=8)
    assert_all(comm, np.array_equal(boxes, _boxes(decomposition))
               and np.array_equal(again.id, balanced.id), "a balanced load was rebalanced")


def check_extra_work(comm, setup):
    """A rank that carries work beyond its particles (a body's substeps) gets that much less
    particle work at the next rebalance: every rank's load, particles plus extra, within the
    tolerance of the mean; a balanced load with its extra is then left alone."""
    global_scene = random_scene(6000, 60.0, seed=7, setup=setup)
    decomposition = build_decomposition(
        comm, make_case(0.0, 60.0, setup, rebalance_interval=4))
    mine = decomposition.distribute(global_scene)
    # The last rank runs a third of a rank's share of extra work.
    extra = np.zeros(comm.size)
    extra[-1] = 6000 / comm.size / 3
    decomposition.set_extra_work(extra)
    before = decomposition.imbalance(mine)
    mine = decomposition.rebalance(mine, step=6)
    after = decomposition.imbalance(mine)
    assert_all(comm, after <= 1.10, f"imbalance with the extra work {after:.4f} after "
                                    f"rebalancing (was {before:.3f})")
    check_ownership(comm, decomposition, mine, 6000, "rebalance with extra work")
    if comm.size > 1:
        # Its share of all the work less its extra: 2500 of 3000 particles on 2 ranks.
        expected = (6000 + extra[-1]) / comm.size - extra[-1]
        counts = decomposition.counts(mine)
        assert_all(comm, before > 1.1 and abs(counts[-1] - expected) < 0.03 * expected,
                   f"the rank with extra work owns {counts[-1]} particles, expected "
                   f"{expected:.0f} (imbalance before {before:.3f})")
    boxes = _boxes(decomposition)
    again = decomposition.rebalance(mine, step=8)
    assert_all(comm, np.array_equal(boxes, _boxes(decomposition))
               and np.array_equal(again.id, mine.id), "a balanced load was rebalanced")


def check_rebalance_projection(comm, setup):
    """Within the tolerance but drifting: a periodic check rebalances ahead of the crossing."""
    global_scene = random_scene(6000, 60.0, seed=8, setup=setup)
    decomposition = build_decomposition(
        comm, make_case(0.0, 60.0, setup, rebalance_interval=4))
    mine = decomposition.distribute(global_scene)
    mine = decomposition.rebalance(mine, step=4)  # balanced: the drift is measured from here
    assert_all(comm, decomposition.rebalance_count == 0, "a balanced load was rebalanced")
    if comm.size == 1:
        return
    # Move 6 % of the mean load from the last region into the first: imbalance 1.06.
    mean = 6000 // comm.size
    last = np.flatnonzero(decomposition.owner(global_scene.position) == comm.size - 1)
    moved = last[:int(0.06 * mean)]
    here = np.isin(mine.id, moved)
    corner = decomposition.box(0)[1]  # into rank 0's box, within a margin of its corner
    inward = corner[None, :] - 1.0 - 4.0 * mine.id[here, None] / 6000.0
    mine.position[here] = np.where(np.isfinite(corner), inward, mine.position[here])
    mine = decomposition.migrate(mine)
    imbalance = decomposition.imbalance(mine)
    assert_all(comm, abs(imbalance - 1.06) < 1e-9, f"set-up: imbalance {imbalance}")
    boxes = _boxes(decomposition)
    mine = decomposition.rebalance(mine, step=5)  # within tolerance, not periodic: nothing
    assert_all(comm, np.array_equal(boxes, _boxes(decomposition)), "rebalanced within "
                                                                    "tolerance off the interval")
    mine = decomposition.rebalance(mine, step=8)  # 1.06 + 0.06 projected > 1.10: act
    assert_all(comm, decomposition.rebalance_count == 1, "the drift was not anticipated")
    assert_all(comm, decomposition.imbalance(mine) < 1.02, "rebalance left the load uneven")
    check_ownership(comm, decomposition, mine, 6000, "projected rebalance")


def check_sweep(comm, setup):
    """Water moving from one end of a tank to the other stays within 110 % with rebalancing."""
    nx, ny, layers, interval = 120, 24, 4, 5
    tank = lattice(nx + 2 * layers, ny + layers, x0=-layers)
    tank[:, 1] -= layers
    inside = (tank[:, 0] > 0) & (tank[:, 0] < nx) & (tank[:, 1] > 0)
    walls = tank[~inside]
    water = lattice(30, 20, x0=0.0)
    position = np.concatenate([walls, water])
    kind = np.concatenate([np.full(len(walls), WALL, np.int8),
                           np.full(len(water), FLUID, np.int8)])
    kind[:len(walls)][np.abs(walls[:, 0] - nx / 2) > nx / 2 + 2] = DUMMY
    global_scene = scene(position, kind)
    n_total, n_walls = len(position), len(walls)
    decomposition = build_decomposition(
        comm, make_case(-layers, nx + layers, setup, rebalance_interval=interval))
    mine = decomposition.distribute(global_scene)
    worst_checked = worst = 1.0
    for step in range(1, 451):
        halo = decomposition.build_halo(mine)
        owned = halo.id[:halo.n_owned]
        fluid = owned >= n_walls
        # The water block slides right at 0.2 l0 per step until it meets the far wall.
        x0 = (owned[fluid] - n_walls) % 30 + 0.5
        halo.position[:halo.n_owned][fluid, 0] = x0 + min(0.2 * step, nx - 30.0)
        mine = decomposition.migrate(halo)
        mine = decomposition.rebalance(mine, step)
        imbalance = decomposition.imbalance(mine)
        worst = max(worst, imbalance)
        if step % interval == 0:
            worst_checked = max(worst_checked, imbalance)
    check_ownership(comm, decomposition, mine, n_total, "sweep")
    assert_all(comm, worst_checked <= 1.10,
               f"imbalance {worst_checked:.3f} right after a rebalance check")
    assert_all(comm, worst <= 1.10, f"imbalance reached {worst:.3f} between checks")
    if comm.size > 1:
        assert_all(comm, decomposition.rebalance_count > 0, "the sweep never rebalanced")
        assert_all(comm, decomposition.halo_seconds > 0 and decomposition.migration_seconds > 0,
                   "halo/migration timers did not run")


def _errors(comm, action):
    """Run ``action``; return the CaseError message raised on this rank (or None)."""
    try:
        action()
    except CaseError as error:
        return str(error)
    return None


def check_refusals(comm, setup):
    """Too many ranks or too thin regions: the same CaseError on every rank."""
    build = build_decomposition
    # A 5 x 5 domain holds one region of the 3.7-wide halo.
    small = make_case(0.0, 5.0, setup)
    small["domain"]["upper"] = [5.0] * SETUPS[setup][1]
    message = _errors(comm, lambda: build(comm, small))
    messages = comm.allgather(message)
    if comm.size > 1:
        assert_all(comm, message is not None and len(set(messages)) == 1,
                   f"too many ranks: messages {messages}")
        assert_all(comm, "at most 1" in message, f"unclear message: {message}")
    else:
        assert_all(comm, message is None, f"one rank refused: {message}")
    # Room for the slabs, but every particle in one narrow band: interior slabs too thin.
    d = SETUPS[setup][1]
    band = scene(np.column_stack([np.linspace(50.0, 51.0, 3000)] + [np.full(3000, 5.0)] * (d - 1)))
    decomposition = build(comm, make_case(0.0, 100.0, setup))
    message = _errors(comm, lambda: decomposition.distribute(band))
    messages = comm.allgather(message)
    if max(getattr(decomposition, "grid", (comm.size,))) > 2:
        assert_all(comm, message is not None and len(set(messages)) == 1,
                   f"thin slab: messages {messages}")
        assert_all(comm, "thinner than the halo" in message, f"unclear message: {message}")
    else:  # two slabs have no interior slab: nothing is too thin
        assert_all(comm, message is None, f"refused without an interior slab: {message}")
    # After a rebalance: keep the old edges instead (a warning), never fail.
    decomposition = build(comm, make_case(0.0, 100.0, setup, rebalance_interval=1))
    mine = decomposition.distribute(random_scene(3000, 100.0, seed=6, setup=setup))
    boxes = _boxes(decomposition)
    mine.position[:, 0] = 50.0 + mine.id / 3000.0
    mine = decomposition.rebalance(decomposition.migrate(mine), step=1)
    if max(getattr(decomposition, "grid", (comm.size,))) > 2:
        assert_all(comm, np.array_equal(boxes, _boxes(decomposition)),
                   "a rebalance made regions thinner than the halo")
    check_ownership(comm, decomposition, mine, 3000, "refused rebalance")


def check_empty_rank(comm, setup):
    """A rank with no particles still takes part in every collective call."""
    decomposition = build_decomposition(
        comm, make_case(0.0, 30.0, setup, rebalance_interval=1))
    mine = decomposition.distribute(random_scene(600, 30.0, seed=7, setup=setup))
    # Everything moves into the first region's corner: the other ranks end up empty.
    mine.position[:] = 0.01 * mine.id[:, None] / 600.0
    mine = decomposition.migrate(mine)
    halo = decomposition.build_halo(mine)
    decomposition.refresh([halo.pressure, halo.velocity])
    imbalance = decomposition.imbalance(halo)
    assert_all(comm, abs(imbalance - comm.size) < 1e-12, f"imbalance {imbalance}")
    mine = decomposition.rebalance(halo, step=1)  # all x within 0.01: refused, not hung
    check_ownership(comm, decomposition, mine, 600, "empty ranks")


def check_by_id_blocks(comm):
    """Regrouping by id blocks gives one id-sorted array in rank order, for output."""
    global_scene = random_scene(1000, 30.0, seed=9)
    decomposition = build_decomposition(comm, make_case(0.0, 30.0))
    halo = decomposition.build_halo(decomposition.distribute(global_scene))
    block, offset, total = by_id_blocks(halo, comm)
    ids = all_ids(comm, block)
    assert_all(comm, total == 1000 and np.array_equal(ids, np.arange(1000)),
               "id blocks are not the sorted ids 0..N-1 in rank order")
    offsets = comm.allgather(offset)
    counts = comm.allgather(block.n_owned)
    assert_all(comm, offsets == list(np.concatenate([[0], np.cumsum(counts)[:-1]])),
               f"offsets {offsets} do not follow counts {counts}")
    assert_all(comm, np.array_equal(block.position, global_scene.position[block.id])
               and np.array_equal(block.pressure, global_scene.pressure[block.id]),
               "fields did not travel with their ids")
    # Every particle on one rank, some ids missing: still sorted, nothing lost.
    only = halo.select(np.flatnonzero((halo.id[:halo.n_owned] % 7 != 3)))
    everything = Particles.concatenate(comm.allgather(only))
    gathered = everything if comm.rank == 0 else everything.select(np.empty(0, np.int64))
    block, offset, total = by_id_blocks(gathered, comm)
    ids = all_ids(comm, block)
    expected = np.concatenate(comm.allgather(halo.id[:halo.n_owned]))
    expected = np.sort(expected[expected % 7 != 3])
    assert_all(comm, np.array_equal(ids, expected) and total == len(expected),
               "id blocks from one full rank lost or reordered particles")


def check_agree(comm):
    """An error raised on one rank is raised on every rank, same type and message."""
    def fail_on_last():
        if comm.rank == comm.size - 1:
            raise CaseError(f"bad thing seen by rank {comm.rank}")
        return comm.rank
    try:
        agree(comm, fail_on_last)
        message = None
    except CaseError as error:
        message = str(error)
    messages = comm.allgather(message)
    assert_all(comm, messages == [f"bad thing seen by rank {comm.size - 1}"] * comm.size,
               f"agree gave {messages}")
    assert_all(comm, agree(comm, lambda: comm.rank * 2) == comm.rank * 2, "agree's result")
    failed = None
    try:
        assert_all(comm, comm.rank != 0, "rank 0 says no")
    except AssertionError as error:
        failed = str(error)
    assert_all(comm, failed == "rank 0: rank 0 says no", f"assert_all raised {failed!r}")


def check_lazy_migration(comm, setup):
    """With a margin, particles stray up to it before migrating, and the halo stays complete."""
    margin = 0.5
    global_scene = random_scene(2000, 40.0, seed=10, setup=setup)
    decomposition = build_decomposition(
        comm, make_case(0.0, 40.0, setup, migration_margin=margin))
    assert_all(comm, decomposition.halo_width == HALO + margin
               and decomposition.min_width == HALO + 2 * margin, "halo/region widths")
    mine = decomposition.distribute(global_scene)
    position = global_scene.position.copy()
    # Everyone moves by +-0.45 along every axis: some leave their region, none by more
    # than the margin.
    position += np.where(global_scene.id % 2 == 0, 0.45, -0.45)[:, None]
    mine.position[:] = position[mine.id]
    before = mine.id.copy()
    mine = decomposition.migrate(decomposition.build_halo(mine))
    assert_all(comm, np.array_equal(mine.id, before) and decomposition.migration_count == 0,
               "particles within the margin migrated")
    strays = np.count_nonzero(decomposition.owner(mine.position) != comm.rank)
    if comm.size > 1:
        assert_all(comm, comm.allreduce(strays) > 0, "the test moved nobody out of a slab")
    # The halo covers every neighbour of the strays too.
    halo = decomposition.build_halo(mine)
    local = set(halo.id.tolist())
    reach = RE_LAPLACIAN * SPACING
    missing = 0
    for start in range(0, halo.n_owned, 256):
        block = halo.position[start:min(start + 256, halo.n_owned)]
        d2 = ((block[:, None, :] - position[None, :, :]) ** 2).sum(axis=2)
        near = np.unique(np.nonzero(d2 < reach * reach)[1])
        missing += sum(1 for j in near.tolist() if j not in local)
    assert_all(comm, missing == 0, f"{missing} neighbours of owned particles missing")
    # One particle goes past the margin: every stray migrates, ownership is strict again.
    first = int(np.flatnonzero(decomposition.owner(global_scene.position) == 0)[0])
    if comm.size > 1:
        upper = decomposition.box(0)[1]
        axis = int(np.flatnonzero(np.isfinite(upper))[0])
        position[first, axis] = upper[axis] + margin + 0.2
    halo.position[:halo.n_owned] = position[halo.id[:halo.n_owned]]
    mine = decomposition.migrate(halo)
    if comm.size > 1:
        assert_all(comm, decomposition.migration_count == 1, "no migration past the margin")
    check_ownership(comm, decomposition, mine, 2000, "lazy migration")


def check_eager_migration(comm, setup):
    """``eager`` migrates the strays within the margin at once, on every rank when one
    rank asks (the pressure solver asks when its preconditioner is due anyway)."""
    margin = 0.5
    global_scene = random_scene(2000, 40.0, seed=10, setup=setup)
    decomposition = build_decomposition(
        comm, make_case(0.0, 40.0, setup, migration_margin=margin))
    mine = decomposition.distribute(global_scene)
    position = global_scene.position + np.where(global_scene.id % 2 == 0, 0.45, -0.45)[:, None]
    mine.position[:] = position[mine.id]
    mine = decomposition.migrate(decomposition.build_halo(mine), eager=comm.rank == 0)
    if comm.size > 1:
        assert_all(comm, decomposition.migration_count == 1, "eager: no migration")
    assert_all(comm, np.all(decomposition.owner(mine.position) == comm.rank),
               "eager: strays left within the margin")
    check_ownership(comm, decomposition, mine, 2000, "eager migration")


def check_weighted_balance(comm, setup):
    """Regions balance work, not counts: dummies weigh parallel.dummy_weight (0.1) of a
    fluid particle, at the start (exact quantiles) and when rebalancing (histograms)."""
    global_scene = random_scene(4000, 40.0, seed=12, setup=setup)
    x = global_scene.position[:, 0]
    global_scene.kind[:] = np.where(x > 20.0, DUMMY, FLUID)
    decomposition = build_decomposition(comm, make_case(0.0, 40.0, setup, migration_margin=0.5))
    mine = decomposition.distribute(global_scene)
    check_ownership(comm, decomposition, mine, 4000, "weighted distribute")
    if comm.size == 1:
        return
    counts = decomposition.counts(mine)
    imbalance = decomposition.imbalance(mine)
    assert_all(comm, imbalance < 1.05 and counts.max() > 1.5 * counts.min(),
               f"distribute: work imbalance {imbalance:.3f}, counts {list(counts)}")
    # The dummies change sides: the work is uneven until the regions move.
    mine.kind[:] = np.where(mine.position[:, 0] > 20.0, FLUID, DUMMY)
    before = decomposition.imbalance(mine)
    mine = decomposition.rebalance(mine, step=decomposition.rebalance_interval)
    after = decomposition.imbalance(mine)
    assert_all(comm, before > 1.3 and after < 1.05 and decomposition.rebalance_count == 1,
               f"rebalance: work imbalance {before:.3f} -> {after:.3f}")
    check_ownership(comm, decomposition, mine, 4000, "weighted rebalance")


def check_thin_work_falls_back_to_count(comm, setup):
    """Where regions balanced by work would be thinner than the halo (the fluid crowded in
    a strip, dummies everywhere), the start balances by count instead of refusing."""
    rng = np.random.default_rng(13)
    _, dimension, across = SETUPS[setup]

    def uniform(n, lo, hi):
        return np.column_stack([rng.uniform(lo, hi, n)]
                               + [rng.uniform(0.0, across, n) for _ in range(dimension - 1)])

    # 3000 fluid in x < 8, 6000 dummies beyond: by work (3000 + 600) 3 or 4 ranks would cut
    # the strip into pieces under the halo's 3.7; by count its first region is 6 to 8 wide.
    position = np.vstack([uniform(3000, 0.0, 8.0), uniform(6000, 8.0, 80.0)])
    kind = np.concatenate([np.full(3000, FLUID, np.int8), np.full(6000, DUMMY, np.int8)])
    decomposition = build_decomposition(comm, make_case(0.0, 80.0, setup))
    mine = decomposition.distribute(scene(position, kind))
    check_ownership(comm, decomposition, mine, 9000, "count fallback")
    if comm.size >= 3:
        counts = decomposition.counts(mine)
        assert_all(comm, counts.max() < 1.1 * counts.mean(),
                   f"count fallback: counts {list(counts)}")


# Checks of one decomposition through its interface, run for every set-up.
GENERIC = {
    "halo": check_halo,
    "refresh": check_refresh,
    "migrate": check_migrate,
    "lazy_migration": check_lazy_migration,
    "eager_migration": check_eager_migration,
    "weighted_balance": check_weighted_balance,
    "thin_work_falls_back_to_count": check_thin_work_falls_back_to_count,
    "rebalance": check_rebalance,
    "rebalance_projection": check_rebalance_projection,
    "extra_work": check_extra_work,
    "refusals": check_refusals,
    "empty_rank": check_empty_rank,
}
# The sweep's tank is 2D.
SWEEPS = {"slabs:sweep": lambda comm: check_sweep(comm, "slabs"),
          "blocks:sweep": lambda comm: check_sweep(comm, "blocks")}


def _bind(check, setup):
    return lambda comm: check(comm, setup)


CHECKS = {
    "slabs:distribute_counts": check_distribute_counts,
    "blocks:distribute_counts": check_block_counts,
    **{f"{setup}:{name}": _bind(check, setup) for setup in SETUPS
       for name, check in GENERIC.items()},
    **SWEEPS,
    "by_id_blocks": check_by_id_blocks,
    "agree": check_agree,
}


def run_checks(comm, names=None):
    results = {}
    for name in names or CHECKS:
        try:
            CHECKS[name](comm)
            results[name] = None
        except AssertionError as error:  # collective: every rank is here together
            results[name] = str(error) or "assertion failed"
    return results


def main(argv):
    comm = MPI.COMM_WORLD
    with abort_on_exception(comm):
        if argv[1] == "checks":
            results = run_checks(comm, argv[3:] or None)
            if comm.rank == 0:
                with open(argv[2], "w") as handle:
                    json.dump(results, handle)
        elif argv[1] == "abort":
            if comm.rank == comm.size - 1:
                raise ValueError("boom on purpose")
            comm.Barrier()  # would wait for ever without the abort
        else:
            raise SystemExit(f"unknown mode {argv[1]!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
