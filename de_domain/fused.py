"""Fused multi-step DEM kernels: the whole step of :class:`~de_domain.engine.Engine`.

One step is two parallel regions, inside one njit'd loop over steps that returns
to Python only when the Verlet lists must be rebuilt (or the requested steps are
done):

* region 1, per block of particles (in spatial order): every pair (i, j) of the
  half list whose i-side is a particle of the block — contact force on i, its
  n × F, overlap and contact history per pair; energy sums per block;
* region 2, per block of particles: the force/torque on each particle gathered
  from its i-side pairs (ascending j) then its j-side pairs (ascending i), the
  plane walls it may touch (ascending wall index,
  :func:`de_domain.walls.plane_wall_contacts`), the facet triangles it may
  touch (ascending triangle index, :func:`de_domain.walls.facet_contacts_of`),
  then gravity, background damping and the leapfrog update
  (:func:`de_domain.integrate.integrate_block`); energy sums and the largest
  displacement per block;
* serial: energy books, facet vertex forces and impulses, wall and vertex motion,
  the rebuild test.

The kernels take the state grouped in the named tuples of :mod:`de_domain.state`
(settings, particles, contact parameters, pair list, plane walls, facet meshes and
their candidates) and unpack the fields they read into locals at the top, so the
loops read like the equations and compile as with positional arrays.

Ordering and determinism. Particles keep their positions in the public arrays;
the loops visit them in a spatial (cell-list) order ``perm`` for cache locality.
``perm`` is fixed when the lists are first built and refreshed every
``PERM_EVERY`` steps (on the step count, never on rebuilds), so results do not
depend on the thread count or the rebuild frequency. Every per-particle sum is
taken in a canonical order (pairs by original index, i-side before j-side, walls
by index, facets by triangle), so positions, velocities, forces, torques, contact
histories and wall forces are bit-identical for any thread count, any skin (list
rebuild frequency) and either storage path (in place through ``perm``, or spatially
sorted copies); only the energy books are summed in block order.
``settings.in_order`` says the arrays are the spatially sorted copies (index = perm position): the kernels then skip the
``perm`` lookup (one dependent load less per pair). Particle, pair and slot indices
are cast to unsigned (``np.uint64``) before they index arrays: Numba then emits no
negative-index wraparound (a compare and a select per array access; −10 % in region 1).

Storage (CSR over perm positions ``s``, built by :mod:`de_domain.neighbors`): pairs of
particle ``perm[s]`` as i-side are ``pairs.i_start[s]:pairs.i_start[s+1]`` (partner
perm position ``pairs.pair_js``, sorted by index); its j-side pairs are the slots
``pairs.j_start[s]:pairs.j_start[s+1]`` of ``pairs.j_record`` (sorted by i; pair p
writes its force and torque on j to slot ``pairs.j_slot[p]``). Plane-wall candidates
(walls within r + skin at the build) are ``walls.start[s]:walls.start[s+1]`` with
their own sparse history. Facet candidates are a CSR over the public particle index
(``candidates.start``/``candidates.triangle``, reached through
``candidates.particle_index[s]``).
"""
import math

import numpy as np
from numba import njit, prange

from .contact_laws import (
    FASTMATH,
    HERTZ,
    ContactBodies,
    ContactGeometry,
    RelativeMotion,
    Springs,
    contact_force_inlined,
    linear_normal_stiffness,
    released_energy,
)
from .integrate import IntegrationTerms, integrate_block
from .rigid import LANES, N_W, W_INERTIA, W_MOMENTUM, W_OMEGA, W_QUAT, leapfrog_lanes, to_body, to_space
from .state import (
    BOOK_ACCUMULATED,
    BOOK_FIRST,
    BOOK_INITIAL_TOTAL,
    BOOK_INITIALISED,
    BOOK_LAST,
    BOOK_STATE,
    CLOCK_PARTICLE_SHIFT,
    CLOCK_STEPS,
    CLOCK_TIME,
    E_DAMPING,
    E_FRICTION,
    E_NORMAL,
    E_ROLLING,
    E_TANGENTIAL,
    I_BACKGROUND_DAMPING,
    I_BOUNDARY_WORK,
    I_GRAVITY,
    I_KINETIC_ROTATIONAL,
    I_KINETIC_TRANSLATIONAL,
    MEMBER_FORCE,
    MEMBER_POSITION,
    MEMBER_TORQUE,
    N_CONTACT_ENERGY,
    N_INTEGRATION,
    N_RATE,
    N_STATE,
    N_WALL_ENERGY,
    W_CONTACT,
    W_WORK,
    StepBuffers,
)
from .walls import facet_contacts_of, facet_vertex_forces, plane_wall_contacts

