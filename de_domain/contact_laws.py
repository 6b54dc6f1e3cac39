"""Contact laws for one contact (docs/design.md §2.2–2.7), shared by sphere–sphere, sphere–wall
and sphere–facet kernels.

Conventions (docs/design.md §2.2): ``n`` points from body i (always a sphere) to body j
(sphere, wall or facet); ``overlap`` δ > 0 in contact; ``v_r`` is the velocity of
j's contact point relative to i's; the returned force is the force **on i** (j gets
the opposite). The rolling moment ``M_r`` is stored as the moment on i (j gets −M_r);
it is the −k_r Δθ_r spring of docs/design.md §2.7 seen from j.

Law selection is an integer (``LINEAR`` or ``HERTZ``) resolved in one place,
:func:`normal_force_and_stiffness`; every kernel calls the one law, ``contact_force``
(``contact_force_inlined`` in the sphere-pair loop).

Parameters are read in place as ``pair_params[a, b, PAIR_*]`` for the material pair
(a, b): taking the row ``pair_params[a, b]`` would make an array view, which costs a
reference-count increment and decrement (two calls, atomic) per contact.
``contact_force_inlined`` is inlined (Numba IR) into the sphere-pair kernel, where a call
would pass 27 arguments and return 14 values through memory per contact; inlined, it
takes that kernel's ``FASTMATH`` flags (the same as its own).
"""
import math
from collections import namedtuple

from numba import njit

from .materials import (
    PAIR_DAMPING_RATIO,
    PAIR_DAMPING_RATIO_HERTZ,
    PAIR_E_STAR,
    PAIR_FRICTION,
    PAIR_G_STAR,
    PAIR_ROLLING_FRICTION,
    PAIR_ROLLING_STIFFNESS,
    PAIR_STIFFNESS_RATIO,
)

# LLVM flags of the contact kernels: reciprocals and no signed zeros; never "nnan"/"ninf"
# (NaN is a marker in the pair kernel). Never "contract" either: with FMA contraction a
# process that had just compiled the kernels ran other bits than one that loaded the same
# kernels from Numba's on-disk cache (a 300-sphere settle parted after 4,000 steps; a loose
# deposit ended at e = 0.829 against 0.835), so a rerun could differ from the first run.
FASTMATH = {"arcp", "nsz"}
LINEAR = 0
HERTZ = 1
LAWS = {"linear": LINEAR, "hertz": HERTZ}

