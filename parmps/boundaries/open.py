"""Open boundaries: inflow buffer zones and outlets (docs/design.md §1.7, kind 4).

Inlet. A box of ``m`` lattice columns along the flow (one axis) of inflow-buffer
particles over ``count`` lanes, the lattice points across the flow (a line in 2D, a
rectangle or the points inside a circle in 3D). Lane ``k`` moves at ``shape_k U(t)``:
``U(t)`` the mean velocity (constant, ramped or tabulated, parmps.core.timeseries),
``shape_k`` the profile across the opening (uniform or the fully developed laminar one,
parmps.boundaries.profiles) scaled so that ``l0^(d-1) sum_k shape_k`` is the opening's
area, so that the delivered flow rate is exactly the mean times the area. Particle
``(c, k)`` of inlet ``j`` sits at the distance
``s_ck(t) = (m - c - 1/2) l0 + shape_k S(t)`` downstream of the upstream face, with
``S(t)`` the exact integral of U from 0: columns 0..m-1 fill the buffer at t = 0, and
column ``c >= m`` of lane ``k`` enters at the upstream face once ``s_ck(t) >= 0``, each
lane on its own. Its global id is ``base_j + c * count + k``, with
``base_j = N_scene + j * 2**40``, so ids depend on the case and the time alone, never on
the rank count or the step sizes; every rank computes the entering particles and keeps
those its slab owns. Buffer particles take part in the fluid step like fluid (number
density, pressure unknowns, neighbours of the fluid) but their positions and velocities
are reset to the prescribed motion after it; a particle whose ``s`` passes the buffer's
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
from parmps.boundaries.profiles import parabolic
from parmps.boundaries.settings import inflow_table
from parmps.core.timeseries import Constant, Ramp, Table

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
        self.axis = int(nonzero[0])
        # The axes across the flow: a lane is a point of a lattice over them.
        self.cross = [a for a in range(len(velocity)) if a != self.axis]
        self.direction = np.zeros(len(velocity))
        self.sign = 1.0 if velocity[self.axis] > 0 else -1.0
        self.direction[self.axis] = self.sign
        self.mean = mean_velocity(self.name, spec, abs(float(velocity[self.axis])))
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
        self.across, self.shape = lanes(self.name, spec, lower[self.cross], upper[self.cross],
                                        counts, spacing)
        self.count = len(self.across)
        self.base = int(base)
        # Lane k holds the columns 0..created[k]-1.
        self.created = np.full(self.count, self.columns, np.int64)

    def distance(self, column, lane, time):
        """s_ck(t) = (m - c - 1/2) l0 + shape_k S(t): how far particle (c, k) is downstream
        of the upstream face, S(t) the integral of the mean velocity."""
        return (self.columns - column - 0.5) * self.spacing + \
            self.shape[lane] * self.mean.integral(time)

    def _particles(self, column, lane, time):
        """Buffer particles (column c, lane k): ids base + c count + k, and their ``s``."""
        s = self.distance(column, lane, time)
        position = np.empty((len(column), len(self.direction)))
        position[:, self.axis] = self.upstream + self.sign * s
        position[:, self.cross] = self.across[lane]
        velocity = np.outer(self.shape[lane] * self.mean.value(time), self.direction)
        return Particles({
            "id": self.base + column * self.count + lane,
            "kind": np.full(len(column), INFLOW, np.int8),
            "position": position,
            "velocity": velocity,
        }), s

    def initial(self):
        column = np.repeat(np.arange(self.columns, dtype=np.int64), self.count)
        lane = np.tile(np.arange(self.count, dtype=np.int64), self.columns)
        return self._particles(column, lane, 0.0)[0]

    def update(self, particles, time):
        """Prescribed motion of this inlet's owned buffer particles; returns how many
        became fluid (local)."""
        n = particles.n_owned
        ids = particles.id[:n]
        mine = np.flatnonzero((particles.kind[:n] == INFLOW) & (ids >= self.base) &
                              (ids < self.base + ID_STRIDE))
        offset = ids[mine] - self.base
        moved, s = self._particles(offset // self.count, offset % self.count, time)
        particles.position[mine] = moved.position
        particles.velocity[mine] = moved.velocity
        passed = mine[s > self.depth]
        particles.kind[passed] = FLUID
        return len(passed)

    def entering(self, time):
        """The particles whose time to enter has come, lane by lane (the same on every
        rank): lane k's columns up to the last with s >= 0."""
        lane_all = np.arange(self.count, dtype=np.int64)
        last = np.floor(self.columns - 0.5 + self.shape * self.mean.integral(time) /
                        self.spacing).astype(np.int64)
        # Rounding may put the last column a hair upstream of the face: it waits.
        last -= self.distance(last, lane_all, time) < 0.0
        new = np.maximum(last + 1 - self.created, 0)
        lane = np.repeat(lane_all, new)
        # Column created[k] + j for the j-th new particle of lane k.
        first = np.repeat(self.created, new)
        j = np.arange(len(lane)) - np.repeat(np.cumsum(new) - new, new)
        self.created = self.created + new
        return self._particles(first + j, lane, time)[0]

    def speed(self, time, until):
        """The fastest lane's largest speed over [time, until]."""
        return float(self.shape.max()) * self.mean.peak(time, until)


