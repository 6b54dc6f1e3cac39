"""The DEM over MPI ranks: owned particles, ghosts, migration, bit-identical results.

Each rank owns the particles of its slab (:mod:`de_domain.decomposition`) and
keeps ghost copies of the particles of other ranks within the ghost width. Its
arrays hold owned particles and ghosts together, **in ascending global id** (the
particle's index in the engine's input), with ``Particles.ghost`` marking the
ghosts. That one rule makes every result independent of the rank count:

* the pair half list is "j > i" by local index, i.e. by global id, so a pair
  straddling two ranks is computed on both, with i the lower id, the same
  operands, the same history — the same bits;
* each owned particle sums its i-side pairs (ascending id), its j-side pairs
  (ascending id), its walls and facets in the serial code's order (de_domain.fused);
* wall forces are summed over the contacts of all ranks in global-id blocks
  (the serial code's order), facet vertex forces over all ranks' active
  candidates sorted by (id, triangle) — both gathered on every rank.

One step is: the compiled step of :mod:`de_domain.fused` on this rank's arrays
(in the spatially sorted copies, which stay alive between list rebuilds), then
the ghost exchange (:class:`de_domain.comm.GhostExchange`), then an all-reduce of
"a list rebuild is due" (with facet meshes, carried by the gather of the facet
contacts). A rebuild moves every owned particle that left its slab to its new
owner with its wall and facet contact history, sends every pair history (from the
rank owning the pair's lower id) to the owners of both particles, re-cuts the slabs
when the counts per rank are uneven (:func:`de_domain.decomposition.needs_rebalance`),
sends the new ghosts and rebuilds the lists. Energy books are summed over ranks in rank order.

Clumps (docs/design.md §2.19): their members are particles like any other; every rank holds
every clump, advances those it owns a member of, and gets the loads of their members on other
ranks each step (:meth:`Domain.share_member_loads`, between the contacts and the clumps' update
of :meth:`Engine.step_on_copies`); each clump's state goes from the one rank that books it to all
at rebuilds and at the end of a run (:func:`sync_clumps`; :func:`share_clumps` chooses).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from numba import njit

from . import fused
from .comm import GhostExchange, RowGather, concatenate_records, exchange_records, gather_rows, sum_in_rank_order
from .decomposition import SlabDecomposition, balanced_cuts, needs_rebalance, spread_axis
from .neighbors import MAX_SPREAD, ContactRecords, record_keys
from .particles import ARRAY_FIELDS
from .state import BOOK_INITIALISED, MEMBER_COLUMNS

CLUMP_COLUMNS = 19  # a clump's state between ranks: pos, vel, quat, angmom, force, torque

ID_MASK = (1 << 32) - 1


class Domain:
    """One rank's share: communicator, decomposition, global ids of the local rows,
    the ghost exchange plan, and counters for the benchmarks."""

    def __init__(self, comm, n_global):
        self.comm = comm
        self.n_global = int(n_global)
        self.decomposition = None
        self.ids = np.empty(0, np.int64)
        self.exchange = None
        self.facet_contacts = RowGather(comm, 8)  # (global id, triangle, λ, F) of each facet contact
        self.member_loads = RowGather(comm, 1 + MEMBER_COLUMNS)  # (member slot, load) of members others need
        self.clump_states = RowGather(comm, 1 + CLUMP_COLUMNS)  # (clump, state) of the clumps this rank leads
        self.sent_members = np.zeros(0, np.bool_)  # per member slot: its load goes to the other ranks each step
        self._flag = np.zeros(1, np.int32)
        self.migrated = 0  # particles this rank sent away, all rebuilds
        self.rebuilds = 0

    def share_member_loads(self, clumps):
        """The loads (``clumps.member_load``, :data:`~de_domain.state.ClumpArrays`) of the members
        of clumps that straddle ranks, from their owners to every rank (collective): each rank
        then holds every member's load of the clumps it advances. A member has one owner: each
        row arrives once, with its owner's bits."""
        local = self.member_loads.local_rows(clumps.member_row.size)
        count = _sent_member_loads(self.sent_members, clumps.member_load, local)
        rows, _, _ = self.member_loads.gather(count)
        _place_member_loads(rows, clumps.member_load)

    def any_rank(self, flag):
        """Is ``flag`` true on any rank (collective, through a kept buffer)?"""
        self._flag[0] = bool(flag)
        self.comm.Allreduce(MPI.IN_PLACE, self._flag, op=MPI.MAX)
        return bool(self._flag[0])


