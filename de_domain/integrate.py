"""Leapfrog integration with gravity, background damping and DOF constraints
(DESIGN.md §2 "Time integration", "Background damping"; thesis Eq. 3.38–3.44).

Per DOF with resultant F (contacts + gravity):
    F_d = −α_b |F| sign(v^{n−½}) − α_v m v^{n−½}     (Cundall local + viscous)
    v^{n+½} = v^{n−½} + Δt (F + F_d)/m,   x^{n+1} = x^n + Δt v^{n+½}
the same for rotations with I and the torque (no gravity). A blocked DOF keeps its
velocity; a prescribed DOF takes its prescribed velocity. The reaction needed by
a blocked/prescribed DOF does work, booked as boundary work.

Energies at time n use v^n = (v^{n−½} + v^{n+½})/2, with which the leapfrog
kinetic energy change equals the work Σ F·v^n Δt exactly.
"""
import numpy as np
from numba import njit, prange

BLOCK = 256
N_ENERGY = 5  # kinetic translational, kinetic rotational, gravity potential, background damping, boundary work


@njit(parallel=True, cache=True)
def leapfrog(dt, gravity, local_damping, viscous_damping, n_owned, pos, vel, accel, angvel, mass, inertia,
             blocked, prescribed, prescribed_velocity, force, torque, block_energy):
    """Advance owned particles one step; adds gravity into ``force``; stores the
    translational acceleration (v^{n+½} − v^{n−½})/Δt in ``accel``; energies per block."""
    n_blocks = (n_owned + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        ke_t = 0.0
        ke_r = 0.0
        potential = 0.0
        damping = 0.0
        boundary = 0.0
        for i in range(b * BLOCK, min((b + 1) * BLOCK, n_owned)):
            m = mass[i]
            for d in range(6):
                if d < 3:
                    force[i, d] += m * gravity[d]
                    f = force[i, d]
                    v = vel[i, d]
                    inv = 1.0 / m
                    weight = m
                else:
                    f = torque[i, d - 3]
                    v = angvel[i, d - 3]
                    inv = 1.0 / inertia[i]
                    weight = inertia[i]
                if blocked[i, d] or prescribed[i, d]:
                    v_new = prescribed_velocity[i, d] if prescribed[i, d] else v
                    v_mid = 0.5 * (v + v_new)
                    reaction = (v_new - v) * weight / dt - f
                    boundary += reaction * v_mid * dt
                else:
                    f_damp = -viscous_damping * weight * v
                    if local_damping > 0.0 and v != 0.0:
                        f_damp -= local_damping * abs(f) * np.sign(v)
                    v_new = v + dt * (f + f_damp) * inv
                    v_mid = 0.5 * (v + v_new)
                    damping -= f_damp * v_mid * dt
                if d < 3:
                    ke_t += 0.5 * m * v_mid * v_mid
                    potential -= m * gravity[d] * pos[i, d]
                    accel[i, d] = (v_new - v) / dt
                    vel[i, d] = v_new
                    pos[i, d] += dt * v_new
                else:
                    ke_r += 0.5 * weight * v_mid * v_mid
                    angvel[i, d - 3] = v_new
        block_energy[b, 0] = ke_t
        block_energy[b, 1] = ke_r
        block_energy[b, 2] = potential
        block_energy[b, 3] = damping
        block_energy[b, 4] = boundary