def mean_velocity(name, spec, speed):
    """The inlet's mean speed as a function of time: constant, ramped or tabulated."""
    if spec["table"]:
        table = inflow_table(name, spec)
        return Table(table[:, 0], table[:, 1])
    if spec["ramp"] is not None:
        return Ramp(speed, spec["ramp"])
    return Constant(speed)


def lanes(name, spec, lower, upper, counts, spacing):
    """The lanes' positions across the flow (count x (d - 1)) and their speeds over the
    mean, scaled so that their sum times l0^(d-1) is the opening's area: the delivered
    flow rate is the mean times the area, whatever the lattice."""
    across = lattice_points(lower, counts, spacing)
    centre = 0.5 * (lower + upper)
    radius = spec["radius"] if spec["shape"] == "circle" else None
    if radius is not None:
        # Only the lattice points strictly inside the circle are lanes.
        across = across[np.sum((across - centre) ** 2, axis=1) < radius ** 2]
        area = np.pi * radius ** 2
    else:
        area = float(np.prod(upper - lower))
    if spec["profile"] == "parabolic":
        shape = parabolic(across, centre, upper - lower, radius)
    else:
        shape = np.ones(len(across))
    lane_area = spacing ** len(counts)
    scale = area / (lane_area * shape.sum())
    if abs(scale - 1.0) > 1e-9:
        log.info("%s: %d lanes, a %s profile scaled by %.6f so that the flow rate is the "
                 "mean times the area %.6g m^%d", name, len(across), spec["profile"], scale,
                 area, len(counts))
    return across, shape * scale


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
        # Every inlet's lanes' counts, one after the other.
        lanes = [inlet.created for inlet in self.inlets]
        return {"lanes_created": np.concatenate(lanes) if lanes else np.zeros(0, np.int64),
                "inflow_total": self.inflow_total, "outflow_total": self.outflow_total}

    def restore_state(self, saved):
        if "lanes_created" in saved:
            created = np.asarray(saved["lanes_created"], np.int64)
            ends = np.cumsum([inlet.count for inlet in self.inlets])
            for inlet, lane in zip(self.inlets, np.split(created, ends[:-1])):
                inlet.created = lane.copy()
        else:
            # A checkpoint from before the lanes: one column count per (uniform) inlet.
            for inlet, created in zip(self.inlets, np.atleast_1d(saved["created"])):
                inlet.created = np.full(inlet.count, int(created), np.int64)
        self.inflow_total = int(saved["inflow_total"])
        self.outflow_total = int(saved["outflow_total"])

    def initial_particles(self, scene_count):
        """The buffers' particles at t = 0, to add after the scene's ``scene_count``
        particles (inlet j's ids start at scene_count + j * 2**40)."""
        for j, inlet in enumerate(self.inlets):
            inlet.base = scene_count + j * ID_STRIDE
        return [(inlet.name, inlet.initial()) for inlet in self.inlets]

    def speed(self, time, until):
        """The inlets' fastest lane over [time, until]: a ramp or a table speeds them up."""
        return max([inlet.speed(time, until) for inlet in self.inlets], default=0.0)

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
            entering = inlet.entering(time)
            if entering.n_owned:
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