class DistributedRun:
    """The run object (:mod:`de_domain.runs`) of an engine spread over the ranks of
    ``domain.comm``: the steps of :func:`run` and the collectives, in rank order where the
    order changes the bits."""

    def __init__(self, domain):
        self.domain = domain
        self.comm = domain.comm

    @property
    def is_root(self):
        return self.comm.rank == 0

    def run(self, engine, nsteps):
        run(engine, nsteps)

    def wall_totals(self, engine):
        wall_totals(engine)

    def minimum(self, value):
        return self.comm.allreduce(value, op=MPI.MIN)

    def maximum(self, value):
        return self.comm.allreduce(value, op=MPI.MAX)

    def broadcast(self, value):
        return self.comm.bcast(value)

    def concatenate(self, array):
        return np.concatenate(self.comm.allgather(array))

    def barrier(self):
        self.comm.Barrier()

    def books(self, engine, books):
        return reduce_books(engine, books)

    def owned_rows(self, engine):
        return gather_owned(engine)

    def contact_records(self, engine):
        return gather_records(engine)


@njit(cache=True)
def _sent_member_loads(sent, member_load, rows):
    """Rows (member slot, load) of the members ``sent``, into ``rows``; returns their count."""
    n = 0
    for k in range(sent.size):
        if sent[k]:
            rows[n, 0] = k
            for d in range(member_load.shape[1]):
                rows[n, 1 + d] = member_load[k, d]
            n += 1
    return n


@njit(cache=True)
def _place_member_loads(rows, member_load):
    """Each gathered row's load into its member's slot of ``member_load``."""
    for r in range(rows.shape[0]):
        k = int(rows[r, 0])
        for d in range(member_load.shape[1]):
            member_load[k, d] = rows[r, 1 + d]


def distribute(engine, particles, comm):
    """Keep this rank's slab of the global ``particles`` (identical on every rank);
    the ghosts come with the first list build."""
    domain = Domain(comm, particles.n)
    engine.domain = domain
    engine.runner = DistributedRun(domain)
    ids = np.arange(particles.n, dtype=np.int64)
    domain.decomposition = _decompose(comm, particles.pos, particles.radius, engine.neighbors.skin, gathered=True)
    mine = domain.decomposition.owner(particles.pos) == comm.rank
    domain.ids = ids[mine]
    engine.particles = particles.take(mine)
    engine.acceleration = engine.acceleration[mine].copy()
    share_clumps(engine)


def _decompose(comm, pos, radius, skin, gathered=False):
    """Slabs cut at equal particle counts along the axis of largest spread. ``pos``:
    every particle's (``gathered``) or this rank's owned ones."""
    lo = pos.min(axis=0) if pos.shape[0] else np.full(3, np.inf)
    hi = pos.max(axis=0) if pos.shape[0] else np.full(3, -np.inf)
    r_max = float(radius.max()) if radius.size else 0.0
    if not gathered:
        lo, hi = lo.copy(), hi.copy()
        comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        r_max = comm.allreduce(r_max, op=MPI.MAX)
    axis = spread_axis(lo, hi)
    coordinates = pos[:, axis] if gathered else gather_rows(comm, pos[:, axis])
    return SlabDecomposition(axis, balanced_cuts(coordinates, comm.size), 2.0 * r_max + skin)


def _rows(particles, acceleration, ids, mask):
    """The particle record of the rows ``mask``: every per-particle array, the
    acceleration and the global id."""
    out = {name: getattr(particles, name)[mask] for name in ARRAY_FIELDS}
    out["acceleration"] = acceleration[mask]
    out["id"] = ids[mask]
    return out


