"""Steppers: what advances a run's state by dt, and the limits their stability puts on dt.

A stepper has ``DIAGNOSTICS`` (its own columns, name -> dtype), ``start(state)``,
``dt_limits(state)`` (a list of :class:`~parmps.run.timestep.Limit`),
``advance(state, dt)`` (from ``state.time``; the step is ``state.step + 1``),
``check(state)`` (after the step: stop loudly if it went wrong; the fluid stepper also
drops the fluid that left the domain, :mod:`parmps.run.escaped`),
``failure_cause(where)`` (a sentence the loop adds to a failure's message, or None),
``diagnostics(state)`` and ``progress(state)`` (a progress line's text), and
``checkpoint_state()`` / ``restore_state(saved)`` for checkpoints.

- :class:`FluidStepper`: one MPS projection step of the particles, with the
  decomposition's update and every participant of the step (moving walls, a
  coupling with bodies, open boundaries: :mod:`parmps.fluid.participant`).
- :class:`SolidStepper`: bodies alone (no fluid, no PETSc): the solid model's
  substeps fill each step.
"""

import logging

import numpy as np

from parmps.core import settings as core_settings
from parmps.core.geometry import outside_box
from parmps.core.particles import FLUID, INFLOW
from parmps.geometry.domain import Domain
from parmps.errors import RunFailure
from parmps.fluid import energy
from parmps.fluid.projection import check_finite, max_speed
from parmps.geometry.walls import MaterialDepth
from parmps.run import guards
from parmps.run.escaped import EscapedFluid
from parmps.run.timestep import Limit

log = logging.getLogger(__name__)

# A rise of the energy budget above its lowest value, over the initial energy, that a failure's
# message names as its likely cause.
ENERGY_RISE = 0.01


