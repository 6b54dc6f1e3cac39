"""Rotation of a rigid body (a clump of spheres) by unit quaternions: the NO_SQUISH scheme.

Scheme: Miller, Eleftheriou, Pattnaik, Ndirango, Newns & Martyna (2002), "Symplectic quaternion
scheme for biophysical molecular dynamics", J. Chem. Phys. 116, 8649 (LAMMPS ``fix rigid/nve``
uses it). Symplectic and time-reversible: the energy of a torque-free body oscillates within
O(Δt²) without drift, and the angular momentum in the space frame is kept to round-off
(docs/design.md §2.19).

Conventions. A quaternion q = (q0, q1, q2, q3) rotates body-frame vectors into the space
frame, x = q ⊗ (0, x_b) ⊗ q*; the body frame is the principal frame of the body's inertia
(moments I = (I1, I2, I3)). The conjugate momentum of q is p = 2 q ⊗ (0, L_b), with L_b the
angular momentum in the body frame; then L_b,k = ½ p·P_k q, where P_k q = q ⊗ (0, e_k):

    P_1 q = (−q1,  q0,  q3, −q2),  P_2 q = (−q2, −q3,  q0,  q1),  P_3 q = (−q3,  q2, −q1,  q0).

The free rotation about body axis k for a time t is exact (Miller et al., Eq. 21–22):
ζ = t (p·P_k q)/(4 I_k), q ← cos ζ q + sin ζ P_k q, p ← cos ζ p + sin ζ P_k p. A step of the
free body is the symmetric product R_3(Δt/2) R_2(Δt/2) R_1(Δt) R_2(Δt/2) R_3(Δt/2).

In the DEM's leapfrog (the spheres' scheme, docs/design.md §2.13) the space-frame angular
momentum lives at half steps: L^{n+½} = L^{n−½} + τⁿ Δt, then q^{n+1} is the free rotation
of (qⁿ, p(qⁿ, L^{n+½})) over Δt. This is Miller's kick–rotate–kick with the two half kicks of
consecutive steps merged, so the orientations are those of the published scheme.
"""
import math

from numba import njit


@njit(cache=True, error_model="numpy")
def quat_multiply(a, b):
    """a ⊗ b (Hamilton product) of two quaternions given as 4-tuples."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, error_model="numpy")
def to_space(q, x, y, z):
    """The body-frame vector (x, y, z) in the space frame: q ⊗ (0, x) ⊗ q* = R(q) x."""
    q0, q1, q2, q3 = q
    # R(q) x = x + 2 q0 (u × x) + 2 u × (u × x), u = (q1, q2, q3)
    tx = 2.0 * (q2 * z - q3 * y)
    ty = 2.0 * (q3 * x - q1 * z)
    tz = 2.0 * (q1 * y - q2 * x)
    return (x + q0 * tx + (q2 * tz - q3 * ty),
            y + q0 * ty + (q3 * tx - q1 * tz),
            z + q0 * tz + (q1 * ty - q2 * tx))


@njit(cache=True, error_model="numpy")
def to_body(q, x, y, z):
    """The space-frame vector (x, y, z) in the body frame: R(q)ᵀ x."""
    return to_space((q[0], -q[1], -q[2], -q[3]), x, y, z)


@njit(cache=True, error_model="numpy")
def _permuted(k, v):
    """P_k v (module docstring) for k = 1, 2, 3."""
    v0, v1, v2, v3 = v
    if k == 1:
        return (-v1, v0, v3, -v2)
    if k == 2:
        return (-v2, -v3, v0, v1)
    return (-v3, v2, -v1, v0)


@njit(cache=True, error_model="numpy")
def conjugate_momentum(q, lx, ly, lz):
    """p = 2 q ⊗ (0, L_b) for the space-frame angular momentum (lx, ly, lz)."""
    bx, by, bz = to_body(q, lx, ly, lz)
    p0, p1, p2, p3 = quat_multiply(q, (0.0, bx, by, bz))
    return (2.0 * p0, 2.0 * p1, 2.0 * p2, 2.0 * p3)


@njit(cache=True, error_model="numpy")
def body_momentum(q, p):
    """L_b,k = ½ p·P_k q, k = 1, 2, 3."""
    a = _permuted(1, q)
    b = _permuted(2, q)
    c = _permuted(3, q)
    return (0.5 * (p[0] * a[0] + p[1] * a[1] + p[2] * a[2] + p[3] * a[3]),
            0.5 * (p[0] * b[0] + p[1] * b[1] + p[2] * b[2] + p[3] * b[3]),
            0.5 * (p[0] * c[0] + p[1] * c[1] + p[2] * c[2] + p[3] * c[3]))


@njit(cache=True, error_model="numpy")
def _rotate_about(k, q, p, inertia_k, t):
    """The exact free rotation about body axis k for a time t (module docstring)."""
    qk = _permuted(k, q)
    pk = _permuted(k, p)
    zeta = t * (p[0] * qk[0] + p[1] * qk[1] + p[2] * qk[2] + p[3] * qk[3]) / (4.0 * inertia_k)
    c = math.cos(zeta)
    s = math.sin(zeta)
    return ((c * q[0] + s * qk[0], c * q[1] + s * qk[1], c * q[2] + s * qk[2], c * q[3] + s * qk[3]),
            (c * p[0] + s * pk[0], c * p[1] + s * pk[1], c * p[2] + s * pk[2], c * p[3] + s * pk[3]))


@njit(cache=True, error_model="numpy")
def free_rotation(q, p, inertia, dt):
    """One NO_SQUISH step of the torque-free body: R_3(Δt/2) R_2(Δt/2) R_1(Δt) R_2(Δt/2) R_3(Δt/2)
    (``inertia``: the principal moments I1, I2, I3). Returns (q, p), q renormalised."""
    half = 0.5 * dt
    q, p = _rotate_about(3, q, p, inertia[2], half)
    q, p = _rotate_about(2, q, p, inertia[1], half)
    q, p = _rotate_about(1, q, p, inertia[0], dt)
    q, p = _rotate_about(2, q, p, inertia[1], half)
    q, p = _rotate_about(3, q, p, inertia[2], half)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm), p


@njit(cache=True, error_model="numpy")
def rotational_leapfrog(q, angular_momentum, torque, inertia, dt):
    """One leapfrog step of the rotation (module docstring): L^{n+½} = L^{n−½} + τⁿ Δt (space
    frame), then qⁿ → q^{n+1} by :func:`free_rotation`. Returns (q^{n+1}, L^{n+½}, ω), ω the
    space-frame angular velocity R I⁻¹ Rᵀ L^{n+½} at the new orientation (the rate the members
    move with over the next step)."""
    lx = angular_momentum[0] + torque[0] * dt
    ly = angular_momentum[1] + torque[1] * dt
    lz = angular_momentum[2] + torque[2] * dt
    q_new, _ = free_rotation(q, conjugate_momentum(q, lx, ly, lz), inertia, dt)
    bx, by, bz = to_body(q_new, lx, ly, lz)
    omega = to_space(q_new, bx / inertia[0], by / inertia[1], bz / inertia[2])
    return q_new, (lx, ly, lz), omega


@njit(cache=True, error_model="numpy")
def rotational_energy(q, p, inertia):
    """½ Σ_k L_b,k² / I_k, the Hamiltonian of the free body that NO_SQUISH keeps."""
    b1, b2, b3 = body_momentum(q, p)
    return 0.5 * (b1 * b1 / inertia[0] + b2 * b2 / inertia[1] + b3 * b3 / inertia[2])
