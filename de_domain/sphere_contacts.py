"""Sphere–sphere contact kernel and deterministic per-particle force reduction —
the step-by-step *reference* implementation. The engine runs the fused kernels of
:mod:`de_domain.fused`; tests/dem/test_fused_kernels.py checks that they give
bit-identical results to these.

Stage 1 (:func:`sphere_pair_forces`): a parallel loop over fixed-size blocks of the
half Verlet list computes each pair's force and torques into per-pair arrays and
per-block energy sums. Stage 2 (:func:`sum_pair_forces`): each particle sums its
pairs through the i-side and j-side CSR lists in ascending pair order. Neither
stage has a race or an order that depends on the thread count, so results are
bit-identical for any ``numba.set_num_threads``.
"""
import numpy as np
from numba import njit, prange

from .contact_laws import contact_force, linear_normal_stiffness, released_energy

BLOCK = 1024
N_ENERGY = 5  # e_normal, e_tangential, e_rolling, friction, damping


@njit(parallel=True, cache=True)
def sphere_pair_forces(law, dt, pos, vel, accel, angvel, radius, mass, material, young, pair_params,
                       pair_i, pair_j, history, pair_force, pair_torque_i, pair_torque_j, pair_overlap,
                       block_energy):
    """DESIGN.md §2 contact geometry for every listed pair i < j; force on i stored.

    Contact point on the overlap midpoint plane: arms a_i = r_i − δ/2 along n,
    a_j = r_j − δ/2 along −n. Effective radii: k_n from radii (linear), R* and
    r̄ = r_i r_j/(r_i + r_j) (Hertz, rolling); m* = m_i m_j/(m_i + m_j).
    """
    m = pair_i.size
    n_blocks = (m + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        for k in range(N_ENERGY):
            block_energy[b, k] = 0.0
        for p in range(b * BLOCK, min((b + 1) * BLOCK, m)):
            i = pair_i[p]
            j = pair_j[p]
            dx = pos[j, 0] - pos[i, 0]
            dy = pos[j, 1] - pos[i, 1]
            dz = pos[j, 2] - pos[i, 2]
            dist = np.sqrt(dx * dx + dy * dy + dz * dz)
            ri = radius[i]
            rj = radius[j]
            overlap = ri + rj - dist
            h = history[p]
            if overlap <= 0.0:
                if h[0] != 0.0 or h[1] != 0.0 or h[2] != 0.0 or h[3] != 0.0 or h[4] != 0.0 or h[5] != 0.0:
                    params = pair_params[material[i], material[j]]
                    k_lin = linear_normal_stiffness(young[material[i]], ri, young[material[j]], rj)
                    r_red = ri * rj / (ri + rj)
                    block_energy[b, 3] += released_energy(law, params, k_lin, r_red, r_red,
                                                          h[0], h[1], h[2], h[3], h[4], h[5])
                    h[:] = 0.0
                pair_overlap[p] = overlap
                pair_force[p, :] = 0.0
                pair_torque_i[p, :] = 0.0
                pair_torque_j[p, :] = 0.0
                continue
            nx = dx / dist
            ny = dy / dist
            nz = dz / dist
            ai = ri - 0.5 * overlap
            aj = rj - 0.5 * overlap
            # contact-point velocities: i at +a_i n, j at −a_j n
            vix = vel[i, 0] + ai * (angvel[i, 1] * nz - angvel[i, 2] * ny)
            viy = vel[i, 1] + ai * (angvel[i, 2] * nx - angvel[i, 0] * nz)
            viz = vel[i, 2] + ai * (angvel[i, 0] * ny - angvel[i, 1] * nx)
            vjx = vel[j, 0] - aj * (angvel[j, 1] * nz - angvel[j, 2] * ny)
            vjy = vel[j, 1] - aj * (angvel[j, 2] * nx - angvel[j, 0] * nz)
            vjz = vel[j, 2] - aj * (angvel[j, 0] * ny - angvel[j, 1] * nx)
            params = pair_params[material[i], material[j]]
            k_lin = linear_normal_stiffness(young[material[i]], ri, young[material[j]], rj)
            r_red = ri * rj / (ri + rj)
            m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
            dvn = 0.5 * dt * ((accel[j, 0] - accel[i, 0]) * nx + (accel[j, 1] - accel[i, 1]) * ny
                              + (accel[j, 2] - accel[i, 2]) * nz)
            res = contact_force(law, params, nx, ny, nz, overlap, vjx - vix, vjy - viy, vjz - viz, dvn,
                                angvel[j, 0] - angvel[i, 0], angvel[j, 1] - angvel[i, 1],
                                angvel[j, 2] - angvel[i, 2], k_lin, r_red, r_red, m_eff,
                                h[0], h[1], h[2], h[3], h[4], h[5], dt)
            fx, fy, fz = res[0], res[1], res[2]
            h[0] = res[3]; h[1] = res[4]; h[2] = res[5]
            h[3] = res[6]; h[4] = res[7]; h[5] = res[8]
            pair_overlap[p] = overlap
            pair_force[p, 0] = fx
            pair_force[p, 1] = fy
            pair_force[p, 2] = fz
            cx = ny * fz - nz * fy
            cy = nz * fx - nx * fz
            cz = nx * fy - ny * fx
            # torque on i: (a_i n) × F + M_r ; on j: (−a_j n) × (−F) − M_r
            pair_torque_i[p, 0] = ai * cx + res[6]
            pair_torque_i[p, 1] = ai * cy + res[7]
            pair_torque_i[p, 2] = ai * cz + res[8]
            pair_torque_j[p, 0] = aj * cx - res[6]
            pair_torque_j[p, 1] = aj * cy - res[7]
            pair_torque_j[p, 2] = aj * cz - res[8]
            for k in range(N_ENERGY):
                block_energy[b, k] += res[9 + k]


@njit(parallel=True, cache=True)
def sum_pair_forces(n_owned, i_start, j_start, j_pairs, pair_force, pair_torque_i, pair_torque_j,
                    force, torque):
    """force_i = Σ_{pairs (i,·)} F − Σ_{pairs (·,i)} F (overwrites: this is the force reset)."""
    for i in prange(n_owned):
        fx = 0.0; fy = 0.0; fz = 0.0
        tx = 0.0; ty = 0.0; tz = 0.0
        for p in range(i_start[i], i_start[i + 1]):
            fx += pair_force[p, 0]; fy += pair_force[p, 1]; fz += pair_force[p, 2]
            tx += pair_torque_i[p, 0]; ty += pair_torque_i[p, 1]; tz += pair_torque_i[p, 2]
        for s in range(j_start[i], j_start[i + 1]):
            p = j_pairs[s]
            fx -= pair_force[p, 0]; fy -= pair_force[p, 1]; fz -= pair_force[p, 2]
            tx += pair_torque_j[p, 0]; ty += pair_torque_j[p, 1]; tz += pair_torque_j[p, 2]
        force[i, 0] = fx; force[i, 1] = fy; force[i, 2] = fz
        torque[i, 0] = tx; torque[i, 1] = ty; torque[i, 2] = tz
