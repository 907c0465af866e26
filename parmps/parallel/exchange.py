"""What every decomposition shares: packed particle rows, exchanges, by-id blocks.

Particle data travels as packed bytes (one row of bytes per particle, all
fields side by side) through buffer-based calls, so nothing is pickled on the
per-step path. :func:`exchange` sends such rows to any set of neighbour ranks
at once; :func:`send_to_ranks` moves particles to arbitrary ranks in one
all-to-all; :func:`by_id_blocks` regroups particles by blocks of ids for
output, whatever decomposition holds them.
"""

import numpy as np
from mpi4py import MPI

from parmps.core.particles import FIELDS, Particles

# Message tags of the neighbour exchange: counts, then data.
_TAG_COUNT, _TAG_DATA = 711, 712


# --- packing per-particle arrays into bytes ---------------------------------------------------

def _row_bytes(array):
    return array.dtype.itemsize * int(np.prod(array.shape[1:], dtype=np.int64))


def pack(arrays, index):
    """Rows ``index`` of each array, packed side by side into a (n, row_bytes) uint8 array."""
    n = len(index)
    columns = []
    for array in arrays:
        rows = np.ascontiguousarray(array[index])
        per_row = int(np.prod(array.shape[1:], dtype=np.int64))
        columns.append(rows.reshape(n, per_row).view(np.uint8))
    if not columns:
        return np.empty((n, 0), np.uint8)
    return np.ascontiguousarray(np.concatenate(columns, axis=1))


def unpack_into(buffer, arrays, start):
    """Write the packed rows of ``buffer`` into ``arrays[start:start + len(buffer)]``."""
    m = len(buffer)
    offset = 0
    for array in arrays:
        width = _row_bytes(array)
        chunk = np.ascontiguousarray(buffer[:, offset:offset + width])
        array[start:start + m] = chunk.view(array.dtype).reshape((m,) + array.shape[1:])
        offset += width


def unpack_new(buffer, templates):
    """New arrays (like ``templates`` in dtype and trailing shape) from packed rows."""
    m = len(buffer)
    out = [np.empty((m,) + t.shape[1:], t.dtype) for t in templates]
    unpack_into(buffer, out, 0)
    return out


def field_arrays(particles):
    return [particles.arrays[name] for name in FIELDS]


def exchange(comm, neighbours, outgoing, counts=None):
    """Send ``outgoing[k]`` (packed rows) to ``neighbours[k]`` and receive from each of them.

    Collective over the neighbour relation, which must be symmetric (every rank
    that sends to r also receives from r). Non-blocking sends and receives, so
    all directions share one round of latency; with ``counts`` (rows expected
    from each neighbour) the count messages are skipped. Returns the received
    rows, one (m_k, row_bytes) uint8 array per neighbour, in ``neighbours`` order.
    """
    width = outgoing[0].shape[1] if outgoing else 0
    if counts is None:
        sent = [np.array([len(rows)], np.int64) for rows in outgoing]
        got = [np.zeros(1, np.int64) for _ in neighbours]
        requests = [comm.Irecv(buffer, source=r, tag=_TAG_COUNT)
                    for buffer, r in zip(got, neighbours)]
        requests += [comm.Isend(buffer, dest=r, tag=_TAG_COUNT)
                     for buffer, r in zip(sent, neighbours)]
        MPI.Request.Waitall(requests)
        counts = [int(buffer[0]) for buffer in got]
    incoming = [np.empty((int(m), width), np.uint8) for m in counts]
    requests = [comm.Irecv([buffer, MPI.BYTE], source=r, tag=_TAG_DATA)
                for buffer, r in zip(incoming, neighbours)]
    requests += [comm.Isend([np.ascontiguousarray(rows), MPI.BYTE], dest=r, tag=_TAG_DATA)
                 for rows, r in zip(outgoing, neighbours)]
    MPI.Request.Waitall(requests)
    return incoming


