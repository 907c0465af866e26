"""The mass-spring model: every body of a case, behind the SolidModel interface.

Bodies are built by :mod:`parmps.solids.mass_spring.build` and advanced by
their own Verlet substeps (:mod:`parmps.solids.mass_spring.body`), each with
the longest substep its stiffest node allows times a safety factor, or a fixed
one. The run guard here stops a body that has blown up: non-finite nodes, an
volume constraint that lost control (``VOLUME_ERROR_LIMIT``) or springs
stretched far beyond anything linear springs model (``STRETCH_LIMIT``) — the
signatures of forces too large for the substep or an inverted boundary, without
which a run goes on to its end time with meaningless numbers.
"""

import math

import numpy as np

from parmps.errors import CaseError, RunFailure
from parmps.solids.mass_spring.body import boundary_facets, substep_count
from parmps.solids.mass_spring.build import build_bodies
from parmps.solids.mass_spring.shell import displaced_by_shell
from parmps.solids.model import SolidModel

# The volume constraint holds |V - V0|/V0 near 1e-12; ten percent means the
# Lagrange step no longer controls the boundary.
VOLUME_ERROR_LIMIT = 0.1

# Linear springs stretched twenty times their rest length model nothing real;
# in practice only an unstable integration or a runaway load gets there.
STRETCH_LIMIT = 20.0



class MassSpringModel(SolidModel):
    """Every mass-spring body of a case.

    ``advance(t, dt_outer)`` runs each body's own substeps with its fluid
    force held constant (the weak coupling of docs/design.md); bodies are
    independent, so the coupling gives each to one rank.
    """

    # The Newton steps a substep may take on the volume multiplier (body.volume_multiplier):
    # with the slope held at the current position each shrinks the error by about the
    # step's displacement over the body's size; one or two reach 1e-12 in the cases here.
    CONSTRAINT_ITERATIONS = 8

    def __init__(self, bodies, substep=0.0, safety=0.5, constraint_prediction="iterated",
                 constraint_tolerance=1e-12):
        self.bodies = list(bodies)
        # "quadratic" was the one extra pass this iteration replaces.
        iterations = 0 if constraint_prediction == "linear" else self.CONSTRAINT_ITERATIONS
        for body in self.bodies:
            body.constraint_iterations = iterations
            body.constraint_tolerance = float(constraint_tolerance)
        d = self.bodies[0].dimension if self.bodies else 2
        # Per body and step: name -> trailing shape.
        self.SERIES = {"volume_error": (), "fluid_force": (d,), "centroid": (d,),
                       "second_moment": (d, d), "newton_steps": ()}
        if any(body.membrane is not None for body in self.bodies):
            self.SERIES["area_error"] = ()
        self.safety = float(safety)
        self.fixed_substep = float(substep)
        # The limits are eigen solves: computed once, for the substeps and the summary.
        self.limits = {body.name: body.stability_limit() for body in self.bodies}
        self.substeps = {body.name: self._substep_of(body) for body in self.bodies}
        self.last_substep_counts = {body.name: 0 for body in self.bodies}

    def _substep_of(self, body):
        limit = self.limits[body.name]
        if self.fixed_substep > 0.0:
            if self.fixed_substep >= limit:
                raise CaseError(f"solid.substep ({self.fixed_substep:.6g} s) is above the "
                                f"stability limit of body '{body.name}' ({limit:.6g} s from its "
                                f"stiffest node); use at most {self.safety * limit:.3g} s or "
                                f"0 for automatic")
            return self.fixed_substep
        return self.safety * limit

    @classmethod
    def from_case(cls, case):
        solid = case.get("solid", {})
        return cls(build_bodies(case), substep=solid.get("substep", 0.0),
                   safety=solid.get("safety", 0.5),
                   constraint_prediction=solid.get("constraint_prediction", "iterated"),
                   constraint_tolerance=solid.get("constraint_tolerance", 1e-12))

    def __len__(self):
        return len(self.bodies)

    def __iter__(self):
        return iter(self.bodies)

    def body(self, name):
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(name)

    def stable_substep(self):
        """The smallest substep any body uses [s]."""
        return min(self.substeps.values(), default=math.inf)

    def substep_counts(self, dt_outer):
        return {name: substep_count(dt_outer, dt) for name, dt in self.substeps.items()}

    def advance(self, time, dt_outer, fluid_force=None):
        """Advance every body from ``time`` by ``dt_outer``.

        ``fluid_force`` maps a body name to an (n_nodes, d) force on its nodes,
        held constant over the substeps; bodies not named feel none.
        Returns the substep count of every body.
        """
        fluid_force = fluid_force or {}
        for body in self.bodies:
            force = fluid_force.get(body.name)
            body.fluid_force[:] = 0.0 if force is None else force
            self.last_substep_counts[body.name] = body.advance(time, dt_outer,
                                                               self.substeps[body.name])
            if body.membrane is not None:
                try:
                    body.membrane.check_extension(body.name)
                except RunFailure as exc:
                    raise RunFailure(f"t = {time + dt_outer:.6g} s: {exc}") from None
            if not np.all(np.isfinite(body.position)):
                raise RunFailure(f"body '{body.name}' became non-finite at t = "
                                 f"{time + dt_outer:.6g} s")
        return dict(self.last_substep_counts)

    def diagnostics(self):
        """Per body: volume_error, centroid (d,), second_moment (d, d) of the enclosed region,
        fluid_force (d,) and newton_steps (the
        most Newton steps on the volume multiplier any substep of the last step took)."""
        out = {body.name: {"volume_error": body.volume_error(),
                           "centroid": body.centroid(),
                           "second_moment": body.second_moment(),
                           "fluid_force": body.total_fluid_force(),
                           "newton_steps": body.newton_steps}
               for body in self.bodies}
        if "area_error" in self.SERIES:
            # The total area of a cell membrane (0 for the other bodies).
            for body in self.bodies:
                out[body.name]["area_error"] = (body.membrane.area_error(body.position)
                                                if body.membrane is not None else 0.0)
        return out

    def stable_substeps(self):
        return dict(self.substeps)

    def stability_limits(self):
        """Each body's Verlet step limit [s], as the substeps were chosen from it."""
        return dict(self.limits)

    def set_drag(self, k, rate, target):
        self.bodies[k].set_drag(rate, target)

    def advance_body(self, k, time, dt):
        body = self.bodies[k]
        count = body.advance(time, dt, self.substeps[body.name])
        self.last_substep_counts[body.name] = count
        return count

    def particle_counts(self):
        return [body.n_material for body in self.bodies]

    def node_inverse_mass(self, k):
        body = self.bodies[k]
        return body.inverse_mass[:body.n_material]

    def boundary(self, k):
        # The material's own outline: a body closed over anchors on a wall (2D) counts
        # the fluid inside its material, not between it and the wall.
        body = self.bodies[k]
        return body.position, boundary_facets(body.outline)

    def displaces(self, points, spacing, domain=None):
        taken = np.zeros(len(points), bool)
        for body in self.bodies:
            if body.encloses_fluid:
                seen = points if domain is None else domain.near(points,
                                                                 body.position.mean(axis=0))
                taken |= displaced_by_shell(seen, body.position, body.facets, spacing)
        return taken

    def encloses_fluid(self, k):
        return self.bodies[k].encloses_fluid

    def kinetic_energy(self):
        return sum(body.energy()[0] for body in self.bodies)

    def mechanical_energy(self):
        return sum(sum(body.energy()) + body.potential_energy() for body in self.bodies)

    def series(self):
        return self.diagnostics()

    def springs(self, k):
        return self.bodies[k].springs

    def surface(self, k):
        return self.bodies[k].facets

    def attributes(self, k):
        body = self.bodies[k]
        return {"rest_volume": body.rest_volume, "nodes": body.n_nodes}

    def check(self, step, time):
        check_bodies(self.bodies, step, time)

    STATE = ("position", "velocity", "fluid_force")

    def state(self):
        out = {}
        for body in self.bodies:
            entry = {name: getattr(body, name).copy() for name in self.STATE}
            if body.acceleration is not None:
                entry["acceleration"] = body.acceleration.copy()
            entry["multiplier"] = np.array(body.multiplier)
            out[body.name] = entry
        return out

    def restore(self, state):
        for body in self.bodies:
            entry = state[body.name]
            for name in self.STATE:
                getattr(body, name)[...] = entry[name]
            body.acceleration = entry["acceleration"].copy() if "acceleration" in entry \
                else None
            body.multiplier = float(entry["multiplier"])


