"""Benchmark: the dam break at several sizes and rank counts, one JSON line per run::

    python -m parmps bench [--particles N ...] [--ranks R ...] [--steps S] [--warmup W]
                           [--repeat K] [--set SECTION.KEY=VALUE ...]
    python -m parmps bench --time-to-solution [--spacing L0 ...] [--ranks R ...]
                           [--end-time T] [--set SECTION.KEY=VALUE ...]
    python -m parmps bench --solid-cost [--ranks R ...] [--steps S] [--warmup W]
    python -m parmps bench --periodic-cost [--ranks R ...] [--steps S] [--warmup W]
    python -m parmps bench --setup-cost [--ranks R ...] [--spacing L0]

(``scripts/bench.py`` is the same command.)

Each run builds cases/dam_break.toml at the spacing that gives about N particles
(fluid, walls and dummies), takes W warm-up steps (numba compilation, first
AMG set-ups), then times S steps. It prints particles, ranks, steps, seconds,
us_per_particle_step, a breakdown of seconds by part (the slowest rank's; the
fastest rank's in ``breakdown_fastest``) and max_rss_mb, the peak resident memory
summed over the ranks; ``fluid``, ``rows_per_step`` (the particles with sums of
their own: the fluid and the walls near it, not the dummies or the dry walls; the
mean over the timed steps) and ``us_per_row_step``. A tank's walls are a smaller
share of its particles the finer its spacing, and dry walls cost almost nothing, so
the cost per row-step tells a size's cost apart from its mix of particles.
``--set`` applies case overrides as parmps does (a pressure scheme, say).
``--repeat K`` runs the rank counts in turn K times (A B A B) and ends with one more
line, the speed-up of each rank count over the first: the median over the rounds of
each round's ratio of times, and their range (:func:`paired_speed_up`). These machines
drift by 15 % and more between runs; one pair is not a measurement.
Runs with more ranks than cores oversubscribe, which the line records.

``--scene dam_break_3d`` does the same with SPHERIC's 3D dam break
(cases/dam_break_3d.toml, its tank as it is, probes left out) and adds
``bytes_per_particle`` (max_rss over particles); with ``--time-to-solution`` it
runs that case at 0.55/20 m (``--spacing``) to t = 0.5 s on 1 and 2 ranks against
``TIME_TO_SOLUTION_TARGETS_3D``: half of DualSPHysics 5.4's CPU build on the same
scene, spacing and cores, measured on one of these 2-core machines (846 s on 1 core,
423 s on 2; 48,622 particles, 2,563 steps).

``--solid-cost`` times a still tank of 100k fluid particles (48^3 less the body, l0 = 1 cm)
around a submerged rubber lattice body of 22^3 = 10,648 nodes (``--scene body_3d``) against
the same tank with water in the body's place (``--scene body_3d_fluid``), A B A B on each
rank count, and prints the body's share of the step, ``solid_cost``, against
``SOLID_COST_TARGET`` (10 %). The breakdown's ``other`` is what the fluid's parts leave: the
bodies' substeps, their coupling and the driver.

``--periodic-cost`` times a 3D square duct, 20 l0 across and 60 l0 long (l0 = 1 cm), walls on
four sides, periodic along its axis and driven by a body force (``--scene duct_periodic``),
against the same duct with an inlet buffer at one end and an outlet at the other
(``--scene duct_open``), A B A B on each rank count, and prints periodicity's extra cost per
particle-step, ``periodic_cost``, against ``PERIODIC_COST_TARGET`` (5 %).

``--setup-cost`` times the set-up (the scene built, distributed and checked: each worker line's
``setup_seconds``) of SPHERIC Test 2 from its meshes (``--scene dam_break_3d_meshed``, an open
tank and a closed box read from STL files) against the same scene from boxes, at about a
million particles, A B A B on each rank count, and prints the meshed set-up's extra time,
``setup_cost``, against ``SETUP_COST_TARGET`` (within twice the boxes': 1.0).

``--time-to-solution`` runs cases/dam_break_2d_peer.toml (the 2D dam break of
MPS-Basic's and DualSPHysics's examples) as a user would, ``python -m parmps``
under mpirun, to t = 0.5 s (``--end-time``) at each spacing (5 mm and 2.5 mm by
default) on each rank count (1 and 2), and prints per run: ``wall_seconds``, the
loop's time (the last row of /diagnostics/wall_seconds: start-up and the final
close are not in it), ``steps``, ``us_per_particle_step`` (the loop's time over
particles x steps), ``ksp_iterations`` (their total), ``cpu_seconds`` (user + system
time of the whole job, every rank, start-up included: on a shared machine it moves
less with the load than the wall time; MPI's busy waiting counts in it on 2 ranks),
``load`` (the 1-minute load average at the start), ``target_seconds`` and
``within_target`` for the four runs that have a speed target
(``TIME_TO_SOLUTION_TARGETS``, to t = 0.5 s), and the surge front:

- ``front_m``: the leading edge on the floor at the end time, the largest x of the
  fluid particles whose centres lie within ``FLOOR_BAND`` (20 mm) of the floor,
  plus half a spacing (where the particles' volume ends), measured from the left
  wall (:func:`parmps.tools.analysis.front`). By t = 0.5 s the surge has reached the
  right wall (x = 1 m) and runs up it,
  so ``front_m`` says the water is there; ``front_rms`` is the accuracy figure:
- ``front_rms``: the column is Martin & Moyce's n^2 = 2 (height 2a, a = 0.25 m), so
  the surge front of every frame is compared with their record for
  T = t sqrt(2 g / a) <= 2.8, before the front meets the right wall
  (validation/dam_break's metric, unshifted RMS relative error).
"""

