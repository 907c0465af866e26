"""The probes as one observer: each probe at its own cadence, its series in result.h5
(``/probes/<name>/time`` and ``value``) and in ``OUTDIR/probes/<name>.csv``.

Samples are taken after a step (positions corrected, the step's pressure), from
sums over every rank's owned particles reduced once per step
(:mod:`parmps.probes.sampling`), so every rank holds the same values; rank 0
writes the rows, after a collective resize, like :mod:`parmps.io.series`.
"""

import logging
import math
import os

import numpy as np

from parmps.io.series import Series
from parmps.probes.sampling import (SampleRows, kernel_sums, lattice_sum, mean_sum,
                                    shepard_pressure, surface_height, water_depth)
from parmps.probes.settings import rest_positions
from parmps.run.observers import Observer
from parmps.run.schedule import SimulatedInterval

log = logging.getLogger("parmps.run")

# The out-of-plane depth a 2D force is integrated over [m].
DEPTH = 1.0

UNITS = {"pressure": "Pa", "level": "m", "force": "N", "displacement": "m"}


class Probe:
    """One probe's geometry: its sample points (None for a body's force) and how a value is
    made from their sums.

    ``row`` is ``(origin, direction, step, count, cross, cross_step, cross_count)`` as
    :class:`SampleRows` takes them; a force probe's ``area`` [m^2] is the wall area each
    sample stands for (in 2D per metre of depth, ``DEPTH``) and ``normals`` its normal.
    """

    def __init__(self, spec, spacing, dimension=2, rest=None, boxes=(), walls=None):
        """``rest``: a displacement probe's nodes' mean rest position; ``boxes``: the case's
        wall boxes ``(lower, upper)`` (a force probe on a wall box); ``walls``: name ->
        (points, lengths or areas, normals into the fluid) on the surface of each named
        [[wall]] (a force probe on one)."""
        self.name = spec["name"]
        self.kind = spec["kind"]
        self.spec = spec
        self.dimension = dimension
        # A solid-only case has no spacing: its probes read nodes only.
        self.radius = spec["radius"] * spacing if spacing is not None else 0.0
        self.full_sum = lattice_sum(spec["radius"], dimension)
        # The depth integrates the fill: its mean over the water must be 1, not its peak.
        self.mean_sum = mean_sum(spec["radius"], dimension)
        self.min_fill = spec["min_fill"]
        self.shape = (dimension,) if self.kind in ("force", "displacement") else ()
        self.rest = rest
        normal = np.zeros(dimension)
        if spec["normal"] is not None:
            normal = np.asarray(spec["normal"], float) / np.linalg.norm(spec["normal"])
        self.normal = normal
        self.rows, self.area, self.normals = [], [], []
        if self.kind == "pressure":
            # A point on a wall: half a spacing along the normal, the first fluid layer's line.
            self.rows = [(np.asarray(spec["position"]) + 0.5 * spacing * normal,
                          np.eye(dimension)[0], spacing, 1, None, 1.0, 1)]
        elif self.kind == "level":
            bottom, top = (np.asarray(p, float) for p in spec["line"])
            step = 0.25 * spacing
            count = int(math.floor((top[-1] - bottom[-1]) / step + 1e-9)) + 1
            self.rows = [(bottom, np.eye(dimension)[-1], step, count, None, 1.0, 1)]
            self.heights = bottom[-1] + step * np.arange(count)
        elif self.kind == "force" and spec.get("wall"):
            self._add_samples(*walls[spec["wall"]], spacing)
        elif self.kind == "force" and not spec["body"]:
            for lower, upper, outward in self._faces(spec, boxes):
                self._add_patch(lower, upper, outward, spacing)

    def _faces(self, spec, boxes):
        """The wall faces a force probe integrates over: ``(corner, corner, normal into the
        fluid)`` for its segment (2D) or patch (3D), or every face of its wall box."""
        if spec["segment"] or spec["patch"]:
            a, b = (np.asarray(p, float) for p in (spec["segment"] or spec["patch"]))
            return [(a, b, self.normal)]
        lower, upper = (np.asarray(c, float) for c in boxes[spec["wall_box"]])
        faces = []
        for axis in range(self.dimension):
            for side, plane in ((-1.0, lower[axis]), (1.0, upper[axis])):
                low, high = lower.copy(), upper.copy()
                low[axis] = high[axis] = plane
                faces.append((low, high, side * np.eye(self.dimension)[axis]))
        return faces

    def _add_patch(self, a, b, normal, spacing):
        """Samples every half spacing or less over the segment or axis-aligned rectangle
        with corners ``a`` and ``b``, shifted half a spacing along ``normal`` onto the
        centre line (plane) of the first fluid layer."""
        shift = 0.5 * spacing * normal
        if self.dimension == 2:
            length = float(np.linalg.norm(b - a))
            directions = [((b - a) / length, length)]
        else:
            directions = [(np.eye(len(a))[axis] * np.sign(b[axis] - a[axis]),
                           abs(b[axis] - a[axis]))
                          for axis in range(len(a)) if b[axis] != a[axis]]
        grid = []
        for direction, length in directions:
            # A length of a whole number of half spacings is that many samples, whatever
            # its round-off (0.06 / 0.005 is 12.000000000000002).
            count = max(1, math.ceil(length / (0.5 * spacing) * (1 - 1e-12)))
            grid.append((direction, length / count, count))
        (u, du, nu), (v, dv, nv) = grid if len(grid) == 2 else (grid[0], (None, 1.0, 1))
        origin = a + 0.5 * du * u + (0.5 * dv * v if v is not None else 0.0) + shift
        self.rows.append((origin, u, du, nu, v, dv, nv))
        self.area.append(du * (dv if v is not None else DEPTH))
        self.normals.append(normal)

    def _add_samples(self, points, weights, normals, spacing):
        """One sample a row at each of ``points`` on a wall's surface, moved half a spacing
        along its normal (into the fluid) onto the first fluid layer, standing for its
        length (2D, times DEPTH) or area (3D)."""
        for point, weight, normal in zip(points, weights, normals):
            self.rows.append((point + 0.5 * spacing * normal, np.eye(self.dimension)[0],
                              spacing, 1, None, 1.0, 1))
            self.area.append(weight * (DEPTH if self.dimension == 2 else 1.0))
            self.normals.append(normal)

    @property
    def sample_count(self):
        return sum(row[3] * row[6] for row in self.rows)

    def attributes(self):
        out = {"kind": self.kind, "units": UNITS[self.kind]}
        for key in ("position", "normal", "line", "segment", "patch", "nodes"):
            if self.spec[key] not in (None, []):
                out[key] = np.asarray(self.spec[key], float)
        if self.kind == "level":
            out["reading"] = self.spec["reading"]
        if self.spec["body"]:
            out["body"] = self.spec["body"]
        if self.kind == "force" and not self.spec["body"] and self.spec["wall_box"] >= 0:
            out["wall_box"] = self.spec["wall_box"]
        if self.kind == "force" and self.spec.get("wall"):
            out["wall"] = self.spec["wall"]
        if self.rows:
            out["radius"] = self.radius
            out["min_fill"] = self.min_fill
            out["kernel"] = "Wendland C2, Shepard-normalised"
        if self.kind == "force" and self.dimension == 2:
            out["depth"] = DEPTH
        return out

    def value(self, sums, bodies, traction=None):
        """``bodies``: name -> the body (its nodes' positions and fluid forces);
        ``traction``: the walls' viscous forces (:class:`parmps.fluid.wall_traction.
        WallTraction`), or None."""
        if self.kind == "displacement":
            body = bodies[self.spec["body"]]
            return body.position[self.spec["nodes"]].mean(axis=0) - self.rest
        if self.kind == "pressure":
            return float(shepard_pressure(sums, self.full_sum, self.min_fill)[0])
        if self.kind == "level":
            if self.spec["reading"] == "depth":
                return water_depth(sums, self.mean_sum, self.heights)
            return surface_height(sums, self.full_sum, self.heights)
        if not self.rows:
            return np.asarray(bodies[self.spec["body"]].total_fluid_force(), float)
        # A sample with too little fluid beside it is dry: no load there.
        pressure = np.nan_to_num(shepard_pressure(sums, self.full_sum, self.min_fill))
        force = np.zeros(self.dimension)
        if traction is not None and self.name in traction.blocks:
            # The tangential stress the surface's pressure leaves out (a wall or wall box).
            force += traction.viscous_force(self.name)
        offset = 0
        for row, area, normal in zip(self.rows, self.area, self.normals):
            count = row[3] * row[6]
            force -= normal * (pressure[offset:offset + count].sum() * area)
            offset += count
        return force


