"""Output: one HDF5 file per run, written collectively, and an XDMF sidecar (DESIGN.md §5).

Every rank writes its owned particles, sorted by global id, at an offset from an
exclusive scan of the counts; a rank with no particles still joins every
collective call (dataset creation, resizing). Metadata calls are collective in
HDF5's MPI-IO mode, so every rank makes them with the same arguments. After each
frame the file is flushed and the XDMF rewritten, so a run that stops early
leaves a readable file holding every frame it finished.
"""

import logging
import os

import numpy as np

from parmps import __version__

log = logging.getLogger(__name__)

DIAGNOSTICS = ("step", "time", "dt", "ksp_iterations", "ksp_residual", "max_speed",
               "kinetic_energy", "n_fluid", "wall_seconds")
FRAME_FIELDS = ("id", "kind", "position", "velocity", "pressure", "number_density")


def _h5py(comm):
    if comm.size > 1:
        # Debian's h5py picks its MPI build when it sees it runs under mpirun.
        os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")
    import h5py
    return h5py


def open_file(path, comm, mode="w"):
    h5py = _h5py(comm)
    if comm.size > 1:
        if not h5py.get_config().mpi:
            raise RuntimeError("h5py has no MPI support: install python3-h5py-mpi")
        return h5py.File(path, mode, driver="mpio", comm=comm)
    return h5py.File(path, mode)


class Output:
    """result.h5 and result.xdmf in ``directory`` for one run."""

    def __init__(self, comm, directory, case_text, extra_diagnostics=()):
        self.comm = comm
        self.directory = directory
        self.path = os.path.join(directory, "result.h5")
        self.xdmf_path = os.path.join(directory, "result.xdmf")
        self.file = open_file(self.path, comm)
        self.file.attrs["complete"] = False
        case = self.file.create_group("case")
        case.attrs["toml"] = case_text
        case.attrs["parmps_version"] = __version__
        case.attrs["ranks"] = comm.size
        self.frames = self.file.create_group("frames")
        # 0, 1, 2, ... as long as the largest frame: the XDMF's vertex
        # connectivity (ParaView's XDMF3 reader makes no cells without one).
        self.vertex_index = self.file.create_dataset(
            "vertex_index", shape=(0,), maxshape=(None,), chunks=(4096,), dtype=np.int64)
        diagnostics = self.file.create_group("diagnostics")
        self.diagnostic_names = DIAGNOSTICS + tuple(extra_diagnostics)
        self.diagnostics = {}
        for name in self.diagnostic_names:
            dtype = np.int64 if name in ("step", "ksp_iterations", "n_fluid") else np.float64
            self.diagnostics[name] = diagnostics.create_dataset(
                name, shape=(0,), maxshape=(None,), chunks=(1024,), dtype=dtype)
        self.pending = {name: [] for name in self.diagnostic_names}
        self.rows_written = 0
        self.frame_list = []  # (step, time, total particles)

    def add_diagnostics(self, values):
        """Queue one row of diagnostics (the same values on every rank)."""
        for name in self.diagnostic_names:
            self.pending[name].append(values.get(name, np.nan))

    def flush_diagnostics(self):
        count = len(self.pending["step"])
        if count == 0:
            return
        start = self.rows_written
        for name in self.diagnostic_names:
            dataset = self.diagnostics[name]
            dataset.resize((start + count,))
            if self.comm.rank == 0:
                dataset[start:start + count] = np.asarray(self.pending[name],
                                                          dtype=dataset.dtype)
            self.pending[name] = []
        self.rows_written += count

    def write_frame(self, step, time, dt, particles):
        """Write the owned particles (sorted by id) as /frames/<step>; collective.

        The particles are first regrouped by blocks of ids, so the frame is one
        array in ascending id whatever the rank count.
        """
        from parmps.parallel.slabs import by_id_blocks
        owned, offset, total = by_id_blocks(particles, self.comm)
        count = len(owned)
        group = self.frames.create_group(f"{step:08d}")
        group.attrs["time"] = time
        group.attrs["step"] = step
        group.attrs["dt"] = dt
        for name in FRAME_FIELDS:
            data = owned.arrays[name]
            dataset = group.create_dataset(name, shape=(total,) + data.shape[1:],
                                           dtype=data.dtype)
            if count:
                dataset[offset:offset + count] = data
        capacity = len(self.vertex_index)
        if total > capacity:
            self.vertex_index.resize((total,))
            if self.comm.rank == 0:
                self.vertex_index[capacity:] = np.arange(capacity, total, dtype=np.int64)
        self.frame_list.append((step, time, total))
        self.flush_diagnostics()
        self.file.flush()
        if self.comm.rank == 0:
            write_xdmf(self.xdmf_path, os.path.basename(self.path), self.frame_list,
                       len(self.vertex_index))

    def close(self, complete):
        self.flush_diagnostics()
        self.file.attrs["complete"] = bool(complete)
        self.file.close()