def rebuild(engine):
    """Migration, new decomposition if uneven, new ghosts, new lists (module docstring)."""
    domain = engine.domain
    comm = domain.comm
    check_finite(engine)
    sync_clumps(engine)  # every clump's state on every rank: a member may arrive where its clump was not advanced
    pending = engine.take_pending_records()  # a checkpoint's history, on every rank
    owned = engine.particles.owned
    if needs_rebalance(comm.allgather(int(owned.sum()))):
        domain.decomposition = _decompose(comm, engine.particles.pos[owned], engine.particles.radius[owned],
                                          engine.neighbors.skin)
    mine, history = _migrate(engine)
    targets = domain.decomposition.ghost_ranks(mine["pos"], comm.rank)
    outgoing = {r: {"particles": {k: v[targets[:, r]] for k, v in mine.items()}}
                for r in range(comm.size) if targets[:, r].any()}
    received = exchange_records(comm, outgoing)
    ghosts = concatenate_records([d["particles"] for d in received.values()], mine)
    _install(engine, mine, ghosts, ContactRecords(**history) if pending is None else pending)
    nl = engine.neighbors
    send = {r: nl.iperm[np.searchsorted(domain.ids, mine["id"][targets[:, r]])] for r in outgoing}
    receive = {r: nl.iperm[np.searchsorted(domain.ids, d["particles"]["id"])] for r, d in received.items()}
    domain.exchange = GhostExchange(comm, send, receive)
    share_clumps(engine)
    domain.rebuilds += 1


def _migrate(engine):
    """Owned particles that left the slab go to their new owner with their wall and facet
    histories; every pair history goes (from the rank owning the pair's lower id) to the
    owners of both particles. Returns this rank's new owned records (ascending id) and the
    contact history it keeps or received."""
    domain = engine.domain
    comm = domain.comm
    rank = comm.rank
    p = engine.particles
    ids = domain.ids
    owned = p.owned
    records = engine.neighbors.records(owned=owned)
    new_owner = domain.decomposition.owner(p.pos)  # ghosts included: their positions are current
    owner_of = {"pair": (new_owner[np.searchsorted(ids, records.pair_keys >> 32)],
                         new_owner[np.searchsorted(ids, records.pair_keys & ID_MASK)]),
                "wall": (new_owner[np.searchsorted(ids, records.wall_keys >> 32)],),
                "facet": (new_owner[np.searchsorted(ids, records.facet_keys >> 32)],)}

    def history_for(r):
        keep = {kind: np.logical_or.reduce([o == r for o in owners]) for kind, owners in owner_of.items()}
        return {k: getattr(records, k)[keep[k.split("_")[0]]] for k in ContactRecords._fields}

    leaving = owned & (new_owner != rank)
    outgoing = {}
    for r in range(comm.size):
        if r == rank:
            continue
        moving = leaving & (new_owner == r)
        history = history_for(r)
        if moving.any() or any(v.size for k, v in history.items() if k.endswith("keys")):
            outgoing[r] = {"particles": _rows(p, engine.acceleration, ids, moving), "history": history}
    received = exchange_records(comm, outgoing)
    domain.migrated += int(leaving.sum())
    staying = _rows(p, engine.acceleration, ids, owned & (new_owner == rank))
    mine = concatenate_records([staying] + [d["particles"] for d in received.values()], staying)
    order = np.argsort(mine["id"], kind="stable")
    kept = history_for(rank)
    history = concatenate_records([kept] + [d["history"] for d in received.values()], kept)
    return {k: v[order] for k, v in mine.items()}, history


def _install(engine, mine, ghosts, carried):
    """This rank's rows: ``mine`` (owned) and ``ghosts`` merged in ascending id; the lists
    built with the ``carried`` contact history."""
    local = concatenate_records([mine, ghosts], mine)
    order = np.argsort(local["id"], kind="stable")
    local = {k: v[order] for k, v in local.items()}
    ghost = np.ones(local["id"].size, np.bool_)
    ghost[np.argsort(order)[:mine["id"].size]] = False
    engine.domain.ids = local["id"]
    engine.install_rows(local, ghost, engine.domain.ids, carried)


def check_finite(engine):
    """Collective: raise the same FloatingPointError on every rank if any rank holds an
    owned particle whose position is not finite or that flew off (the serial list build's
    checks, agreed before particles are sent anywhere)."""
    p = engine.particles
    comm = engine.domain.comm
    pos = p.pos[p.owned]
    bad = np.flatnonzero(~np.isfinite(pos).all(axis=1))
    message = None
    if bad.size:
        message = (f"{bad.size} particle position(s) are not finite on rank {comm.rank} (first: particle "
                   f"{engine.domain.ids[p.owned][bad[0]]}); the run has diverged (time step above the critical "
                   "one, or a force or velocity set to NaN/inf?)")
    lo = pos.min(axis=0) if pos.shape[0] and not bad.size else np.full(3, np.inf)
    hi = pos.max(axis=0) if pos.shape[0] and not bad.size else np.full(3, -np.inf)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    spread = float(np.max(hi - lo)) if np.all(hi >= lo) else 0.0
    reach = engine.domain.decomposition.width
    messages = [m for m in comm.allgather(message) if m is not None]
    if messages:
        raise FloatingPointError(f"neighbour build: {messages[0]}")
    if not spread < MAX_SPREAD * reach:
        raise FloatingPointError(f"neighbour build: the particles spread over {spread:.3g} m, more than "
                                 f"{MAX_SPREAD:.0e} interaction ranges; the run has diverged (a force, "
                                 "velocity or time step far too large?)")