def by_id_blocks(particles, comm):
    """The owned particles regrouped so that rank r holds the r-th block of ids, sorted.

    Collective. Ids are split into ``comm.size`` equal ranges between the
    smallest and the largest id; each rank gets the particles of its range in
    ascending id, so writing each rank's particles at ``offset`` (returned, the
    exclusive scan of the counts) gives one array sorted by id whatever the rank
    count (for output). Returns (Particles, offset, total).
    """
    owned = particles.owned() if particles.n_ghost else particles
    if comm.size == 1:
        return sorted_by_id(owned), 0, owned.n_owned
    ids = owned.id
    bounds = np.array([-ids.min() if len(ids) else np.iinfo(np.int64).min,
                       ids.max() if len(ids) else np.iinfo(np.int64).min], np.int64)
    comm.Allreduce(MPI.IN_PLACE, bounds, op=MPI.MAX)
    low, high = -bounds[0], bounds[1]
    if high < low:  # no particles anywhere
        return owned, 0, 0
    span = high - low + 1
    # Block of each id: floor((id - low) * size / span), in exact integer arithmetic.
    destination = ((ids - low) * comm.size // span).astype(np.int64)
    block = sorted_by_id(send_to_ranks(owned, destination, comm))
    count = np.array([block.n_owned], np.int64)
    offset = np.zeros(1, np.int64)
    comm.Exscan(count, offset)
    total = np.zeros(1, np.int64)
    comm.Allreduce(count, total)
    return block, int(offset[0]) if comm.rank > 0 else 0, int(total[0])


def send_to_ranks(particles, destination, comm):
    """Every particle sent to rank ``destination[k]`` in one all-to-all; collective.

    Returns the particles this rank received (owned only, in sender-rank order).
    """
    arrays = field_arrays(particles)
    order = np.argsort(destination, kind="stable")
    buffer = pack(arrays, order)
    send_counts = np.bincount(destination, minlength=comm.size).astype(np.int64)
    recv_counts = np.empty(comm.size, np.int64)
    comm.Alltoall(send_counts, recv_counts)
    received = alltoallv_rows(comm, buffer, send_counts, recv_counts)
    return Particles(dict(zip(FIELDS, unpack_new(received, arrays))))


def alltoallv_rows(comm, buffer, send_counts, recv_counts):
    """Packed rows ``buffer`` (grouped by destination rank, ``send_counts`` of each) sent in
    one all-to-all; returns the rows received, ``recv_counts`` from each rank in rank order."""
    row = buffer.shape[1]
    received = np.empty((int(recv_counts.sum()), row), np.uint8)
    send_bytes = send_counts * row
    recv_bytes = recv_counts * row
    comm.Alltoallv([np.ascontiguousarray(buffer), (send_bytes, _displacements(send_bytes)),
                    MPI.BYTE],
                   [received, (recv_bytes, _displacements(recv_bytes)), MPI.BYTE])
    return received


def imbalance_of(counts):
    mean = counts.sum() / len(counts)
    return float(counts.max() / mean) if mean > 0 else 1.0


def _displacements(counts):
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def merge_by_id(particles, kept, incoming):
    """Owned rows ``kept`` of ``particles`` plus ``incoming`` (arrays in FIELDS order), by id.

    The kept rows are usually in ascending id already (migrate keeps them so):
    then the few incoming particles are merged in with one scatter per field
    instead of a concatenation and a sort.
    """
    ids = particles.arrays["id"][kept]
    incoming_ids = incoming[list(FIELDS).index("id")]
    k, m = len(kept), len(incoming_ids)
    if m == 0 or not np.all(ids[1:] > ids[:-1]):
        parts = [particles.select(kept), Particles(dict(zip(FIELDS, incoming)))]
        return sorted_by_id(Particles.concatenate(parts))
    order = np.argsort(incoming_ids, kind="stable")
    sorted_ids = incoming_ids[order]
    # Final slot of each row: its rank among the kept plus the incoming ids below it.
    # One gather per field from [all rows of particles, incoming rows].
    source = np.empty(k + m, np.int64)
    source[np.arange(k) + np.searchsorted(sorted_ids, ids)] = kept
    source[np.arange(m) + np.searchsorted(ids, sorted_ids)] = len(particles) + order
    merged = {}
    for name, extra in zip(FIELDS, incoming):
        merged[name] = np.concatenate([particles.arrays[name], extra]).take(source, axis=0)
    return Particles(merged)


def sorted_by_id(particles):
    ids = particles.arrays["id"]
    if len(ids) < 2 or np.all(ids[1:] > ids[:-1]):
        return particles
    return particles.select(np.argsort(ids, kind="stable"))
