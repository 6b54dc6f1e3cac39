"""Fused multi-step DEM kernels: the whole step of :class:`~de_domain.engine.Engine`.

One step is two parallel regions, inside one njit'd loop over steps that returns
to Python only when the Verlet lists must be rebuilt (or the requested steps are
done):

* region 1, per block of particles (in spatial order): every pair (i, j) of the
  half list whose i-side is a particle of the block — contact force on i, its
  n × F, overlap and contact history per pair; energy sums per block;
* region 2, per block of particles: the force/torque on each particle gathered
  from its i-side pairs (ascending j) then its j-side pairs (ascending i), the
  plane walls it may touch (ascending wall index), the facet triangles it may
  touch (ascending triangle index, :func:`de_domain.walls.facet_contacts_of`),
  gravity, background damping and the leapfrog update; energy sums and the largest
  displacement per block;
* serial: energy books, facet vertex forces and impulses, wall and vertex motion,
  the rebuild test.

Time integration (DESIGN.md §2; thesis Eq. 3.38–3.44), per DOF with resultant F
(contacts + gravity):

    F_d = −α_b |F| sign(v^{n−½}) − α_v m v^{n−½}     (Cundall local + viscous)
    v^{n+½} = v^{n−½} + Δt (F + F_d)/m,   x^{n+1} = x^n + Δt v^{n+½}

the same for rotations with I and the torque (no gravity). A blocked DOF keeps its
velocity, a prescribed DOF takes its prescribed velocity; the reaction they need
does work, booked as boundary work. Energies at tⁿ use v^n = (v^{n−½} + v^{n+½})/2,
with which the leapfrog kinetic-energy change equals Σ F·v^n Δt exactly.

Ordering and determinism. Particles keep their positions in the public arrays;
the loops visit them in a spatial (cell-list) order ``perm`` for cache locality.
``perm`` is fixed when the lists are first built and refreshed every
``PERM_EVERY`` steps (on the step count, never on rebuilds), so results do not
depend on the thread count or the rebuild frequency. Every per-particle sum is
taken in a canonical order (pairs by original index, i-side before j-side, walls
by index, facets by triangle), so positions, velocities, forces, torques, contact
histories and wall forces are bit-identical for any thread count, any skin (list
rebuild frequency) and either storage path (in place through ``perm``, or spatially
sorted copies); only the energy books are summed in block order. ``in_order`` says the arrays are
the spatially sorted copies (index = perm position): the kernels then skip the
``perm`` lookup (one dependent load less per pair). Particle, pair and slot indices
are cast to unsigned (``np.uint64``) before they index arrays: Numba then emits no
negative-index wraparound (a compare and a select per array access; −10 % in region 1).

Storage (CSR over perm positions ``s``): pairs of particle ``perm[s]`` as i-side are
``i_start[s]:i_start[s+1]`` (partner ``pair_j``, sorted by index); its j-side pairs
are the slots ``j_start[s]:j_start[s+1]`` of ``j_rec`` (sorted by i; pair p writes
its force and torque on j to slot ``j_slot[p]``). Plane-wall candidates
(walls within r + skin at the build) are ``w_start[s]:w_start[s+1]`` with their
own sparse history. Facet candidates are a CSR over the public particle index
(``f_start``/``f_tri``, reached through ``orig[s]``).
"""
import math

import numpy as np
from numba import njit, prange

from .contact_laws import FASTMATH, HERTZ, contact_force, linear_normal_stiffness, released_energy
from .walls import facet_contacts_of, facet_vertex_forces

PBLOCK = 256          # particles per parallel work item (and per energy block)
PERM_EVERY = 100_000  # steps between refreshes of the spatial order
N_E1 = 5              # pair energies: e_normal, e_tangential, e_rolling, friction, damping
N_E2 = 11             # wall energies (6: work, e_n, e_t, e_r, friction, damping) + integrate (5)
N_BOOKS = 23          # state 6, acc 5, first 5, last 5, initial_total, initialised


# --------------------------------------------------------------------------- building
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
def count_or_fill_pairs(pos, radius, skin, dims, cell_start, cell_particles, particle_cell, perm,
                        n_active, i_start, j_out, fill):
    """Half list (partners j > i) of particle perm[s], per perm position s; sorted by j."""
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
                        if j <= i:
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
    out = np.empty(i_start[-1], np.int32)
    for s in range(perm.size):
        for p in range(i_start[s], i_start[s + 1]):
            out[p] = perm[s]
    return out


