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

The sines and cosines of the sub-rotations are computed here (:func:`sin_cos`), not by the math
library: a loop over clumps with no library call in it is one the compiler runs four clumps at
a time (AVX2), the clump step's largest cost otherwise (docs/performance.md).
"""
import math

import numpy as np
from numba import njit

# Taylor coefficients of sin r / r and cos r in r² (to r¹⁶ / 17! and r¹⁶ / 16!)
_SIN = tuple((-1.0) ** j / math.factorial(2 * j + 1) for j in range(9))
_COS = tuple((-1.0) ** j / math.factorial(2 * j) for j in range(9))
_TWO_OVER_PI = 2.0 / math.pi
_HALF_PI_HI = 1.5707963267341256   # π/2 = HI + LO (fdlibm): HI the first 33 bits, k HI exact for |k| < 2²⁰
_HALF_PI_LO = 6.077100506506192e-11
_ROUNDER = 1.5 * 2.0 ** 52         # (x + R) − R is x rounded to the nearest integer, |x| < 2⁵¹

# The bodies one call advances together, and their work array: field f of body c at
# w[f LANES + c], so that in each loop over the bodies every access is a fixed distance from the
# others and the compiler computes four bodies at a time.
LANES = 64
W_QUAT = 0        # q (4 fields): qⁿ in, q^{n+1} out
W_MOMENTUM = 4    # the space-frame angular momentum L^{n+½} (3)
W_CONJUGATE = 7   # p (4), the rotation's own
W_INERTIA = 11    # principal moments I1, I2, I3 (3)
W_OMEGA = 14      # out: ω = R I⁻¹ Rᵀ L^{n+½} at q^{n+1} (3)
N_W = 17


@njit(cache=True, error_model="numpy", inline="always")
def sin_cos(z):
    """(cos z, sin z) without a library call or a branch, so that a loop of it is vectorised:
    Cody & Waite's reduction r = z − k π/2 (k the nearest integer, π/2 in two parts so that k π/2
    is subtracted without rounding for z within ±10⁵), r within ±π/4, the Taylor series of sin r
    and cos r to r¹⁷ and r¹⁶ (truncation below (π/4)¹⁸/18! < 2·10⁻¹⁸), then the quadrant k mod 4.
    Within 2 ulp of the math library's for z within ±10⁵ (tested)."""
    k = (z * _TWO_OVER_PI + _ROUNDER) - _ROUNDER
    r = (z - k * _HALF_PI_HI) - k * _HALF_PI_LO
    r2 = r * r
    s = r * (_SIN[0] + r2 * (_SIN[1] + r2 * (_SIN[2] + r2 * (_SIN[3] + r2 * (_SIN[4] + r2 * (
        _SIN[5] + r2 * (_SIN[6] + r2 * (_SIN[7] + r2 * _SIN[8]))))))))
    c = _COS[0] + r2 * (_COS[1] + r2 * (_COS[2] + r2 * (_COS[3] + r2 * (_COS[4] + r2 * (
        _COS[5] + r2 * (_COS[6] + r2 * (_COS[7] + r2 * _COS[8])))))))
    half = (0.5 * (k - 0.5) + _ROUNDER) - _ROUNDER          # ⌊k/2⌋
    odd = k - 2.0 * half                                     # k mod 2: 0 or 1
    upper = half - 2.0 * ((0.5 * (half - 0.5) + _ROUNDER) - _ROUNDER)  # ⌊k/2⌋ mod 2: 1 in quadrants 2, 3
    # exact selections by 0 and 1: sin z = ±(sin r or cos r), cos z = ±(cos r or sin r)
    sin_z = (1.0 - 2.0 * upper) * (odd * c + (1.0 - odd) * s)
    cos_z = (1.0 - 2.0 * (odd + upper - 2.0 * odd * upper)) * (odd * s + (1.0 - odd) * c)
    return cos_z, sin_z


