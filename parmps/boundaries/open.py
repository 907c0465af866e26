"""Open boundaries: inflow buffer zones and outlets (docs/design.md §1.7, kind 4).

Inlet. A box of ``m`` lattice columns (cross-sections of the flow: lines in
2D, rectangles in 3D) of inflow-buffer particles that move rigidly at the
uniform velocity U0 (along one axis). Column
``c`` of inlet ``j`` sits at the distance ``s_c(t) = (m - c - 1/2) l0 + |U0| t``
downstream of the upstream face: columns 0..m-1 fill the buffer at t = 0, and
column ``c >= m`` enters at the upstream face once ``s_c(t) >= 0``. Particle
``k`` of column ``c`` has the global id ``base_j + c * count + k``, with
``base_j = N_scene + j * 2**40`` and ``count`` the particles per column, so ids
depend on the case and the time alone, never on the rank count; every rank
computes the new column and keeps the particles its slab owns. Buffer
particles take part in the fluid step like fluid (number density, pressure
unknowns, neighbours of the fluid) but their positions and velocities are reset
to the prescribed motion after it; a particle whose ``s`` passes the buffer's
depth becomes fluid.

Outlet. A side of the domain through which fluid leaves: particles beyond
that side are removed after every step, before the run checks that every
particle is inside the domain. With a non-zero outlet ``velocity`` the fluid
within ``buffer`` layers of the side becomes an outflow buffer (kind 4 too)
that moves rigidly at that velocity until it leaves: the outflow then matches
the inflow instead of following the MPS pressure noise, whose clamped positive
mean would otherwise push the fluid out through a free (P = 0) end faster than
it enters. The buffer is Dirichlet (P = 0) by default (``pressure =
"dirichlet"``): it gives the otherwise closed channel its pressure level;
``pressure = "fluid"`` makes its particles pressure unknowns.

Cumulative counts of particles that became fluid (inflow) and were removed
(outflow) go into the diagnostics, with ``n_fluid``; in a steady state the two
rates balance.
"""

import logging

import numpy as np
from mpi4py import MPI

from parmps.errors import CaseError
from parmps.fluid.participant import Participant
from parmps.core.particles import FLUID, INFLOW, Particles
from parmps.core.geometry import format_point
from parmps.geometry.scene import lattice_count, lattice_points

log = logging.getLogger(__name__)

ID_STRIDE = 2 ** 40  # ids reserved per inlet


def side_of(name, dimension):
    """``(axis, sign)`` of a domain side: left/right along x, front/back along y (3D),
    bottom/top along the vertical, the last axis."""
    return {"left": (0, -1), "right": (0, 1), "front": (1, -1), "back": (1, 1),
            "bottom": (dimension - 1, -1), "top": (dimension - 1, 1)}[name]