@njit(cache=True, error_model="numpy")
def build_wall_candidates(pos, radius, skin, perm, iperm, n_owned, wall_point, wall_normal):
    """Plane walls within r + skin of each owned particle (CSR over perm positions),
    and the candidates in ascending particle order (for the wall-force totals)."""
    n = perm.size
    nw = wall_point.shape[0]
    w_start = np.zeros(n + 1, np.int64)
    for s in range(n):
        i = perm[s]
        c = 0
        if i < n_owned:
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
        if i < n_owned:
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


# --------------------------------------------------------------------------- stepping
@njit(cache=True, error_model="numpy", fastmath=FASTMATH)  # region 1 only (contact_laws.FASTMATH)
def _pair_block(b, in_order, law, dt, pos, vel, accel, angvel, radius, mass, material, young, pair_params,
                perm, i_start, pair_js, j_slot, ht, hr, rolling, j_rec, pair_ov, force, torque, e1):
    """Region 1 work item: the i-side pairs of perm positions [b·PBLOCK, (b+1)·PBLOCK).

    ``j_rec[j_slot[p]]`` = force (3) and torque (3) pair p puts on its j, written in
    the j-side order that region 2 reads contiguously; ``pair_ov[p]`` = overlap (NaN right
    after a rebuild: unknown; −1 for a pair that was apart in this and the last step,
    whose distance is then not taken). History: tangential spring ``ht[p]``; rolling moment
    ``hr[p]`` only if ``rolling`` (any pair with β_r > 0; else it is identically
    zero and not stored). The i-side part of each particle's force/torque sum
    (ascending j) is written to ``force``/``torque``; region 2 continues it with the
    j-side pairs."""
    n = perm.size
    en = 0.0
    et = 0.0
    er = 0.0
    fr = 0.0
    dm = 0.0
    for s in range(b * PBLOCK, min((b + 1) * PBLOCK, n)):
        i = np.uint64(s) if in_order else np.uint64(perm[s])
        ri = radius[i]
        mi = material[i]
        sfx = 0.0; sfy = 0.0; sfz = 0.0
        stx = 0.0; sty = 0.0; stz = 0.0
        for p in range(i_start[s], i_start[s + 1]):
            j = np.uint64(pair_js[p]) if in_order else np.uint64(perm[pair_js[p]])
            dx = pos[j, 0] - pos[i, 0]
            dy = pos[j, 1] - pos[i, 1]
            dz = pos[j, 2] - pos[i, 2]
            d2 = dx * dx + dy * dy + dz * dz
            rj = radius[j]
            previous = pair_ov[p]
            if previous <= 0.0 and d2 >= (ri + rj) * (ri + rj):
                pair_ov[p] = -1.0  # apart now and last step: history and j_rec are already zero
                continue
            dist = np.sqrt(d2)
            overlap = ri + rj - dist
            pair_ov[p] = overlap
            if overlap <= 0.0:
                if previous <= 0.0:
                    continue
                mrx = 0.0; mry = 0.0; mrz = 0.0
                if rolling:
                    mrx = hr[p, 0]; mry = hr[p, 1]; mrz = hr[p, 2]
                if (ht[p, 0] != 0.0 or ht[p, 1] != 0.0 or ht[p, 2] != 0.0
                        or mrx != 0.0 or mry != 0.0 or mrz != 0.0):
                    k_lin = linear_normal_stiffness(young[mi], ri, young[material[j]], rj)
                    r_red = ri * rj / (ri + rj)
                    fr += released_energy(law, pair_params, mi, material[j], k_lin, r_red, r_red, ht[p, 0], ht[p, 1],
                                          ht[p, 2], mrx, mry, mrz)
                    for k in range(3):
                        ht[p, k] = 0.0
                        if rolling:
                            hr[p, k] = 0.0
                q = np.uint64(j_slot[p])
                for k in range(6):
                    j_rec[q, k] = 0.0
                continue
            inv_dist = 1.0 / dist
            nx = dx * inv_dist
            ny = dy * inv_dist
            nz = dz * inv_dist
            ai = ri - 0.5 * overlap
            aj = rj - 0.5 * overlap
            vix = vel[i, 0] + ai * (angvel[i, 1] * nz - angvel[i, 2] * ny)
            viy = vel[i, 1] + ai * (angvel[i, 2] * nx - angvel[i, 0] * nz)
            viz = vel[i, 2] + ai * (angvel[i, 0] * ny - angvel[i, 1] * nx)
            vjx = vel[j, 0] - aj * (angvel[j, 1] * nz - angvel[j, 2] * ny)
            vjy = vel[j, 1] - aj * (angvel[j, 2] * nx - angvel[j, 0] * nz)
            vjz = vel[j, 2] - aj * (angvel[j, 0] * ny - angvel[j, 1] * nx)
            k_lin = linear_normal_stiffness(young[mi], ri, young[material[j]], rj)
            r_red = ri * rj / (ri + rj) if law == HERTZ or rolling else 0.0  # R* (Hertz), r̄ (rolling)
            m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
            dvn = 0.5 * dt * ((accel[j, 0] - accel[i, 0]) * nx + (accel[j, 1] - accel[i, 1]) * ny
                              + (accel[j, 2] - accel[i, 2]) * nz)
            mrx = 0.0; mry = 0.0; mrz = 0.0
            if rolling:
                mrx = hr[p, 0]; mry = hr[p, 1]; mrz = hr[p, 2]
            res = contact_force(law, pair_params, mi, material[j], nx, ny, nz, overlap,
                                vjx - vix, vjy - viy, vjz - viz, dvn,
                                angvel[j, 0] - angvel[i, 0], angvel[j, 1] - angvel[i, 1],
                                angvel[j, 2] - angvel[i, 2], k_lin, r_red, r_red, m_eff,
                                ht[p, 0], ht[p, 1], ht[p, 2], mrx, mry, mrz, dt)
            fx, fy, fz = res[0], res[1], res[2]
            for k in range(3):
                ht[p, k] = res[3 + k]
                if rolling:
                    hr[p, k] = res[6 + k]
            cx = ny * fz - nz * fy
            cy = nz * fx - nx * fz
            cz = nx * fy - ny * fx
            q = np.uint64(j_slot[p])  # j gets −F and (a_j n) × F − M_r
            j_rec[q, 0] = -fx
            j_rec[q, 1] = -fy
            j_rec[q, 2] = -fz
            if rolling:
                j_rec[q, 3] = aj * cx - res[6]
                j_rec[q, 4] = aj * cy - res[7]
                j_rec[q, 5] = aj * cz - res[8]
            else:
                j_rec[q, 3] = aj * cx
                j_rec[q, 4] = aj * cy
                j_rec[q, 5] = aj * cz
            sfx += fx; sfy += fy; sfz += fz
            stx += ai * cx + res[6]
            sty += ai * cy + res[7]
            stz += ai * cz + res[8]
            en += res[9]
            et += res[10]
            er += res[11]
            fr += res[12]
            dm += res[13]
        force[i, 0] = sfx; force[i, 1] = sfy; force[i, 2] = sfz
        torque[i, 0] = stx; torque[i, 1] = sty; torque[i, 2] = stz
    e1[b, 0] = en
    e1[b, 1] = et
    e1[b, 2] = er
    e1[b, 3] = fr
    e1[b, 4] = dm