@njit(cache=True, error_model="numpy", inline="always")
def quat_multiply(a, b):
    """a ⊗ b (Hamilton product) of two quaternions given as 4-tuples."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, error_model="numpy", inline="always")
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


@njit(cache=True, error_model="numpy", inline="always")
def to_body(q, x, y, z):
    """The space-frame vector (x, y, z) in the body frame: R(q)ᵀ x."""
    return to_space((q[0], -q[1], -q[2], -q[3]), x, y, z)


@njit(cache=True, error_model="numpy", inline="always")
def _permuted(k, v):
    """P_k v (module docstring) for k = 1, 2, 3, by selection (no branch)."""
    v0, v1, v2, v3 = v
    e1 = k == 1
    e2 = k == 2
    return (-(v1 if e1 else (v2 if e2 else v3)), v0 if e1 else (-v3 if e2 else v2),
            v3 if e1 else (v0 if e2 else -v1), -v2 if e1 else (v1 if e2 else v0))


@njit(cache=True, error_model="numpy", inline="always")
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
def _rotate_about_lanes(w, count, k, t):
    """The exact free rotation about body axis k for a time t (module docstring) of the first
    ``count`` bodies of the work array ``w``: ζ = t (p·P_k q)/(4 I_k), q ← cos ζ q + sin ζ P_k q,
    p ← cos ζ p + sin ζ P_k p."""
    # I_k by exact selection (1 I + 0 I' + 0 I''), no index that depends on k: the compiler
    # must see every access a fixed distance from the others to vectorise the loop
    f1 = 1.0 if k == 1 else 0.0
    f2 = 1.0 if k == 2 else 0.0
    f3 = 1.0 if k == 3 else 0.0
    for c in range(count):
        q = (w[W_QUAT * LANES + c], w[(W_QUAT + 1) * LANES + c], w[(W_QUAT + 2) * LANES + c],
             w[(W_QUAT + 3) * LANES + c])
        p = (w[W_CONJUGATE * LANES + c], w[(W_CONJUGATE + 1) * LANES + c], w[(W_CONJUGATE + 2) * LANES + c],
             w[(W_CONJUGATE + 3) * LANES + c])
        inertia_k = (f1 * w[W_INERTIA * LANES + c] + f2 * w[(W_INERTIA + 1) * LANES + c]
                     + f3 * w[(W_INERTIA + 2) * LANES + c])
        qk = _permuted(k, q)
        pk = _permuted(k, p)
        zeta = t * (p[0] * qk[0] + p[1] * qk[1] + p[2] * qk[2] + p[3] * qk[3]) / (4.0 * inertia_k)
        cz, sz = sin_cos(zeta)
        w[W_QUAT * LANES + c] = cz * q[0] + sz * qk[0]
        w[(W_QUAT + 1) * LANES + c] = cz * q[1] + sz * qk[1]
        w[(W_QUAT + 2) * LANES + c] = cz * q[2] + sz * qk[2]
        w[(W_QUAT + 3) * LANES + c] = cz * q[3] + sz * qk[3]
        w[W_CONJUGATE * LANES + c] = cz * p[0] + sz * pk[0]
        w[(W_CONJUGATE + 1) * LANES + c] = cz * p[1] + sz * pk[1]
        w[(W_CONJUGATE + 2) * LANES + c] = cz * p[2] + sz * pk[2]
        w[(W_CONJUGATE + 3) * LANES + c] = cz * p[3] + sz * pk[3]


@njit(cache=True, error_model="numpy")
def _free_rotation_lanes(w, count, dt):
    """One NO_SQUISH step of the first ``count`` torque-free bodies of the work array ``w``:
    R_3(Δt/2) R_2(Δt/2) R_1(Δt) R_2(Δt/2) R_3(Δt/2), q not renormalised."""
    for j in range(5):  # one call site, its axis not a constant: one compiled specialisation
        _rotate_about_lanes(w, count, abs(j - 2) + 1, dt if j == 2 else 0.5 * dt)


@njit(cache=True, error_model="numpy")
def leapfrog_lanes(w, count, dt):
    """The rotation of one leapfrog step (module docstring) of the first ``count`` bodies of the
    work array ``w`` (fields ``W_*``), their angular momenta already kicked to L^{n+½}: q^{n+1} the
    NO_SQUISH step of (qⁿ, p(qⁿ, L^{n+½})), renormalised, and ω = R I⁻¹ Rᵀ L^{n+½} at q^{n+1} (the
    rate the members move with over the next step)."""
    for c in range(count):
        q = (w[W_QUAT * LANES + c], w[(W_QUAT + 1) * LANES + c], w[(W_QUAT + 2) * LANES + c],
             w[(W_QUAT + 3) * LANES + c])
        w[W_CONJUGATE * LANES + c], w[(W_CONJUGATE + 1) * LANES + c], w[(W_CONJUGATE + 2) * LANES + c], \
            w[(W_CONJUGATE + 3) * LANES + c] = conjugate_momentum(q, w[W_MOMENTUM * LANES + c],
                                                                  w[(W_MOMENTUM + 1) * LANES + c],
                                                                  w[(W_MOMENTUM + 2) * LANES + c])
    _free_rotation_lanes(w, count, dt)
    for c in range(count):
        q0 = w[W_QUAT * LANES + c]; q1 = w[(W_QUAT + 1) * LANES + c]
        q2 = w[(W_QUAT + 2) * LANES + c]; q3 = w[(W_QUAT + 3) * LANES + c]
        norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q = (q0 / norm, q1 / norm, q2 / norm, q3 / norm)
        bx, by, bz = to_body(q, w[W_MOMENTUM * LANES + c], w[(W_MOMENTUM + 1) * LANES + c],
                             w[(W_MOMENTUM + 2) * LANES + c])
        omega = to_space(q, bx / w[W_INERTIA * LANES + c], by / w[(W_INERTIA + 1) * LANES + c],
                         bz / w[(W_INERTIA + 2) * LANES + c])
        w[W_QUAT * LANES + c], w[(W_QUAT + 1) * LANES + c], w[(W_QUAT + 2) * LANES + c], \
            w[(W_QUAT + 3) * LANES + c] = q
        w[W_OMEGA * LANES + c], w[(W_OMEGA + 1) * LANES + c], w[(W_OMEGA + 2) * LANES + c] = omega


@njit(cache=True, error_model="numpy")
def _one_body(q, p, inertia):
    """A work array holding one body (lane 0): q, p and the inertia."""
    w = np.zeros(N_W * LANES)
    for j in range(4):
        w[(W_QUAT + j) * LANES] = q[j]
        w[(W_CONJUGATE + j) * LANES] = p[j]
    for j in range(3):
        w[(W_INERTIA + j) * LANES] = inertia[j]
    return w


@njit(cache=True, error_model="numpy")
def free_rotation(q, p, inertia, dt):
    """One NO_SQUISH step of one torque-free body (``inertia``: the principal moments I1, I2, I3),
    by :func:`_free_rotation_lanes` on a block of one. Returns (q, p), q renormalised."""
    w = _one_body(q, p, inertia)
    _free_rotation_lanes(w, w.size // (N_W * LANES), dt)  # 1, not a constant: no specialisation of its own
    q0 = w[W_QUAT * LANES]; q1 = w[(W_QUAT + 1) * LANES]; q2 = w[(W_QUAT + 2) * LANES]; q3 = w[(W_QUAT + 3) * LANES]
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return ((q0 / norm, q1 / norm, q2 / norm, q3 / norm),
            (w[W_CONJUGATE * LANES], w[(W_CONJUGATE + 1) * LANES], w[(W_CONJUGATE + 2) * LANES],
             w[(W_CONJUGATE + 3) * LANES]))


@njit(cache=True, error_model="numpy")
def rotational_leapfrog(q, angular_momentum, torque, inertia, dt):
    """One leapfrog step of the rotation of one body (module docstring), by :func:`leapfrog_lanes`
    on a block of one: L^{n+½} = L^{n−½} + τⁿ Δt (space frame), then qⁿ → q^{n+1}. Returns
    (q^{n+1}, L^{n+½}, ω), ω the space-frame angular velocity R I⁻¹ Rᵀ L^{n+½} at the new orientation."""
    w = _one_body(q, (0.0, 0.0, 0.0, 0.0), inertia)
    lx = angular_momentum[0] + torque[0] * dt
    ly = angular_momentum[1] + torque[1] * dt
    lz = angular_momentum[2] + torque[2] * dt
    w[W_MOMENTUM * LANES] = lx; w[(W_MOMENTUM + 1) * LANES] = ly; w[(W_MOMENTUM + 2) * LANES] = lz
    leapfrog_lanes(w, w.size // (N_W * LANES), dt)  # 1, not a constant: the engine's specialisation
    return ((w[W_QUAT * LANES], w[(W_QUAT + 1) * LANES], w[(W_QUAT + 2) * LANES], w[(W_QUAT + 3) * LANES]),
            (lx, ly, lz), (w[W_OMEGA * LANES], w[(W_OMEGA + 1) * LANES], w[(W_OMEGA + 2) * LANES]))


@njit(cache=True, error_model="numpy")
def rotational_energy(q, p, inertia):
    """½ Σ_k L_b,k² / I_k, the Hamiltonian of the free body that NO_SQUISH keeps."""
    b1, b2, b3 = body_momentum(q, p)
    return 0.5 * (b1 * b1 / inertia[0] + b2 * b2 / inertia[1] + b3 * b3 / inertia[2])