import argparse
import json
import math
import os
import resource
import statistics
import sys
import tempfile
import time

import numpy as np

from parmps.errors import CaseError
from parmps.validation import ROOT

CASE = os.path.join(ROOT, "cases", "dam_break.toml")
PEER_CASE = os.path.join(ROOT, "cases", "dam_break_2d_peer.toml")
SCENES = {"dam_break": CASE, "dam_break_3d": os.path.join(ROOT, "cases", "dam_break_3d.toml"),
          "dam_break_3d_meshed": os.path.join(ROOT, "cases", "dam_break_3d_meshed.toml")}
# The solid's cost (--solid-cost): a still tank FLUID_CELLS particles a side at l0 = 1 cm
# around a submerged lattice body of BODY_NODES^3 nodes (10,648: the 10k-node body in
# a 100k-particle fluid), against the same tank with the body's place filled with water. The
# body is rubber (the elastic gate's E = 12 MPa, rho = 1100 kg/m^3), its volume kept.
FLUID_CELLS, BODY_NODES, BODY_SPACING = 48, 22, 0.01
SOLID_COST_TARGET = 0.10
# Periodicity's cost (--periodic-cost): a 3D square duct DUCT_SECTION cells across and
# DUCT_LENGTH long at l0 = BODY_SPACING, walls on four sides, periodic along x and driven by a
# body force, against the same duct with an inlet and an outlet (the same particles to within
# the inlet's buffer); the cost per particle-step of the first over the second, minus one.
DUCT_SECTION, DUCT_LENGTH = 20, 60
PERIODIC_COST_TARGET = 0.05
# A meshed scene's set-up (--setup-cost): SPHERIC Test 2 from its meshes at about a million
# particles within twice the set-up of the same scene from boxes (target: extra <= 1).
SETUP_PARTICLES = 1_000_000
SETUP_COST_TARGET = 1.0
# The 3D time to solution: 0.55/20 m to t = 0.5 s, half of DualSPHysics's seconds.
SPACINGS_3D = (0.0275,)
TIME_TO_SOLUTION_TARGETS_3D = {(0.0275, 1): 423.0, (0.0275, 2): 211.5}
PEER_SPACINGS = (0.005, 0.0025)
# Fluid within this height of the floor counts for the front (spray above it does not).
FLOOR_BAND = 0.02
# The comparison with Martin & Moyce stops before the front meets the right wall at Z = 4.
FRONT_COMPARE_UNTIL = 2.8
# Speed targets of --time-to-solution, (spacing, ranks) -> loop seconds to t = 0.5 s: half
# of what the main of November 2026 (b2f74f8; density source, minimum gradient, cfl 0.2,
# rtol 1e-8) took on a quiet 2-core AMD EPYC VM: 82, 57, 735 and 407 s. The machine's
# timings drift by +-15 %, and by more under load: compare paired runs (README).
TIME_TO_SOLUTION_TARGETS = {(0.005, 1): 41.0, (0.005, 2): 28.5,
                            (0.0025, 1): 367.5, (0.0025, 2): 203.5}
TARGET_END_TIME = 0.5


