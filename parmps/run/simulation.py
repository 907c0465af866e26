"""A case set up on a communicator: its stepper, its state and its observers, ready to run.

:class:`Simulation` builds what the case needs and nothing more: a solid-only
case (bodies and no fluid or wall geometry) gets the solid stepper and never
loads PETSc or the scene; a case with fluid gets the decomposition, the scene,
the MPS step and whichever participants it has (moving walls, bodies and their
coupling, open boundaries).
"""

import logging
import time as wallclock

import numpy as np

from parmps.core.particles import FLUID, KIND_NAMES, Particles
from parmps.core.settings import has_fluid
from parmps.geometry.domain import Domain
from parmps.io.checkpoint import write_checkpoint
from parmps.io.frames import FrameWriter
from parmps.io.result import ResultFile
from parmps.run import observers as observing
from parmps.run.resources import memory_estimate
from parmps.run.driver import DRIVER_DIAGNOSTICS, RunState, advance, run_collectively
from parmps.run.interrupt import Interruption
from parmps.run.schedule import EndCondition
from parmps.run.steppers import FluidStepper, SolidStepper
from parmps.run.timestep import choose_dt
from parmps.solids import solid_model

log = logging.getLogger("parmps.run")


class Simulation:
    """One run of a case: ``summary()`` for ``--check``, ``execute()`` to run it."""

    def __init__(self, case, case_text, comm, directory, end_time=None, solver_options=None,
                 checkpoint=None):
        """``solver_options``: the solvers' options from the command line, solver
        (``"pressure"``, ``"viscous"``) -> name without the prefix -> value (see
        :func:`parmps.fluid.ppe.initialise`).
        ``checkpoint``: a :class:`parmps.io.checkpoint.Checkpoint` to continue from."""
        self.solver_options = dict(solver_options or {})
        self.checkpoint = checkpoint
        self.interruption = Interruption()
        self.result = None
        self.run_observers = []
        self.case = case
        self.case_text = case_text
        self.comm = comm
        self.directory = directory
        self.end_time = case["time"]["end"] if end_time is None else end_time
        self.model = solid_model(case)
        self.coupling = None
        self.wall_traction = None
        self.state = RunState()
        self.pressure_solver = None
        if has_fluid(case) or self.model is None:
            self._set_up_fluid()
        else:
            self.decomposition = None
            self.stepper = SolidStepper(case, comm, self.model)
            self.counts = {"solid node": sum(len(body.position) for body in self.model.bodies)}
            # Rank 0 writes the nodes; the others hold none, of the case's dimension
            # (the frame writer's exchange packs every rank's rows alike).
            self.state.particles = (self.model.node_particles(every_node=True)
                                    if comm.rank == 0 else Particles.empty(case["dimension"]))
        if checkpoint is not None:
            self._restore(checkpoint.state)

    def _restore(self, saved):
        """The run's state as the checkpoint left it; the particles were distributed from
        its global set (the halo and pair lists follow at the first step), and the bodies
        are restored here, before the coupling's first step."""
        self.state.restore_state(saved["run"])
        self.stepper.restore_state(saved["stepper"])
        if self.decomposition is None and self.comm.rank == 0:
            self.state.particles = self.model.node_particles(every_node=True)
        log.info("continuing from the checkpoint at step %d, t = %.6g s (written on %d "
                 "rank(s))", self.state.step, self.state.time, self.checkpoint.ranks)
    def _set_up_fluid(self):
        from parmps.geometry import scene
        from parmps.fluid.projection import FluidSolver
        from parmps.parallel import create_decomposition
        case, comm = self.case, self.comm
        self.decomposition = create_decomposition(comm, case)
        open_boundaries = None
        if case["inlet"] or case["outlet"]:
            from parmps.boundaries.open import OpenBoundaries
            open_boundaries = OpenBoundaries(case, comm)
        global_scene, origin, sources = scene.build(case, self.model, open_boundaries)
        # Walls with prescribed motion, when the case has any; checked against the
        # domain up to the end time here, on every rank alike, like the scene.
        from parmps.boundaries.walls import MovingWalls
        moving_walls = MovingWalls.from_scene(case, global_scene, origin, sources)
        if moving_walls is not None:
            moving_walls.check_domain(case, global_scene, self.end_time)
            moving_walls.set_velocity(global_scene, 0.0)
        self.counts = {KIND_NAMES[k]: int(np.count_nonzero(global_scene.kind == k))
                       for k in KIND_NAMES if np.any(global_scene.kind == k)}
        # A continued run redistributes the checkpoint's particles over this rank count.
        self.state.particles = self.decomposition.distribute(
            global_scene if self.checkpoint is None else self.checkpoint.particles)
        self.decomposition.log_choice()
        self.fluid = FluidSolver(case, comm, self.decomposition)
        if moving_walls is not None:
            moving_walls.fluid = self.fluid
        if self.model is not None:
            from parmps.coupling import coupling_scheme
            self.coupling = coupling_scheme(case, self.model, comm, self.fluid)
        # The viscous force on the walls force probes read, from the step's own velocities:
        # after the fluid step, before an open boundary changes the particle set.
        from parmps.fluid.wall_traction import WallTraction
        self.wall_traction = WallTraction.from_scene(case, global_scene, origin, sources,
                                                     self.fluid, self.end_time)
        # The order is the order of the hooks within a step.
        participants = [p for p in (moving_walls, self.wall_traction, self.coupling,
                                    open_boundaries) if p is not None]
        self.stepper = FluidStepper(case, comm, self.decomposition, self.fluid, participants,
                                    initial_fluid=self.counts.get(KIND_NAMES[FLUID], 0))

    # -- --check ----------------------------------------------------------------------------

    def summary(self):
        """What --check prints: counts by kind, reference values, first dt, memory, bodies."""
        total = sum(self.counts.values())
        self.stepper.start(self.state)
        limits = self.stepper.dt_limits(self.state)
        summary = {"dimension": self.case["dimension"],
                   "particles": dict(self.counts, total=total),
                   "initial_dt": choose_dt(self.case["time"], limits, 1),
                   "dt_limits": dict({"dt_max": self.case["time"]["dt_max"]},
                                     **{limit.name: limit.seconds for limit in limits}),
                   "ranks": self.comm.size}
        if self.decomposition is not None:
            c = self.fluid.constants
            summary.update({"n0": c.n0, "n0_laplacian": c.n0_laplacian,
                            "lambda0": c.lambda0,
                            "radii": {"number_density": c.re_number_density / c.spacing,
                                      "laplacian": c.re_laplacian / c.spacing},
                            "memory_estimate_mb": memory_estimate(self.case) / 2 ** 20})
        if self.model is not None and self.decomposition is None:
            counts = self.model.substep_counts(summary["initial_dt"])
            substeps = self.model.stable_substeps()
            limits = self.model.stability_limits()
            summary["bodies"] = {body.name: {
                "nodes": body.n_nodes, "springs": len(body.springs),
                "area": body.rest_volume, "volume_constraint": body.volume_constraint,
                "stability_limit": limits[body.name],
                "substep": substeps[body.name],
                "substeps_per_step": counts[body.name],
            } for body in self.model.bodies}
        return summary

    # -- the run ----------------------------------------------------------------------------

    def observers(self, result, extra=()):
        """The run's observers, in the order they see each step: ``extra`` first."""
        case = self.case
        interval = case["time"]["output_interval"]
        columns = dict(DRIVER_DIAGNOSTICS, **self.stepper.DIAGNOSTICS)
        writer = FrameWriter(result, case.get("dimension", 2), self.model,
                             Domain.from_case(case))
        found = list(extra) + [observing.Diagnostics(result, columns, interval, self.end_time)]
        if self.model is not None:
            found.append(observing.BodySeries(result, self.model, self.coupling, interval,
                                              self.end_time))
        if case["probe"]:
            from parmps.geometry.walls import probed_walls
            from parmps.probes.observer import Probes
            found.append(Probes(result, case["probe"], case["particles"]["spacing"],
                                self.model, interval, self.end_time, case["body"],
                                case["dimension"],
                                [(box["lower"], box["upper"]) for box in case["wall_box"]],
                                probed_walls(case), Domain.from_case(case),
                                self.wall_traction))
        if case["check"]:
            from parmps.checks import check_observers
            found += check_observers(case, result, self.model, interval, self.end_time)
        if self.decomposition is not None:
            found.append(observing.EnergyWatch(self.comm, interval, self.end_time))
        found += [observing.Frames(writer, interval, self.end_time, case["output"]["frames"]),
                  observing.Progress(self._progress_line)]
        return found

    def _progress_line(self, state):
        rate = state.particle_steps / max(state.elapsed, 1e-12)
        # Extrapolated from the simulated time done so far.
        left = state.elapsed / state.time * (self.end_time - state.time) if state.time else 0.0
        return (f"step {state.step}  t = {state.time:.4g} s  dt = {state.dt:.3g} s  "
                f"{self.stepper.progress(state)}  {rate:.3g} particle-steps/s  "
                f"{left:.0f} s left")

    def execute(self, extra_observers=()):
        """Run to the end time; returns the path of result.h5."""
        comm, case = self.comm, self.case
        if self.decomposition is not None:
            from parmps.fluid.ppe import PressureSolver
            self.pressure_solver = PressureSolver(
                comm, case["pressure"], self.solver_options.get("pressure"),
                dimension=len(case["domain"]["lower"]),
                re_laplacian=case["mps"]["re_laplacian"])
            self.fluid.pressure_solver = self.pressure_solver
            self.fluid.implicit_viscosity.command_line = self.solver_options.get("viscous", {})
            log.info("pressure solver: %s", self.pressure_solver.describe())
        if self.model is not None:
            dt = case["time"]["fixed_dt"] or case["time"]["dt_max"]
            for name, count in self.model.substep_counts(dt).items():
                log.info("body %s: %d substeps of %.3g s per step of %.3g s", name, count,
                         dt / count, dt)
        try:
            result = ResultFile(comm, self.directory, self.case_text,
                                resume=self.checkpoint is not None)
            self.result = result
            observers = self.observers(result, extra_observers)
            if self.checkpoint is not None:
                saved = self.checkpoint.state["observers"]
                for observer in observers:
                    if observer.name is not None and observer.name in saved:
                        observer.restore_state(saved[observer.name])
            # Last: it sees the file as the other observers left it after the step.
            observers.append(observing.Checkpoints(comm, self.write_checkpoint,
                                                   case["output"]["checkpoint_interval"],
                                                   self.interruption))
            self.run_observers = observers
            end = EndCondition(self.end_time, case["time"]["max_steps"])
            with self.interruption.installed():
                path = run_collectively(comm, result, observers, self.state, lambda: advance(
                    comm, self.state, self.stepper, observers, end, case["time"]))
        finally:
            if self.pressure_solver is not None:
                self.pressure_solver.destroy()
                self.fluid.implicit_viscosity.destroy()
        state = self.state
        if state.outcome == "interrupted":
            log.info("stopped at step %d, t = %.4g s after %.1f s", state.step, state.time,
                     state.elapsed)
            return path
        log.info("done: %d steps to t = %.4g s in %.1f s (%.3g particle-steps/s, %.2f us per "
                 "particle-step)%s", state.step, state.time, state.elapsed,
                 state.particle_steps / max(state.elapsed, 1e-12),
                 1e6 * state.elapsed / max(state.particle_steps, 1),
                 self.stepper.summary(state))
        return path

    def write_checkpoint(self, state):
        """Write OUTDIR/checkpoint.h5 from every contributor's state (collective)."""
        start = wallclock.perf_counter()
        saved = {"run": state.checkpoint_state(),
                 "stepper": self.stepper.checkpoint_state(),
                 "observers": {observer.name: observer.checkpoint_state()
                               for observer in self.run_observers if observer.name is not None}}
        # The result file as the checkpoint knows it: a crash after this loses no frame
        # the checkpoint counts on.
        self.result.file.flush()
        size = write_checkpoint(self.comm, self.directory, self.case_text, state.particles,
                                saved)
        log.info("checkpoint at step %d, t = %.6g s: %.3g MB in %.2f s", state.step,
                 state.time, size / 1e6, wallclock.perf_counter() - start)
