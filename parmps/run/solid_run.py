"""Solid-only runs and the solids' part of the output (DESIGN.md §5).

A case with ``[[body]]`` tables and no fluid or wall geometry runs here: no
scene, no decomposition, no fluid solver and no PETSc. Every rank advances the
(small) bodies alike and takes part in the collective HDF5 calls; rank 0 holds
the nodes as its particles and writes the data.

:class:`SolidOutput` extends the run's :class:`~parmps.io.output.Output` with

- ``/solids/<body>/time``, ``volume_error``, ``fluid_force`` (T x 2),
  ``centroid`` (T x 2): one row per step; ``/solids/<body>/springs`` (S x 2);
- ``/frames/<step>/solids/<body>/position`` and ``velocity`` (nodes in order);
- a second temporal collection in ``result.xdmf`` that draws every body's
  springs as a Polyline topology of 2-node segments, so ParaView shows the mesh.
"""

import logging
import math
import os

import numpy as np

from parmps.run import guards
from parmps.errors import RunFailure
from parmps.io.output import Output
from parmps.core.particles import SOLID, Particles
from parmps.solids.mass_spring.body import SolidSystem
from parmps.run.schedule import Schedule, run_collectively

log = logging.getLogger(__name__)

SOLID_SERIES = {"time": (), "volume_error": (), "fluid_force": (2,), "centroid": (2,)}
GEOMETRY_SECTIONS = ("fluid_block", "tank", "wall_box")


def is_solid_only(case):
    """A case with bodies and no fluid or wall particles: it needs no fluid machinery."""
    return bool(case.get("body")) and not any(case.get(name) for name in GEOMETRY_SECTIONS)


def node_particles(system):
    """Every body's nodes as solid-node particles, ids in body order."""
    bodies = system.bodies
    counts = [body.n_nodes for body in bodies]
    return Particles({
        "id": np.arange(sum(counts), dtype=np.int64),
        "kind": np.full(sum(counts), SOLID, np.int8),
        "position": np.concatenate([body.position for body in bodies]),
        "velocity": np.concatenate([body.velocity for body in bodies]),
        "body": np.repeat(np.arange(len(bodies), dtype=np.int32), counts),
        "node": np.concatenate([np.arange(n, dtype=np.int32) for n in counts]),
    })


class SolidOutput(Output):
    """The run's Output plus the per-body series, node frames and spring topology."""

    def __init__(self, comm, directory, case_text, system, extra_diagnostics=(),
                 extra_series=()):
        super().__init__(comm, directory, case_text, extra_diagnostics)
        self.system = system
        # More scalar series per body (e.g. fluid_inside in a coupled run).
        self.series_shapes = dict(SOLID_SERIES, **{name: () for name in extra_series})
        self.solid_groups = {}
        self.solid_series = {}
        root = self.file.create_group("solids")
        for body in system.bodies:
            group = root.create_group(body.name)
            springs = group.create_dataset("springs", shape=body.springs.shape, dtype=np.int64)
            group.attrs["rest_volume"] = body.rest_volume
            group.attrs["nodes"] = body.n_nodes
            if comm.rank == 0:
                springs[...] = body.springs
            self.solid_groups[body.name] = group
            for name, shape in self.series_shapes.items():
                group.create_dataset(name, shape=(0,) + shape, maxshape=(None,) + shape,
                                     chunks=(1024,) + shape, dtype=np.float64)
            self.solid_series[body.name] = {name: [] for name in self.series_shapes}
        self.solid_rows = 0

    def add_solid_row(self, time, extra=None):
        """Queue one row of every body's series (same values on every rank).

        ``extra`` maps a body name to the values of the extra series.
        """
        for name, values in self.system.diagnostics().items():
            series = self.solid_series[name]
            series["time"].append(time)
            values = dict(values, **(extra or {}).get(name, {}))
            for key in self.series_shapes:
                if key != "time":
                    series[key].append(values.get(key, np.nan))

    def flush_diagnostics(self):
        super().flush_diagnostics()
        count = len(next(iter(self.solid_series.values()))["time"]) if self.solid_series else 0
        if count == 0:
            return
        for name, series in self.solid_series.items():
            group = self.solid_groups[name]
            for key in self.series_shapes:
                dataset = group[key]
                dataset.resize((self.solid_rows + count,) + dataset.shape[1:])
                if self.comm.rank == 0:
                    dataset[self.solid_rows:] = np.asarray(series[key], dtype=np.float64)
                series[key] = []
        self.solid_rows += count

    def write_frame(self, step, time, dt, particles):
        # The parent writes the particles, flushes the series and writes the
        # particle XDMF; the node arrays and the springs' grids are added after.
        super().write_frame(step, time, dt, particles)
        group = self.frames[f"{step:08d}"].create_group("solids")
        for body in self.system.bodies:
            sub = group.create_group(body.name)
            for key in ("position", "velocity"):
                data = getattr(body, key)
                dataset = sub.create_dataset(key, shape=data.shape, dtype=np.float64)
                if self.comm.rank == 0:
                    dataset[...] = data
        self.file.flush()
        if self.comm.rank == 0:
            add_spring_grids(self.xdmf_path, os.path.basename(self.path), self.frame_list,
                             [(body.name, body.n_nodes, len(body.springs))
                              for body in self.system.bodies])