def _duct(periodic):
    """The raw case of the periodic-cost scene (see DUCT_SECTION): periodic along x and
    driven by gravity along -x, or open, water entering at the right end through an inlet
    buffer and leaving through the left side, both moving at 0.1 m/s along -x."""
    l0 = BODY_SPACING
    side, length, wall = DUCT_SECTION * l0, DUCT_LENGTH * l0, 4 * l0
    raw = {"title": f"{'periodic' if periodic else 'open'} duct (bench)",
           "domain": {"lower": [0.0, -wall, -wall], "upper": [length, side + wall, side + wall]},
           "particles": {"spacing": l0}, "fluid": {"viscosity": 1e-2},
           "time": {"end": 1.0}}
    walls = []
    for axis in (1, 2):
        for lo, hi in ((-wall, 0.0), (side, side + wall)):
            lower, upper = [0.0, 0.0, 0.0], [length, side, side]
            lower[axis], upper[axis] = lo, hi
            if axis == 1:  # the side walls take the corners
                lower[2], upper[2] = -wall, side + wall
            walls.append({"lower": lower, "upper": upper})
    raw["wall_box"] = walls
    velocity = [-0.1, 0.0, 0.0]
    if periodic:
        raw["domain"]["periodic"] = ["x"]
        raw["physics"] = {"gravity": [-1.0, 0.0, 0.0]}
        raw["fluid_block"] = [{"lower": [0.0, 0.0, 0.0], "upper": [length, side, side],
                               "velocity": velocity}]
        return raw
    raw["physics"] = {"gravity": [0.0, 0.0, 0.0]}
    raw["fluid_block"] = [{"lower": [0.0, 0.0, 0.0], "upper": [length - wall, side, side],
                           "velocity": velocity}]
    raw["inlet"] = [{"lower": [length - wall, 0.0, 0.0], "upper": [length, side, side],
                     "velocity": velocity}]
    raw["outlet"] = [{"side": "left", "velocity": velocity, "buffer": 4}]
    return raw


BUILT_SCENES = {"body_3d": lambda: _submerged_body(True),
                "body_3d_fluid": lambda: _submerged_body(False),
                "duct_periodic": lambda: _duct(True), "duct_open": lambda: _duct(False)}


