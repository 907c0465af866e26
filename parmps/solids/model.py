"""What the run and the coupling need of a solid model: the interface every model implements.

A model holds every body of a case. Bodies are small next to the fluid: every
rank holds all of them; the coupling makes one rank advance each body and
broadcasts its nodes' state. A body's *nodes* are its material points; the ones
that are particles of the fluid (a body may have fixed anchor points that are
not) come first, in a fixed order, and are the body's node particles.
"""

import numpy as np

from parmps.core.particles import SOLID, Particles


class SolidModel:
    """The interface. ``bodies`` is a list; each body has ``name``, ``position`` and
    ``velocity`` (n_nodes x d, updated in place) and ``fluid_force`` (n_nodes x d)."""

    bodies = ()

    @classmethod
    def from_case(cls, case):
        raise NotImplementedError

    # -- what the fluid sees ----------------------------------------------------------------
    def particle_counts(self):
        """How many nodes of each body are particles of the fluid (in body order)."""
        raise NotImplementedError

    def node_particles(self, every_node=False):
        """Every body's particle nodes as SOLID particles: ids from 0 in body order, with
        ``body`` and ``node`` set (the coupling finds them again by those). With
        ``every_node`` the fixed nodes that are no particles too (a solid-only run's
        frames show every node)."""
        counts = ([len(body.position) for body in self.bodies] if every_node
                  else self.particle_counts())
        total = sum(counts)
        bodies = self.bodies
        dimension = bodies[0].position.shape[1] if bodies else 2
        return Particles({
            "id": np.arange(total, dtype=np.int64),
            "kind": np.full(total, SOLID, np.int8),
            "position": (np.concatenate([b.position[:m] for b, m in zip(bodies, counts)])
                         if total else np.empty((0, dimension))),
            "velocity": (np.concatenate([b.velocity[:m] for b, m in zip(bodies, counts)])
                         if total else np.empty((0, dimension))),
            "body": np.repeat(np.arange(len(bodies), dtype=np.int32), counts),
            "node": (np.concatenate([np.arange(m, dtype=np.int32) for m in counts])
                     if total else np.empty(0, np.int32)),
        })

    def node_inverse_mass(self, k):
        """1/m of body k's particle nodes [1/kg] (0 for a node that does not move)."""
        raise NotImplementedError

    def boundary(self, k):
        """Body k's material boundary, closed: (vertices (n, d), facets (m, d) of indices
        into them), facets as :meth:`surface` gives them (2D: edges of a loop; 3D: outward
        triangles). What the coupling knows of a body's shape: it counts the fluid inside
        with :func:`parmps.core.geometry.inside_boundary`."""
        raise NotImplementedError

    def displaces(self, points, spacing, domain=None):
        """Which of the fluid's lattice ``points`` (k, d) the bodies take the place of: a
        closed shell's surface stands in for the fluid within its clearance (the fluid on
        both sides of it stays), across a periodic seam of ``domain`` too. Bodies whose
        nodes sit on the fluid's lattice (a lattice body) displace nothing here: the case
        leaves their place free, and the scene refuses overlaps."""
        return np.zeros(len(points), bool)

    def encloses_fluid(self, k):
        """Whether body k holds fluid inside its boundary (a closed shell): the crossing
        check then counts particles that change sides of the boundary itself."""
        return False

    # -- time stepping --------------------------------------------------------------------
    def stable_substeps(self):
        """{body name: the longest stable substep [s]}."""
        raise NotImplementedError

    def substep_counts(self, dt):
        """{body name: substeps in a step of dt}."""
        raise NotImplementedError

    def advance_body(self, k, time, dt):
        """Advance body k from ``time`` by ``dt`` with its ``fluid_force`` held; returns
        the substeps taken."""
        raise NotImplementedError

    def set_drag(self, k, rate, target):
        """The fluid's viscous drag on body k's nodes over its next advance_body, taken
        implicitly in the substeps: ``m_i rate_i (target_i - v_i)``, ``rate`` (n_nodes,)
        [1/s], ``target`` (n_nodes, d) [m/s]; after the advance ``fluid_force`` holds the held
        force plus the step's mean drag."""
        raise NotImplementedError

    def advance(self, time, dt):
        """Advance every body (solid-only runs, where every rank does the same)."""
        return {body.name: self.advance_body(k, time, dt) for k, body in enumerate(self.bodies)}

    # -- what the run reads ---------------------------------------------------------------
    def max_speed(self):
        return max((float(np.sqrt((body.velocity ** 2).sum(axis=1)).max())
                    for body in self.bodies), default=0.0)

    def kinetic_energy(self):
        raise NotImplementedError

    def mechanical_energy(self):
        """The bodies' kinetic, elastic and gravitational potential energy [J]."""
        raise NotImplementedError

    def check(self, step, time):
        """Raise RunFailure if a body has blown up (the same verdict on every rank)."""
        raise NotImplementedError

    SERIES = {}  # name -> trailing shape of each per-body, per-step series

    def series(self):
        """{body name: {series name: value}} for the current state."""
        raise NotImplementedError

    def springs(self, k):
        """Body k's connectivity as node index pairs (the mesh ParaView draws)."""
        raise NotImplementedError

    def surface(self, k):
        """Body k's boundary facets (m, d) as node indices (2D: the loop's edges; 3D:
        outward triangles, the mesh ParaView draws as its surface), or None."""
        return None

    def attributes(self, k):
        """Constant attributes of body k for the output (e.g. its rest area)."""
        return {}

    # -- checkpoints ----------------------------------------------------------------------
    def state(self):
        """Everything the future of every body depends on: {body: {name: array}}."""
        raise NotImplementedError

    def restore(self, state):
        raise NotImplementedError