PBLOCK = 256          # particles per parallel work item (and per energy block)
PERM_EVERY = 100_000  # steps between refreshes of the spatial order


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)  # region 1 only (contact_laws.FASTMATH)
def _pair_block(b, settings, particles, params, pairs, e1):
    """Region 1 work item: the i-side pairs of perm positions [b·PBLOCK, (b+1)·PBLOCK).

    ``pairs.j_record[pairs.j_slot[p]]`` = force (3) and torque (3) pair p puts on its
    j, written in the j-side order that region 2 reads contiguously;
    ``pairs.overlap[p]`` = overlap (NaN right after a rebuild: unknown; −1 for a pair
    that was apart in this and the last step, whose distance is then not taken).
    History: tangential spring ``pairs.tangential[p]``; rolling moment
    ``pairs.rolling_moment[p]`` only if ``settings.rolling`` (any pair with β_r > 0;
    else it is identically zero and not stored). The i-side part of each particle's
    force/torque sum (ascending j) is written to ``particles.force``/``torque``;
    region 2 continues it with the j-side pairs. ``e1[b]``: the block's contact
    energy terms (``state.E_*``) of the pairs whose i-side is owned (a pair between
    ranks is computed on both, booked on one)."""
    law = settings.law
    dt = settings.dt
    in_order = settings.in_order
    rolling = settings.rolling
    ghost = particles.ghost
    pos = particles.pos
    vel = particles.vel
    accel = particles.accel
    angvel = particles.angvel
    radius = particles.radius
    mass = particles.mass
    material = particles.material
    force = particles.force
    torque = particles.torque
    young = params.young
    pair_params = params.pair_params
    perm = pairs.perm
    i_start = pairs.i_start
    pair_js = pairs.pair_js
    j_slot = pairs.j_slot
    ht = pairs.tangential
    hr = pairs.rolling_moment
    j_rec = pairs.j_record
    pair_ov = pairs.overlap
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
        counted = not ghost[i]  # a pair with a ghost i-side is booked on the rank owning i
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
                    released = released_energy(law, pair_params, mi, material[j], k_lin, r_red,
                                               Springs(ht[p, 0], ht[p, 1], ht[p, 2], mrx, mry, mrz))
                    if counted:
                        fr += released
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
            res = contact_force_inlined(law, pair_params, mi, material[j], ContactGeometry(nx, ny, nz, overlap),
                                RelativeMotion(vjx - vix, vjy - viy, vjz - viz, dvn, angvel[j, 0] - angvel[i, 0],
                                               angvel[j, 1] - angvel[i, 1], angvel[j, 2] - angvel[i, 2]),
                                ContactBodies(k_lin, r_red, r_red, m_eff),
                                Springs(ht[p, 0], ht[p, 1], ht[p, 2], mrx, mry, mrz), dt)
            fx, fy, fz = res.fx, res.fy, res.fz
            springs = res.springs
            ht[p, 0] = springs.ftx
            ht[p, 1] = springs.fty
            ht[p, 2] = springs.ftz
            if rolling:
                hr[p, 0] = springs.mrx
                hr[p, 1] = springs.mry
                hr[p, 2] = springs.mrz
            cx = ny * fz - nz * fy
            cy = nz * fx - nx * fz
            cz = nx * fy - ny * fx
            q = np.uint64(j_slot[p])  # j gets −F and (a_j n) × F − M_r
            j_rec[q, 0] = -fx
            j_rec[q, 1] = -fy
            j_rec[q, 2] = -fz
            if rolling:
                j_rec[q, 3] = aj * cx - springs.mrx
                j_rec[q, 4] = aj * cy - springs.mry
                j_rec[q, 5] = aj * cz - springs.mrz
            else:
                j_rec[q, 3] = aj * cx
                j_rec[q, 4] = aj * cy
                j_rec[q, 5] = aj * cz
            sfx += fx; sfy += fy; sfz += fz
            stx += ai * cx + springs.mrx
            sty += ai * cy + springs.mry
            stz += ai * cz + springs.mrz
            if counted:
                energy = res.energy
                en += energy.normal
                et += energy.tangential
                er += energy.rolling
                fr += energy.friction
                dm += energy.damping
        force[i, 0] = sfx; force[i, 1] = sfy; force[i, 2] = sfz
        torque[i, 0] = stx; torque[i, 1] = sty; torque[i, 2] = stz
    e1[b, E_NORMAL] = en
    e1[b, E_TANGENTIAL] = et
    e1[b, E_ROLLING] = er
    e1[b, E_FRICTION] = fr
    e1[b, E_DAMPING] = dm


@njit(cache=True, error_model="numpy")
def gather_j_side(first, last, in_order, particles, pairs):
    """Region 2's first pass, over perm positions [first, last): each owned particle's i-side
    sums of region 1 (in ``particles.force``/``torque``) continued with its j-side records,
    ascending i (a pair not in contact has a zero record)."""
    ghost = particles.ghost
    force = particles.force
    torque = particles.torque
    perm = pairs.perm
    j_start = pairs.j_start
    j_rec = pairs.j_record
    for s in range(first, last):
        i = np.uint64(s) if in_order else np.uint64(perm[s])
        if ghost[i]:
            continue
        fx = force[i, 0]; fy = force[i, 1]; fz = force[i, 2]
        tx = torque[i, 0]; ty = torque[i, 1]; tz = torque[i, 2]
        for q in range(np.uint64(j_start[s]), np.uint64(j_start[s + 1])):
            fx += j_rec[q, 0]; fy += j_rec[q, 1]; fz += j_rec[q, 2]
            tx += j_rec[q, 3]; ty += j_rec[q, 4]; tz += j_rec[q, 5]
        force[i, 0] = fx; force[i, 1] = fy; force[i, 2] = fz
        torque[i, 0] = tx; torque[i, 1] = ty; torque[i, 2] = tz