def shift_agreed(engine):
    """Is the particles' largest displacement that the rebuild test reads (the engine's
    ``particle_shift``) the largest over all ranks? It is when the last step gathered
    it with the facet contacts (:func:`facet_vertex_forces`) and the sorted copies hold the
    state since. The rest of the test (walls, facet vertices) is the same on every rank, so
    the test then is too: no all-reduce needed (the serial test's result: the largest
    displacement over the ranks is the serial one, bit for bit)."""
    return bool(engine.facets) and engine.copies_hold_state and engine.particle_shift >= 0.0


def run(engine, nsteps):
    """``nsteps`` distributed steps (module docstring), on the sorted copies (left
    holding the state at the end if ``engine.keep_sorted``)."""
    domain = engine.domain
    boundaries = engine.boundaries()  # read once: the steps advance them and write them back
    engine.book_boundary_jumps(boundaries)
    due = engine.lists_due(boundaries)  # this rank's part of the test
    agreed = shift_agreed(engine)  # is ``due`` already the same on every rank?
    for _ in range(int(nsteps)):
        if due if agreed else domain.any_rank(due):
            engine.write_back()
            rebuild(engine)
        copies, due = engine.step_on_copies(boundaries, domain.share_member_loads)
        domain.exchange.exchange(copies)
        if engine.facets:  # the flag rides with the facet contacts' gather
            due, agreed = facet_vertex_forces(engine, due), True
    if not engine.keep_sorted:
        engine.write_back()
    sync_clumps(engine)
    if engine.wall_forces_each_run:
        wall_totals(engine)
    else:
        engine.wall_forces_stale = bool(engine.walls)


def wall_totals(engine):
    """The force of all ranks' particles on each plane wall, summed in the serial
    order (global-id blocks of ``fused.PBLOCK``), on every rank."""
    if not engine.walls:
        return
    nl = engine.neighbors
    ids = engine.domain.ids
    comm = engine.domain.comm
    rows = np.concatenate([ids[nl.w_particle][:, None].astype(np.float64), nl.w_idx[:, None].astype(np.float64),
                           nl.w_force], axis=1)
    rows = gather_rows(comm, rows)
    gid = rows[:, 0].astype(np.int64)
    wall = rows[:, 1].astype(np.int32)
    order = np.lexsort((wall, gid)).astype(np.int32)
    totals = fused.wall_totals(len(engine.walls), wall, gid, order, np.ascontiguousarray(rows[:, 2:]), fused.PBLOCK)
    for w, plane in enumerate(engine.walls):
        plane.force = totals[w].copy()


@njit(cache=True, error_model="numpy")
def _facet_contact_rows(f_start, f_tri, ids, facet_lambda, facet_force, rows):
    """Rows (global id, triangle, λ (3), F (3)) of the facet candidates with a force, in
    candidate order, into ``rows``; returns their count."""
    n = 0
    for i in range(f_start.size - 1):
        for c in range(f_start[i], f_start[i + 1]):
            if facet_force[c, 0] != 0.0 or facet_force[c, 1] != 0.0 or facet_force[c, 2] != 0.0:
                rows[n, 0] = ids[i]
                rows[n, 1] = f_tri[c]
                for d in range(3):
                    rows[n, 2 + d] = facet_lambda[c, d]
                    rows[n, 5 + d] = facet_force[c, d]
                n += 1
    return n