ContactGeometry = namedtuple("ContactGeometry", "nx ny nz overlap")
"""Unit normal n from body i to body j and the overlap δ (> 0 in contact)."""
RelativeMotion = namedtuple("RelativeMotion", "vx vy vz dvn wx wy wz")
"""v_r: velocity of j's contact point relative to i's (v^{n−½}); ``dvn`` = ½Δt (a_j − a_i)·n,
the step from v_rn^{n−½} to v_rn at tⁿ; w = ω_j − ω_i."""
ContactBodies = namedtuple("ContactBodies", "k_linear r_star r_roll m_eff")
"""Linear normal stiffness, R* (Hertz), r̄ (rolling arm) and effective mass m* of the pair."""
Springs = namedtuple("Springs", "ftx fty ftz mrx mry mrz")
"""Contact history: tangential spring force on i (3), rolling moment on i (3)."""
ContactEnergy = namedtuple("ContactEnergy", "normal tangential rolling friction damping")
"""Elastic energy stored at tⁿ (normal, tangential, rolling) and this step's dissipation
(friction incl. rolling plasticity, normal damping), in the order of ``state.E_*``."""
ContactResult = namedtuple("ContactResult", "fx fy fz springs energy")
"""Force on i, the updated history and the energy terms of one contact step."""


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def linear_normal_stiffness(young_i, radius_i, young_j, radius_j):
    """k_n = k_i k_j/(k_i + k_j) with k = 4 E r (thesis Eq. 3.28–3.30): 2 E r* for equal E."""
    k_i = 4.0 * young_i * radius_i
    k_j = 4.0 * young_j * radius_j
    return k_i * k_j / (k_i + k_j)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def normal_force_and_stiffness(law, overlap, k_linear, r_star, pair_params, a, b):
    """Elastic normal force, tangent normal stiffness, tangential stiffness, stored energy.

    LINEAR: f = k_n δ, k_t = k_n/κ, U = ½ k_n δ².
    HERTZ:  f = 4/3 E* √(R* δ) δ, k_n = df/dδ = 2 E* √(R* δ), k_t = 8 G* √(R* δ),
            U = 8/15 E* √R* δ^{5/2}.
    """
    if law == HERTZ:
        root = math.sqrt(r_star * overlap)
        e_star = pair_params[a, b, PAIR_E_STAR]
        f = 4.0 / 3.0 * e_star * root * overlap
        return f, 2.0 * e_star * root, 8.0 * pair_params[a, b, PAIR_G_STAR] * root, 0.4 * f * overlap
    f = k_linear * overlap
    return f, k_linear, k_linear / pair_params[a, b, PAIR_STIFFNESS_RATIO], 0.5 * f * overlap


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def rotate_into_plane(x, y, z, nx, ny, nz):
    """Project a stored tangential vector on the plane normal to n and rescale it to its
    old magnitude (rigid rotation of the spring with the contact, docs/design.md §2.6).

    The scale is |x|/|x − (x·n)n| = (1 − q)^(−½), q = (x·n)²/|x|². For the small turns of
    one step (q < 1e-6) it is the series 1 + q/2 + 3q²/8 (truncation < 4e-19, below
    round-off), which keeps the square root and division off the contact's dependency
    chain; otherwise the exact ratio. Returns the vector and its old squared magnitude."""
    norm2_old = x * x + y * y + z * z
    if norm2_old == 0.0:
        return x, y, z, 0.0
    inv_norm2_old = 1.0 / norm2_old  # depends on the stored vector only: computed early
    dot = x * nx + y * ny + z * nz
    x -= dot * nx
    y -= dot * ny
    z -= dot * nz
    q = dot * dot * inv_norm2_old
    if q < 1e-6:
        scale = 1.0 + q * (0.5 + 0.375 * q)
    else:
        norm2_rot = x * x + y * y + z * z
        if norm2_rot <= 0.0:
            return x, y, z, norm2_old
        scale = math.sqrt(norm2_old / norm2_rot)
    return x * scale, y * scale, z * scale, norm2_old


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def rolling_moment(k_r, mr_max, nx, ny, nz, wrx, wry, wrz, mrx, mry, mrz, dt):
    """Rolling resistance, an elastic–plastic spring (docs/design.md §2.7): the stored moment on i
    rotated into the tangent plane, M_r* = M_r + k_r Δθ_r with Δθ_r = (ω_j − ω_i)Δt
    projected on that plane, and |M_r| ≤ ``mr_max`` = η_r f_n r̄. Returns the moment, its
    elastic energy and the plastic work of this step (as for the tangential spring)."""
    inv_kr = 1.0 / k_r
    mrx, mry, mrz, mr2_old = rotate_into_plane(mrx, mry, mrz, nx, ny, nz)
    w_n = wrx * nx + wry * ny + wrz * nz
    mrx += k_r * (wrx - w_n * nx) * dt
    mry += k_r * (wry - w_n * ny) * dt
    mrz += k_r * (wrz - w_n * nz) * dt
    mr2_trial = mrx * mrx + mry * mry + mrz * mrz
    if mr2_trial <= mr_max * mr_max:
        return mrx, mry, mrz, 0.5 * mr2_trial * inv_kr, 0.0
    mr_trial = math.sqrt(mr2_trial)
    scale = mr_max / mr_trial
    if mr_max > 0.0:
        dissipation = (mr_trial - mr_max) * mr_max * inv_kr
    else:
        dissipation = 0.5 * mr2_old * inv_kr
    return mrx * scale, mry * scale, mrz * scale, 0.5 * mr_max * mr_max * inv_kr, dissipation


