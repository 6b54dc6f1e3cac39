"""UFL of the explicit mixed displacement–pressure formulation (DESIGN §4).

Notation: u, v displacement and velocity (P1 vector), p mean stress (P1 scalar,
tension positive), π projected pressure gradient (P1 vector), τ the element
stabilisation parameter (DG0), G, K, ρ the shear modulus, bulk modulus and density
(DG0, so materials may differ between cell groups).  N is a P1 shape function;
w, q, ψ are test functions.

Every form here is linear in the test function and is assembled as a vector (per
step) or once (lumped matrices, loads).
"""

from __future__ import annotations

import ufl


def strain(u):
    """ε(u) = sym ∇u (small strain)."""
    return ufl.sym(ufl.grad(u))


def deviatoric_stress(u, G):
    """s(u) = 2G dev ε(u)."""
    return 2.0 * G * ufl.dev(strain(u))


def von_mises(u, G):
    """σ_vM = √(3/2 s:s); the mean stress p does not enter."""
    s = deviatoric_stress(u, G)
    return ufl.sqrt(1.5 * ufl.inner(s, s))


def lumped_mass(q, rho):
    """M = ρ ∫ N (row-sum lumped mass, one value per node)."""
    return rho * q * ufl.dx


def lumped_pressure_mass(q, K):
    """M_p = ∫ N / K."""
    return q / K * ufl.dx


def lumped_projection_mass(q, tau):
    """G̃ = ∫ τ N."""
    return tau * q * ufl.dx


def internal_force_and_projection(z, u, p, G, tau):
    """Step 1's f_int = ∫ Bᵀ(s(u) + p I) and step 4's ∫ τ N ∇p, in one element pass.

    ``z`` is a test function of a 6-component P1 space: z[0:3] = w (momentum),
    z[3:6] = ψ (pressure-gradient projection).  Both parts need only (u, p) at the
    same time level, so they share one assembly.
    """
    w = ufl.as_vector([z[0], z[1], z[2]])
    psi = ufl.as_vector([z[3], z[4], z[5]])
    stress = deviatoric_stress(u, G) + p * ufl.Identity(3)
    return (ufl.inner(stress, ufl.grad(w)) + tau * ufl.inner(psi, ufl.grad(p))) * ufl.dx


def internal_force_displacement(w, u, G, K):
    """Pure-displacement P1: f_int = ∫ Bᵀ(s(u) + K div u I) (locks as ν → 1/2)."""
    stress = deviatoric_stress(u, G) + K * ufl.div(u) * ufl.Identity(3)
    return ufl.inner(stress, ufl.grad(w)) * ufl.dx


def pressure_increment(z, v, p, pi, tau, dt):
    """Step 3's right-hand side, its two parts on separate components of a 2-component test z:

    z[0]: Δt ∫ q div v^{n+½}        (volumetric rate)
    z[1]: ∫ τ ∇q·(∇p^n + π^n)       (OSS stabilisation; kept apart for its dissipation)
    """
    return (dt * z[0] * ufl.div(v) + tau * ufl.inner(ufl.grad(z[1]), ufl.grad(p) + pi)) * ufl.dx


def deviatoric_strain_energy(u, G):
    """∫ G dev ε : dev ε  (the volumetric part is ½ Σ M_p p² for the mixed form)."""
    e = ufl.dev(strain(u))
    return G * ufl.inner(e, e) * ufl.dx


def volumetric_strain_energy(u, K):
    """∫ K/2 (div u)²  (pure-displacement formulation only)."""
    return 0.5 * K * ufl.div(u) ** 2 * ufl.dx


def traction_load(w, traction, ds):
    """∫_Γ t·w (t a constant vector in Pa)."""
    return ufl.inner(traction, w) * ds


def normal_pressure_load(w, pressure, ds, n):
    """∫_Γ −p_n n·w (p_n > 0 pushes into the body)."""
    return -pressure * ufl.inner(n, w) * ds


def body_force_load(w, rho, acceleration):
    """∫ ρ b·w (b a constant acceleration, e.g. gravity)."""
    return rho * ufl.inner(acceleration, w) * ufl.dx
