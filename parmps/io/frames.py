"""Particle frames in result.h5, each one array sorted by global id whatever the rank count.

``/frames/<step, 8 digits>`` holds ``FRAME_FIELDS`` of every particle and the
attributes ``time``, ``step`` and ``dt``; ``/vertex_index`` is 0, 1, 2, ... as
long as the largest frame, the particles' vertex connectivity in the XDMF; with
bodies, ``/frames/<step>/solids/<body>/position`` and ``velocity`` hold every node
(anchors included) in the body's own order, ``/solids/<body>/springs`` the mesh once
and ``/solids/<body>/surface`` its boundary facets (m, d) once (2D: the loop's edges; 3D:
outward triangles).
"""

import os

import numpy as np

from parmps.core.particles import Particles
from parmps.io.xdmf import write_xdmf

FRAME_FIELDS = ("id", "kind", "position", "velocity", "pressure", "number_density")
FRAME_ATTRIBUTES = ("time", "step", "dt")


class FrameWriter:
    """Writes frames into a :class:`~parmps.io.result.ResultFile` and keeps its XDMF current."""

    def __init__(self, result, dimension=2, solids=None, domain=None):
        self.result = result
        # Along a periodic axis a particle may stray past a face until it migrates: the
        # frames show it where it is, inside the domain.
        self.domain = domain if domain is not None and domain.is_periodic else None
        self.comm = result.comm
        self.dimension = dimension
        self.solids = solids
        self.frames = result.file.require_group("frames")
        # 0, 1, 2, ... as long as the largest frame: the XDMF's vertex connectivity
        # (ParaView's XDMF3 reader makes no cells from a Polyvertex without one).
        # A continued run finds it, and its frames, in the file.
        if "vertex_index" in result.file:
            self.vertex_index = result.file["vertex_index"]
        else:
            self.vertex_index = result.file.create_dataset(
                "vertex_index", shape=(0,), maxshape=(None,), chunks=(4096,), dtype=np.int64)
        # (step, time, total particles)
        self.frame_list = [(int(group.attrs["step"]), float(group.attrs["time"]),
                            len(group["id"])) for _, group in sorted(self.frames.items())]
        self.bodies = []
        if solids is not None:
            root = result.file.require_group("solids")
            for k, body in enumerate(solids.bodies):
                group = root.require_group(body.name)
                springs = solids.springs(k)
                surface = solids.surface(k)
                if "springs" not in group:
                    for key, value in solids.attributes(k).items():
                        group.attrs[key] = value
                    self._write_once(group, "springs", springs)
                    if surface is not None:
                        self._write_once(group, "surface", surface)
                # A result written before surfaces were stored has none.
                shape = group["surface"].shape if "surface" in group else (0, 0)
                self.bodies.append((body.name, len(body.position), len(springs), shape))

    def _write_once(self, group, name, array):
        """An integer array written once by rank 0 (collective creation)."""
        dataset = group.create_dataset(name, shape=array.shape, dtype=np.int64)
        if self.comm.rank == 0:
            dataset[...] = array

    def write(self, step, time, dt, particles):
        """Write the owned particles (and every body's nodes) as /frames/<step>; collective.

        The particles are first regrouped by blocks of ids, so the frame is one
        array in ascending id whatever the rank count.
        """
        group = self.frames.create_group(f"{step:08d}")
        group.attrs["time"] = time
        group.attrs["step"] = step
        group.attrs["dt"] = dt
        if self.domain is not None:
            n = particles.n_owned
            arrays = {name: array[:n] for name, array in particles.arrays.items()}
            arrays["position"] = self.domain.wrapped(arrays["position"])
            particles = Particles(arrays, n_owned=n, dimension=particles.dimension)
        total = write_by_id(group, particles, FRAME_FIELDS, self.comm)
        if self.solids is not None:
            solids = group.create_group("solids")
            for body in self.solids.bodies:
                sub = solids.create_group(body.name)
                for key in ("position", "velocity"):
                    data = getattr(body, key)
                    dataset = sub.create_dataset(key, shape=data.shape, dtype=np.float64)
                    if self.comm.rank == 0:
                        dataset[...] = data
        capacity = len(self.vertex_index)
        if total > capacity:
            self.vertex_index.resize((total,))
            if self.comm.rank == 0:
                self.vertex_index[capacity:] = np.arange(capacity, total, dtype=np.int64)
        self.frame_list.append((step, time, total))

    def drop_after(self, step):
        """Delete the frames after ``step`` (collective): those an interrupted run wrote
        after its checkpoint, which the continued run writes again."""
        for name in sorted(self.frames):
            if int(self.frames[name].attrs["step"]) > step:
                del self.frames[name]
        self.frame_list = [item for item in self.frame_list if item[0] <= step]

    def publish(self):
        """Flush the file and rewrite the XDMF so readers see every frame written so far."""
        self.result.file.flush()
        if self.comm.rank == 0:
            write_xdmf(self.result.xdmf_path, os.path.basename(self.result.path),
                       self.frame_list, len(self.vertex_index), self.dimension, self.bodies)


def write_by_id(group, particles, fields, comm):
    """Write ``fields`` of the owned particles into ``group`` as arrays sorted by global id,
    whatever the rank count; collective. Returns the particle count.

    The particles are first regrouped by blocks of ids, so each rank writes one
    contiguous block at the offset of an exclusive scan.
    """
    # Here, not at the top: reading frames back must not start MPI.
    from parmps.parallel.exchange import by_id_blocks
    owned, offset, total = by_id_blocks(particles, comm)
    count = owned.n_owned
    for name in fields:
        data = owned.arrays[name]
        dataset = group.create_dataset(name, shape=(total,) + data.shape[1:], dtype=data.dtype)
        if count:
            dataset[offset:offset + count] = data
    return total


def read_frame(path, step=None):
    """One frame of a result file as a dict of arrays sorted by id (the last frame by default).
    A shorthand of :func:`parmps.open_result`, which reads lazily."""
    from parmps.result import open_result
    with open_result(path) as result:
        frames = result.frames
        return (frames[-1] if step is None else frames.at_step(step)).as_dict()


def read_frames(path):
    """Every frame of a result file, each a dict of arrays sorted by id (a shorthand of
    :func:`parmps.open_result`)."""
    from parmps.result import open_result
    with open_result(path) as result:
        return [frame.as_dict() for frame in result.frames]