@njit(cache=True, error_model="numpy")
def _particle_block(b, settings, particles, params, pairs, walls, meshes, candidates, clumps, e2, dmax):
    """Region 2 work item, the owned particles of perm positions [b·PBLOCK, (b+1)·PBLOCK),
    in passes over the block: the gather, the plane walls, the facets, then gravity,
    damping and the leapfrog. Each particle's sum takes the same terms in the same
    order as in one pass (a particle's walls, facets and update read only its own
    state), and every pass unpacks the named tuples once per block.
    ``e2[b]``: the boundary terms (``state.W_*``) then the integration terms
    (``state.I_*``, from column ``N_WALL_ENERGY``); ``dmax[b]``: the largest squared
    displacement since the last list build (inf for a NaN)."""
    in_order = settings.in_order
    ghost = particles.ghost
    pos = particles.pos
    force = particles.force
    torque = particles.torque
    ref_pos = particles.ref_pos
    perm = pairs.perm
    f_start = candidates.start
    particle_index = candidates.particle_index
    has_facets = candidates.triangle.size > 0
    first = b * PBLOCK
    last = min((b + 1) * PBLOCK, perm.size)
    we = np.zeros(N_WALL_ENERGY)
    gather_j_side(first, last, in_order, particles, pairs)
    plane_wall_contacts(first, last, settings, particles, params, perm, walls, we)
    if has_facets:  # triangle facets, after the plane walls
        for s in range(first, last):
            i = np.uint64(s) if in_order else np.uint64(perm[s])
            k = particle_index[s]
            if ghost[i] or f_start[k + 1] == f_start[k]:
                continue
            resultant = facet_contacts_of(i, k, settings, particles, params, meshes, candidates,
                                          (force[i, 0], force[i, 1], force[i, 2], torque[i, 0], torque[i, 1],
                                           torque[i, 2]), we)
            for d in range(3):
                force[i, d] = resultant[d]
                torque[i, d] = resultant[3 + d]
    terms = integrate_block(first, last, settings, particles, perm, clumps.member_of,
                            IntegrationTerms(0.0, 0.0, 0.0, 0.0, 0.0))
    d2max = 0.0
    for s in range(first, last):
        i = np.uint64(s) if in_order else np.uint64(perm[s])
        if ghost[i]:
            continue
        ex = pos[i, 0] - ref_pos[i, 0]
        ey = pos[i, 1] - ref_pos[i, 1]
        ez = pos[i, 2] - ref_pos[i, 2]
        d2 = ex * ex + ey * ey + ez * ez
        d2max = max(d2max, d2)
        if d2 != d2:  # NaN: a diverged particle forces the rebuild, whose check stops the run
            d2max = math.inf
    for k in range(N_WALL_ENERGY):
        e2[b, k] = we[k]
    for k in range(N_INTEGRATION):
        e2[b, N_WALL_ENERGY + k] = terms[k]
    dmax[b] = d2max


@njit(cache=True, error_model="numpy")
def _clump_dof(f, v, m, inv, dt, local_damping, viscous_damping):
    """One DOF of a clump's centre: the leapfrog with background damping −α_v m v − α_b |F| sign(v̂ⁿ),
    v̂ⁿ = v^{n−½} + ½ Δt F / m. Returns v^{n+½}, vⁿ and the damping's work."""
    f_damp = -viscous_damping * m * v
    v_est = v + 0.5 * dt * f * inv
    if local_damping > 0.0 and v_est != 0.0:
        f_damp -= local_damping * abs(f) * np.sign(v_est)
    v_new = v + dt * (f + f_damp) * inv
    v_mid = 0.5 * (v + v_new)
    return v_new, v_mid, f_damp * v_mid * dt


@njit(cache=True, error_model="numpy")
def _place_member(pos, vel, accel, angvel, ref_pos, row, x, y, z, vx, vy, vz, wx, wy, wz, dt):
    """A clump's member moved to (x, y, z) with velocity (vx, vy, vz) and spin (wx, wy, wz); its
    acceleration (v^{n+½} − v^{n−½})/Δt. Returns its squared displacement since the last list
    build (inf for a NaN)."""
    accel[row, 0] = (vx - vel[row, 0]) / dt
    accel[row, 1] = (vy - vel[row, 1]) / dt
    accel[row, 2] = (vz - vel[row, 2]) / dt
    pos[row, 0] = x; pos[row, 1] = y; pos[row, 2] = z
    vel[row, 0] = vx; vel[row, 1] = vy; vel[row, 2] = vz
    angvel[row, 0] = wx; angvel[row, 1] = wy; angvel[row, 2] = wz
    ex = x - ref_pos[row, 0]
    ey = y - ref_pos[row, 1]
    ez = z - ref_pos[row, 2]
    e2 = ex * ex + ey * ey + ez * ez
    return e2 if e2 == e2 else math.inf


