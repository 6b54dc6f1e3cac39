"""Time integration of one particle: gravity, background damping, leapfrog, held DOFs.

docs/design.md §2.13 (thesis Eq. 3.38–3.44), per DOF with resultant F (contacts + gravity):

    F_d = −α_b |F| sign(v^{n−½}) − α_v m v^{n−½}     (Cundall local + viscous)
    v^{n+½} = v^{n−½} + Δt (F + F_d)/m,   x^{n+1} = x^n + Δt v^{n+½}

the same for rotations with I and the torque (no gravity). A blocked DOF keeps its
velocity, a prescribed DOF takes its prescribed velocity; the reaction they need
does work, booked as boundary work. Energies at tⁿ use v^n = (v^{n−½} + v^{n+½})/2,
with which the leapfrog kinetic-energy change equals Σ F·v^n Δt exactly.
"""
from collections import namedtuple

import numpy as np
from numba import njit

IntegrationTerms = namedtuple("IntegrationTerms", [
    "kinetic_translational", "kinetic_rotational",  # ½ m v^n·v^n, ½ I ω^n·ω^n
    "gravity",                                      # −m g·x^n
    "background_damping",                           # dissipated by F_d this step
    "boundary_work",                                # work of the reactions of held DOFs this step
])
"""Running sums over a block of particles, in the order of ``state.I_*``."""


@njit(cache=True, error_model="numpy")
def leapfrog_dof(f, v, m, inv, dt, held, prescribed, prescribed_velocity, local_damping, viscous_damping):
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
def integrate_block(first, last, settings, particles, perm, member_of, terms):
    """Advance the owned free particles of perm positions [first, last) by one step from
    the contact resultant in ``particles.force``/``torque`` (gravity is added here, so
    ``force`` ends as the full resultant; a clump's member, ``member_of[i] ≥ 0``, is moved
    by its clump, :func:`de_domain.fused.integrate_clumps`). Returns the running :data:`IntegrationTerms`
    ``terms`` with these particles' added, particle by particle and DOF by DOF. One
    call per block: the named tuples are unpacked once per block (each unpacked array
    costs an atomic reference-count increment and decrement)."""
    dt = settings.dt
    gravity = settings.gravity
    local_damping = settings.local_damping
    viscous_damping = settings.viscous_damping
    pos = particles.pos
    vel = particles.vel
    accel = particles.accel
    angvel = particles.angvel
    force = particles.force
    torque = particles.torque
    blocked = particles.blocked
    prescribed = particles.prescribed
    prescribed_velocity = particles.prescribed_velocity
    mass = particles.mass
    inertia = particles.inertia
    ghost = particles.ghost
    ke_t, ke_r, potential, damping, boundary = terms
    for s in range(first, last):
        i = np.uint64(s) if settings.in_order else np.uint64(perm[s])
        if ghost[i] or member_of[i] >= 0:
            continue
        m = mass[i]
        inv = 1.0 / m
        constrained = False
        if settings.has_constraints:
            for d in range(6):
                if blocked[i, d] or prescribed[i, d]:
                    constrained = True
        for d in range(3):
            force[i, d] += m * gravity[d]
            v = vel[i, d]
            held = constrained and (blocked[i, d] or prescribed[i, d])
            v_new, v_mid, work, damped = leapfrog_dof(force[i, d], v, m, inv, dt, held, prescribed[i, d],
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
            v_new, v_mid, work, damped = leapfrog_dof(torque[i, d], angvel[i, d], weight, inv, dt, held,
                                                      prescribed[i, d + 3], prescribed_velocity[i, d + 3],
                                                      local_damping, viscous_damping)
            boundary += work
            damping -= damped
            ke_r += 0.5 * weight * v_mid * v_mid
            angvel[i, d] = v_new
    return IntegrationTerms(ke_t, ke_r, potential, damping, boundary)