class Probes(Observer):
    """Every ``[[probe]]`` of the case (docs/design.md §5.1)."""

    name = "probes"

    def __init__(self, result, specs, spacing, model, flush_interval, end_time, bodies=(),
                 dimension=2, boxes=(), walls=None, domain=None, traction=None):
        """``bodies``: the case's [[body]] tables (a displacement probe's rest positions);
        ``boxes``: the case's wall boxes as ``(lower, upper)`` (a force probe on one);
        ``walls``: the named walls' surface samples (see :class:`Probe`); ``domain``: the
        domain (its periodic axes: a sample beside a seam sees across it); ``traction``: the
        viscous force on the walls the force probes read (a WallTraction), or None."""
        self.result = result
        self.traction = traction
        self.domain = domain
        self.comm = result.comm
        self.model = model
        by_name = {spec["name"] or f"body{k}": spec for k, spec in enumerate(bodies)}
        self.probes = [Probe(spec, spacing, dimension, rest_positions(by_name[spec["body"]])[
            spec["nodes"]].mean(axis=0) if spec["kind"] == "displacement" else None, boxes,
            walls)
            for spec in specs]
        # The widest support: how far beyond a periodic face a sample may look.
        self.reach = max((p.radius for p in self.probes), default=0.0)
        self.cadences = [SimulatedInterval(p.spec["interval"], end_time)
                         if p.spec["interval"] > 0 else None for p in self.probes]
        self.flush_cadence = SimulatedInterval(flush_interval, end_time)
        root = result.file.require_group("probes")
        self.series = []
        for probe in self.probes:
            # A continued run finds its groups in the file.
            group = root.require_group(probe.name)
            for key, value in probe.attributes().items():
                group.attrs[key] = value
            self.series.append(Series(group, {"time": (np.float64, ()),
                                              "value": (np.float64, probe.shape)}))
        self.csv_directory = os.path.join(result.directory, "probes")
        self._rows = {}
        self.resumed = False

    # -- the run -------------------------------------------------------------------------

    def start(self, state):
        log.info("probes: %s, written to %s", ", ".join(f"{p.name} ({p.kind})"
                                                        for p in self.probes), self.csv_directory)
        if self.comm.rank == 0:
            os.makedirs(self.csv_directory, exist_ok=True)
            for probe, series in zip(self.probes, self.series):
                axes = "xyz"[:probe.dimension]
                columns = {"force": "time," + ",".join(f"f{a}" for a in axes),
                           "displacement": "time," + ",".join(f"d{a}" for a in axes)}.get(
                    probe.kind, "time,value")
                with open(self._csv_path(probe), "w") as handle:
                    handle.write(f"# probe {probe.name}: {probe.kind} "
                                 f"[{UNITS[probe.kind]}], time [s]\n{columns}\n")
                    if self.resumed:
                        # A continued run: the rows up to its checkpoint, from result.h5.
                        # (No row when the run stopped before the probe's first sample.)
                        self._write_rows(handle, series.datasets["time"][:series.rows],
                                         series.datasets["value"][:series.rows])

    def observe(self, state):
        due = tuple(k for k, cadence in enumerate(self.cadences)
                    if cadence is None or cadence.due(state.time))
        if due:
            for k, value in zip(due, self.sample(state, due)):
                self.series[k].add({"time": state.time, "value": value})
        if self.flush_cadence.due(state.time):
            self.flush()

    def finish(self, state):
        self.flush()

    def sample(self, state, due):
        """The values of the probes ``due`` (indices) in the state as it stands."""
        rows = self._sample_rows(due)
        sums = None
        if rows is not None:
            position, kind, pressure, n = self._owned_with_images(state.particles)
            sums = kernel_sums(rows, position, kind, pressure, n, self.comm)
        bodies = {}
        if self.model is not None:
            bodies = {body.name: body for body in self.model.bodies}
        values, offset = [], 0
        for k in due:
            probe = self.probes[k]
            count = probe.sample_count
            values.append(probe.value(sums[offset:offset + count] if count else None, bodies,
                                      self.traction))
            offset += count
        return values

    def _owned_with_images(self, particles):
        """(position, kind, pressure, count) of the owned particles, and along a periodic
        axis their images within a support of a face too: a sample beside the seam sees
        the particles beyond it (each rank adds its owned ones: nothing counts twice)."""
        n = particles.n_owned
        position, kind = particles.position[:n], particles.kind[:n]
        pressure = particles.pressure[:n]
        if self.domain is None or not self.domain.is_periodic:
            return position, kind, pressure, n
        index, shift = self.domain.images(position, self.reach)
        return (np.concatenate([position, position[index] + shift]),
                np.concatenate([kind, kind[index]]),
                np.concatenate([pressure, pressure[index]]), n + len(index))

    def _sample_rows(self, due):
        # One row set per combination of due probes; most runs see one or two.
        if due not in self._rows:
            rows = [(row, self.probes[k].radius) for k in due for row in self.probes[k].rows]
            self._rows[due] = None if not rows else self._as_sample_rows(rows)
        return self._rows[due]

    @staticmethod
    def _as_sample_rows(rows):
        """SampleRows of ``(row, radius)`` pairs, a row as :class:`Probe` keeps it."""
        d = len(rows[0][0][0])
        column = list(zip(*(row for row, _ in rows)))
        cross = [np.zeros(d) if c is None else c for c in column[4]]
        return SampleRows(column[0], column[1], column[2], column[3],
                          [radius for _, radius in rows], cross, column[5], column[6])

    def flush(self):
        if self.comm.rank == 0:
            for probe, series in zip(self.probes, self.series):
                if not series.pending["time"]:
                    continue
                with open(self._csv_path(probe), "a") as handle:
                    self._write_rows(handle, series.pending["time"], series.pending["value"])
        for series in self.series:
            series.flush(self.comm.rank)

    @staticmethod
    def _write_rows(handle, times, values):
        """One CSV line per sample: its time, then its value's components (a scalar, or a
        vector of the probe's shape)."""
        for t, value in zip(times, values):
            handle.write(",".join(repr(float(v)) for v in (t, *np.ravel(value))) + "\n")

    def _csv_path(self, probe):
        return os.path.join(self.csv_directory, f"{probe.name}.csv")

    # -- what a checkpoint carries --------------------------------------------------------

    def checkpoint_state(self):
        """Plain arrays: each probe's next due time (NaN: every step) and rows written."""
        self.flush()
        return {"next_time": np.array([np.nan if c is None else c.next_time
                                       for c in self.cadences]),
                "rows": np.array([s.rows for s in self.series], np.int64),
                "next_flush": np.array([self.flush_cadence.next_time])}

    def restore_state(self, arrays):
        for cadence, next_time in zip(self.cadences, arrays["next_time"]):
            if cadence is not None:
                cadence.next_time = float(next_time)
        self.flush_cadence.next_time = float(arrays["next_flush"][0])
        # Rows written after the checkpoint (by a run that went on) are dropped.
        for series, rows in zip(self.series, arrays["rows"]):
            series.truncate(int(rows))
        self.resumed = True