@njit(cache=True, error_model="numpy")
def collect_member_loads(particles, clumps):
    """Each member's contact force, torque and position, of the rows this process holds
    (``member_row`` ≥ 0), into ``clumps.member_load`` (template order)."""
    force = particles.force
    torque = particles.torque
    pos = particles.pos
    member_row = clumps.member_row
    load = clumps.member_load
    for k in range(member_row.size):
        if member_row[k] < 0:
            continue
        row = np.uint64(member_row[k])
        for d in range(3):
            load[k, MEMBER_FORCE + d] = force[row, d]
            load[k, MEMBER_TORQUE + d] = torque[row, d]
            load[k, MEMBER_POSITION + d] = pos[row, d]


CBLOCK = LANES  # clumps per parallel work item (one work array of the rotation)

# The clumps' own fields in the rotation's work array of a block (de_domain.rigid: W_* and these)
RW_TORQUE = N_W        # the contacts' torque τⁿ (3 fields)
RW_KINETIC = N_W + 3   # out: ½ L_bᵀ I⁻¹ L_b at tⁿ, L = (L^{n−½} + L^{n+½})/2 at qⁿ
RW_DAMPING = N_W + 4   # out: the damping torque's work over the step
N_RW = N_W + 5


@njit(cache=True, error_model="numpy", inline="always")
def _sign(x):
    """sign x (0 at 0), by selection (vectorisable, unlike np.sign's call)."""
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True, error_model="numpy", inline="always")
def _damping_torque(t, w, big_l, local_damping, viscous_damping):
    """A clump's background damping torque on one space component: −α_v L − α_b |τ| sign(ω)
    (the spheres' −α_v I ω − α_b |τ| sign(ω), docs/design.md §2.13, with I ω = L)."""
    return -viscous_damping * big_l - local_damping * abs(t) * _sign(w)


@njit(cache=True, error_model="numpy")
def _kick_clumps(w, count, dt, local_damping, viscous_damping):
    """The angular-momentum half of the clumps' step, for the first ``count`` clumps of the work
    array ``w``: L^{n+½} = L^{n−½} + (τ + τ_d) Δt with the background damping
    τ_d = −α_v L − α_b |τ| sign(ω) per space component, ω at tⁿ estimated from L^{n−½} + ½ Δt τ
    (the sign the local damping opposes; YADE's NewtonIntegrator does the same: with ω^{n−½} a
    clump's fast rotational mode is amplified); the kinetic energy at tⁿ with
    L = (L^{n−½} + L^{n+½})/2 at qⁿ, and the damping's work with that ω. No branch and no call:
    the loop is vectorised."""
    for c in range(count):
        q = (w[W_QUAT * CBLOCK + c], w[(W_QUAT + 1) * CBLOCK + c], w[(W_QUAT + 2) * CBLOCK + c],
             w[(W_QUAT + 3) * CBLOCK + c])
        lx = w[W_MOMENTUM * CBLOCK + c]; ly = w[(W_MOMENTUM + 1) * CBLOCK + c]; lz = w[(W_MOMENTUM + 2) * CBLOCK + c]
        tx = w[RW_TORQUE * CBLOCK + c]; ty = w[(RW_TORQUE + 1) * CBLOCK + c]; tz = w[(RW_TORQUE + 2) * CBLOCK + c]
        i1 = w[W_INERTIA * CBLOCK + c]; i2 = w[(W_INERTIA + 1) * CBLOCK + c]; i3 = w[(W_INERTIA + 2) * CBLOCK + c]
        bx, by, bz = to_body(q, lx + 0.5 * dt * tx, ly + 0.5 * dt * ty, lz + 0.5 * dt * tz)
        wx, wy, wz = to_space(q, bx / i1, by / i2, bz / i3)
        dx = _damping_torque(tx, wx, lx, local_damping, viscous_damping)
        dy = _damping_torque(ty, wy, ly, local_damping, viscous_damping)
        dz = _damping_torque(tz, wz, lz, local_damping, viscous_damping)
        nx = lx + (tx + dx) * dt; ny = ly + (ty + dy) * dt; nz = lz + (tz + dz) * dt
        bx, by, bz = to_body(q, 0.5 * (lx + nx), 0.5 * (ly + ny), 0.5 * (lz + nz))
        mx, my, mz = to_space(q, bx / i1, by / i2, bz / i3)
        w[RW_KINETIC * CBLOCK + c] = 0.5 * (bx * bx / i1 + by * by / i2 + bz * bz / i3)
        w[RW_DAMPING * CBLOCK + c] = -(dx * mx + dy * my + dz * mz) * dt
        w[W_MOMENTUM * CBLOCK + c] = nx; w[(W_MOMENTUM + 1) * CBLOCK + c] = ny; w[(W_MOMENTUM + 2) * CBLOCK + c] = nz