class Inlet:
    """One inflow buffer zone; see the module docstring."""

    def __init__(self, spec, index, case, base):
        self.name = f"inlet[{index}]"
        spacing = case["particles"]["spacing"]
        self.spacing = spacing
        velocity = np.asarray(spec["velocity"], dtype=float)
        nonzero = np.flatnonzero(velocity != 0.0)
        if len(nonzero) != 1:
            raise CaseError(f"{self.name}.velocity {list(velocity)} must be non-zero and along "
                            f"one axis (every other component zero)")
        self.velocity = velocity
        self.axis = int(nonzero[0])
        # The axes across the flow: a column is a lattice over them.
        self.cross = [a for a in range(len(velocity)) if a != self.axis]
        self.sign = 1.0 if velocity[self.axis] > 0 else -1.0
        self.speed = abs(float(velocity[self.axis]))
        lower = np.asarray(spec["lower"], dtype=float)
        upper = np.asarray(spec["upper"], dtype=float)
        domain_lower = np.asarray(case["domain"]["lower"])
        domain_upper = np.asarray(case["domain"]["upper"])
        if np.any(lower < domain_lower - 1e-12) or np.any(upper > domain_upper + 1e-12):
            raise CaseError(f"{self.name} {format_point(lower, 'g', '[]')}-"
                            f"{format_point(upper, 'g', '[]')} is outside the domain "
                            f"{format_point(domain_lower, 'g', '[]')}-"
                            f"{format_point(domain_upper, 'g', '[]')}")
        self.columns = lattice_count(f"{self.name} depth along the flow",
                              upper[self.axis] - lower[self.axis], spacing)
        needed = int(np.ceil(case["mps"]["re_laplacian"]))
        if self.columns < needed:
            raise CaseError(f"{self.name} is {self.columns} particles deep along the flow; it "
                            f"needs at least {needed} (mps.re_laplacian) so the fluid next to "
                            f"it has a full neighbourhood")
        counts = [lattice_count(f"{self.name} width across the flow",
                                upper[a] - lower[a], spacing) for a in self.cross]
        self.depth = self.columns * spacing
        self.upstream = lower[self.axis] if self.sign > 0 else upper[self.axis]
        # One column's cross-section (count × (d - 1)): the lattice across the flow.
        self.across = lattice_points(lower[self.cross], counts, spacing)
        self.count = len(self.across)
        self.base = int(base)
        self.created = self.columns  # columns 0..created-1 exist

    def distance(self, column, time):
        """s_c(t): distance of column c downstream of the upstream face."""
        return (self.columns - column - 0.5) * self.spacing + self.speed * time

    def _positions(self, column, time):
        """Positions of the particles of the given columns (arrays of equal length)."""
        s = self.distance(column, time)
        position = np.empty((len(column), len(self.velocity)))
        position[:, self.axis] = self.upstream + self.sign * s
        return position, s

    def particles(self, columns, time):
        """Buffer particles of whole columns: ids base + c count + k."""
        column = np.repeat(np.asarray(columns, dtype=np.int64), self.count)
        k = np.tile(np.arange(self.count, dtype=np.int64), len(columns))
        position, _ = self._positions(column, time)
        position[:, self.cross] = self.across[k]
        return Particles({
            "id": self.base + column * self.count + k,
            "kind": np.full(len(column), INFLOW, np.int8),
            "position": position,
            "velocity": np.tile(self.velocity, (len(column), 1)),
        })

    def initial(self):
        return self.particles(np.arange(self.columns), 0.0)

    def update(self, particles, time):
        """Prescribed motion of this inlet's owned buffer particles; returns how many
        became fluid (local)."""
        n = particles.n_owned
        ids = particles.id[:n]
        mine = np.flatnonzero((particles.kind[:n] == INFLOW) & (ids >= self.base) &
                              (ids < self.base + ID_STRIDE))
        offset = ids[mine] - self.base
        column, k = offset // self.count, offset % self.count
        position, s = self._positions(column, time)
        position[:, self.cross] = self.across[k]
        particles.position[mine] = position
        particles.velocity[mine] = self.velocity
        passed = mine[s > self.depth]
        particles.kind[passed] = FLUID
        return len(passed)

    def new_columns(self, time):
        """Columns whose time to enter has come (the same on every rank)."""
        last = int(np.floor(self.columns - 0.5 + self.speed * time / self.spacing)) + 1
        columns = np.arange(self.created, max(last, self.created) + 1)
        columns = columns[self.distance(columns, time) >= 0.0]
        if len(columns):
            self.created = int(columns[-1]) + 1
        return columns