def spacing_for(target, scene_name="dam_break"):
    """The l0 = a/m (a the case's column width) whose dam-break scene holds closest to
    ``target`` particles."""
    from parmps.geometry import scene
    from parmps.tools import analysis
    if scene_name in BUILT_SCENES:
        # Sized in cells, not by a target count.
        return BODY_SPACING, len(scene.build(_case(None, scene_name=scene_name))[0])
    if scene_name != "dam_break":
        return _spacing_3d(target, scene_name)
    lower, upper = analysis.fluid_extent(_case(None))
    width, height = upper - lower
    # The fluid alone is m x (height/width) m particles; the walls add a few percent,
    # so only the m a little below that count are built and counted.
    fluid_only = max(10, int(math.sqrt(target * width / height)))
    candidates = range(int(0.85 * fluid_only), fluid_only + 1, max(1, fluid_only // 60))
    best = None
    for m in candidates:
        spacing = width / m
        total = len(scene.build(_case(spacing))[0])
        if best is None or abs(total - target) < abs(best[1] - target):
            best = (spacing, total)
    return best


def _spacing_3d(target, scene_name):
    """The spacing whose 3D scene holds about ``target`` particles: the count goes as
    l0^-3, corrected by building the scene twice."""
    from parmps.geometry import scene
    spacing = _case(None, scene_name=scene_name)["particles"]["spacing"]
    total = None
    for _ in range(3):
        total = len(scene.build(_case(spacing, scene_name=scene_name))[0])
        if abs(total - target) < 0.02 * target:
            break
        spacing *= (total / target) ** (1.0 / 3.0)
    return spacing, total


def _submerged_body(with_body):
    """The raw case of the solid-cost scene: a closed still tank, FLUID_CELLS cells a side,
    whose centre holds a BODY_NODES^3-node rubber body (nodes on the fluid's lattice, the
    water in six blocks around it), or the same place filled with a seventh block of water."""
    side, l0 = FLUID_CELLS * BODY_SPACING, BODY_SPACING
    start = (FLUID_CELLS - BODY_NODES) // 2 * l0
    end = start + BODY_NODES * l0
    raw = {"title": "submerged body (bench)",
           "domain": {"lower": [-8 * l0] * 3, "upper": [side + 8 * l0] * 2 + [side + 16 * l0]},
           "particles": {"spacing": l0},
           "time": {"end": 1.0},
           "tank": [{"lower": [0.0] * 3, "upper": [side, side, side + 8 * l0]}]}
    blocks = []
    for axis in range(3):
        # Below and above the body along this axis, over the slab the previous axes left.
        for lo, hi in ((0.0, start), (end, side)):
            lower, upper = [start] * 3, [end] * 3
            lower[axis], upper[axis] = lo, hi
            lower[axis + 1:], upper[axis + 1:] = [0.0] * (2 - axis), [side] * (2 - axis)
            blocks.append({"lower": lower, "upper": upper})
    raw["fluid_block"] = blocks
    if not with_body:
        # Water in the body's place after the water around it, as the body's nodes come
        # after it: the order in memory, which the search and the row sort feel, stays
        # close (one block of water in the whole tank searched 20 % faster).
        blocks.append({"lower": [start] * 3, "upper": [end] * 3})
        return raw
    raw["body"] = [{"name": "body", "nx": BODY_NODES, "ny": BODY_NODES, "nz": BODY_NODES,
                    "spacing": l0, "lower": [start + 0.5 * l0] * 3,
                    "youngs_modulus": 1.2e7, "density": 1100.0, "volume_constraint": True}]
    return raw


def _case(spacing, steps=0, overrides=(), scene_name="dam_break"):
    from parmps import config, schema
    from parmps.geometry.settings import resolve_paths
    if scene_name in BUILT_SCENES:
        raw = BUILT_SCENES[scene_name]()
    else:
        with open(SCENES[scene_name], "rb") as handle:
            raw = config.load_text(handle.read().decode())
        resolve_paths(raw, SCENES[scene_name])  # a meshed scene's files, from its case
    for assignment in overrides:
        config.apply_override(raw, assignment)
    if spacing is not None:
        raw["particles"]["spacing"] = spacing
    if scene_name != "dam_break":
        raw["probe"] = []
        raw["time"]["max_steps"] = steps
        raw.setdefault("output", {})["frames"] = False
        return schema.validate(raw)
    # A tank twice as tall as the column, as the run-up needs for 25 steps, keeps the
    # count mostly fluid (the case's taller walls are for the splash at t > 0.4 s).
    tank, domain = raw["tank"][0], raw["domain"]
    headroom = domain["upper"][1] - tank["upper"][1]
    column = raw["fluid_block"][0]
    tank["upper"][1] = tank["lower"][1] + 2 * (column["upper"][1] - column["lower"][1])
    domain["upper"][1] = tank["upper"][1] + headroom
    raw["time"]["max_steps"] = steps
    raw.setdefault("output", {})["frames"] = False
    return schema.validate(raw)


class _SolveTraffic:
    """What PETSc's own log counts of the pressure solve (its set-ups included): messages
    and bytes a rank sends, and its reductions. Open MPI's monitoring does not see PETSc's
    neighbour exchanges (persistent requests), so the scaling record takes them from here.
    PETSc counts a message when it is sent and again when it is received; half its count
    is what a rank sends (the exchanges are symmetric)."""

    EVENT = "KSPSolve"

    def __init__(self):
        from petsc4py import PETSc
        PETSc.Log.begin()
        self.event = PETSc.Log.Event(self.EVENT)
        self.start = self._now()

    def _now(self):
        info = self.event.getPerfInfo()
        return {"solve_messages": 0.5 * info["numMessages"],
                "solve_bytes": 0.5 * info["messageLength"],
                "solve_reductions": float(info["numReductions"])}

    def mark(self):
        self.start = self._now()

    def since_mark(self):
        now = self._now()
        return {name: now[name] - self.start[name] for name in now}


class _WarmTally:
    """An observer that starts the clock once the warm-up steps are done and counts, over the
    timed steps, this rank's ghost-to-owned ratio, the solve's iterations, the most
    neighbour ranks and the rows of the step (the owned particles with sums of their own:
    neither dummies nor dry walls)."""

    def __init__(self, comm, run, warmup, solve_traffic):
        self.comm, self.run, self.warmup = comm, run, warmup
        self.solve_traffic = solve_traffic
        self.marks = {}
        self.ghost_ratio, self.iterations, self.neighbours, self.rows = 0.0, 0, 0, 0

    def __call__(self, state):
        decomposition = self.run.decomposition
        if state.step > self.warmup:
            particles = state.particles
            self.ghost_ratio += decomposition.n_ghost / max(particles.n_owned, 1)
            self.iterations += int(state.diagnostics.get("ksp_iterations", 0))
            self.neighbours = max(self.neighbours, len(decomposition.neighbours))
            self.rows += rows_of_the_step(particles)
        if state.step == self.warmup:
            self.comm.Barrier()
            self.marks = {"start": time.perf_counter(),
                          "fluid": dict(self.run.fluid.timers.seconds),
                          "halo": decomposition.halo_seconds,
                          "migration": decomposition.migration_seconds,
                          "setups": self.run.pressure_solver.setups}
            self.solve_traffic.mark()

    def breakdown(self, seconds, op="MAX"):
        """Each phase's seconds over the timed steps, the slowest rank's (``op`` "MIN": the
        fastest rank's, which with the slowest's shows where the ranks' work differs)."""
        from mpi4py import MPI
        timers, decomposition, marks = self.run.fluid.timers, self.run.decomposition, self.marks
        parts = {part: timers.seconds[part] - marks["fluid"][part]
                 for part in ("neighbours", "operators", "viscous", "assembly", "solve",
                              "output")}
        parts["halo"] = decomposition.halo_seconds - marks["halo"]
        parts["migration"] = decomposition.migration_seconds - marks["migration"]
        # The rest of the step: the bodies' substeps, the coupling, the driver's phases.
        parts["other"] = max(0.0, seconds - sum(parts.values()))
        return {k: self.comm.allreduce(v, op=getattr(MPI, op)) for k, v in parts.items()}


def rows_of_the_step(particles):
    """The owned particles that had rows in the last step: every one but the dummies and the
    dry walls (docs/performance.md, "Walls away from the water leave the step"). The step's
    work goes with them, so their share of the particles sets the cost per particle-step
    when the walls' share changes with the size."""
    from parmps.core.particles import DUMMY
    n = particles.n_owned
    return int(np.count_nonzero((particles.kind[:n] != DUMMY) & (particles.dry[:n] == 0)))


def worker(args):
    """One timed run on the ranks of COMM_WORLD; rank 0 prints the JSON line."""
    from mpi4py import MPI

    from parmps.core.particles import FLUID
    from parmps.run.observers import Callback
    from parmps.run.simulation import Simulation
    comm = MPI.COMM_WORLD
    solve_traffic = _SolveTraffic()
    spacing = args.spacing[0]
    case = _case(spacing, steps=args.warmup + args.steps, overrides=args.overrides,
                 scene_name=args.scene)
    directory = comm.bcast(tempfile.mkdtemp(prefix="parmps-bench-") if comm.rank == 0 else None)
    comm.Barrier()
    started = time.perf_counter()
    run = Simulation(case, "", comm, directory)
    # The set-up: the scene built (walls and fluid of any shape laid), distributed, checked.
    setup_seconds = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
    tally = _WarmTally(comm, run, args.warmup, solve_traffic)
    run.execute(extra_observers=[Callback(tally)])
    comm.Barrier()
    seconds = time.perf_counter() - tally.marks["start"]
    breakdown = tally.breakdown(seconds)
    fastest = tally.breakdown(seconds, "MIN")
    particles = comm.allreduce(run.state.particles.n_owned)
    owned = run.state.particles.kind[:run.state.particles.n_owned]
    fluid = comm.allreduce(int(np.count_nonzero(owned == FLUID)))
    rows = comm.allreduce(tally.rows) / args.steps
    solve = {name: comm.allreduce(value / args.steps, op=MPI.MAX)
             for name, value in solve_traffic.since_mark().items()}
    ghosts_per_owned = comm.allreduce(tally.ghost_ratio / args.steps, op=MPI.MAX)
    neighbours = comm.allreduce(tally.neighbours, op=MPI.MAX)
    # Peak resident memory of every rank (kB on Linux), summed: the job's footprint.
    memory = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1024.0
    if comm.rank == 0:
        line = {
            "particles": particles, "ranks": comm.size, "steps": args.steps,
            "seconds": round(seconds, 4), "setup_seconds": round(setup_seconds, 3),
            "us_per_particle_step": round(1e6 * seconds / (particles * args.steps), 3),
            "fluid": fluid, "rows_per_step": round(rows),
            "us_per_row_step": round(1e6 * seconds / (max(rows, 1) * args.steps), 3),
            "breakdown": {k: round(v, 4) for k, v in breakdown.items()},
            "breakdown_fastest": {k: round(v, 4) for k, v in fastest.items()},
            "max_rss_mb": round(memory, 1),
            "bytes_per_particle": round(memory * 2 ** 20 / particles),
            "spacing": spacing,
            "decomposition": run.decomposition.name,
            "ghosts_per_owned": round(ghosts_per_owned, 4),
            "neighbours": neighbours,
            "ksp_iterations_per_step": round(tally.iterations / args.steps, 2),
            "amg_setups": run.pressure_solver.setups - tally.marks["setups"],
            **{name: round(value, 1) for name, value in solve.items()},
            "oversubscribed": comm.size > (os.cpu_count() or 1),
        }
        if args.overrides:
            line["set"] = list(args.overrides)
        print(json.dumps(line), flush=True)
        import shutil
        shutil.rmtree(directory, ignore_errors=True)


def time_to_solution(spacing, ranks, end_time, overrides, scene_name="dam_break"):
    """One run of the peer dam break (or of ``scene_name``'s 3D case) to ``end_time``;
    returns its JSON line as a dict."""
    import shutil

    from parmps import open_result
    from parmps.tools import analysis
    from parmps.validation import launch
    out = tempfile.mkdtemp(prefix="parmps-tts-")
    try:
        case_file = PEER_CASE if scene_name == "dam_break" else SCENES[scene_name]
        sets = [f"particles.spacing={spacing!r}"] + list(overrides)
        command = launch.command(case_file, out, sets, petsc=(), ranks=ranks)
        # Exactly the end time asked for (the launcher's own formatting rounds to 6 digits).
        command += ["--end-time", repr(end_time)]
        load = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        status, _, stderr, _ = launch.execute(command, timeout=None, cwd=ROOT, spin=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        line = {"case": os.path.relpath(case_file, ROOT), "spacing": spacing, "ranks": ranks,
                "end_time": end_time, "load": round(load, 2)}
        if status != 0:
            return dict(line, error=stderr.strip().splitlines()[-3:])
        path = os.path.join(out, "result.h5")
        with open_result(path) as result:
            diagnostics = result.diagnostics
            seconds = float(diagnostics["wall_seconds"][-1])
            steps = int(diagnostics["step"][-1])
            iterations = int(diagnostics["ksp_iterations"].sum())
            case = result.case
            last = result.frames[-1]
            particles = len(last)
            if scene_name == "dam_break":
                tank = case["tank"][0]
                line["front_m"] = round(analysis.front(
                    last, tank["lower"][0], spacing, floor=tank["lower"][1], band=FLOOR_BAND), 4)
        line.update({
            "particles": particles, "wall_seconds": round(seconds, 3), "steps": steps,
            "us_per_particle_step": round(1e6 * seconds / (particles * steps), 3),
            "ksp_iterations": iterations,
            "cpu_seconds": round(after.ru_utime + after.ru_stime
                                 - before.ru_utime - before.ru_stime, 1),
            "oversubscribed": ranks > (os.cpu_count() or 1)})
        targets = TIME_TO_SOLUTION_TARGETS_3D
        if scene_name == "dam_break":
            line.update(_front_rms(path, case, end_time))
            targets = TIME_TO_SOLUTION_TARGETS
        target = targets.get((spacing, ranks))
        if target is not None and end_time == TARGET_END_TIME:
            line["target_seconds"] = target
            line["within_target"] = seconds <= target
        if overrides:
            line["set"] = list(overrides)
        return line
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _front_rms(path, case, end_time):
    """The surge front against Martin & Moyce (unshifted RMS) for a run that reaches
    FRONT_COMPARE_UNTIL; nothing for a shorter one."""
    from parmps import validation
    from parmps.tools import analysis
    if end_time * analysis.dam_break_time_scale(case) < FRONT_COMPARE_UNTIL:
        return {}
    dam_break = validation.load("dam_break")
    front = analysis.surge_front_error(
        path, case, dam_break.reference, compare_until=FRONT_COMPARE_UNTIL,
        delay_range=dam_break.metric["delay_range"], delay_step=dam_break.metric["delay_step"])
    return {"front_rms": round(front["rms"], 4)}


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise CaseError(f"bench: {message}")


def _at_least_one(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, not '{text}'")
    return value


def build_parser():
    parser = _Parser(prog="parmps bench", description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, nargs="+", default=[2500, 10000, 40000])
    parser.add_argument("--ranks", type=int, nargs="+",
                        help="rank counts (default 1; 1 2 with --time-to-solution)")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--repeat", type=_at_least_one, default=1,
                        help="run the rank counts in turn this many times (A B A B), then "
                             "print the speed-up over the first rank count: the median of "
                             "the rounds' ratios")
    parser.add_argument("--set", action="append", default=[], dest="overrides",
                        metavar="SECTION.KEY=VALUE", help="a case override, as parmps --set")
    parser.add_argument("--time-to-solution", action="store_true",
                        help="run cases/dam_break_2d_peer.toml to --end-time and print the "
                             "wall time, steps, cost and front of each run")
    parser.add_argument("--spacing", type=float, nargs="+",
                        help="with --time-to-solution: l0 [m] (default 0.005 0.0025); with "
                             "--setup-cost: the one l0 [m] (default: about 1M particles)")
    parser.add_argument("--end-time", type=float, default=0.5,
                        help="with --time-to-solution: simulated seconds (default 0.5)")
    parser.add_argument("--scene", choices=tuple(SCENES) + tuple(BUILT_SCENES),
                        default="dam_break",
                        help="dam_break (2D, the default), dam_break_3d (SPHERIC Test 2), "
                             "dam_break_3d_meshed (the same from meshes), "
                             "body_3d or body_3d_fluid (the --solid-cost pair), "
                             "duct_periodic or duct_open (the --periodic-cost pair)")
    parser.add_argument("--setup-cost", action="store_true",
                        help="SPHERIC Test 2 from its meshes against the same scene from "
                             "boxes at about a million particles (or --spacing), paired A B "
                             "A B: the meshed set-up's extra time against its target "
                             "(within twice the boxes')")
    parser.add_argument("--periodic-cost", action="store_true",
                        help="a 3D duct periodic along its axis against the same duct with "
                             "an inlet and an outlet, paired A B A B; periodicity's cost per "
                             "particle-step against its 5 %% target")
    parser.add_argument("--solid-cost", action="store_true",
                        help="a 10,648-node rubber body in a 100k-particle still tank "
                             "against the tank with water in its place, paired A B A B; "
                             "the body's share of the step against its 10 %% target")
    parser.add_argument("--scaling", action="store_true",
                        help="the scaling record: per rank count (default 1 2 3 4 6 8) the "
                             "messages and bytes per step and rank, ghosts per owned particle, "
                             "CG iterations (parmps.validation.scaling); needs Open MPI")
    parser.add_argument("--project", metavar="RECORD",
                        help="the projected parallel efficiency at 100-10,000 ranks for 10 M "
                             "and 100 M particles from a --scaling record of the 3D scene "
                             "(a file of its JSON lines)")
    parser.add_argument("--cost", type=float,
                        help="with --project: seconds per particle-step on one rank, instead "
                             "of the record's 1-rank line")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    return parser


def main(argv=None):
    """The ``bench`` command; returns the exit status."""
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    if args.worker:
        # Before numpy loads OpenBLAS, for a worker started by hand (cProfile) as for one
        # the launcher starts: a second BLAS thread per rank spins in GAMG's coarse solves.
        from parmps.parallel.mpi import one_blas_thread_per_rank
        one_blas_thread_per_rank(os.environ)
        worker(args)
        return 0
    if args.time_to_solution:
        status = 0
        spacings = PEER_SPACINGS if args.scene == "dam_break" else SPACINGS_3D
        for spacing in args.spacing or spacings:
            for ranks in args.ranks or [1, 2]:
                line = time_to_solution(spacing, ranks, args.end_time, args.overrides,
                                        args.scene)
                status = status or int("error" in line)
                print(json.dumps(line), flush=True)
        return status
    if args.project:
        return _project(args.project, args.cost)
    if args.solid_cost:
        return solid_cost(args)
    if args.periodic_cost:
        return periodic_cost(args)
    if args.setup_cost:
        return setup_cost(args)
    if args.scaling:
        from parmps.validation import scaling
        status = 0
        for target in args.particles:
            spacing, _ = spacing_for(target, args.scene)
            status = status or scaling.record(args, spacing)
        return status
    return sizes(args)


def _project(path, cost=None):
    """Print the model's terms and its projection lines from the record at ``path``."""
    from parmps.core.settings import search_radius
    from parmps.validation import scaling
    try:
        with open(path) as handle:
            lines = [json.loads(text) for text in handle if text.startswith("{")]
        lines = [line for line in lines if "error" not in line]
        case = _case(None, scene_name="dam_break_3d")
        # The halo in spacings: the search reach and both migration margins.
        halo = (search_radius(case) / case["particles"]["spacing"]
                + case["parallel"]["migration_margin"])
        terms, projected = scaling.project(lines, halo, cost=cost)
    except (OSError, ValueError, KeyError) as exc:
        raise CaseError(f"bench --project {path}: {exc}") from None
    print(json.dumps(dict(terms, halo_spacings=round(halo, 3))), flush=True)
    for line in projected:
        print(json.dumps(line), flush=True)
    return 0


def sizes(args):
    """The timed runs of the dam break at each size and rank count, one JSON line each."""
    status = 0
    for target in args.particles:
        spacing, _ = spacing_for(target, args.scene)
        rounds = []
        for _ in range(args.repeat):
            lines = []
            for ranks in args.ranks or [1]:
                line = _timed_run(args, args.scene, spacing, ranks)
                status = status or int("error" in line)
                print(json.dumps(line if "error" not in line else dict(line, particles=target)),
                      flush=True)
                lines.append(line)
            rounds.append(lines)
        if args.repeat > 1 and len(args.ranks or [1]) > 1:
            print(json.dumps(dict(paired_speed_up(rounds), scene=args.scene)), flush=True)
    return status


def paired_speed_up(rounds):
    """The speed-up of each rank count over the first, from runs made in turn: per round
    (one run of each rank count, one after the other) the ratio of their times, and over
    the rounds the median, which a machine whose speed drifts between rounds moves least.
    Rounds with a failed run are left out."""
    ratios = {}
    particles = None
    for lines in rounds:
        if any("error" in line for line in lines):
            continue
        particles = lines[0]["particles"]
        for line in lines[1:]:
            ratios.setdefault(str(line["ranks"]), []).append(
                lines[0]["seconds"] / line["seconds"])
    return {"particles": particles, "base_ranks": rounds[0][0]["ranks"],
            "rounds": len(rounds),
            "speed_up": {ranks: round(statistics.median(values), 3)
                         for ranks, values in ratios.items()},
            "speed_up_range": {ranks: [round(min(values), 3), round(max(values), 3)]
                               for ranks, values in ratios.items()}}


def _timed_run(args, scene_name, spacing, ranks):
    """One worker run of ``scene_name`` on ``ranks`` ranks; its JSON line as a dict."""
    from parmps.parallel.mpi import mpirun_command
    from parmps.validation import launch
    argv = [sys.executable, "-m", "parmps.validation.bench", "--worker", "--spacing",
            repr(spacing), "--steps", str(args.steps), "--warmup", str(args.warmup),
            "--scene", scene_name]
    argv += [word for override in args.overrides for word in ("--set", override)]
    command = mpirun_command(ranks, argv) if ranks > 1 else argv
    code, stdout, stderr, _ = launch.execute(command, timeout=None, cwd=ROOT, spin=True)
    lines = [line for line in stdout.splitlines() if line.startswith("{")]
    if code != 0 or not lines:
        return {"scene": scene_name, "ranks": ranks, "error": stderr.strip().splitlines()[-3:]}
    return json.loads(lines[-1])


def _paired_runs(args, scenes, ranks, figure, spacing=BODY_SPACING):
    """``figure`` of each of ``scenes`` (a pair), run in turn twice (A B A B) on ``ranks``
    ranks, one JSON line per run: {scene: [figure, figure]}, or None when a run failed."""
    found = {scene_name: [] for scene_name in scenes}
    for _ in range(2):
        for scene_name in scenes:
            line = _timed_run(args, scene_name, spacing, ranks)
            print(json.dumps(dict(line, scene=scene_name)), flush=True)
            if "error" in line:
                return None
            found[scene_name].append(line[figure])
    return found


def solid_cost(args):
    """The submerged body's share of the step: the tank with the body and the tank with
    water in its place, paired (A B A B) on each rank count; one JSON line per run, then
    the summary against SOLID_COST_TARGET."""
    status = 0
    for ranks in args.ranks or [1]:
        seconds = _paired_runs(args, ("body_3d_fluid", "body_3d"), ranks, "seconds")
        if seconds is None:
            return 1
        fluid, body = (sum(seconds[name]) for name in ("body_3d_fluid", "body_3d"))
        cost = body / fluid - 1.0
        status = status or int(cost > SOLID_COST_TARGET)
        print(json.dumps({"ranks": ranks, "body_nodes": BODY_NODES ** 3,
                          "fluid_particles": FLUID_CELLS ** 3 - BODY_NODES ** 3,
                          "seconds_water": seconds["body_3d_fluid"],
                          "seconds_body": seconds["body_3d"],
                          "solid_cost": round(cost, 4), "target": SOLID_COST_TARGET,
                          "within_target": cost <= SOLID_COST_TARGET}), flush=True)
    return status


def periodic_cost(args):
    """Periodicity's cost per particle-step: the periodic duct and the open one, paired
    (A B A B) on each rank count; one JSON line per run, then the summary against
    PERIODIC_COST_TARGET."""
    status = 0
    for ranks in args.ranks or [1]:
        cost = _paired_runs(args, ("duct_open", "duct_periodic"), ranks,
                            "us_per_particle_step")
        if cost is None:
            return 1
        ratio = [p / o for p, o in zip(cost["duct_periodic"], cost["duct_open"])]
        extra = statistics.median(ratio) - 1.0
        status = status or int(extra > PERIODIC_COST_TARGET)
        print(json.dumps({"ranks": ranks, "us_open": cost["duct_open"],
                          "us_periodic": cost["duct_periodic"],
                          "periodic_cost": round(extra, 4), "target": PERIODIC_COST_TARGET,
                          "within_target": extra <= PERIODIC_COST_TARGET}), flush=True)
    return status


def setup_cost(args):
    """A meshed scene's set-up against the same scene of boxes: SPHERIC Test 2 built from
    its meshes (cases/dam_break_3d_meshed.toml) and from boxes, at the spacing that gives
    SETUP_PARTICLES (or ``--spacing``), paired (A B A B) on each rank count, one step each;
    one JSON line per run, then the summary against SETUP_COST_TARGET."""
    status = 0
    args.steps, args.warmup = 1, 1  # the timed step needs one before it
    spacing = (args.spacing[0] if args.spacing else
               spacing_for(SETUP_PARTICLES, "dam_break_3d")[0])
    for ranks in args.ranks or [1]:
        seconds = _paired_runs(args, ("dam_break_3d", "dam_break_3d_meshed"), ranks,
                               "setup_seconds", spacing)
        if seconds is None:
            return 1
        ratio = [m / b for m, b in zip(seconds["dam_break_3d_meshed"], seconds["dam_break_3d"])]
        extra = statistics.median(ratio) - 1.0
        status = status or int(extra > SETUP_COST_TARGET)
        print(json.dumps({"ranks": ranks, "spacing": spacing,
                          "seconds_boxes": seconds["dam_break_3d"],
                          "seconds_meshed": seconds["dam_break_3d_meshed"],
                          "setup_cost": round(extra, 4), "target": SETUP_COST_TARGET,
                          "within_target": extra <= SETUP_COST_TARGET}), flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