@njit(cache=True, error_model="numpy")
def _leapfrog_dof(f, v, m, inv, dt, held, prescribed, prescribed_velocity, local_damping, viscous_damping):
    """One DOF of the leapfrog (module docstring): returns v^{n+½}, v^n, the work of the
    reaction of a held (blocked/prescribed) DOF and the work of the damping force."""
    if held:
        v_new = prescribed_velocity if prescribed else v
        v_mid = 0.5 * (v + v_new)
        reaction = (v_new - v) * m / dt - f
        return v_new, v_mid, reaction * v_mid * dt, 0.0
    f_damp = -viscous_damping * m * v
    if local_damping > 0.0 and v != 0.0:
        f_damp -= local_damping * abs(f) * np.sign(v)
    v_new = v + dt * (f + f_damp) * inv
    v_mid = 0.5 * (v + v_new)
    return v_new, v_mid, 0.0, f_damp * v_mid * dt


@njit(cache=True, error_model="numpy")
def _particle_block(b, in_order, has_constraints, law, dt, gravity, local_damping, viscous_damping, n_owned,
                    pos, vel, accel, angvel, radius, mass, inertia, material, blocked, prescribed,
                    prescribed_velocity, force, torque, young, pair_params,
                    perm, j_start, j_rec,
                    wall_point, wall_normal, wall_vel, wall_mat, w_start, w_idx, w_hist, w_fn, w_force,
                    orig, vertices, vertex_vel, triangles, tri_edges, tri_mat, tri_mesh, f_start, f_tri, f_hist,
                    f_active, f_force, f_lambda, ref_pos, e2, dmax):
    """Region 2 work item: gather, plane walls, facets, then gravity, damping and
    leapfrog of the owned particles of perm positions [b·PBLOCK, (b+1)·PBLOCK).
    ``orig[s]`` is the particle's index in the public arrays (the facet CSR's index)."""
    n = perm.size
    we = np.zeros(6)
    sums = np.zeros(6)
    ke_t = 0.0
    ke_r = 0.0
    potential = 0.0
    damping = 0.0
    boundary = 0.0
    d2max = 0.0
    for s in range(b * PBLOCK, min((b + 1) * PBLOCK, n)):
        i = np.uint64(s) if in_order else np.uint64(perm[s])
        if i >= np.uint64(n_owned):
            continue
        # the i-side sums of region 1, continued with the j-side records (ascending i);
        # a pair not in contact has a zero record
        fx = force[i, 0]; fy = force[i, 1]; fz = force[i, 2]
        tx = torque[i, 0]; ty = torque[i, 1]; tz = torque[i, 2]
        for q in range(np.uint64(j_start[s]), np.uint64(j_start[s + 1])):
            fx += j_rec[q, 0]; fy += j_rec[q, 1]; fz += j_rec[q, 2]
            tx += j_rec[q, 3]; ty += j_rec[q, 4]; tz += j_rec[q, 5]
        r = radius[i]
        # plane walls (DESIGN.md §2 with the wall as body j; walls module docstring)
        for c in range(w_start[s], w_start[s + 1]):
            w = w_idx[c]
            dist = 0.0
            for d in range(3):
                dist += (pos[i, d] - wall_point[w, d]) * wall_normal[w, d]
            overlap = r - dist
            k_lin = linear_normal_stiffness(young[material[i]], r, young[wall_mat[w]], r)
            if overlap <= 0.0:
                if (w_hist[c, 0] != 0.0 or w_hist[c, 1] != 0.0 or w_hist[c, 2] != 0.0
                        or w_hist[c, 3] != 0.0 or w_hist[c, 4] != 0.0 or w_hist[c, 5] != 0.0):
                    we[4] += released_energy(law, pair_params, material[i], wall_mat[w], k_lin, r, r,
                                             w_hist[c, 0], w_hist[c, 1], w_hist[c, 2],
                                             w_hist[c, 3], w_hist[c, 4], w_hist[c, 5])
                    for k in range(6):
                        w_hist[c, k] = 0.0
                w_fn[c] = 0.0
                for k in range(3):
                    w_force[c, k] = 0.0
                continue
            nx = -wall_normal[w, 0]
            ny = -wall_normal[w, 1]
            nz = -wall_normal[w, 2]
            arm = r - 0.5 * overlap
            vcx = vel[i, 0] + arm * (angvel[i, 1] * nz - angvel[i, 2] * ny)
            vcy = vel[i, 1] + arm * (angvel[i, 2] * nx - angvel[i, 0] * nz)
            vcz = vel[i, 2] + arm * (angvel[i, 0] * ny - angvel[i, 1] * nx)
            dvn = -0.5 * dt * (accel[i, 0] * nx + accel[i, 1] * ny + accel[i, 2] * nz)
            res = contact_force(law, pair_params, material[i], wall_mat[w], nx, ny, nz, overlap,
                                wall_vel[w, 0] - vcx, wall_vel[w, 1] - vcy, wall_vel[w, 2] - vcz, dvn,
                                -angvel[i, 0], -angvel[i, 1], -angvel[i, 2],
                                k_lin, r, r, mass[i], w_hist[c, 0], w_hist[c, 1], w_hist[c, 2],
                                w_hist[c, 3], w_hist[c, 4], w_hist[c, 5], dt)
            wfx, wfy, wfz = res[0], res[1], res[2]
            for k in range(6):
                w_hist[c, k] = res[3 + k]
            w_fn[c] = -(wfx * nx + wfy * ny + wfz * nz)
            w_force[c, 0] = wfx
            w_force[c, 1] = wfy
            w_force[c, 2] = wfz
            fx += wfx
            fy += wfy
            fz += wfz
            tx += arm * (ny * wfz - nz * wfy) + res[6]
            ty += arm * (nz * wfx - nx * wfz) + res[7]
            tz += arm * (nx * wfy - ny * wfx) + res[8]
            we[0] += (wfx * wall_vel[w, 0] + wfy * wall_vel[w, 1] + wfz * wall_vel[w, 2]) * dt
            for k in range(5):
                we[k + 1] += res[9 + k]
        if f_tri.size:  # triangle facets (walls.facet_contacts_of), after the plane walls
            k = orig[s]
            if f_start[k + 1] > f_start[k]:
                sums[0] = fx; sums[1] = fy; sums[2] = fz
                sums[3] = tx; sums[4] = ty; sums[5] = tz
                facet_contacts_of(i, k, law, dt, pos, vel, accel, angvel, radius, mass, material, young,
                                  pair_params, vertices, vertex_vel, triangles, tri_edges, tri_mat, tri_mesh,
                                  f_start, f_tri, f_hist, f_active, f_force, f_lambda, sums, we)
                fx = sums[0]; fy = sums[1]; fz = sums[2]
                tx = sums[3]; ty = sums[4]; tz = sums[5]
        force[i, 0] = fx; force[i, 1] = fy; force[i, 2] = fz
        torque[i, 0] = tx; torque[i, 1] = ty; torque[i, 2] = tz
        # gravity, background damping, leapfrog (module docstring)
        m = mass[i]
        inv = 1.0 / m
        constrained = False
        if has_constraints:
            for d in range(6):
                if blocked[i, d] or prescribed[i, d]:
                    constrained = True
        for d in range(3):
            force[i, d] += m * gravity[d]
            v = vel[i, d]
            held = constrained and (blocked[i, d] or prescribed[i, d])
            v_new, v_mid, work, damped = _leapfrog_dof(force[i, d], v, m, inv, dt, held, prescribed[i, d],
                                                       prescribed_velocity[i, d], local_damping, viscous_damping)
            boundary += work
            damping -= damped
            ke_t += 0.5 * m * v_mid * v_mid
            potential -= m * gravity[d] * pos[i, d]
            accel[i, d] = (v_new - v) / dt
            vel[i, d] = v_new
            pos[i, d] += dt * v_new
        weight = inertia[i]
        inv = 1.0 / weight
        for d in range(3):
            held = constrained and (blocked[i, d + 3] or prescribed[i, d + 3])
            v_new, v_mid, work, damped = _leapfrog_dof(torque[i, d], angvel[i, d], weight, inv, dt, held,
                                                       prescribed[i, d + 3], prescribed_velocity[i, d + 3],
                                                       local_damping, viscous_damping)
            boundary += work
            damping -= damped
            ke_r += 0.5 * weight * v_mid * v_mid
            angvel[i, d] = v_new
        ex = pos[i, 0] - ref_pos[i, 0]
        ey = pos[i, 1] - ref_pos[i, 1]
        ez = pos[i, 2] - ref_pos[i, 2]
        d2 = ex * ex + ey * ey + ez * ez
        d2max = max(d2max, d2)
        if d2 != d2:  # NaN: a diverged particle forces the rebuild, whose check stops the run
            d2max = math.inf
    for k in range(6):
        e2[b, k] = we[k]
    e2[b, 6] = ke_t
    e2[b, 7] = ke_r
    e2[b, 8] = potential
    e2[b, 9] = damping
    e2[b, 10] = boundary
    dmax[b] = d2max