def spring_collection(h5_name, frames, bodies):
    """XDMF text: a temporal collection of every body's springs as 2-node polylines."""
    steps = []
    for step, time, _ in frames:
        grids = []
        for name, n_nodes, n_springs in bodies:
            base = f"{h5_name}:/frames/{step:08d}/solids/{name}"
            grids.append(f"""          <Grid Name="{name}" GridType="Uniform">
            <Topology TopologyType="Polyline" NumberOfElements="{n_springs}" NodesPerElement="2">
              <DataItem Dimensions="{n_springs} 2" NumberType="Int" Precision="8" Format="HDF">{h5_name}:/solids/{name}/springs</DataItem>
            </Topology>
            <Geometry GeometryType="XY">
              <DataItem Dimensions="{n_nodes} 2" NumberType="Float" Precision="8" Format="HDF">{base}/position</DataItem>
            </Geometry>
            <Attribute Name="velocity" AttributeType="Vector" Center="Node">
              <DataItem Dimensions="{n_nodes} 2" NumberType="Float" Precision="8" Format="HDF">{base}/velocity</DataItem>
            </Attribute>
          </Grid>""")
        steps.append(f"""      <Grid Name="solids step {step}" GridType="Collection" CollectionType="Spatial">
        <Time Value="{time:.10g}"/>
""" + "\n".join(grids) + """
      </Grid>""")
    return ("""    <Grid Name="springs" GridType="Collection" CollectionType="Temporal">
""" + "\n".join(steps) + """
    </Grid>
""")


def add_spring_grids(path, h5_name, frames, bodies):
    """Insert the spring collection into the XDMF file the particle writer made."""
    with open(path) as handle:
        text = handle.read()
    marker = "  </Domain>"
    if marker not in text:
        log.warning("%s has no </Domain>: springs not added to the XDMF", path)
        return
    text = text.replace(marker, spring_collection(h5_name, frames, bodies) + marker, 1)
    temporary = path + ".tmp"
    with open(temporary, "w") as handle:
        handle.write(text)
    os.replace(temporary, path)


