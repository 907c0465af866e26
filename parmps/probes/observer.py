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
                                    shepard_pressure,
                                    surface_height, water_depth)
from parmps.probes.settings import rest_positions
from parmps.run.observers import Observer
from parmps.run.schedule import SimulatedInterval

log = logging.getLogger("parmps.run")

# The out-of-plane depth a 2D force is integrated over [m].
DEPTH = 1.0

UNITS = {"pressure": "Pa", "level": "m", "force": "N", "displacement": "m"}


class Probe:
    """One probe's geometry: its row of sample points (None for a body's force) and how a
    value is made from their sums."""

    def __init__(self, spec, spacing, rest=None):
        """``rest``: a displacement probe's nodes' mean rest position (2,)."""
        self.name = spec["name"]
        self.kind = spec["kind"]
        self.spec = spec
        self.radius = spec["radius"] * spacing
        self.min_fill = spec["min_fill"]
        self.shape = (2,) if self.kind in ("force", "displacement") else ()
        self.rest = rest
        normal = np.zeros(2)
        if spec["normal"] is not None:
            normal = np.asarray(spec["normal"], float) / math.hypot(*spec["normal"])
        self.normal = normal
        # A point on a wall: half a spacing along the normal, the first fluid layer's line.
        shift = 0.5 * spacing * normal
        self.ds = 0.0
        if self.kind == "pressure":
            self.row = (np.asarray(spec["position"]) + shift, (1.0, 0.0), spacing, 1)
        elif self.kind == "level":
            bottom, top = (np.asarray(p, float) for p in spec["line"])
            step = 0.25 * spacing
            count = int(math.floor((top[-1] - bottom[-1]) / step + 1e-9)) + 1
            # Up the last axis, the vertical one.
            self.row = (bottom, np.eye(len(bottom))[-1], step, count)
            self.heights = bottom[-1] + step * np.arange(count)
        elif spec["segment"]:
            a, b = (np.asarray(p, float) for p in spec["segment"])
            length = math.hypot(*(b - a))
            count = max(1, math.ceil(length / (0.5 * spacing)))
            self.ds = length / count
            tangent = (b - a) / length
            self.row = (a + 0.5 * self.ds * tangent + shift, tangent, self.ds, count)
        else:
            self.row = None
        dimension = len(self.row[0]) if self.row else 2
        self.full_sum = lattice_sum(spec["radius"], dimension)
        # The depth integrates the fill: its mean over the water must be 1, not its peak.
        self.mean_sum = mean_sum(spec["radius"], dimension)

    def attributes(self):
        out = {"kind": self.kind, "units": UNITS[self.kind]}
        for key in ("position", "normal", "line", "segment", "nodes"):
            if self.spec[key] not in (None, []):
                out[key] = np.asarray(self.spec[key], float)
        if self.kind == "level":
            out["reading"] = self.spec["reading"]
        if self.spec["body"]:
            out["body"] = self.spec["body"]
        if self.row is not None:
            out["radius"] = self.radius
            out["min_fill"] = self.min_fill
            out["kernel"] = "Wendland C2, Shepard-normalised"
        if self.kind == "force":
            out["depth"] = DEPTH
        return out

    def value(self, sums, bodies):
        """``bodies``: name -> the body (its nodes' positions and fluid forces)."""
        if self.kind == "displacement":
            body = bodies[self.spec["body"]]
            return body.position[self.spec["nodes"]].mean(axis=0) - self.rest
        if self.kind == "pressure":
            return float(shepard_pressure(sums, self.full_sum, self.min_fill)[0])
        if self.kind == "level":
            if self.spec["reading"] == "depth":
                return water_depth(sums, self.mean_sum, self.heights)
            return surface_height(sums, self.full_sum, self.heights)
        if self.row is None:
            return np.asarray(bodies[self.spec["body"]].total_fluid_force(), float)
        # A sample with too little fluid beside it is dry: no load there.
        pressure = np.nan_to_num(shepard_pressure(sums, self.full_sum, self.min_fill))
        return -self.normal * (pressure.sum() * self.ds * DEPTH)


class Probes(Observer):
    """Every ``[[probe]]`` of the case (docs/design.md §5.1)."""

    name = "probes"

    def __init__(self, result, specs, spacing, model, flush_interval, end_time, bodies=()):
        """``bodies``: the case's [[body]] tables (a displacement probe's rest positions)."""
        self.result = result
        self.comm = result.comm
        self.model = model
        by_name = {spec["name"] or f"body{k}": spec for k, spec in enumerate(bodies)}
        self.probes = [Probe(spec, spacing, rest_positions(by_name[spec["body"]])[
            spec["nodes"]].mean(axis=0) if spec["kind"] == "displacement" else None)
            for spec in specs]
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
                columns = {"force": "time,fx,fy", "displacement": "time,dx,dy"}.get(
                    probe.kind, "time,value")
                with open(self._csv_path(probe), "w") as handle:
                    handle.write(f"# probe {probe.name}: {probe.kind} "
                                 f"[{UNITS[probe.kind]}], time [s]\n{columns}\n")
                    if self.resumed:
                        # A continued run: the rows up to its checkpoint, from result.h5.
                        times = series.datasets["time"][:series.rows]
                        values = series.datasets["value"][:series.rows].reshape(len(times), -1)
                        self._write_rows(handle, times, values)

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
            p = state.particles
            sums = kernel_sums(rows, p.position, p.kind, p.pressure, p.n_owned, self.comm)
        bodies = {}
        if self.model is not None:
            bodies = {body.name: body for body in self.model.bodies}
        values, offset = [], 0
        for k in due:
            probe = self.probes[k]
            count = probe.row[3] if probe.row is not None else 0
            values.append(probe.value(sums[offset:offset + count] if count else None, bodies))
            offset += count
        return values

    def _sample_rows(self, due):
        # One row set per combination of due probes; most runs see one or two.
        if due not in self._rows:
            rows = [self.probes[k].row for k in due if self.probes[k].row is not None]
            self._rows[due] = None if not rows else SampleRows(
                [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows],
                [r[3] for r in rows], [self.probes[k].radius for k in due
                                       if self.probes[k].row is not None])
        return self._rows[due]

    def flush(self):
        if self.comm.rank == 0:
            for probe, series in zip(self.probes, self.series):
                if not series.pending["time"]:
                    continue
                values = np.asarray(series.pending["value"], float).reshape(
                    len(series.pending["time"]), -1)
                with open(self._csv_path(probe), "a") as handle:
                    self._write_rows(handle, series.pending["time"], values)
        for series in self.series:
            series.flush(self.comm.rank)

    @staticmethod
    def _write_rows(handle, times, values):
        for t, row in zip(times, values):
            handle.write(",".join(repr(float(v)) for v in (t, *row)) + "\n")

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