def _contact_force(law, pair_params, a, b, geometry, motion, bodies, springs, dt):
    """One contact step of docs/design.md §2.3–2.7.

    Normal: f_n = f_el(δ) − c_n v_rn, c_n = 2α√(m* k_n), clipped to f_n ≥ 0, with
    α calibrated per law so that the rebound equals the set restitution. The
    dashpot uses the normal relative velocity at tⁿ, v_rn^{n−½} + ``dvn`` with
    ``dvn`` = ½Δt (a_j − a_i)·n from the last step's accelerations (second order,
    and its dissipation matches the leapfrog kinetic-energy change).
    Tangential: stored force rotated into the new tangent plane (magnitude kept),
    F_t* = F_t + k_t v_rt Δt, Coulomb radial return |F_t| ≤ μ f_n.
    Rolling: M_r* = M_r + k_r Δθ_r (moment on i, Δθ_r = (ω_j − ω_i)Δt projected on
    the tangent plane), k_r = β_r k_t r̄², |M_r| ≤ η_r f_n r̄.

    Materials ``a`` (body i) and ``b`` (body j); the arguments are the named tuples
    above. Returns a :data:`ContactResult`: the force on i, the new springs and the
    energy terms. The friction terms use YADE's plastic work (|F*| − |F|)|F|/k_t.
    """
    nx, ny, nz, overlap = geometry
    vrx, vry, vrz, dvn, wrx, wry, wrz = motion
    k_linear, r_star, r_roll, m_eff = bodies
    ftx, fty, ftz, mrx, mry, mrz = springs
    f_el, k_n, k_t, e_normal = normal_force_and_stiffness(law, overlap, k_linear, r_star, pair_params, a, b)
    v_rn = vrx * nx + vry * ny + vrz * nz
    v_rn_mid = v_rn + dvn
    alpha = pair_params[a, b, PAIR_DAMPING_RATIO_HERTZ] if law == HERTZ else pair_params[a, b, PAIR_DAMPING_RATIO]
    c_n = 2.0 * alpha * math.sqrt(m_eff * k_n)
    f_n = f_el - c_n * v_rn_mid
    if f_n < 0.0:
        f_n = 0.0
    damping_dissipation = -(f_n - f_el) * v_rn_mid * dt

    # tangential spring: rotate into the new tangent plane, keep magnitude
    ftx, fty, ftz, ft2_old = rotate_into_plane(ftx, fty, ftz, nx, ny, nz)
    vtx = vrx - v_rn * nx
    vty = vry - v_rn * ny
    vtz = vrz - v_rn * nz
    ftx += k_t * vtx * dt
    fty += k_t * vty * dt
    ftz += k_t * vtz * dt
    ft2_trial = ftx * ftx + fty * fty + ftz * ftz
    ft_max = pair_params[a, b, PAIR_FRICTION] * f_n
    inv_kt = 1.0 / k_t
    friction_dissipation = 0.0
    if ft2_trial > ft_max * ft_max:  # slip (squares compared: no root while sticking)
        ft_trial = math.sqrt(ft2_trial)
        scale = ft_max / ft_trial
        ftx *= scale
        fty *= scale
        ftz *= scale
        if ft_max > 0.0:
            friction_dissipation = (ft_trial - ft_max) * ft_max * inv_kt
        else:  # zero normal force (μ = 0 or f_n clipped): the stored spring is released
            friction_dissipation = 0.5 * ft2_old * inv_kt
        e_tangential = 0.5 * ft_max * ft_max * inv_kt
    else:
        e_tangential = 0.5 * ft2_trial * inv_kt

    beta_r = pair_params[a, b, PAIR_ROLLING_STIFFNESS]
    if beta_r > 0.0:
        mrx, mry, mrz, e_rolling, rolling_dissipation = rolling_moment(
            beta_r * k_t * r_roll * r_roll, pair_params[a, b, PAIR_ROLLING_FRICTION] * f_n * r_roll,
            nx, ny, nz, wrx, wry, wrz, mrx, mry, mrz, dt)
        friction_dissipation += rolling_dissipation
    else:
        mrx = 0.0
        mry = 0.0
        mrz = 0.0
        e_rolling = 0.0

    fx = -f_n * nx + ftx
    fy = -f_n * ny + fty
    fz = -f_n * nz + ftz
    return ContactResult(fx, fy, fz, Springs(ftx, fty, ftz, mrx, mry, mrz),
                         ContactEnergy(e_normal, e_tangential, e_rolling, friction_dissipation, damping_dissipation))


#: the contact law as the wall and facet kernels call it: one compiled function (their contacts
#: are few; inlining it everywhere tripled the first compilation to 60 s)
contact_force = njit(cache=True, error_model="numpy", fastmath=FASTMATH)(_contact_force)
#: the same law inlined (Numba IR) into the caller: the sphere-pair loop (``fused._pair_block``:
#: −8 % per step)
contact_force_inlined = njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")(_contact_force)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def released_energy(law, pair_params, a, b, k_linear, r_roll, springs):
    """Elastic energy left in the tangential/rolling springs when a contact opens.

    It is booked as friction dissipation (the springs are released), using the
    stiffness at the smallest overlap of the law (linear: exact; Hertz: the spring
    force is already ≈ 0 at δ → 0 because |F_t| ≤ μ f_n → 0).
    """
    if law == HERTZ:
        return 0.0
    ftx, fty, ftz, mrx, mry, mrz = springs
    k_t = k_linear / pair_params[a, b, PAIR_STIFFNESS_RATIO]
    e = 0.5 * (ftx * ftx + fty * fty + ftz * ftz) / k_t
    beta_r = pair_params[a, b, PAIR_ROLLING_STIFFNESS]
    if beta_r > 0.0:
        k_r = beta_r * k_t * r_roll * r_roll
        e += 0.5 * (mrx * mrx + mry * mry + mrz * mrz) / k_r
    return e