@njit(cache=True, error_model="numpy")
def _advance_clumps(first, last, settings, particles, clumps, terms, shift):
    """Advance the clumps ``clumps.active[first:last]`` (at most ``CBLOCK``) by one step from their
    members' loads (``member_load``, docs/design.md §2.19), member by member in template order, then
    place their members this process holds (``member_row`` ≥ 0). Per clump:
    F = M g + Σ F_m, τ = Σ (x_m − x_c) × F_m + T_m; the centre by the spheres' leapfrog with
    background damping (:func:`de_domain.integrate.leapfrog_dof`); the orientation by
    :func:`_kick_clumps` and NO_SQUISH (:func:`de_domain.rigid.leapfrog_lanes`), the block's clumps
    together; then each member at x_c + R(q) b_m with v_c + ω × R(q) b_m and ω, its acceleration
    (v^{n+½} − v^{n−½})/Δt. ``terms[c]``: clump c's terms (``state.I_*``: kinetic energies at tⁿ
    with the mean of the half-step momenta, gravity, damping); ``shift[c]``: its placed members'
    largest squared displacement since the last list build."""
    dt = settings.dt
    gravity = settings.gravity
    local_damping = settings.local_damping
    viscous_damping = settings.viscous_damping
    pos = particles.pos
    vel = particles.vel
    accel = particles.accel
    angvel = particles.angvel
    ref_pos = particles.ref_pos
    load = clumps.member_load
    centre = clumps.pos
    velocity = clumps.vel
    quat = clumps.quat
    angmom = clumps.angmom
    mass = clumps.mass
    moments = clumps.moments
    start = clumps.member_start
    member_row = clumps.member_row
    member_body = clumps.member_body
    active = clumps.active
    w = np.empty(N_RW * CBLOCK)
    for a in range(first, last):
        c = active[a]
        lane = a - first
        ke_t = 0.0
        potential = 0.0
        damping = 0.0
        m = mass[c]
        inv = 1.0 / m
        fx = m * gravity[0]; fy = m * gravity[1]; fz = m * gravity[2]
        tx = 0.0; ty = 0.0; tz = 0.0
        for k in range(start[c], start[c + 1]):
            rx = load[k, MEMBER_POSITION] - centre[c, 0]
            ry = load[k, MEMBER_POSITION + 1] - centre[c, 1]
            rz = load[k, MEMBER_POSITION + 2] - centre[c, 2]
            gx = load[k, MEMBER_FORCE]; gy = load[k, MEMBER_FORCE + 1]; gz = load[k, MEMBER_FORCE + 2]
            fx += gx; fy += gy; fz += gz
            tx += ry * gz - rz * gy + load[k, MEMBER_TORQUE]
            ty += rz * gx - rx * gz + load[k, MEMBER_TORQUE + 1]
            tz += rx * gy - ry * gx + load[k, MEMBER_TORQUE + 2]
        clumps.force[c, 0] = fx; clumps.force[c, 1] = fy; clumps.force[c, 2] = fz
        clumps.torque[c, 0] = tx; clumps.torque[c, 1] = ty; clumps.torque[c, 2] = tz
        # the centre: the spheres' leapfrog, DOF by DOF (no tuple indexed by a variable: Numba
        # would give each such read a stack slot inside the loop, and a long run overflows the stack)
        for d in range(3):
            f = fx if d == 0 else (fy if d == 1 else fz)
            v = velocity[c, d]
            v_new, v_mid, damped = _clump_dof(f, v, m, inv, dt, local_damping, viscous_damping)
            ke_t += 0.5 * m * v_mid * v_mid
            potential -= m * gravity[d] * centre[c, d]
            damping -= damped
            velocity[c, d] = v_new
            centre[c, d] += dt * v_new
        terms[c, I_KINETIC_TRANSLATIONAL] = ke_t
        terms[c, I_GRAVITY] = potential
        terms[c, I_BACKGROUND_DAMPING] = damping
        terms[c, I_BOUNDARY_WORK] = 0.0
        for k in range(4):
            w[(W_QUAT + k) * CBLOCK + lane] = quat[c, k]
        for k in range(3):
            w[(W_MOMENTUM + k) * CBLOCK + lane] = angmom[c, k]
            w[(W_INERTIA + k) * CBLOCK + lane] = moments[c, k]
        w[RW_TORQUE * CBLOCK + lane] = tx; w[(RW_TORQUE + 1) * CBLOCK + lane] = ty
        w[(RW_TORQUE + 2) * CBLOCK + lane] = tz
    _kick_clumps(w, last - first, dt, local_damping, viscous_damping)
    leapfrog_lanes(w, last - first, dt)
    for a in range(first, last):
        c = active[a]
        lane = a - first
        terms[c, I_KINETIC_ROTATIONAL] = w[RW_KINETIC * CBLOCK + lane]
        terms[c, I_BACKGROUND_DAMPING] += w[RW_DAMPING * CBLOCK + lane]
        for k in range(4):
            quat[c, k] = w[(W_QUAT + k) * CBLOCK + lane]
        for k in range(3):
            angmom[c, k] = w[(W_MOMENTUM + k) * CBLOCK + lane]
        q_new = (quat[c, 0], quat[c, 1], quat[c, 2], quat[c, 3])
        ox = w[W_OMEGA * CBLOCK + lane]; oy = w[(W_OMEGA + 1) * CBLOCK + lane]; oz = w[(W_OMEGA + 2) * CBLOCK + lane]
        cx = centre[c, 0]; cy = centre[c, 1]; cz = centre[c, 2]
        vx = velocity[c, 0]; vy = velocity[c, 1]; vz = velocity[c, 2]
        d2max = 0.0
        for k in range(start[c], start[c + 1]):
            if member_row[k] < 0:  # another rank's: placed there
                continue
            row = np.uint64(member_row[k])
            rx, ry, rz = to_space(q_new, member_body[k, 0], member_body[k, 1], member_body[k, 2])
            d2max = max(d2max, _place_member(pos, vel, accel, angvel, ref_pos, row, cx + rx, cy + ry, cz + rz,
                                             vx + oy * rz - oz * ry, vy + oz * rx - ox * rz, vz + ox * ry - oy * rx,
                                             ox, oy, oz, dt))
        shift[c] = d2max




