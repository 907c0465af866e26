"""Periodic images: the ghosts that carry the particles near a periodic face across the seam.

Along a periodic axis (``domain.periodic``) a particle within the halo width of one face
is also needed beyond the opposite face, shifted by the period: that shifted copy is its
image. Each rank makes the images of its own particles (one per face it is near, and one
per corner where it is near faces of two or three periodic axes) and sends each to every
rank whose region, grown by the halo width, holds it: to a neighbour across a seam the
decomposition cuts, and to itself along an axis it does not cut (on one rank, every
image is its own). The regions are the decomposition's boxes, so the same code serves
slabs and blocks on any rank count; the images follow the decomposition's own ghosts,
in the order of the ranks that sent them, each sender's in its own order.

Every pair across the seam is then an ordinary pair of a particle and an image, found by
the pair search as any other: no kernel needs to know of the seam. :meth:`refresh`
copies the owners' current values into the images, the positions shifted again.
"""

import numpy as np

from parmps.core.particles import FIELDS, Particles
from parmps.parallel.exchange import alltoallv_rows, field_arrays, pack, unpack_into


class PeriodicImages:
    """The images of one rank's particles and where they went (see the module)."""

    def __init__(self, comm, domain, halo_width):
        self.comm = comm
        self.domain = domain
        self.halo_width = float(halo_width)
        self.clear()

    def clear(self):
        """No images (after a migration: the owned rows changed)."""
        self.count = 0
        self._index = np.empty(0, np.int64)
        self._shift = np.empty((0, self.domain.dimension))
        self._send_counts = np.zeros(self.comm.size, np.int64)
        self._recv_counts = np.zeros(self.comm.size, np.int64)

    def destinations(self, image_position, boxes):
        """(image rows, rank) of every image within the halo width of a rank's region;
        ``boxes``: (lower, upper) corners of each rank's region, +-inf where open."""
        h = self.halo_width
        rows, ranks = [], []
        for rank, (lower, upper) in enumerate(boxes):
            inside = np.all((image_position > lower - h) & (image_position < upper + h), axis=1)
            found = np.flatnonzero(inside)
            rows.append(found)
            ranks.append(np.full(len(found), rank, np.int64))
        return np.concatenate(rows), np.concatenate(ranks)

    def build(self, halo, n_owned, boxes):
        """``halo`` (owned rows then the decomposition's ghosts) with this rank's share of
        every rank's images appended; collective. Remembers what went where for refresh."""
        position = halo.position[:n_owned]
        index, shift = self.domain.images(position, self.halo_width)
        rows, rank = self.destinations(position[index] + shift, boxes)
        order = np.argsort(rank, kind="stable")
        self._index, self._shift = index[rows[order]], shift[rows[order]]
        self._send_counts = np.bincount(rank, minlength=self.comm.size).astype(np.int64)
        self._recv_counts = self._counts_received(self._send_counts)
        self.count = int(self._recv_counts.sum())
        self._start = len(halo)
        arrays = field_arrays(halo)
        position_slot = list(FIELDS).index("position")
        received = self._send(arrays, (position_slot,))
        combined = {}
        for name, array in zip(FIELDS, arrays):
            out = np.empty((len(halo) + self.count,) + array.shape[1:], array.dtype)
            out[:len(halo)] = array
            combined[name] = out
        unpack_into(received, list(combined.values()), self._start)
        return Particles(combined, n_owned=halo.n_owned)

    def refresh(self, targets, positions):
        """The owners' current values of ``targets`` (arrays over every row) into the image
        rows, in place; the arrays ``positions`` (indices into ``targets``) shifted."""
        received = self._send(targets, positions)
        unpack_into(received, targets, self._start)

    def _send(self, arrays, positions):
        gathered = [array[self._index] for array in arrays]
        for slot in positions:
            gathered[slot] = gathered[slot] + self._shift
        rows = pack(gathered, np.arange(len(self._index)))
        if self.comm.size == 1:
            return rows
        return alltoallv_rows(self.comm, rows, self._send_counts, self._recv_counts)

    def _counts_received(self, send_counts):
        if self.comm.size == 1:
            return send_counts.copy()
        received = np.empty(self.comm.size, np.int64)
        self.comm.Alltoall(send_counts, received)
        return received