class FluidStepper:
    """The particles' MPS step on a decomposition, with the step's participants."""

    DIAGNOSTICS = {"ksp_iterations": np.int64, "ksp_residual": np.float64,
                   # CG iterations of the implicit viscosity's solves (summed over the
                   # velocity components); 0 in a step that took viscosity explicitly
                   "viscous_iterations": np.int64,
                   "max_speed": np.float64, "kinetic_energy": np.float64,
                   # the fluid's potential energy above the initial fluid's lowest point,
                   # and kinetic plus potential [J, per metre of depth in 2D]
                   "potential_energy": np.float64, "fluid_energy": np.float64,
                   # cumulative energy the fluid was given by inlets, outlets, moving walls
                   # and the removal of escaped fluid (negative: taken away) [J]
                   "boundary_work": np.float64,
                   "n_fluid": np.int64,
                   # fluid particles that left the domain and were removed, cumulative
                   "n_escaped": np.int64,
                   # largest rank's owned work over the mean, as the step ran (after
                   # its rebalance)
                   "imbalance": np.float64}

    def __init__(self, case, comm, decomposition, fluid, participants, initial_fluid):
        """``initial_fluid``: the fluid particles at t = 0, the base of
        ``domain.max_escaped_fraction``."""
        self.case = case
        self.comm = comm
        self.decomposition = decomposition
        self.fluid = fluid
        self.participants = list(participants)
        self.spacing = case["particles"]["spacing"]
        # The walls of any shape, for the guard (their meshes read once, here).
        self.shaped_walls = MaterialDepth(case) if case.get("wall") else None
        # What a wall-penetration message names: the source's relaxation, if it has one.
        source = case["mps"]["source"]
        has_relaxation = "relaxation" in case["mps"][source]
        self.source_settings = (f"mps.{source}.relaxation",) if has_relaxation else ()
        self.escaped = EscapedFluid(case, comm, initial_fluid)
        self.DIAGNOSTICS = dict(self.DIAGNOSTICS)
        for participant in self.participants:
            self.DIAGNOSTICS.update(participant.DIAGNOSTICS)
        self.fluid_speed = 0.0
        self.stats = {"ksp_iterations": 0, "ksp_residual": 0.0, "viscous_iterations": 0}
        self.step_imbalance = 1.0
        constants = fluid.constants
        self.particle_mass = constants.density * constants.spacing ** constants.dimension
        # The body force g(t): the step is given its mean over the step (the exact
        # impulse), the energy its value at the diagnostics' time. Along a periodic axis it
        # has no potential: its power on the fluid is integrated instead (the drive).
        self.body_force = core_settings.body_force(case)
        self.periodic = Domain.from_case(case).periodic
        self.gravity = energy.split_body_force(fluid.gravity, self.periodic)[0]
        if self.body_force.varies:
            # The work of a varying body force on the fluid, -sum m dg . (x - datum) over
            # the steps (this rank's share) [J]: the potential energy's explicit change.
            self.DIAGNOSTICS["body_force_work"] = np.float64
        self.field_work = 0.0
        self.energy_datum = None  # set at the first start, kept by checkpoints
        # The fluid's energy after the first step, and the lowest budget (fluid and bodies
        # less the boundaries' work) since: a rise above it is a numerical source.
        self.initial_energy = None
        self.lowest_budget = None
        self.rise_scale = 0.0
        # This rank's share of the energy fluid particles brought in when they joined the
        # fluid (at an inlet) less what they took away (an outlet, escaped fluid), and of
        # the work of the body force along the periodic axes [J].
        self.exchanged_energy = 0.0

    def checkpoint_state(self):
        """Every participant's state, by its name, and the escaped fluid's count (collective)."""
        saved = {p.name: p.checkpoint_state() for p in self.participants if p.name is not None}
        saved[self.escaped.name] = self.escaped.checkpoint_state()
        saved["energy"] = {"datum": np.asarray(self.energy_datum, dtype=float),
                           "exchanged": self.comm.allreduce(self.exchanged_energy),
                           "field_work": self.comm.allreduce(self.field_work),
                           "initial": np.nan if self.initial_energy is None
                           else self.initial_energy,
                           "lowest": np.nan if self.lowest_budget is None
                           else self.lowest_budget}
        return saved

    def restore_state(self, saved):
        for participant in self.participants:
            if participant.name is not None:
                # A checkpoint written before a participant kept state has none of it.
                participant.restore_state(saved.get(participant.name, {}))
        # A checkpoint written before the count existed had removed none.
        self.escaped.restore_state(saved.get(self.escaped.name, {"total": 0}))
        # A checkpoint written before the energy existed: the datum is taken at start.
        if "energy" in saved:
            self.energy_datum = np.asarray(saved["energy"]["datum"], dtype=float)
            # One rank carries the total so far; the sum over the ranks is the total.
            self.exchanged_energy = (float(saved["energy"]["exchanged"])
                                     if self.comm.rank == 0 else 0.0)
            self.field_work = (float(saved["energy"].get("field_work", 0.0))
                               if self.comm.rank == 0 else 0.0)
            if not np.isnan(saved["energy"]["initial"]):
                self.initial_energy = float(saved["energy"]["initial"])
                self.lowest_budget = float(saved["energy"]["lowest"])
                # The next diagnostics row brings the work done so far into it.
                self.rise_scale = abs(self.initial_energy)

    def start(self, state):
        # The largest fluid speed; the check after each step measures it for the next.
        self.fluid_speed = max_speed(state.particles, self.comm)
        self._set_gravity(state.time)
        if self.energy_datum is None:
            self.energy_datum = energy.energy_datum(state.particles, self.gravity, self.comm)
        # The walls away from the water weigh as dummies in the balance from the first
        # step's cut on (the first update rebalances when they move the load past
        # parallel.base.FIRST_CUT_TOLERANCE).
        particles = self.decomposition.build_halo(state.particles.owned())
        self.fluid.mark_dry(particles)
        state.particles = particles

    def speed(self, time):
        """The speed the next step's dt must respect: the fluid's and every participant's."""
        settings = self.case["time"]
        horizon = settings["fixed_dt"] or settings["dt_max"]
        return max([self.fluid_speed] + [participant.speed(time, time + horizon)
                                         for participant in self.participants])

    def dt_limits(self, state):
        settings = self.case["time"]
        limits = []
        speed = self.speed(state.time)
        if speed > 0:
            limits.append(Limit("Courant", settings["cfl"] * self.spacing / speed,
                                f"max speed {speed:.4g} m/s needs dt <= "
                                f"{settings['cfl'] * self.spacing / speed:.4g} s "
                                f"(time.cfl = {settings['cfl']:g})"))
        viscosity = self.fluid.constants.viscosity
        # Under mps.viscosity_scheme "auto" a step beyond the viscous limit takes the
        # viscous term implicitly (FluidSolver.viscosity_implicit): the limit limits nothing.
        if viscosity > 0 and self.fluid.viscosity_scheme == "explicit":
            seconds = self.fluid.viscous_limit
            limits.append(Limit("viscous", seconds,
                                f"fluid.viscosity = {viscosity:g} m^2/s needs dt <= "
                                f"time.viscous_number x spacing^2 / viscosity = {seconds:.4g} s"))
        return limits

    def advance(self, state, dt):
        step = state.step + 1
        time = state.time
        particles = state.particles
        for participant in self.participants:
            participant.before_exchange(particles, time, dt)
        self._count_extra_work(dt)
        timers = self.fluid.timers
        timers.start("halo")
        particles = self.decomposition.update(particles, step,
                                              eager=self.fluid.rows_may_move())
        self.step_imbalance = self.decomposition.imbalance(particles)
        timers.stop()
        dirichlet = None
        for participant in self.participants:
            mask = participant.before_pressure(particles, time, dt)
            if mask is not None:
                dirichlet = mask if dirichlet is None else dirichlet | mask
        mobility = None
        for participant in self.participants:
            given = participant.pressure_mobility(particles)
            if given is not None:
                mobility = given if mobility is None else mobility * given
        if self.body_force.varies:
            before = self._first_moment(particles)
            self.fluid.gravity = self.body_force.mean(time, time + dt)
        drive = energy.split_body_force(self.fluid.gravity, self.periodic)[1]
        power = self._drive_power(particles, drive)
        buffers = self._buffer_velocities(particles)
        self.stats = self.fluid.step(particles, dt, step, dirichlet, mobility)
        self.exchanged_energy += self._buffer_work(particles, buffers, dt)
        # The drive's work: the trapezoidal rule over the step, as the velocities change.
        self.exchanged_energy += 0.5 * dt * (power + self._drive_power(particles, drive))
        if self.body_force.varies:
            # The same fluid, before and after its step: the field's change times the
            # fluid's mean first moment over the step.
            moment = 0.5 * (before + self._first_moment(particles))
            self._set_gravity(time + dt)
            self.field_work -= float((self.gravity - self._last_gravity) @ moment)
        for participant in self.participants:
            if participant.exchanges_fluid:
                before = sum(self._fluid_energy(particles))
            particles = participant.after_fluid(particles, time, dt, self.decomposition)
            if participant.exchanges_fluid:
                self.exchanged_energy += sum(self._fluid_energy(particles)) - before
        state.particles = particles

    def _set_gravity(self, time):
        """The body force the energy is measured with: g(time)."""
        if self.body_force.varies:
            self._last_gravity = self.gravity
            self.gravity = energy.split_body_force(self.body_force.value(time),
                                                   self.periodic)[0]

    @staticmethod
    def _buffer_velocities(particles):
        """(rows, velocities) of this rank's owned inflow and outflow buffer particles at the
        start of a step: the velocities their prescribed motion gives them for the step."""
        n = particles.n_owned
        rows = np.flatnonzero(particles.kind[:n] == INFLOW)
        return rows, particles.velocity[rows].copy()

    def _buffer_work(self, particles, buffers, dt):
        """This rank's work the buffers (pistons of a set speed) did on the fluid in a step:
        minus the fluid's force on them, ``m (du/dt - g)`` from the velocity change the step
        gave them (they move like fluid in it; their prescribed motion resets them after),
        times the velocity they move at, ``u``. Their loss of mechanical energy would add
        ``-m du^2 / 2``, which is no work (a piston's speed does not change in the step): it
        is large where the buffer's pressure gradient is large against its speed, at the
        start of a ramp (docs/history.md). The fluid step moves the particles in place: the
        rows still hold them."""
        rows, velocity = buffers
        if not len(rows):
            return 0.0
        change = particles.velocity[rows] - velocity - dt * self.fluid.gravity
        return -self.particle_mass * float(np.einsum("ij,ij->", velocity, change))

    def _first_moment(self, particles):
        """This rank's sum of m (x - datum) over its owned fluid."""
        n = particles.n_owned
        fluid = particles.kind[:n] == FLUID
        return self.particle_mass * (particles.position[:n][fluid] - self.energy_datum).sum(0)

    def _count_extra_work(self, dt):
        """Tell the decomposition the work each rank does beyond its particles (a body's
        substeps run on its owner), so the balance gives that rank fewer particles."""
        weight = self.case["parallel"]["node_substep_weight"]
        work = [w for w in (p.node_substeps(dt) for p in self.participants) if w is not None]
        if work and weight > 0:
            self.decomposition.set_extra_work(weight * np.sum(work, axis=0))

    def check(self, state):
        """Stop loudly on NaN, a particle leaving the domain (fluid is removed instead when
        the case says so) or going through a wall, or a Courant breach; measures the
        largest fluid speed for the next step."""
        comm = self.comm
        particles = state.particles
        step = state.step
        check_finite(particles, comm, step)
        for participant in self.participants:
            participant.check(particles, step, state.time)
        before = sum(self._fluid_energy(particles))
        particles, escaped_speed = self.escaped.apply(particles, step, state.time,
                                                      self.particle_owner)
        if particles.n_owned != state.particles.n_owned:
            self.exchanged_energy += sum(self._fluid_energy(particles)) - before
        state.particles = particles
        speed = max_speed(particles, comm)
        # The removed particles moved in this step too: one thrown out by a step too long
        # is a Courant breach.
        courant = max(speed, escaped_speed) * state.dt / self.spacing
        if courant > 1.0:
            fixed = self.case["time"]["fixed_dt"]
            advice = (f"; the fixed time.fixed_dt = {fixed:g} s breaks the Courant limit: lower "
                      f"it or set it to 0 for adaptive steps" if fixed > 0 else "")
            raise RunFailure(f"step {step}: Courant number {courant:.3g} > 1 (max fluid speed "
                             f"{max(speed, escaped_speed):.4g} m/s, dt {state.dt:.3g} s): "
                             f"particles jump more than a spacing per step: the step was too "
                             f"long, or the run went unstable{advice}")
        # After the Courant check: a particle that jumped into a wall because the
        # step was too long should be reported as the Courant breach it is.
        guards.check_wall_penetration(particles, guards.wall_rectangles(self.case, state.time),
                                      self.spacing, comm, step, self.source_settings)
        guards.check_shaped_walls(particles, self.shaped_walls, self.case, state.time,
                                  self.spacing, comm, step, self.source_settings)
        self.fluid_speed = speed

    def particle_owner(self, pid):
        """The first participant's ``(description, advice)`` for particle ``pid``, or None."""
        for participant in self.participants:
            owner = participant.particle_owner(pid)
            if owner is not None:
                return owner
        return None

    def diagnostics(self, state):
        comm = self.comm
        particles = state.particles
        n = particles.n_owned
        fluid = particles.kind[:n] == FLUID
        work = self.exchanged_energy + sum(p.work() for p in self.participants)
        sums = np.array([*self._fluid_energy(particles, fluid), work,
                         np.count_nonzero(fluid), self.field_work])
        kinetic, potential, work, n_fluid, field_work = comm.allreduce(sums)
        values = {"ksp_iterations": self.stats["ksp_iterations"],
                  "ksp_residual": self.stats["ksp_residual"],
                  "viscous_iterations": self.stats["viscous_iterations"],
                  "max_speed": self.fluid_speed, "kinetic_energy": kinetic,
                  "potential_energy": potential, "fluid_energy": kinetic + potential,
                  "boundary_work": work,
                  "n_fluid": int(n_fluid),
                  "n_escaped": self.escaped.total,
                  "imbalance": self.step_imbalance}
        if self.body_force.varies:
            values["body_force_work"] = field_work
        for participant in self.participants:
            values.update(participant.diagnostics())
        self._follow_budget(values)
        return values

    def _follow_budget(self, values):
        budget = energy.budget(values)
        if self.initial_energy is None:
            self.initial_energy, self.lowest_budget = values["fluid_energy"], budget
        self.rise_scale = energy.rise_scale(self.initial_energy, values)
        self.budget = budget
        self.lowest_budget = min(self.lowest_budget, budget)

    def energy_rise(self):
        """How far the fluid's and bodies' energy, less the boundaries' work, has risen above
        its lowest value so far, over the fluid's initial energy (0 before the first step)."""
        if self.initial_energy is None or self.rise_scale == 0.0:
            return 0.0
        return (self.budget - self.lowest_budget) / self.rise_scale

    def _drive_power(self, particles, drive):
        """This rank's power of the body force ``drive`` (along the periodic axes; None:
        none) on its owned fluid [W]."""
        if drive is None:
            return 0.0
        return energy.body_force_power(particles, self.particle_mass, drive)

    def _fluid_energy(self, particles, mask=None):
        """This rank's (kinetic, potential) energy of its owned fluid."""
        return energy.fluid_energy(particles, self.particle_mass, self.gravity,
                                   self.energy_datum, mask)

    def failure_cause(self, where=None):
        causes = [cause for cause in (p.failure_cause(where) for p in self.participants)
                  if cause is not None]
        rise = self.energy_rise()
        if rise > ENERGY_RISE:
            # Fluid thrown out of the domain or through a wall by a numerical source: the
            # domain and the walls are not what to change.
            causes.append(f"the fluid's mechanical energy had risen by {100 * rise:.3g} % of "
                          f"its initial value with no work done on it (a numerical source in "
                          f"the pressure scheme, docs/design.md §1.8: mps.gradient, "
                          f"mps.source, time.cfl)")
        return "; ".join(causes) or None

    def progress(self, state):
        return f"ksp {self.stats['ksp_iterations']} its"

    def summary(self, state):
        return self.escaped.summary()