@njit(parallel=True, cache=True, error_model="numpy")
def _clump_region(settings, particles, clumps, terms, shift):
    """:func:`_advance_clumps` over blocks of ``CBLOCK`` active clumps, in parallel (a clump's
    members are its own rows: no two work items write one row)."""
    nc = clumps.active.size
    for b in prange((nc + CBLOCK - 1) // CBLOCK):
        _advance_clumps(b * CBLOCK, min((b + 1) * CBLOCK, nc), settings, particles, clumps, terms, shift)


@njit(cache=True, error_model="numpy")
def integrate_clumps(settings, particles, clumps, terms, shift, integration):
    """The active clumps advanced by one step (:func:`_clump_region`); the terms of those this
    process books (``clumps.booked``) added to ``integration`` clump by clump in order (the same
    bits for any thread count). Returns the placed members' largest squared displacement since
    the last list build."""
    _clump_region(settings, particles, clumps, terms, shift)
    d2max = 0.0
    for a in range(clumps.active.size):
        c = clumps.active[a]
        if clumps.booked[c]:
            for k in range(N_INTEGRATION):
                integration[k] += terms[c, k]
        d2max = max(d2max, shift[c])
    return d2max


@njit(cache=True, error_model="numpy")
def record_energy(books, contact, boundary, integration):
    """Energy books of one step (Engine.energy; slots ``state.BOOK_*``): the state at
    tⁿ, the rate terms accumulated and of the last step, the first step's rate terms
    and the initial total the first time. ``contact``, ``boundary`` and
    ``integration`` are this step's sums (``state.E_*``, ``W_*``, ``I_*``)."""
    state = (integration[I_KINETIC_TRANSLATIONAL], integration[I_KINETIC_ROTATIONAL], integration[I_GRAVITY],
             contact[E_NORMAL] + boundary[W_CONTACT + E_NORMAL],
             contact[E_TANGENTIAL] + boundary[W_CONTACT + E_TANGENTIAL],
             contact[E_ROLLING] + boundary[W_CONTACT + E_ROLLING])
    rate = (boundary[W_WORK], integration[I_BOUNDARY_WORK],
            contact[E_FRICTION] + boundary[W_CONTACT + E_FRICTION],
            contact[E_DAMPING] + boundary[W_CONTACT + E_DAMPING], integration[I_BACKGROUND_DAMPING])
    for k in range(N_STATE):
        books[BOOK_STATE + k] = state[k]
    for k in range(N_RATE):
        books[BOOK_ACCUMULATED + k] += rate[k]
        books[BOOK_LAST + k] = rate[k]
    if books[BOOK_INITIALISED] == 0.0:
        for k in range(N_RATE):
            books[BOOK_FIRST + k] = rate[k]
        total = 0.0
        for k in range(N_STATE):
            total += state[k]
        books[BOOK_INITIAL_TOTAL] = total
        books[BOOK_INITIALISED] = 1.0


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


@njit(cache=True, error_model="numpy")
def _move_boundaries(settings, walls, meshes, candidates):
    """After a step: x_wall += v Δt, the facet vertex forces and impulses (F Δt), the
    vertices += v Δt. Returns the largest squared displacement of a wall point or a
    vertex since the last list build."""
    dt = settings.dt
    wall_point = walls.point
    wall_velocity = walls.velocity
    wall_ref = walls.ref_point
    vertex_velocity = meshes.vertex_velocity
    vertex_force = meshes.vertex_force
    vertex_impulse = meshes.vertex_impulse
    ref_vertices = meshes.ref_vertices
    dw2 = 0.0
    for w in range(wall_point.shape[0]):
        dd = 0.0
        for d in range(3):
            wall_point[w, d] = wall_point[w, d] + wall_velocity[w, d] * dt
            dd += (wall_point[w, d] - wall_ref[w, d]) * (wall_point[w, d] - wall_ref[w, d])
        dw2 = max(dw2, dd)
    vertices = meshes.vertices
    if vertices.shape[0]:
        facet_vertex_forces(meshes, candidates)
        for v in range(vertices.shape[0]):
            dd = 0.0
            for d in range(3):
                vertex_impulse[v, d] += vertex_force[v, d] * dt
                vertices[v, d] += vertex_velocity[v, d] * dt
                dd += (vertices[v, d] - ref_vertices[v, d]) * (vertices[v, d] - ref_vertices[v, d])
            dw2 = max(dw2, dd)
    return dw2


@njit(cache=True, error_model="numpy")
def facet_jump_work(vertex_force, now, known):
    """Work of facet vertices displaced from outside between two runs, with the last step's
    vertex forces (force on the facets): W = −Σ_v F_v·(x_v,now − x_v,known), summed vertex by
    vertex (the same bits for the engine and for a compiled caller)."""
    work = 0.0
    for v in range(now.shape[0]):
        for d in range(3):
            work -= vertex_force[v, d] * (now[v, d] - known[v, d])
    return work


@njit(cache=True, error_model="numpy")
def boundary_jumps(wall_point, wall_known, vertices, vertices_known, vertex_force):
    """What moved from outside since the engine last left the boundaries: (walls moved,
    work of the facet vertices' jump). The work is :func:`facet_jump_work` over all meshes'
    vertices (0 if none moved), and then ``vertices_known`` := ``vertices``; the walls'
    work needs their last forces, which the caller books."""
    walls_moved = False
    for w in range(wall_point.shape[0]):
        for d in range(3):
            walls_moved = walls_moved or wall_point[w, d] != wall_known[w, d]
    for v in range(vertices.shape[0]):
        for d in range(3):
            if vertices[v, d] != vertices_known[v, d]:
                work = facet_jump_work(vertex_force, vertices, vertices_known)
                vertices_known[:, :] = vertices
                return walls_moved, work
    return walls_moved, 0.0


@njit(parallel=True, cache=True, error_model="numpy")
def _pair_region(nb, settings, particles, params, pairs, e1):
    """Region 1 of a step: :func:`_pair_block` over the blocks, in parallel."""
    for b in prange(nb):
        _pair_block(b, settings, particles, params, pairs, e1)


@njit(parallel=True, cache=True, error_model="numpy")
def _particle_region(nb, settings, particles, params, pairs, walls, meshes, candidates, clumps, e2, dmax):
    """Region 2 of a step: :func:`_particle_block` over the blocks, in parallel."""
    for b in prange(nb):
        _particle_block(b, settings, particles, params, pairs, walls, meshes, candidates, clumps, e2, dmax)


@njit(cache=True, error_model="numpy")
def step_buffers(n, nc):
    """The :data:`~de_domain.state.StepBuffers` of a step over ``n`` particle rows and ``nc`` clumps."""
    nb = (n + PBLOCK - 1) // PBLOCK
    return StepBuffers(np.zeros((nb, N_CONTACT_ENERGY)), np.zeros((nb, N_WALL_ENERGY + N_INTEGRATION)), np.zeros(nb),
                       np.zeros((nc, N_INTEGRATION)), np.zeros(nc), np.zeros(N_CONTACT_ENERGY), np.zeros(N_WALL_ENERGY),
                       np.zeros(N_INTEGRATION))


@njit(cache=True, error_model="numpy")
def step_forces(settings, particles, params, pairs, walls, meshes, candidates, clumps, buffers):
    """The two parallel regions of one step: every contact, then every free particle advanced
    (the clumps' members are left for :func:`finish_step`)."""
    nb = buffers.shift.size
    _pair_region(nb, settings, particles, params, pairs, buffers.contact)
    _particle_region(nb, settings, particles, params, pairs, walls, meshes, candidates, clumps, buffers.boundary,
                     buffers.shift)


@njit(cache=True, error_model="numpy")
def finish_step(settings, particles, walls, meshes, candidates, clumps, buffers, books, clock):
    """The serial end of one step, after :func:`step_forces` (and the members' loads collected in
    ``clumps.member_load``): the blocks' sums in block order, the clumps advanced, the energy
    books, the boundaries moved, the clock, and the rebuild test. Returns whether a list
    rebuild is due before the next step."""
    e1 = buffers.contact
    e2 = buffers.boundary
    dmax = buffers.shift
    nb = dmax.size
    contact = buffers.contact_sum
    boundary = buffers.boundary_sum
    integration = buffers.integration_sum
    contact[:] = 0.0
    boundary[:] = 0.0
    integration[:] = 0.0
    for b in range(nb):
        for k in range(N_CONTACT_ENERGY):
            contact[k] += e1[b, k]
    for b in range(nb):
        for k in range(N_WALL_ENERGY):
            boundary[k] += e2[b, k]
        for k in range(N_INTEGRATION):
            integration[k] += e2[b, N_WALL_ENERGY + k]
    d2 = 0.0
    if clumps.mass.size:
        d2 = integrate_clumps(settings, particles, clumps, buffers.clump_terms, buffers.clump_shift, integration)
    record_energy(books, contact, boundary, integration)
    for b in range(nb):
        d2 = max(d2, dmax[b])
    dw2 = _move_boundaries(settings, walls, meshes, candidates)
    clock[CLOCK_TIME] += settings.dt
    clock[CLOCK_STEPS] += 1.0
    dp = math.sqrt(d2)
    clock[CLOCK_PARTICLE_SHIFT] = dp
    return dp + max(dp, math.sqrt(dw2)) > settings.skin


@njit(cache=True, error_model="numpy")
def advance(nsteps, settings, particles, params, pairs, walls, meshes, candidates, clumps, books, clock):
    """Up to ``nsteps`` steps; stops early when the lists must be rebuilt before the
    next step. ``clock``: ``state.CLOCK_TIME``, ``CLOCK_STEPS`` (steps done),
    ``CLOCK_PARTICLE_SHIFT`` (the particle part of the rebuild test, for the next). Per step,
    after the two parallel regions (serial, fixed order): the energy books, the
    boundaries moved (:func:`_move_boundaries`) and the rebuild test (particles, walls
    and vertices against their positions at the last build). Returns whether a
    rebuild is due.

    The two parallel regions are functions of their own (:func:`_pair_region`,
    :func:`_particle_region`), not ``prange`` loops inside this step loop: Numba 0.56 puts
    each parallel loop's schedule on the stack of the function that runs it, with a
    variable size, and never releases it until that function returns — inside a loop of
    steps the stack grew by ≈ 120 bytes a step (2 threads) and a run of 2 spheres at
    rest crashed after 50,000–100,000 steps in one call (numba issue 9029, fixed in
    0.59). A called function's stack is released when it returns.
    """
    buffers = step_buffers(pairs.perm.size, clumps.mass.size)
    for _ in range(nsteps):
        step_forces(settings, particles, params, pairs, walls, meshes, candidates, clumps, buffers)
        if clumps.mass.size:
            collect_member_loads(particles, clumps)
        if finish_step(settings, particles, walls, meshes, candidates, clumps, buffers, books, clock):
            return True
    return False


@njit(parallel=True, cache=True)
def gather_in_order(perm, public, copies, constraints):
    """copies[s] = public[perm[s]] for every per-particle array the step reads (the
    spatially sorted copies; the constraint arrays only when ``constraints``); the
    force and torque are the step's output and are not gathered. (Fields unpacked
    before the parallel loop, as in every kernel here.)"""
    pos, vel, accel, angvel, ref_pos = public.pos, public.vel, public.accel, public.angvel, public.ref_pos
    pos_c, vel_c, accel_c, angvel_c, ref_pos_c = copies.pos, copies.vel, copies.accel, copies.angvel, copies.ref_pos
    radius, mass, inertia, material, ghost = public.radius, public.mass, public.inertia, public.material, public.ghost
    radius_c, mass_c, inertia_c = copies.radius, copies.mass, copies.inertia
    material_c, ghost_c = copies.material, copies.ghost
    blocked, prescribed, prescribed_v = public.blocked, public.prescribed, public.prescribed_velocity
    blocked_c, prescribed_c, prescribed_v_c = copies.blocked, copies.prescribed, copies.prescribed_velocity
    for s in prange(perm.size):
        i = perm[s]
        for d in range(3):
            pos_c[s, d] = pos[i, d]
            vel_c[s, d] = vel[i, d]
            accel_c[s, d] = accel[i, d]
            angvel_c[s, d] = angvel[i, d]
            ref_pos_c[s, d] = ref_pos[i, d]
        radius_c[s] = radius[i]
        mass_c[s] = mass[i]
        inertia_c[s] = inertia[i]
        material_c[s] = material[i]
        ghost_c[s] = ghost[i]
        if constraints:
            for d in range(6):
                blocked_c[s, d] = blocked[i, d]
                prescribed_c[s, d] = prescribed[i, d]
                prescribed_v_c[s, d] = prescribed_v[i, d]


@njit(parallel=True, cache=True)
def scatter_in_order(perm, copies, public):
    """public[perm[s]] = copies[s] for what a step changes: x, v, the acceleration, ω,
    force and torque."""
    pos, vel, accel, angvel, force, torque = (public.pos, public.vel, public.accel, public.angvel, public.force,
                                              public.torque)
    pos_c, vel_c, accel_c, angvel_c, force_c, torque_c = (copies.pos, copies.vel, copies.accel, copies.angvel,
                                                          copies.force, copies.torque)
    for s in prange(perm.size):
        i = perm[s]
        for d in range(3):
            pos[i, d] = pos_c[s, d]
            vel[i, d] = vel_c[s, d]
            accel[i, d] = accel_c[s, d]
            angvel[i, d] = angvel_c[s, d]
            force[i, d] = force_c[s, d]
            torque[i, d] = torque_c[s, d]
