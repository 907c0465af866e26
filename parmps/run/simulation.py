"""The time loop: decomposition, fluid steps, checks, diagnostics, output, progress."""

import logging
import math

import numpy as np

from parmps.core import scene
from parmps.run import guards
from parmps.parallel.slabs import SlabDecomposition
from parmps.errors import RunFailure
from parmps.fluid.projection import FluidSolver, check_finite, max_speed
from parmps.io.output import Output
from parmps.core.particles import FLUID, KIND_NAMES
from parmps.run.schedule import Schedule, run_collectively
from parmps.boundaries.walls import MovingWalls

log = logging.getLogger(__name__)


def choose_dt(case, speed, spacing, step):
    """The step length: adaptive (CFL, viscous and dt_max limits) or the case's fixed dt."""
    settings = case["time"]
    nu = case["fluid"]["viscosity"]
    courant_limit = settings["cfl"] * spacing / speed if speed > 0 else math.inf
    if settings["fixed_dt"] > 0:
        dt = settings["fixed_dt"]
        if dt > courant_limit:
            raise RunFailure(
                f"step {step}: the fixed time.fixed_dt = {dt:g} s breaks the Courant limit: "
                f"max speed {speed:.4g} m/s needs dt <= {courant_limit:.4g} s "
                f"(time.cfl = {settings['cfl']:g}); lower time.fixed_dt or set it to 0 "
                f"for adaptive steps")
        return dt
    limits = [settings["dt_max"], courant_limit]
    if nu > 0:
        limits.append(settings["viscous_number"] * spacing ** 2 / nu)
    return min(limits)


