"""UFL of the explicit mixed displacement–pressure formulation (docs/design.md §4.2).

Notation: u, v displacement and velocity (P1 vector), p mean stress (P1 scalar,
tension positive), π projected pressure gradient (P1 vector), τ the element
stabilisation parameter (DG0), G, K, ρ the shear modulus, bulk modulus and density
(DG0, so materials may differ between cell groups).  N is a P1 shape function;
w, q, ψ are test functions, du, dp trial functions.

The material is linear elastic and small-strain, so every per-step integral of
docs/design.md §4.3 is a constant linear operator of the state.  The bilinear forms here are
assembled once into sparse matrices (K_dev, Bᵀ, P, L; a step applies them and two
transposes); the linear forms once into vectors (lumped matrices, loads) or at
output intervals (energies).
"""

from __future__ import annotations

import ufl


def strain(u):
    """ε(u) = sym ∇u (small strain)."""
    return ufl.sym(ufl.grad(u))


def deviatoric_stress(u, G):
    """s(u) = 2G dev ε(u)."""
    return 2.0 * G * ufl.dev(strain(u))


def von_mises(u, G, initial_stress=None):
    """σ_vM = √(3/2 s:s), s = s(u) + dev σ0 with an initial stress σ0; p does not enter."""
    s = deviatoric_stress(u, G)
    if initial_stress is not None:
        s = s + ufl.dev(initial_stress)
    return ufl.sqrt(1.5 * ufl.inner(s, s))


def geostatic_stress(x, indicator, rho, gravity, ground, k0):
    """σ0 = χ σ_v [K0 (I − ĝ ĝᵀ) + ĝ ĝᵀ], σ_v = −ρ ``|g|`` (x − x_ground)·ĝ (tension positive; χ = 1
    on the cells it applies to, 0 elsewhere); :class:`fe_domain.boundary.GeostaticStress`.
    ``gravity`` g and ``ground`` are constant vectors, ``k0`` a constant."""
    magnitude = ufl.sqrt(ufl.dot(gravity, gravity))
    down = gravity / magnitude
    vertical = ufl.outer(down, down)
    sigma_v = -rho * magnitude * ufl.dot(x - ground, down)
    return indicator * sigma_v * (k0 * (ufl.Identity(3) - vertical) + vertical)


def contraction_stress(indicator, G, K, axis, strain):
    """σ* = χ c (2G (I − â âᵀ) + 2λ I), λ = K − 2G/3: the stress that holds the in-plane
    eigenstrain −c (I − â âᵀ) (``axis`` â a constant unit vector, ``strain`` c a constant);
    :class:`fe_domain.boundary.Contraction`."""
    plane = ufl.Identity(3) - ufl.outer(axis, axis)
    return indicator * strain * (2.0 * G * plane + 2.0 * (K - 2.0 * G / 3.0) * ufl.Identity(3))


def initial_stress_load(w, initial_stress):
    """−∫ σ0 : ∇w, the nodal force that holds an initial stress σ0 in equilibrium."""
    return -ufl.inner(initial_stress, ufl.grad(w)) * ufl.dx


def lumped_mass(q, rho):
    """M = ρ ∫ N (row-sum lumped mass, one value per node)."""
    return rho * q * ufl.dx


def lumped_pressure_mass(q, K):
    """M_p = ∫ N / K."""
    return q / K * ufl.dx


def lumped_projection_mass(q, tau):
    """G̃ = ∫ τ N."""
    return tau * q * ufl.dx


def deviatoric_stiffness(w, du, G):
    """K_dev: ∫ s(du) : ∇w, so that K_dev u = ∫ Bᵀ s(u) (step 1, deviatoric part of f_int)."""
    return ufl.inner(deviatoric_stress(du, G), ufl.grad(w)) * ufl.dx


def displacement_stiffness(w, du, G, K):
    """Pure-displacement P1: K u = ∫ Bᵀ(s(u) + K div u I) (locks as ν → 1/2)."""
    stress = deviatoric_stress(du, G) + K * ufl.div(du) * ufl.Identity(3)
    return ufl.inner(stress, ufl.grad(w)) * ufl.dx


def pressure_divergence(w, dp):
    """Bᵀ: ∫ dp div w, so that Bᵀ p = ∫ Bᵀ p I (step 1, pressure part of f_int).

    Its transpose is step 3's volumetric rate: (Bᵀ)ᵀ v = ∫ q div v.
    """
    return dp * ufl.div(w) * ufl.dx


def pressure_gradient_projection(psi, dp, tau):
    """P: ∫ τ ψ·∇dp, so that π = −G̃⁻¹ P p (step 4).

    Its transpose is step 3's ∫ τ ∇q·π: Pᵀ π.
    """
    return tau * ufl.inner(psi, ufl.grad(dp)) * ufl.dx


def pressure_laplacian(q, dp, tau):
    """L: ∫ τ ∇q·∇dp (step 3's stabilisation is L p + Pᵀ π)."""
    return tau * ufl.inner(ufl.grad(q), ufl.grad(dp)) * ufl.dx


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