class SolidStepper:
    """Bodies alone: every rank advances every (small) body alike; rank 0 holds the nodes
    as its particles, for the frames."""

    DIAGNOSTICS = {"max_speed": np.float64, "kinetic_energy": np.float64,
                   "body_energy": np.float64}

    def __init__(self, case, comm, model):
        self.case = case
        self.comm = comm
        self.model = model
        self.lower = np.asarray(case["domain"]["lower"])
        self.upper = np.asarray(case["domain"]["upper"])

    def checkpoint_state(self):
        # Every rank advances every body alike: any rank's state is the state.
        return {"bodies": self.model.state()}

    def restore_state(self, saved):
        self.model.restore(saved["bodies"])

    def start(self, state):
        pass

    def dt_limits(self, state):
        # The substeps hold the bodies' stability; the outer step only paces the output.
        return []

    def advance(self, state, dt):
        try:
            self.model.advance(state.time, dt)
        except RunFailure as exc:
            # The solver knows the time, the loop the step: name both.
            raise RunFailure(f"step {state.step + 1}: {exc}") from None
        if self.comm.rank == 0:
            state.particles = self.model.node_particles(every_node=True)

    def check(self, state):
        self.model.check(state.step, state.time)
        for body in self.model.bodies:
            outside = outside_box(body.position, self.lower, self.upper)
            if outside.any():
                node = int(np.flatnonzero(outside)[0])
                at = ", ".join(f"{x:.4g}" for x in body.position[node])
                raise RunFailure(f"step {state.step}: node {node} of body '{body.name}' left "
                                 f"the domain at ({at})")

    def diagnostics(self, state):
        return {"max_speed": self.model.max_speed(),
                "kinetic_energy": self.model.kinetic_energy(),
                "body_energy": self.model.mechanical_energy()}

    def failure_cause(self, where=None):
        return None

    def progress(self, state):
        return "  ".join(f"{name}: volume error {values['volume_error']:.3e}"
                         for name, values in self.model.series().items())

    def summary(self, state):
        return "; " + ", ".join(f"{name} volume error {values['volume_error']:.3e}"
                                for name, values in self.model.series().items())
