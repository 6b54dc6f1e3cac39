"""Neighbour search: cell (bin) lists + Verlet lists with a skin (docs/design.md §2.11).

* Sphere pairs are a half list (i < j), sorted by (i, j) (CSR ``i_start``); a second
  CSR (``j_start``, slot ``j_slot[p]`` of pair p) orders the pairs by their j, so that
  forces are summed per particle in a fixed order (deterministic for any thread
  count, no atomics).
* Sphere–facet candidates are sorted by (particle, triangle) (CSR ``f_start``/``f_tri``).
  The canonical order makes every force sum independent of when and on which grid
  the lists were built: results do not change with the rebuild frequency.
* Lists are rebuilt when the largest particle displacement since the last build
  plus the largest of (that, the largest facet-vertex displacement) exceeds the
  skin: for spheres alone this is the usual 2·max|Δx| > skin rule.
* Contact history (tangential spring force, rolling moment) is carried across a
  rebuild by matching sorted int64 pair keys (i·n + j, particle·n_tri + tri).
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from .walls import point_triangle_distance2

MAX_CELLS_PER_PARTICLE = 8

ContactRecords = namedtuple("ContactRecords", [
    "pair_keys", "pair_history",    # (m,) record_keys(id_i, id_j), id_i < id_j; (m, 6) spring, rolling moment
    "wall_keys", "wall_history",    # (c,) record_keys(id, wall); (c, 10) spring, moment, normal force, force
    "facet_keys", "facet_history",  # (c,) record_keys(id, triangle); (c, 6) spring, rolling moment
])
"""Contact history keyed by global particle ids: what survives a list rebuild, a
migration to another rank and a checkpoint (:meth:`NeighborList.records`)."""


def record_keys(first, second):
    """int64 key of (global id, partner): ``first · 2³² + second`` (ids below 2³¹)."""
    return (np.asarray(first, np.int64) << 32) | np.asarray(second, np.int64)


@njit(cache=True, error_model="numpy")
def insertion_sort(a, start, stop):
    """Sort a[start:stop] ascending in place (short neighbour segments)."""
    for k in range(start + 1, stop):
        v = a[k]
        m = k - 1
        while m >= start and a[m] > v:
            a[m + 1] = a[m]
            m -= 1
        a[m + 1] = v


@njit(parallel=True, cache=True, error_model="numpy")
def count_or_fill_pairs(pos, radius, ghost, body, skin, dims, cell_start, cell_particles, particle_cell, perm,
                        n_active, i_start, j_out, fill):
    """Half list (partners j > i) of particle perm[s], per perm position s; sorted by j.
    A pair of two ghosts is left out (no owned particle needs it), and so is a pair of two
    members of one clump (``body``: the clump of each particle, −1 for a free sphere)."""
    for s in prange(n_active):
        i = perm[s]
        cz = particle_cell[i] % dims[2]
        cy = (particle_cell[i] // dims[2]) % dims[1]
        cx = particle_cell[i] // (dims[1] * dims[2])
        count = 0
        start = 0
        if fill:
            start = i_start[s]
        for ax in range(max(cx - 1, 0), min(cx + 2, dims[0])):
            for ay in range(max(cy - 1, 0), min(cy + 2, dims[1])):
                for az in range(max(cz - 1, 0), min(cz + 2, dims[2])):
                    c = (ax * dims[1] + ay) * dims[2] + az
                    for q in range(cell_start[c], cell_start[c + 1]):
                        j = cell_particles[q]
                        if j <= i or (ghost[i] and ghost[j]) or (body[i] >= 0 and body[i] == body[j]):
                            continue
                        cut = radius[i] + radius[j] + skin
                        dx = pos[j, 0] - pos[i, 0]
                        dy = pos[j, 1] - pos[i, 1]
                        dz = pos[j, 2] - pos[i, 2]
                        if dx * dx + dy * dy + dz * dz < cut * cut:
                            if fill:
                                j_out[start + count] = j
                            count += 1
        if not fill:
            i_start[s + 1] = count
        else:
            insertion_sort(j_out, start, start + count)


@njit(cache=True, error_model="numpy")
def build_j_side(perm, iperm, i_start, pair_js):
    """The j-side CSR over perm positions: slots ``j_start[s]:j_start[s+1]`` hold the
    pairs in which particle perm[s] is j, by ascending i; ``j_slot[p]`` is pair p's slot."""
    n = perm.size
    counts = np.zeros(n + 1, np.int64)
    for p in range(pair_js.size):
        counts[pair_js[p] + 1] += 1
    j_start = np.cumsum(counts)
    fill = j_start[:-1].copy()
    j_slot = np.empty(pair_js.size, np.int32)
    for i in range(n):
        s = iperm[i]
        for p in range(i_start[s], i_start[s + 1]):
            sj = pair_js[p]
            j_slot[p] = fill[sj]
            fill[sj] += 1
    return j_start, j_slot


