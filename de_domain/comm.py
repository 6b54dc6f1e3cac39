"""The MPI messages of a distributed DEM run (mpi4py), and nothing else.

* :class:`GhostExchange` — every step, the state the contact laws read of a
  ghost (position, velocity, acceleration, angular velocity: 12 float64) from its
  owner: one preallocated buffer per neighbour rank, non-blocking sends and
  receives, packed and unpacked by compiled loops. Why in Python between two
  compiled steps and not inside the compiled loop (numba-mpi): measured here, a
  message from inside an njit loop saves ≈ 1.5 µs and the return to Python ≈ 2 µs
  per step, < 0.5 % of a step of 40,000 particles per rank; numba-mpi makes every
  kernel that calls it uncacheable (ctypes pointers), i.e. recompiled on every
  run (README, "DEM under MPI").
* :func:`exchange_records` — at list rebuilds only (migration, new ghosts,
  contact history): a dict of arrays per destination rank, one all-to-all.
* :func:`gather_rows` — concatenation of per-rank rows on every rank, in rank order
  (:class:`RowGather`: the same every step, in kept buffers);
  :func:`sum_in_rank_order` — partial sums added in rank order (diagnostics).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from numba import njit

GHOST_COLUMNS = 12  # pos, vel, accel, angvel


@njit(cache=True)
def _pack(buffer, rows, pos, vel, accel, angvel):
    for k in range(rows.size):
        i = rows[k]
        for d in range(3):
            buffer[k, d] = pos[i, d]
            buffer[k, 3 + d] = vel[i, d]
            buffer[k, 6 + d] = accel[i, d]
            buffer[k, 9 + d] = angvel[i, d]


@njit(cache=True)
def _unpack(buffer, rows, pos, vel, accel, angvel):
    for k in range(rows.size):
        i = rows[k]
        for d in range(3):
            pos[i, d] = buffer[k, d]
            vel[i, d] = buffer[k, 3 + d]
            accel[i, d] = buffer[k, 6 + d]
            angvel[i, d] = buffer[k, 9 + d]


class GhostExchange:
    """Ghost state from the owners, every step.

    ``send[r]``: rows (of the arrays handed to :meth:`exchange`) of the owned
    particles rank r keeps as ghosts, ascending global id; ``receive[r]``: rows of
    the ghosts rank r owns, in the same order as r sends them."""

    TAG = 31

    def __init__(self, comm, send, receive):
        self.comm = comm
        self.send = {r: np.ascontiguousarray(rows, np.int64) for r, rows in send.items() if rows.size}
        self.receive = {r: np.ascontiguousarray(rows, np.int64) for r, rows in receive.items() if rows.size}
        self._send_buffers = {r: np.empty((rows.size, GHOST_COLUMNS)) for r, rows in self.send.items()}
        self._receive_buffers = {r: np.empty((rows.size, GHOST_COLUMNS)) for r, rows in self.receive.items()}

    @property
    def n_ghosts(self):
        return int(sum(rows.size for rows in self.receive.values()))

    @property
    def buffer_bytes(self):
        """Bytes of the buffers and row lists this rank holds."""
        return int(sum(b.nbytes for b in (*self._send_buffers.values(), *self._receive_buffers.values(),
                                          *self.send.values(), *self.receive.values())))

    @property
    def bytes_sent(self):
        """Bytes this rank sends per step."""
        return int(sum(b.nbytes for b in self._send_buffers.values()))

    def exchange(self, particles):
        """Overwrite the ghost rows of ``particles`` (a state.ParticleArrays) with their owners'."""
        requests = [self.comm.Irecv(buffer, source=r, tag=self.TAG) for r, buffer in self._receive_buffers.items()]
        for r, buffer in self._send_buffers.items():
            _pack(buffer, self.send[r], particles.pos, particles.vel, particles.accel, particles.angvel)
            requests.append(self.comm.Isend(buffer, dest=r, tag=self.TAG))
        MPI.Request.Waitall(requests)
        for r, buffer in self._receive_buffers.items():
            _unpack(buffer, self.receive[r], particles.pos, particles.vel, particles.accel, particles.angvel)


def exchange_records(comm, outgoing):
    """``outgoing[r]``: dict of arrays for rank r (None: nothing). Returns the dicts
    received, by source rank (only non-empty ones)."""
    received = comm.alltoall([outgoing.get(r) for r in range(comm.size)])
    return {r: d for r, d in enumerate(received) if d is not None}


def concatenate_records(parts, like):
    """Concatenate dicts of arrays (in the order given); ``like`` gives the empty shapes."""
    parts = [p for p in parts if p is not None]
    return {k: (np.concatenate([p[k] for p in parts]) if parts else np.zeros((0,) + v.shape[1:], v.dtype))
            for k, v in like.items()}


def sum_in_rank_order(comm, values):
    """``values`` (this rank's partial sums) added over the ranks in rank order: the same
    bits on every rank, for a given rank count."""
    values = np.asarray(values, dtype=np.float64)
    total = np.zeros_like(values)
    for part in comm.allgather(values):
        total += part
    return total


class RowGather:
    """Float64 rows of every rank, concatenated in rank order on every rank, through buffers
    kept between calls: the row counts (``Allgather``, with a flag and a value of each rank
    riding along), then the rows (``Allgatherv``) — for rows gathered every step (the facet
    contacts of :func:`de_domain.distributed.facet_vertex_forces`, with "a list rebuild is
    due" and the particles' largest displacement)."""

    def __init__(self, comm, columns):
        self.comm, self.columns = comm, int(columns)
        self._local = np.empty((0, self.columns))
        self._all = np.empty((0, self.columns))
        self._count = np.zeros(3)                 # (rows, flag, value) of this rank (counts exact in float64)
        self._counts = np.zeros((comm.size, 3))   # ... of every rank

    def local_rows(self, capacity):
        """The buffer this rank writes its rows into, with room for ``capacity`` rows at least."""
        if self._local.shape[0] < capacity:
            self._local = np.empty((max(int(capacity), 2 * self._local.shape[0]), self.columns))
        return self._local

    def gather(self, count, flag=False, value=0.0):
        """The first ``count`` rows of every rank's :meth:`local_rows` buffer, in rank order,
        whether ``flag`` is true on any rank and the largest ``value`` (collective)."""
        self._count[:] = count, bool(flag), value
        self.comm.Allgather(self._count, self._counts)
        counts = self._counts[:, 0].astype(np.int64)
        total = int(counts.sum())
        if self._all.shape[0] < total:
            self._all = np.empty((max(total, 2 * self._all.shape[0]), self.columns))
        gathered = self._all[:total]
        self.comm.Allgatherv(self._local[:count], [gathered, counts * self.columns])
        return gathered, bool(self._counts[:, 1].any()), float(self._counts[:, 2].max())


def gather_rows(comm, array):
    """Rows of ``array`` from every rank, concatenated in rank order, on every rank."""
    parts = comm.allgather(np.ascontiguousarray(array))
    return np.concatenate(parts) if parts else array