class Run:
    """A case set up on a communicator, ready to step."""

    def __init__(self, case, case_text, comm, directory, end_time=None):
        self.case = case
        self.comm = comm
        self.directory = directory
        self.end_time = case["time"]["end"] if end_time is None else end_time
        self.spacing = case["particles"]["spacing"]
        self.decomposition = SlabDecomposition(comm, case)
        # Solids and open boundaries only when the case has them.
        self.coupling = None
        bodies = None
        if case["body"]:
            from parmps.coupling.weak import SolidCoupling, check_body_spacing
            from parmps.solids.mass_spring.body import SolidSystem
            system = SolidSystem.from_case(case)
            check_body_spacing(case, system.bodies)
            self.coupling = SolidCoupling(system, comm)
            bodies = system.bodies
        self.open_boundaries = None
        if case["inlet"] or case["outlet"]:
            from parmps.boundaries.open import OpenBoundaries
            self.open_boundaries = OpenBoundaries(case, comm)
        global_scene, origin, sources = scene.build(case, bodies, self.open_boundaries)
        # Walls with prescribed motion, when the case has any; checked against the
        # domain up to the end time here, on every rank alike, like the scene.
        self.moving_walls = MovingWalls.from_scene(case, global_scene, origin, sources)
        if self.moving_walls is not None:
            self.moving_walls.check_domain(case, global_scene, self.end_time)
            self.moving_walls.set_velocity(global_scene, 0.0)
        self.counts = {KIND_NAMES[k]: int(np.count_nonzero(global_scene.kind == k))
                       for k in KIND_NAMES if np.any(global_scene.kind == k)}
        self.particles = self.decomposition.distribute(global_scene)
        self.fluid = FluidSolver(case, comm, self.decomposition)
        self.case_text = case_text
        self.time = 0.0
        self.step_number = 0

    def summary(self):
        """What --check prints: counts by kind, reference values, first dt, memory."""
        fluid = self.fluid
        total = sum(self.counts.values())
        dt0 = choose_dt(self.case, self._speed(max_speed(self.particles, self.comm)),
                        self.spacing, 0)
        # Pair lists dominate memory: ~(pi re^2 / l0^2) neighbours, 8+8 bytes each,
        # plus the pair geometry (3 doubles) and the matrix (12 bytes per entry).
        neighbours = math.pi * (fluid.search_radius / self.spacing) ** 2
        memory = total * (neighbours * (16 + 24 + 12) + 400)
        return {
            "particles": dict(self.counts, total=total),
            "n0": fluid.n0, "n0_laplacian": fluid.n0_laplacian, "lambda0": fluid.lambda0,
            "initial_dt": dt0, "memory_estimate_mb": memory / 2 ** 20,
            "ranks": self.comm.size,
        }

    def _speed(self, fluid_speed):
        """The speed the next step's dt must respect: fluid, bodies and moving walls."""
        speed = fluid_speed
        if self.coupling is not None:
            speed = max(speed, self.coupling.max_speed())
        if self.moving_walls is not None:
            settings = self.case["time"]
            horizon = settings["fixed_dt"] or settings["dt_max"]
            speed = max(speed, self.moving_walls.speed(self.time, self.time + horizon))
        return speed

    def execute(self, on_step=None):
        """Run to the end time; ``on_step(run)`` is called after every step (benchmarks)."""
        from parmps.fluid.ppe import PressureSolver
        comm = self.comm
        case = self.case
        self.fluid.pressure_solver = PressureSolver(comm, case["pressure"])
        log.info("pressure solver: %s", self.fluid.pressure_solver.describe())
        # imbalance: largest rank's owned particle count over the mean, for each step.
        extra = ("imbalance",)
        if self.open_boundaries is not None:
            extra += ("inflow", "outflow")
        if self.coupling is not None:
            from parmps.run.solid_run import SolidOutput
            output = SolidOutput(comm, self.directory, self.case_text, self.coupling.system,
                                 extra_diagnostics=extra, extra_series=("fluid_inside",))
            for name, count in self.coupling.system.substep_counts(
                    case["time"]["dt_max"]).items():
                log.info("body %s: %d substeps per step of dt_max", name, count)
        else:
            output = Output(comm, self.directory, self.case_text, extra_diagnostics=extra)
        try:
            return run_collectively(comm, output, lambda: self._loop(output, on_step))
        finally:
            self.fluid.pressure_solver.destroy()

    def _loop(self, output, on_step):
        comm = self.comm
        case = self.case
        schedule = Schedule(self.end_time, case["time"]["max_steps"],
                            case["time"]["output_interval"])
        write_frames = case["output"]["frames"]
        if write_frames:
            output.write_frame(0, 0.0, 0.0, self.particles)
        total_particles = comm.allreduce(self.particles.n_owned)
        particle_steps = 0
        timers = self.fluid.timers
        # The largest fluid speed; the check after each step measures it for the next.
        fluid_speed = max_speed(self.particles, comm)
        while schedule.running(self.time, self.step_number):
            step = self.step_number + 1
            dt = schedule.clip(self.time,
                               choose_dt(case, self._speed(fluid_speed), self.spacing, step))
            if self.moving_walls is not None:
                # Before migration: moved wall particles then change owner like any other.
                self.moving_walls.advance(self.particles, self.time, dt)
            timers.start("halo")
            particles = self.decomposition.migrate(self.particles)
            particles = self.decomposition.rebalance(particles, step)
            particles = self.decomposition.build_halo(particles)
            timers.stop()
            if self.coupling is not None:
                self.coupling.predict(particles, dt)
            dirichlet = None
            if self.open_boundaries is not None:
                dirichlet = self.open_boundaries.before_step(particles)
            stats = self.fluid.step(particles, dt, step, dirichlet)
            if self.coupling is not None:
                self.coupling.step(particles, self.fluid, self.decomposition, self.time, dt)
            if self.open_boundaries is not None:
                particles = self.open_boundaries.apply(particles, self.time + dt,
                                                       self.decomposition.owner, dt)
            self.particles = particles
            self.time += dt
            self.step_number = step
            fluid_speed = self._check(particles, dt, step)
            if on_step is not None:
                on_step(self)
            particle_steps += total_particles
            n = particles.n_owned
            fluid = particles.kind[:n] == FLUID
            kinetic = comm.allreduce(0.5 * case["fluid"]["density"] * self.spacing ** 2 *
                                     float((particles.velocity[:n][fluid] ** 2).sum()))
            n_fluid = comm.allreduce(int(np.count_nonzero(fluid)))
            if self.coupling is not None:
                output.add_solid_row(self.time, self.coupling.extra_rows(particles))
            boundary_counts = ({} if self.open_boundaries is None
                               else self.open_boundaries.diagnostics())
            output.add_diagnostics({**boundary_counts,
                "step": step, "time": self.time, "dt": dt,
                "ksp_iterations": stats["ksp_iterations"], "ksp_residual": stats["ksp_residual"],
                "max_speed": fluid_speed, "kinetic_energy": kinetic, "n_fluid": n_fluid,
                "wall_seconds": schedule.elapsed(),
                "imbalance": self.decomposition.imbalance(particles)})
            if schedule.frame_due(self.time):
                timers.start("output")
                if write_frames:
                    output.write_frame(step, self.time, dt, particles)
                else:
                    output.flush_diagnostics()
                timers.stop()
            if schedule.progress_due():
                log.info("step %d  t = %.4g s  dt = %.3g s  ksp %d its  %.3g particle-steps/s  "
                         "%.0f s left", step, self.time, dt, stats["ksp_iterations"],
                         particle_steps / schedule.elapsed(), schedule.seconds_left(self.time))
        elapsed = schedule.elapsed()
        self.elapsed = elapsed
        self.particle_steps = particle_steps
        log.info("done: %d steps to t = %.4g s in %.1f s (%.3g particle-steps/s, %.2f us per "
                 "particle-step)", self.step_number, self.time, elapsed,
                 particle_steps / max(elapsed, 1e-12),
                 1e6 * elapsed / max(particle_steps, 1))

    def _check(self, particles, dt, step):
        """Stop loudly on NaN, a blown-up body, a particle leaving the domain or going
        through a wall, or a Courant breach; returns the largest fluid speed."""
        comm = self.comm
        check_finite(particles, comm, step)
        if self.coupling is not None:
            guards.check_bodies(self.coupling.system.bodies, step, self.time)
        n = particles.n_owned
        lower = np.asarray(self.case["domain"]["lower"])
        upper = np.asarray(self.case["domain"]["upper"])
        position = particles.position[:n]
        outside = np.any((position < lower) | (position > upper), axis=1)
        local = (int(particles.id[:n][outside][0]),) + tuple(position[outside][0]) \
            if np.any(outside) else None
        escaped = [item for item in comm.allgather(local) if item is not None]
        if escaped:
            pid, x, y = min(escaped)
            wall = None if self.moving_walls is None else self.moving_walls.name_of(pid)
            if wall is not None:
                raise RunFailure(f"step {step}: particle {pid} of the moving {wall} left the "
                                 f"domain at ({x:.4g}, {y:.4g}); stop it earlier "
                                 f"({wall}.move_end) or enlarge the domain")
            raise RunFailure(f"step {step}: particle {pid} left the domain at ({x:.4g}, {y:.4g}) "
                             f"(through a wall, or the domain is too small)")
        speed = max_speed(particles, comm)
        courant = speed * dt / self.spacing
        if courant > 1.0:
            raise RunFailure(f"step {step}: Courant number {courant:.3g} > 1 (max fluid speed "
                             f"{speed:.4g} m/s, dt {dt:.3g} s): particles jump more than a "
                             f"spacing per step; the run is unstable")
        # After the Courant check: a particle that jumped into a wall because the
        # step was too long should be reported as the Courant breach it is.
        guards.check_wall_penetration(particles, guards.wall_rectangles(self.case, self.time),
                                      self.spacing, comm, step)
        return speed
