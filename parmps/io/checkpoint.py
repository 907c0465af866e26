"""OUTDIR/checkpoint.h5: everything the future of a run depends on (docs/design.md §5).

Layout: the file's attributes ``toml`` (the case the run was started with),
``parmps_version`` and ``ranks``; ``/particles/<field>``, every particle of
every kind sorted by global id whatever the rank count (the frames' layout,
with every field of :data:`parmps.core.particles.FIELDS`); ``/state/...``, a
tree of groups and datasets, one group per contributor: the run (time, step,
dt, particle steps, wall seconds), the stepper and its participants (bodies,
inlet counters), the observers (their cadences and series rows).

Contributors implement ``checkpoint_state()`` (collective; returns a nested
dict of arrays and scalars, the same on every rank) and ``restore_state(dict)``.

Written collectively into ``checkpoint.h5.tmp``; rank 0 renames it over
``checkpoint.h5`` only after every rank closed it, so a crash mid-write leaves
the previous checkpoint whole.
"""

import os

import numpy as np

from parmps import __version__
from parmps.core.particles import FIELDS, Particles
from parmps.io.frames import write_by_id
from parmps.io.result import open_file

CHECKPOINT = "checkpoint.h5"


def checkpoint_path(directory):
    return os.path.join(directory, CHECKPOINT)


def write_checkpoint(comm, directory, case_text, particles, tree):
    """Write the particles (owned rows of every rank) and the state ``tree``; collective.

    Returns the size of the file in bytes.
    """
    # Here, not at the top: reading a checkpoint back must not start MPI.
    path = checkpoint_path(directory)
    temporary = path + ".tmp"
    handle = open_file(temporary, comm, "w")
    try:
        handle.attrs["toml"] = case_text
        handle.attrs["parmps_version"] = __version__
        handle.attrs["ranks"] = comm.size
        write_by_id(handle.create_group("particles"), particles, FIELDS, comm)
        _write_tree(handle.create_group("state"), tree, comm.rank)
    finally:
        handle.close()
    # Every rank has closed the file before it takes the place of the last checkpoint.
    comm.Barrier()
    size = 0
    if comm.rank == 0:
        os.replace(temporary, path)
        size = os.path.getsize(path)
    return comm.bcast(size, root=0)


def _write_tree(group, tree, rank):
    # Metadata calls are collective in MPI-IO mode: every rank walks the same tree.
    for key in sorted(tree):
        value = tree[key]
        if isinstance(value, dict):
            _write_tree(group.create_group(key), value, rank)
            continue
        array = np.asarray(value)
        dataset = group.create_dataset(key, shape=array.shape, dtype=array.dtype)
        if rank == 0 and array.size:
            dataset[()] = array


class Checkpoint:
    """A checkpoint read back: ``case_text``, ``particles`` (every particle, by id),
    ``state`` (the tree) and ``ranks`` (the rank count that wrote it)."""

    def __init__(self, case_text, particles, state, ranks):
        self.case_text = case_text
        self.particles = particles
        self.state = state
        self.ranks = ranks


def has_checkpoint(directory):
    return os.path.isfile(checkpoint_path(directory))


def read_checkpoint(directory):
    """Read the whole checkpoint (every rank may call it; no MPI-IO needed to read)."""
    import h5py
    with h5py.File(checkpoint_path(directory), "r") as handle:
        case_text = str(handle.attrs["toml"])
        particles = Particles({name: handle["particles"][name][()] for name in FIELDS
                               if name in handle["particles"]})
        state = _read_tree(handle["state"])
        ranks = int(handle.attrs["ranks"])
    return Checkpoint(case_text, particles, state, ranks)


def read_case_text(directory):
    import h5py
    with h5py.File(checkpoint_path(directory), "r") as handle:
        return str(handle.attrs["toml"])


def _read_tree(group):
    import h5py
    tree = {}
    for key, item in group.items():
        if isinstance(item, h5py.Group):
            tree[key] = _read_tree(item)
        else:
            value = item[()]
            tree[key] = value.item() if np.ndim(value) == 0 else value
    return tree