@njit(cache=True, error_model="numpy")
def record_energy(books, pe, we, ie):
    """Energy books of one step (Engine.energy): state at tⁿ, increments accumulated."""
    state = (ie[0], ie[1], ie[2], pe[0] + we[1], pe[1] + we[2], pe[2] + we[3])
    inc = (we[0], ie[4], pe[3] + we[4], pe[4] + we[5], ie[3])
    for k in range(6):
        books[k] = state[k]
    for k in range(5):
        books[6 + k] += inc[k]
        books[16 + k] = inc[k]
    if books[22] == 0.0:
        for k in range(5):
            books[11 + k] = inc[k]
        total = 0.0
        for k in range(6):
            total += state[k]
        books[21] = total
        books[22] = 1.0


@njit(cache=True, error_model="numpy")
def wall_totals(n_walls, w_idx, w_particle, w_order, w_force, block):
    """Force of the particles on each wall, summed per block of ``block`` particles in
    particle order, then over the blocks (a fixed order for any thread count)."""
    total = np.zeros((n_walls, 3))
    part = np.zeros((n_walls, 3))
    current = -1
    for k in range(w_order.size):
        c = w_order[k]
        b = w_particle[c] // block
        if b != current:
            total += part
            part[:, :] = 0.0
            current = b
        w = w_idx[c]
        for d in range(3):
            part[w, d] -= w_force[c, d]
    total += part
    return total


