"""What takes part in a fluid step besides the fluid: walls that move, open boundaries, bodies.

The fluid stepper (:class:`parmps.run.steppers.FluidStepper`) calls every
participant at three fixed points of a step, in the order the participants
were given; a participant overrides the hooks it needs. A new kind of boundary
or coupling is a new participant, not a new branch in the step.

1. ``before_exchange(particles, time, dt)``: owned particles only, before
   migration and the halo (a moving wall moves here, so its particles migrate
   like any other).
2. ``before_pressure(particles, time, dt)``: owned particles and ghosts, before
   the projection; returns an owned-length mask of particles to hold at P = 0
   (an outlet's pressure reference), or None.
   ``pressure_mobility(particles)``, right after it: None, or rho/rho_i of
   every local particle (owned and ghosts), 1 where the participant has no
   say; the pressure equation then weighs each particle's inertia (a
   coupling's body nodes as particles of their own density).
3. ``after_fluid(particles, time, dt, decomposition)``: after the projection;
   returns the particles (an open boundary adds and removes some: then owned
   only).

``check(particles, step, time)`` stops a step that went wrong for the
participant (a blown-up body). ``failure_cause(where)``: a sentence naming
the physical cause a failed run most likely had that this participant knows of
(a coupling that is unstable for the case's bodies), or None; ``where`` is the
position the failure was seen at, or None; it must be the
same on every rank. ``speed(time, until)`` is the largest speed the participant moves particles at
over [time, until): the step must respect it like the fluid's. ``DIAGNOSTICS``
and ``diagnostics()`` add columns to the run's diagnostics;
``particle_owner(pid)`` names the geometry a particle belongs to and what to
do about it, for messages: ``(description, advice)`` or None.
``work()``: this rank's share of the work the participant has done on the fluid so far
[J] (a moving wall's force times its velocity), not reduced over the ranks; and
``exchanges_fluid``: True for a participant whose ``after_fluid`` adds fluid particles or
takes them away (open boundaries), the energy they carry then counted by the stepper. The
energy check of :mod:`parmps.fluid.energy` counts neither as a source.
A participant with bodies reports their energy as the ``body_energy`` diagnostic.
``node_substeps(dt)``: the bodies' node-substeps each rank will run in a step of
dt (an array over the ranks, the same on every rank), or None: work beyond the
rank's particles, which the decomposition's balance counts
(``parallel.node_substep_weight``).

A participant with state beyond the particles (counters, bodies) has a ``name``
and contributes it to checkpoints: ``checkpoint_state()`` (collective; a dict
of arrays and scalars, the same on every rank) and ``restore_state(saved)``
(a continued run, before its first step).
"""


class Participant:
    DIAGNOSTICS = {}  # column name -> numpy dtype
    name = None  # the group of its checkpoint state; None: it has none
    exchanges_fluid = False  # adds or removes fluid particles in after_fluid

    def checkpoint_state(self):
        return {}

    def restore_state(self, saved):
        pass

    def before_exchange(self, particles, time, dt):
        pass

    def before_pressure(self, particles, time, dt):
        return None

    def pressure_mobility(self, particles):
        return None

    def after_fluid(self, particles, time, dt, decomposition):
        return particles

    def speed(self, time, until):
        return 0.0

    def check(self, particles, step, time):
        """After the step: raise RunFailure if what this participant moves went wrong."""

    def failure_cause(self, where=None):
        return None

    def diagnostics(self):
        return {}

    def particle_owner(self, particle_id):
        return None

    def node_substeps(self, dt):
        return None

    def work(self):
        return 0.0