def morton_order(particle_cell, dims):
    """Particles sorted by the Morton (Z-order) code of their cell, then by index."""
    c = particle_cell.astype(np.int64)
    coords = (c // (dims[1] * dims[2]), (c // dims[2]) % dims[1], c % dims[2])
    key = np.zeros(c.size, np.int64)
    for bit in range(21):
        for axis in range(3):
            key |= ((coords[axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(key, kind="stable").astype(np.int32)


@njit(cache=True, error_model="numpy")
def pair_i_of(perm, i_start):
    """Particle index of the i-side of every pair of the half list."""
    out = np.empty(i_start[-1], np.int32)
    for s in range(perm.size):
        for p in range(i_start[s], i_start[s + 1]):
            out[p] = perm[s]
    return out


@njit(cache=True, error_model="numpy")
def build_wall_candidates(pos, radius, skin, perm, iperm, ghost, wall_point, wall_normal):
    """Plane walls within r + skin of each owned particle (CSR over perm positions),
    and the candidates in ascending particle order (for the wall-force totals)."""
    n = perm.size
    nw = wall_point.shape[0]
    w_start = np.zeros(n + 1, np.int64)
    for s in range(n):
        i = perm[s]
        c = 0
        if not ghost[i]:
            for w in range(nw):
                dist = 0.0
                for d in range(3):
                    dist += (pos[i, d] - wall_point[w, d]) * wall_normal[w, d]
                if dist < radius[i] + skin:
                    c += 1
        w_start[s + 1] = w_start[s] + c
    w_idx = np.empty(w_start[n], np.int32)
    for s in range(n):
        i = perm[s]
        c = w_start[s]
        if not ghost[i]:
            for w in range(nw):
                dist = 0.0
                for d in range(3):
                    dist += (pos[i, d] - wall_point[w, d]) * wall_normal[w, d]
                if dist < radius[i] + skin:
                    w_idx[c] = w
                    c += 1
    w_particle = np.empty(w_start[n], np.int32)
    w_order = np.empty(w_start[n], np.int32)
    k = 0
    for i in range(n):
        s = iperm[i]
        for c in range(w_start[s], w_start[s + 1]):
            w_particle[c] = i
            w_order[k] = c
            k += 1
    return w_start, w_idx, w_particle, w_order


#: particles spread over more than this many interaction ranges: a diverged run, not a model
MAX_SPREAD = 1e9


@njit(cache=True)
def build_cell_grid(pos, n_active, cell_size, max_cells):
    """Counting-sort particles into a uniform grid covering their bounding box.

    Returns (origin, cell_size, dims, cell_start, cell_particles, particle_cell).
    The cell size is enlarged until the number of cells is at most ``max_cells``.
    """
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = np.inf
        hi[d] = -np.inf
    for i in range(n_active):
        for d in range(3):
            lo[d] = min(lo[d], pos[i, d])
            hi[d] = max(hi[d], pos[i, d])
    for d in range(3):  # at most max_cells per axis, so the cell counts below fit an int64
        cell_size = max(cell_size, (hi[d] - lo[d]) / max_cells)
    dims = np.ones(3, dtype=np.int64)
    while True:
        total = 1
        for d in range(3):
            dims[d] = max(1, int(math.floor((hi[d] - lo[d]) / cell_size)) + 1)
            total *= dims[d]
        if total <= max_cells:
            break
        cell_size *= 1.26
    n_cells = dims[0] * dims[1] * dims[2]
    particle_cell = np.empty(n_active, dtype=np.int64)
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n_active):
        c = 0
        for d in range(3):
            k = min(int((pos[i, d] - lo[d]) / cell_size), dims[d] - 1)
            c = c * dims[d] + k
        particle_cell[i] = c
        counts[c + 1] += 1
    cell_start = np.cumsum(counts)
    fill = cell_start[:-1].copy()
    cell_particles = np.empty(n_active, dtype=np.int64)
    for i in range(n_active):
        c = particle_cell[i]
        cell_particles[fill[c]] = i
        fill[c] += 1
    return lo, cell_size, dims, cell_start, cell_particles, particle_cell


@njit(cache=True)
def _triangles_per_cell(vertices, triangles, reach, lo, cell_size, dims):
    """CSR cell → triangles whose bounding box grown by ``reach`` overlaps the cell."""
    n_cells = dims[0] * dims[1] * dims[2]
    n_tri = triangles.shape[0]
    ranges = np.empty((n_tri, 6), dtype=np.int64)
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for t in range(n_tri):
        ok = True
        for d in range(3):
            tmin = min(vertices[triangles[t, 0], d], vertices[triangles[t, 1], d], vertices[triangles[t, 2], d]) - reach
            tmax = max(vertices[triangles[t, 0], d], vertices[triangles[t, 1], d], vertices[triangles[t, 2], d]) + reach
            k0 = int(math.floor((tmin - lo[d]) / cell_size))
            k1 = int(math.floor((tmax - lo[d]) / cell_size))
            if k1 < 0 or k0 > dims[d] - 1:
                ok = False
            ranges[t, 2 * d] = max(k0, 0)
            ranges[t, 2 * d + 1] = min(k1, dims[d] - 1)
        if not ok:
            ranges[t, 1] = -1  # empty range
        for ax in range(ranges[t, 0], ranges[t, 1] + 1):
            for ay in range(ranges[t, 2], ranges[t, 3] + 1):
                for az in range(ranges[t, 4], ranges[t, 5] + 1):
                    counts[(ax * dims[1] + ay) * dims[2] + az + 1] += 1
    start = np.cumsum(counts)
    fill = start[:-1].copy()
    cell_tris = np.empty(start[-1], dtype=np.int64)
    for t in range(n_tri):
        for ax in range(ranges[t, 0], ranges[t, 1] + 1):
            for ay in range(ranges[t, 2], ranges[t, 3] + 1):
                for az in range(ranges[t, 4], ranges[t, 5] + 1):
                    c = (ax * dims[1] + ay) * dims[2] + az
                    cell_tris[fill[c]] = t
                    fill[c] += 1
    return start, cell_tris


@njit(parallel=True, cache=True)
def _count_or_fill_facets(pos, radius, ghost, skin, vertices, triangles, particle_cell, start, cell_tris,
                          n_active, f_start, f_out, fill):
    for i in prange(n_active):
        c = particle_cell[i]
        count = 0
        if ghost[i]:
            if not fill:
                f_start[i + 1] = 0
            continue
        cut = radius[i] + skin
        for s in range(start[c], start[c + 1]):
            t = cell_tris[s]
            d2 = point_triangle_distance2(pos[i, 0], pos[i, 1], pos[i, 2], vertices[triangles[t, 0]],
                                          vertices[triangles[t, 1]], vertices[triangles[t, 2]])
            if d2 < cut * cut:
                if fill:
                    f_out[f_start[i] + count] = t
                count += 1
        if not fill:
            f_start[i + 1] = count
        else:
            insertion_sort(f_out, f_start[i], f_start[i] + count)


def build_facet_list(pos, radius, ghost, n_active, skin, vertices, triangles, grid):
    """Sphere–triangle candidates within r + skin, grouped by particle (CSR)."""
    lo, cell_size, dims, cell_start, cell_particles, particle_cell = grid
    r_max = float(radius[:n_active].max())
    start, cell_tris = _triangles_per_cell(vertices, triangles, r_max + skin, lo, cell_size, dims)
    f_start = np.zeros(n_active + 1, dtype=np.int64)
    dummy = np.empty(0, dtype=np.int32)
    _count_or_fill_facets(pos, radius, ghost, skin, vertices, triangles, particle_cell, start, cell_tris,
                          n_active, f_start, dummy, False)
    f_start = np.cumsum(f_start)
    f_tri = np.empty(f_start[-1], dtype=np.int32)
    _count_or_fill_facets(pos, radius, ghost, skin, vertices, triangles, particle_cell, start, cell_tris,
                          n_active, f_start, f_tri, True)
    return f_start, f_tri


@njit(cache=True)
def transfer_history(old_keys, old_history, new_keys):
    """History rows for ``new_keys``: copied from the matching old key, else zero."""
    order = np.argsort(old_keys)
    sorted_keys = old_keys[order]
    new_history = np.zeros((new_keys.size, old_history.shape[1]))
    for p in range(new_keys.size):
        k = np.searchsorted(sorted_keys, new_keys[p])
        if k < sorted_keys.size and sorted_keys[k] == new_keys[p]:
            new_history[p, :] = old_history[order[k], :]
    return new_history


@njit(cache=True)
def max_displacement(pos, ref_pos, n_active):
    """Largest |x − x_ref| (serial: exact and deterministic); inf if any is NaN."""
    m = 0.0
    for i in range(n_active):
        d = (pos[i, 0] - ref_pos[i, 0]) ** 2 + (pos[i, 1] - ref_pos[i, 1]) ** 2 + (pos[i, 2] - ref_pos[i, 2]) ** 2
        m = max(m, d)
        if d != d:
            return math.inf
    return math.sqrt(m)


@njit(cache=True)
def moved_beyond_skin(particle_shift, pos, ref_pos, n_active, vertices, ref_vertices, wall_point, ref_wall_point,
                      skin):
    """The Verlet test of docs/design.md §2.11: d_p + max(d_p, d_b) > s, with d_p the largest
    displacement of the first ``n_active`` particles and d_b that of the facet vertices and
    wall points since the last build. ``particle_shift``: d_p if known (≥ 0: the last step's,
    ``state.CLOCK_PARTICLE_SHIFT``, the particles not moved since), else measured here."""
    dp = particle_shift if particle_shift >= 0.0 else max_displacement(pos, ref_pos, n_active)
    db = max_displacement(vertices, ref_vertices, vertices.shape[0])
    db = max(db, max_displacement(wall_point, ref_wall_point, wall_point.shape[0]))
    return dp + max(dp, db) > skin


@njit(cache=True)
def lists_outdated(particle_shift, pos, ref_pos, n_active, vertices, ref_vertices, wall_point, ref_wall_point,
                   wall_normal, ref_wall_normal, skin):
    """A wall turned, or :func:`moved_beyond_skin` (one compiled call)."""
    for w in range(wall_normal.shape[0]):
        for d in range(3):
            if wall_normal[w, d] != ref_wall_normal[w, d]:
                return True
    return moved_beyond_skin(particle_shift, pos, ref_pos, n_active, vertices, ref_vertices, wall_point,
                             ref_wall_point, skin)


class NeighborList:
    """Verlet lists (sphere pairs, plane-wall and sphere–facet candidates) with contact history.

    Pairs are stored grouped by their i-side particle (i < j) in the spatial order
    ``perm`` (see :mod:`de_domain.fused`): ``pair_j`` (m,), ``history`` (m, 6) =
    tangential spring force (3), rolling moment (3); ``pair_i`` is derived on demand.
    Plane-wall candidates: ``w_idx``/``w_particle`` (walls within r + skin at the
    build), ``w_hist`` (·, 6), ``w_fn``, ``w_force`` (force on the particle).
    ``facet_history``: (m_f, 6) per sphere–triangle candidate, same layout.
    """

    def __init__(self, skin, max_cells_per_particle=MAX_CELLS_PER_PARTICLE):
        self.skin = float(skin)
        self.max_cells_per_particle = max_cells_per_particle
        self.perm = None
        self.perm_step = 0
        self.iperm = np.empty(0, np.int32)
        self.i_start = np.zeros(1, np.int64)
        self.pair_js = np.empty(0, np.int32)
        self.rolling = False  # store the rolling moments (set by the engine: any pair with β_r > 0)
        self.ht = np.zeros((0, 3))
        self.hr = np.zeros((0, 3))
        self.j_start = np.zeros(1, np.int64)
        self.j_slot = np.empty(0, np.int32)
        self.f_start = np.zeros(1, np.int64)
        self.f_tri = np.empty(0, np.int32)
        self.facet_history = np.zeros((0, 6))
        self.w_start = np.zeros(1, np.int64)
        self.w_idx = np.empty(0, np.int32)
        self.w_particle = np.empty(0, np.int32)
        self.w_order = np.empty(0, np.int32)
        self.w_hist = np.zeros((0, 6))
        self.w_fn = np.zeros(0)
        self.w_force = np.zeros((0, 3))
        self.ref_pos = None
        self.ref_vertices = None
        self.ref_wall_point = np.zeros((0, 3))
        self.ref_wall_normal = np.zeros((0, 3))
        self.n_builds = 0
        self.ids = np.empty(0, np.int64)  # global id of each particle at the last build

    @property
    def pair_i(self):
        """Lower particle index of each stored pair."""
        if self.perm is None:
            return np.empty(0, np.int32)
        return pair_i_of(self.perm, self.i_start)

    @property
    def history(self):
        """(m, 6) copy: tangential spring force (3), rolling moment (3; zero without rolling)."""
        out = np.zeros((self.ht.shape[0], 6))
        out[:, :3] = self.ht
        if self.rolling:
            out[:, 3:] = self.hr
        return out

    def _set_history(self, history):
        self.ht = np.ascontiguousarray(history[:, :3])
        self.hr = np.ascontiguousarray(history[:, 3:]) if self.rolling else np.zeros((0, 3))

    @property
    def pair_j(self):
        """Higher particle index of each stored pair (``pair_js`` is its perm position)."""
        if self.perm is None:
            return np.empty(0, np.int32)
        return self.perm[self.pair_js]

    def needs_rebuild(self, pos, n_active, vertices, wall_point=None, wall_normal=None, ref_pos=None,
                      particle_shift=-1.0):
        """Did particles (``pos`` against ``ref_pos``, default the positions of the last
        build, in the same order; or their largest displacement ``particle_shift`` if ≥ 0),
        walls or vertices move more than the skin allows (:func:`lists_outdated`)?"""
        if self.ref_pos is None or self.ref_pos.shape[0] != n_active or self.perm is None:
            return True
        if wall_point is None:
            wall_point = wall_normal = np.zeros((0, 3))
        if wall_point.shape != self.ref_wall_point.shape:
            return True
        ref_vertices = self.ref_vertices if vertices.shape[0] else vertices
        return lists_outdated(float(particle_shift), pos, self.ref_pos if ref_pos is None else ref_pos, n_active,
                              vertices, ref_vertices, wall_point, self.ref_wall_point, wall_normal,
                              self.ref_wall_normal, self.skin)

    def build(self, pos, radius, n_active, vertices, triangles, wall_point=None, wall_normal=None,
              ghost=None, ids=None, carried=None, new_order=False, body=None):
        """Rebuild all lists and carry the contact history over by key.

        ``ids`` are the particles' global ids (default: their index), ascending, and
        ``ghost`` marks the copies of other ranks' particles (default: none); pairs
        of two ghosts are not listed, nor are the wall and facet candidates of a
        ghost. ``body``: each particle's clump (−1: a free sphere; default: all free); two
        members of one clump are never a pair. The history comes from ``carried`` (:class:`ContactRecords`; default:
        this list's own, :meth:`records`). The spatial order ``perm`` is kept unless
        ``new_order`` (or there is none yet, or the particle count changed)."""
        if wall_point is None:
            wall_point = wall_normal = np.zeros((0, 3))
        ghost = np.zeros(n_active, np.bool_) if ghost is None else ghost
        ids = np.arange(n_active, dtype=np.int64) if ids is None else np.asarray(ids, np.int64)
        carried = self.records() if carried is None else carried
        bad = np.flatnonzero(~np.isfinite(pos[:n_active]).all(axis=1))
        if bad.size:  # the grid would be sized from NaN/inf: stop with the cause instead
            raise FloatingPointError(f"neighbour build: {bad.size} particle position(s) are not finite (first: "
                                     f"particle {ids[bad[0]]}); the run has diverged (time step above the "
                                     "critical one, or a force or velocity set to NaN/inf?)")
        max_cells = max(1000, self.max_cells_per_particle * n_active)
        r_max = float(radius[:n_active].max()) if n_active else 0.0
        spread = float(np.max(np.ptp(pos[:n_active], axis=0))) if n_active else 0.0
        if not spread < MAX_SPREAD * (2.0 * r_max + self.skin):
            raise FloatingPointError(f"neighbour build: the particles spread over {spread:.3g} m, more than "
                                     f"{MAX_SPREAD:.0e} interaction ranges; the run has diverged (a force, "
                                     "velocity or time step far too large?)")
        grid = build_cell_grid(pos, n_active, max(2.0 * r_max + self.skin, 1e-300), max_cells)
        lo, cell_size, dims, cell_start, cell_particles, particle_cell = grid
        if new_order or self.perm is None or self.perm.size != n_active:
            self.perm = morton_order(particle_cell, dims)
            self.iperm = np.empty(n_active, np.int32)
            self.iperm[self.perm] = np.arange(n_active, dtype=np.int32)
        self.ids = ids
        perm = self.perm
        i_start = np.zeros(n_active + 1, dtype=np.int64)
        dummy = np.empty(0, dtype=np.int32)
        body = np.full(n_active, -1, np.int32) if body is None else body
        count_or_fill_pairs(pos, radius, ghost, body, self.skin, dims, cell_start, cell_particles, particle_cell, perm,
                            n_active, i_start, dummy, False)
        i_start = np.cumsum(i_start)
        pair_j = np.empty(i_start[-1], dtype=np.int32)
        count_or_fill_pairs(pos, radius, ghost, body, self.skin, dims, cell_start, cell_particles, particle_cell, perm,
                            n_active, i_start, pair_j, True)
        self.i_start = i_start
        self.pair_js = self.iperm[pair_j]
        self._set_history(transfer_history(carried.pair_keys, carried.pair_history,
                                           record_keys(ids[self.pair_i], ids[pair_j])))
        self.j_start, self.j_slot = build_j_side(perm, self.iperm, i_start, self.pair_js)
        # plane walls
        self.w_start, self.w_idx, self.w_particle, self.w_order = build_wall_candidates(
            pos, radius, self.skin, perm, self.iperm, ghost, wall_point, wall_normal)
        new_hist = transfer_history(carried.wall_keys, carried.wall_history,
                                    record_keys(ids[self.w_particle], self.w_idx))
        self.w_hist = np.ascontiguousarray(new_hist[:, :6])
        self.w_fn = np.ascontiguousarray(new_hist[:, 6])
        self.w_force = np.ascontiguousarray(new_hist[:, 7:])
        self.ref_wall_point = wall_point.copy()
        self.ref_wall_normal = wall_normal.copy()
        # facets
        if triangles.shape[0]:
            self.f_start, self.f_tri = build_facet_list(pos, radius, ghost, n_active, self.skin, vertices,
                                                        triangles, grid)
        else:
            self.f_start, self.f_tri = np.zeros(n_active + 1, np.int64), np.empty(0, np.int32)
        self.facet_history = transfer_history(carried.facet_keys, carried.facet_history,
                                              record_keys(ids[self._facet_particles()], self.f_tri))
        self.ref_pos = pos[:n_active].copy()
        self.ref_vertices = vertices.copy()
        self.n_builds += 1

    def records(self, owned=None):
        """The contact history by global ids (:class:`ContactRecords`), rows that are not
        all zero only. With ``owned`` (bool per particle), only the pairs whose i-side
        (lower id) is owned: each pair once over all ranks."""
        if self.perm is None:
            keys = np.zeros(0, np.int64)
            return ContactRecords(keys, np.zeros((0, 6)), keys, np.zeros((0, 10)), keys, np.zeros((0, 6)))
        ids = self.ids
        pair_i = self.pair_i
        history = self.history
        keep = np.any(history != 0.0, axis=1)
        if owned is not None:
            keep &= owned[pair_i]
        wall = np.concatenate([self.w_hist, self.w_fn[:, None], self.w_force], axis=1)
        live = np.any(wall != 0.0, axis=1)
        facet_live = np.any(self.facet_history != 0.0, axis=1)
        return ContactRecords(record_keys(ids[pair_i[keep]], ids[self.pair_j[keep]]), history[keep],
                              record_keys(ids[self.w_particle[live]], self.w_idx[live]), wall[live],
                              record_keys(ids[self._facet_particles()[facet_live]], self.f_tri[facet_live]),
                              self.facet_history[facet_live])

    def _facet_particles(self):
        counts = np.diff(self.f_start)
        return np.repeat(np.arange(counts.size, dtype=np.int64), counts)

    def memory_bytes(self):
        names = ("perm", "iperm", "i_start", "pair_js", "ht", "hr", "j_start", "j_slot", "f_start", "f_tri",
                 "facet_history", "w_start", "w_idx", "w_particle", "w_order", "w_hist", "w_fn", "w_force",
                 "ref_pos")
        return {f"neighbors.{k}": getattr(self, k).nbytes for k in names if getattr(self, k) is not None}

    STATE = ("perm", "i_start", "pair_js", "f_start", "f_tri", "facet_history", "w_start", "w_idx",
             "w_hist", "w_fn", "w_force", "ref_pos", "ref_vertices", "ref_wall_point", "ref_wall_normal")

    def state(self):
        """Arrays that make the lists and their history restartable bit-for-bit."""
        out = {} if self.perm is None else {k: getattr(self, k) for k in self.STATE}
        if self.perm is not None:
            out["history"] = self.history
        out.update(pair_i=self.pair_i, pair_j=self.pair_j, skin=np.float64(self.skin), n_builds=np.int64(self.n_builds),
                   perm_step=np.int64(self.perm_step))
        return out

    def set_state(self, state):
        self.skin = float(state["skin"])
        self.n_builds = int(state["n_builds"])
        self.perm_step = int(state["perm_step"])
        for k in self.STATE:
            setattr(self, k, state[k].copy())
        self._set_history(state["history"])
        n = self.perm.size
        self.ids = np.arange(n, dtype=np.int64)
        self.iperm = np.empty(n, np.int32)
        self.iperm[self.perm] = np.arange(n, dtype=np.int32)
        self.j_start, self.j_slot = build_j_side(self.perm, self.iperm, self.i_start, self.pair_js)
        self.w_particle = np.repeat(self.perm, np.diff(self.w_start)).astype(np.int32)
        self.w_order = np.argsort(self.w_particle, kind="stable").astype(np.int32)