@njit(parallel=True, cache=True, error_model="numpy")
def advance(nsteps, in_order, has_constraints, rolling, law, dt, gravity, local_damping, viscous_damping, n_owned,
            pos, vel, accel, angvel, radius, mass, inertia, material, blocked, prescribed,
            prescribed_velocity, force, torque, young, pair_params,
            perm, i_start, pair_js, j_start, j_slot, ht, hr, j_rec, pair_ov,
            wall_point, wall_normal, wall_vel, wall_mat, w_start, w_idx, w_hist, w_fn, w_force,
            orig, vertices, vertex_vel, triangles, tri_edges, tri_mat, tri_mesh, f_start, f_tri, f_hist,
            f_active, f_force, f_lambda, vertex_force, vertex_impulse,
            ref_pos, ref_wall_point, ref_vertices, skin, books, clock):
    """Up to ``nsteps`` steps; stops early when the lists must be rebuilt before the
    next step. ``clock`` = [time, steps done]. Per step, after the two parallel
    regions (serial, fixed order): energy books, the force on every facet vertex
    (``vertex_force``; ``vertex_impulse`` += F Δt), x_wall += v Δt, vertices += v Δt,
    and the rebuild test (particles, walls and vertices against their positions at
    the last build). Returns whether a rebuild is due.
    """
    n = perm.size
    nb = (n + PBLOCK - 1) // PBLOCK
    e1 = np.zeros((nb, N_E1))
    e2 = np.zeros((nb, N_E2))
    dmax = np.zeros(nb)
    n_walls = wall_point.shape[0]
    n_vertices = vertices.shape[0]
    rebuild = False
    pe = np.empty(N_E1)
    we = np.empty(6)
    ie = np.empty(5)
    for it in range(nsteps):
        for b in prange(nb):
            _pair_block(b, in_order, law, dt, pos, vel, accel, angvel, radius, mass, material, young, pair_params,
                        perm, i_start, pair_js, j_slot, ht, hr, rolling, j_rec, pair_ov, force, torque, e1)
        for b in prange(nb):
            _particle_block(b, in_order, has_constraints, law, dt, gravity, local_damping, viscous_damping, n_owned,
                            pos, vel, accel, angvel, radius, mass, inertia, material, blocked, prescribed,
                            prescribed_velocity, force, torque, young, pair_params,
                            perm, j_start, j_rec,
                            wall_point, wall_normal, wall_vel, wall_mat, w_start, w_idx, w_hist, w_fn, w_force,
                            orig, vertices, vertex_vel, triangles, tri_edges, tri_mat, tri_mesh, f_start, f_tri,
                            f_hist, f_active, f_force, f_lambda, ref_pos, e2, dmax)
        for k in range(N_E1):
            pe[k] = 0.0
        for k in range(6):
            we[k] = 0.0
        for k in range(5):
            ie[k] = 0.0
        for b in range(nb):
            for k in range(N_E1):
                pe[k] += e1[b, k]
        for b in range(nb):
            for k in range(6):
                we[k] += e2[b, k]
            for k in range(5):
                ie[k] += e2[b, 6 + k]
        record_energy(books, pe, we, ie)
        d2 = 0.0
        for b in range(nb):
            d2 = max(d2, dmax[b])
        dw2 = 0.0
        for w in range(n_walls):
            dd = 0.0
            for d in range(3):
                wall_point[w, d] = wall_point[w, d] + wall_vel[w, d] * dt
                dd += (wall_point[w, d] - ref_wall_point[w, d]) * (wall_point[w, d] - ref_wall_point[w, d])
            dw2 = max(dw2, dd)
        if n_vertices:
            facet_vertex_forces(triangles, f_tri, f_force, f_lambda, vertex_force)
            for v in range(n_vertices):
                dd = 0.0
                for d in range(3):
                    vertex_impulse[v, d] += vertex_force[v, d] * dt
                    vertices[v, d] += vertex_vel[v, d] * dt
                    dd += (vertices[v, d] - ref_vertices[v, d]) * (vertices[v, d] - ref_vertices[v, d])
                dw2 = max(dw2, dd)
        clock[0] += dt
        clock[1] += 1.0
        dp = math.sqrt(d2)
        if dp + max(dp, math.sqrt(dw2)) > skin:
            rebuild = True
            break
    return rebuild