def body_state(body):
    """(finite, |volume error|, largest spring stretch over rest length) of one body."""
    finite = bool(np.all(np.isfinite(body.position)) and np.all(np.isfinite(body.velocity)))
    if not finite:
        return False, np.inf, np.inf
    error = abs(body.volume_error()) if body.volume_constraint else 0.0
    springs = body.springs
    separation = body.position[springs[:, 0]] - body.position[springs[:, 1]]
    length = np.sqrt(np.einsum("ij,ij->i", separation, separation))
    stretch = float((length / body.rest_length).max()) if len(springs) else 1.0
    return True, float(error), stretch


def check_bodies(bodies, step, time):
    """Stop if a body blew up. Bodies are replicated (or broadcast) on every rank,
    so every rank reaches the same verdict without communication."""
    for body in bodies:
        if body.membrane is not None and np.all(np.isfinite(body.position)):
            try:
                body.membrane.check(body.name, body.position)
            except RunFailure as exc:
                raise RunFailure(f"step {step}, t = {time:.6g} s: {exc}") from None
        finite, error, stretch = body_state(body)
        speed = float(np.sqrt((body.velocity ** 2).sum(axis=1)).max()) if finite else np.inf
        if not finite:
            cause = "its node positions or velocities became non-finite"
        elif error > VOLUME_ERROR_LIMIT:
            cause = (f"its area constraint lost control (volume error {error:.3g} > "
                     f"{VOLUME_ERROR_LIMIT:g}; fastest node {speed:.4g} m/s)")
        elif stretch > STRETCH_LIMIT:
            cause = (f"a spring is stretched to {stretch:.3g} times its rest length "
                     f"(> {STRETCH_LIMIT:g}; fastest node {speed:.4g} m/s)")
        else:
            continue
        raise RunFailure(f"step {step}: body '{body.name}' blew up at t = {time:.6g} s: {cause}; "
                         f"the loads or fluid forces are too large for the body, or its "
                         f"substep too long (solid.substep, solid.safety)")