class OpenBoundaries(Participant):
    """The case's inlets and outlets, applied after every step (collective)."""

    # Cumulative particles that became fluid at the inlets and left through the outlets.
    DIAGNOSTICS = {"inflow": np.float64, "outflow": np.float64}

    def __init__(self, case, comm):
        self.comm = comm
        self.inlets = [Inlet(spec, j, case, j * ID_STRIDE)
                       for j, spec in enumerate(case["inlet"])]
        self.outlets = [side_of(spec["side"], case["dimension"]) for spec in case["outlet"]]
        self.lower = np.asarray(case["domain"]["lower"], dtype=float)
        self.upper = np.asarray(case["domain"]["upper"], dtype=float)
        spacing = case["particles"]["spacing"]
        # Outflow buffers: (axis, side, zone start, velocity, P = 0?) for outlets with a
        # velocity.
        self.outflow_buffers = []
        for spec, (axis, side) in zip(case["outlet"], self.outlets):
            velocity = np.asarray(spec["velocity"], dtype=float)
            if np.any(velocity != 0.0):
                edge = self.lower[axis] if side < 0 else self.upper[axis]
                start = edge - side * spec["buffer"] * spacing
                self.outflow_buffers.append((axis, side, start, velocity,
                                             spec["pressure"] == "dirichlet"))
        self._saved = None
        self.inflow_total = 0
        self.outflow_total = 0

    name = "open_boundaries"
    exchanges_fluid = True

    def checkpoint_state(self):
        return {"created": np.array([inlet.created for inlet in self.inlets], np.int64),
                "inflow_total": self.inflow_total, "outflow_total": self.outflow_total}

    def restore_state(self, saved):
        for inlet, created in zip(self.inlets, np.atleast_1d(saved["created"])):
            inlet.created = int(created)
        self.inflow_total = int(saved["inflow_total"])
        self.outflow_total = int(saved["outflow_total"])

    def initial_particles(self, scene_count):
        """The buffers' particles at t = 0, to add after the scene's ``scene_count``
        particles (inlet j's ids start at scene_count + j * 2**40)."""
        for j, inlet in enumerate(self.inlets):
            inlet.base = scene_count + j * ID_STRIDE
        return [(inlet.name, inlet.initial()) for inlet in self.inlets]

    def _in_outflow_zone(self, position, axis, side, start):
        return position[:, axis] < start if side < 0 else position[:, axis] > start

    def before_pressure(self, particles, time, dt):
        return self.before_step(particles)

    def after_fluid(self, particles, time, dt, decomposition):
        return self.apply(particles, time + dt, decomposition.owner, dt)

    def before_step(self, particles):
        """Remember where the owned outflow-buffer particles start the step.

        Returns the owned-length mask of the particles the fluid step must hold
        at P = 0 (outflow buffers with ``pressure = "dirichlet"``), or None.

        With an outflow buffer moving at a set velocity the channel has no free
        surface: a pressure unknown everywhere leaves the PPE only the small
        artificial compressibility to fix the pressure level, which creeps up
        by kilopascals over a run. A P = 0 outlet is the channel's reference.
        """
        if not self.outflow_buffers:
            return None
        n = particles.n_owned
        saved = []
        dirichlet = np.zeros(n, bool)
        for axis, side, start, velocity, zero_pressure in self.outflow_buffers:
            index = np.flatnonzero((particles.kind[:n] == INFLOW) & self._in_outflow_zone(
                particles.position[:n], axis, side, start))
            saved.append((index, particles.position[index].copy(), velocity))
            dirichlet[index] = zero_pressure
        self._saved = saved
        return dirichlet if any(buffer[4] for buffer in self.outflow_buffers) else None

    def _move_outflow_buffers(self, particles, dt):
        """Prescribed motion of the outflow buffers; fluid entering them joins them."""
        if not self.outflow_buffers:
            return
        for index, start_position, velocity in self._saved or []:
            particles.position[index] = start_position + dt * velocity
            particles.velocity[index] = velocity
        n = particles.n_owned
        for axis, side, start, velocity, _ in self.outflow_buffers:
            entering = np.flatnonzero((particles.kind[:n] == FLUID) & self._in_outflow_zone(
                particles.position[:n], axis, side, start))
            particles.kind[entering] = INFLOW
            particles.velocity[entering] = velocity
        self._saved = None

    def apply(self, particles, time, owner, dt=0.0):
        """Move the buffers, turn particles that left them into fluid, add entering
        columns (kept where ``owner(position) == rank``), remove fluid past the outlets.

        Returns owned-only Particles.
        """
        comm = self.comm
        owned = particles.owned()
        self._move_outflow_buffers(owned, dt)
        converted = sum(inlet.update(owned, time) for inlet in self.inlets)
        n = owned.n_owned
        position = owned.position[:n]
        gone = np.zeros(n, bool)
        for axis, side in self.outlets:
            if side < 0:
                gone |= position[:, axis] < self.lower[axis]
            else:
                gone |= position[:, axis] > self.upper[axis]
        gone &= (owned.kind[:n] == FLUID) | (owned.kind[:n] == INFLOW)
        removed = int(np.count_nonzero(gone))
        parts = [owned.select(np.flatnonzero(~gone)) if removed else owned]
        for inlet in self.inlets:
            columns = inlet.new_columns(time)
            if len(columns):
                entering = inlet.particles(columns, time)
                keep = np.flatnonzero(owner(entering.position) == comm.rank)
                parts.append(entering.select(keep))
        result = Particles.concatenate(parts) if len(parts) > 1 else parts[0]
        counts = np.array([converted, removed], np.int64)
        comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        self.inflow_total += int(counts[0])
        self.outflow_total += int(counts[1])
        return result

    def diagnostics(self):
        return {"inflow": self.inflow_total, "outflow": self.outflow_total}