def write_xdmf(path, h5_name, frames, n_vertex_index):
    """An XDMF temporal collection of point clouds that ParaView opens directly.

    Each particle is one Polyvertex cell, so ParaView's default Surface view
    draws them. The connectivity is the first ``total`` entries of the
    ``/vertex_index`` dataset (``n_vertex_index`` long), cut by a HyperSlab: the
    XDMF3 reader makes no cells from a Polyvertex without connectivity, and the
    legacy XDMF reader crashes on an HDF item shorter than its dataset.
    """
    grids = []
    for step, time, total in frames:
        base = f"{h5_name}:/frames/{step:08d}"

        def item(name, dims, number="Float", precision=8):
            return (f'<DataItem Dimensions="{dims}" NumberType="{number}" '
                    f'Precision="{precision}" Format="HDF">{base}/{name}</DataItem>')

        if total:
            topology = f"""<Topology TopologyType="Polyvertex" NumberOfElements="{total}" NodesPerElement="1">
          <DataItem ItemType="HyperSlab" Dimensions="{total}" Type="HyperSlab">
            <DataItem Dimensions="3 1" NumberType="Int" Format="XML">0 1 {total}</DataItem>
            <DataItem Dimensions="{n_vertex_index}" NumberType="Int" Precision="8" Format="HDF">{h5_name}:/vertex_index</DataItem>
          </DataItem>
        </Topology>"""
        else:
            topology = '<Topology TopologyType="Polyvertex" NumberOfElements="0" NodesPerElement="1"/>'
        grids.append(f"""      <Grid Name="step {step}" GridType="Uniform">
        <Time Value="{time:.10g}"/>
        {topology}
        <Geometry GeometryType="XY">{item("position", f"{total} 2")}</Geometry>
        <Attribute Name="pressure" AttributeType="Scalar" Center="Node">{item("pressure", total)}</Attribute>
        <Attribute Name="velocity" AttributeType="Vector" Center="Node">{item("velocity", f"{total} 2")}</Attribute>
        <Attribute Name="number_density" AttributeType="Scalar" Center="Node">{item("number_density", total)}</Attribute>
        <Attribute Name="kind" AttributeType="Scalar" Center="Node">{item("kind", total, "Char", 1)}</Attribute>
        <Attribute Name="id" AttributeType="Scalar" Center="Node">{item("id", total, "Int", 8)}</Attribute>
      </Grid>""")
    text = ("""<?xml version="1.0" ?>
<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>
<Xdmf Version="2.0">
  <Domain>
    <Grid Name="particles" GridType="Collection" CollectionType="Temporal">
""" + "\n".join(grids) + """
    </Grid>
  </Domain>
</Xdmf>
""")
    temporary = path + ".tmp"
    with open(temporary, "w") as handle:
        handle.write(text)
    os.replace(temporary, path)


def read_frame(path, step=None):
    """One frame of a result file as a dict of arrays sorted by id (the last frame by default)."""
    import h5py
    with h5py.File(path, "r") as handle:
        names = sorted(handle["frames"])
        name = names[-1] if step is None else f"{step:08d}"
        group = handle["frames"][name]
        data = {field: group[field][()] for field in FRAME_FIELDS}
        data.update({key: group.attrs[key] for key in ("time", "step", "dt")})
    order = np.argsort(data["id"], kind="stable")
    for field in FRAME_FIELDS:
        data[field] = data[field][order]
    return data