class SolidRun:
    """A solid-only case on a communicator: the same interface as simulation.Run."""

    def __init__(self, case, case_text, comm, directory, end_time=None):
        self.case = case
        self.case_text = case_text
        self.comm = comm
        self.directory = directory
        self.end_time = case["time"]["end"] if end_time is None else end_time
        self.system = SolidSystem.from_case(case)
        settings = case["time"]
        # No fluid: the outer step is the fixed step, else dt_max.
        self.dt = settings["fixed_dt"] if settings["fixed_dt"] > 0 else settings["dt_max"]
        self.counts = {"solid node": sum(body.n_nodes for body in self.system.bodies)}
        self.time = 0.0
        self.step_number = 0

    def particles(self):
        if self.comm.rank == 0:
            return node_particles(self.system)
        return Particles.empty()

    def summary(self):
        counts = self.system.substep_counts(self.dt)
        return {
            "particles": dict(self.counts, total=self.counts["solid node"]),
            "bodies": {body.name: {
                "nodes": body.n_nodes, "springs": len(body.springs),
                "area": body.rest_volume, "volume_constraint": body.volume_constraint,
                "stability_limit": body.stability_limit(),
                "substep": self.system.substeps[body.name],
                "substeps_per_step": counts[body.name],
            } for body in self.system.bodies},
            "initial_dt": self.dt,
            "ranks": self.comm.size,
        }

    def execute(self):
        output = SolidOutput(self.comm, self.directory, self.case_text, self.system)
        return run_collectively(self.comm, output, lambda: self._loop(output))

    def _loop(self, output):
        case = self.case
        schedule = Schedule(self.end_time, case["time"]["max_steps"],
                            case["time"]["output_interval"])
        write_frames = case["output"]["frames"]
        for name, count in self.system.substep_counts(self.dt).items():
            log.info("body %s: %d substeps of %.3g s per step of %.3g s", name, count,
                     self.dt / count, self.dt)
        if write_frames:
            output.write_frame(0, 0.0, 0.0, self.particles())
        lower = np.asarray(case["domain"]["lower"])
        upper = np.asarray(case["domain"]["upper"])
        while schedule.running(self.time, self.step_number):
            step = self.step_number + 1
            dt = schedule.clip(self.time, self.dt)
            try:
                self.system.advance(self.time, dt)
            except RunFailure as exc:
                # The solver knows the time, the loop the step: name both.
                raise RunFailure(f"step {step}: {exc}") from None
            self.time += dt
            self.step_number = step
            self._check(step, lower, upper)
            speed = max((float(np.sqrt((body.velocity ** 2).sum(axis=1)).max())
                         for body in self.system.bodies), default=0.0)
            kinetic = sum(body.energy()[0] for body in self.system.bodies)
            output.add_diagnostics({"step": step, "time": self.time, "dt": dt,
                                    "ksp_iterations": 0, "ksp_residual": math.nan,
                                    "max_speed": speed, "kinetic_energy": kinetic,
                                    "n_fluid": 0, "wall_seconds": schedule.elapsed()})
            output.add_solid_row(self.time)
            if schedule.frame_due(self.time):
                if write_frames:
                    output.write_frame(step, self.time, dt, self.particles())
                else:
                    output.flush_diagnostics()
            if schedule.progress_due():
                log.info("step %d  t = %.4g s  %s", step, self.time, "  ".join(
                    f"{name}: volume error {values['volume_error']:.3e}"
                    for name, values in self.system.diagnostics().items()))
        output.flush_diagnostics()
        self.elapsed = schedule.elapsed()
        log.info("done: %d steps to t = %.4g s in %.1f s; %s", self.step_number, self.time,
                 self.elapsed, ", ".join(f"{name} volume error {v['volume_error']:.3e}"
                                         for name, v in self.system.diagnostics().items()))

    def _check(self, step, lower, upper):
        guards.check_bodies(self.system.bodies, step, self.time)
        for body in self.system.bodies:
            outside = np.any((body.position < lower) | (body.position > upper), axis=1)
            if outside.any():
                node = int(np.flatnonzero(outside)[0])
                x, y = body.position[node]
                raise RunFailure(f"step {step}: node {node} of body '{body.name}' left the "
                                 f"domain at ({x:.4g}, {y:.4g})")