def facet_vertex_forces(engine, due):
    """This step's facet vertex forces from the active candidates of all ranks, in
    (global id, triangle) order — the serial code's — and the impulses F Δt. Returns
    whether ``due`` (a list rebuild) is true on any rank, agreed in the same messages,
    which also leave the largest particle displacement of all ranks in the engine's
    ``particle_shift`` (:func:`shift_agreed`)."""
    nl = engine.neighbors
    gather = engine.domain.facet_contacts
    local = gather.local_rows(engine.facet_force.shape[0])
    count = _facet_contact_rows(nl.f_start, nl.f_tri, engine.domain.ids, engine.facet_lambda, engine.facet_force,
                                local)
    rows, due_anywhere, engine.particle_shift = gather.gather(count, due, engine.particle_shift)
    order = np.argsort(record_keys(rows[:, 0].astype(np.int64), rows[:, 1].astype(np.int64)), kind="stable")
    rows = rows[order]
    engine.set_facet_vertex_forces(rows[:, 1].astype(np.int64), np.ascontiguousarray(rows[:, 2:5]),
                                   np.ascontiguousarray(rows[:, 5:8]))
    return due_anywhere


def gather_owned(engine):
    """The particle records of every rank's owned particles, in global-id order, on
    every rank (collective)."""
    p = engine.particles
    rows = _rows(p, engine.acceleration, engine.domain.ids, p.owned)
    merged = concatenate_records(engine.domain.comm.allgather(rows), rows)
    order = np.argsort(merged["id"], kind="stable")
    return {k: v[order] for k, v in merged.items()}


def gather_records(engine):
    """Every rank's contact history (each pair once), sorted by key, on every rank."""
    records = engine.neighbors.records(owned=engine.particles.owned)
    out = {}
    for kind in ("pair", "wall", "facet"):
        keys = gather_rows(engine.domain.comm, getattr(records, f"{kind}_keys"))
        history = gather_rows(engine.domain.comm, getattr(records, f"{kind}_history"))
        order = np.argsort(keys, kind="stable")
        out[f"{kind}_keys"] = keys[order]
        out[f"{kind}_history"] = history[order]
    return ContactRecords(**out)


def reduce_books(engine, books):
    """Energy books of all ranks summed in rank order (the 'initialised' flag: any)."""
    comm = engine.domain.comm
    total = sum_in_rank_order(comm, books)
    total[BOOK_INITIALISED] = comm.allreduce(books[BOOK_INITIALISED], op=MPI.MAX)
    return total


def share_clumps(engine):
    """After the rows of this rank changed (collective): the clumps it advances (those it owns a
    member of), the one rank that books each clump and sends its state (:func:`sync_clumps`: the
    lowest that advances it), and the members whose loads go to the other ranks each step (its
    owned members of clumps advanced on more than one rank)."""
    c = engine.clumps
    if not c.count:
        return
    domain = engine.domain
    comm = domain.comm
    _, member_row = engine.clump_rows()
    clump_of = c.clump_of_members()
    held = np.zeros(c.count, np.bool_)
    held[clump_of[member_row >= 0]] = True
    holders = held.astype(np.int32)
    comm.Allreduce(MPI.IN_PLACE, holders, op=MPI.SUM)
    lead = np.where(held, comm.rank, comm.size).astype(np.int32)
    comm.Allreduce(MPI.IN_PLACE, lead, op=MPI.MIN)
    engine.set_clump_share(np.flatnonzero(held), lead == comm.rank)
    domain.sent_members = (holders[clump_of] > 1) & (member_row >= 0)


def sync_clumps(engine):
    """Every clump's state (centre, velocity, orientation, angular momentum, last resultant) on
    every rank, from the rank that books it (collective): a rank advances only the clumps it
    owns a member of, so the others' copies are old until this (at each rebuild, before the
    members migrate, and at the end of each run)."""
    c = engine.clumps
    if not c.count:
        return
    _, booked = engine.clump_share()
    mine = np.flatnonzero(booked)
    gather = engine.domain.clump_states
    local = gather.local_rows(mine.size)
    local[:mine.size] = np.column_stack([mine, c.pos[mine], c.vel[mine], c.quat[mine], c.angmom[mine],
                                         c.force[mine], c.torque[mine]])
    rows, _, _ = gather.gather(mine.size)
    k = rows[:, 0].astype(np.int64)
    c.pos[k], c.vel[k], c.quat[k] = rows[:, 1:4], rows[:, 4:7], rows[:, 7:11]
    c.angmom[k], c.force[k], c.torque[k] = rows[:, 11:14], rows[:, 14:17], rows[:, 17:20]
