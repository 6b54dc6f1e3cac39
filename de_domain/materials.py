"""Materials and per-pair contact parameter tables (docs/design.md §2.8).

A :class:`Material` holds the inputs of the thesis Table 3.2. The engine turns a
list of materials into dense ``(n_mat, n_mat, N_PAIR)`` tables once, so the contact
kernels only index arrays.

Pair mixing rules (documented choices, YADE-like):
  * friction μ and restitution e: the smaller of the two (``FrictPhys`` uses
    tan(min φ));
  * stiffness ratio κ, rolling stiffness β_r, rolling friction η_r: arithmetic mean;
  * Hertz–Mindlin: 1/E* = Σ (1−ν²)/E, 1/G* = Σ 2(2−ν)(1+ν)/E;
  * linear law: per-sphere springs k = 4 E r in series (``contact_laws``).
"""
from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

# Columns of the pair table.
PAIR_FRICTION = 0
PAIR_DAMPING_RATIO = 1  # α of c_n = 2α√(m* k_n), see damping_ratio
PAIR_STIFFNESS_RATIO = 2  # κ = k_n / k_t
PAIR_ROLLING_STIFFNESS = 3  # β_r
PAIR_ROLLING_FRICTION = 4  # η_r
PAIR_E_STAR = 5
PAIR_G_STAR = 6
PAIR_DAMPING_RATIO_HERTZ = 7  # α for the Hertz law, see damping_ratio_hertz
N_PAIR = 8


def _check(name, value, low, high, low_open=False):
    ok = (value > low if low_open else value >= low) and value <= high
    if not (ok and math.isfinite(value)):
        bracket = "(" if low_open else "["
        raise ValueError(f"Material.{name} = {value!r} is outside the allowed range {bracket}{low}, {high}]")


@dataclass(frozen=True)
class Material:
    """Sphere/wall material (thesis Table 3.2, docs/design.md §2.8).

    density [kg/m³], young E [Pa], poisson ν, friction μ (Coulomb coefficient),
    restitution e ∈ (0, 1], stiffness_ratio κ = k_n/k_t, rolling_stiffness β_r
    (k_r = β_r k_t r̄²), rolling_friction η_r (``|M_r| ≤ η_r f_n r̄``).
    """

    density: float = 2650.0
    young: float = 1e8
    poisson: float = 0.25
    friction: float = 0.5
    restitution: float = 0.5
    stiffness_ratio: float = 1.5
    rolling_stiffness: float = 0.0
    rolling_friction: float = 0.0

    def __post_init__(self):
        _check("density", self.density, 0.0, math.inf, low_open=True)
        _check("young", self.young, 0.0, math.inf, low_open=True)
        _check("poisson", self.poisson, -1.0, 0.5, low_open=True)
        _check("friction", self.friction, 0.0, math.inf)
        _check("restitution", self.restitution, 0.0, 1.0, low_open=True)
        _check("stiffness_ratio", self.stiffness_ratio, 0.0, math.inf, low_open=True)
        _check("rolling_stiffness", self.rolling_stiffness, 0.0, math.inf)
        _check("rolling_friction", self.rolling_friction, 0.0, math.inf)

    def as_dict(self):
        return asdict(self)


def restitution_of_damping_ratio(alpha: float) -> float:
    """Restitution of the linear spring–dashpot with the no-tension cut-off f_n ≥ 0.

    Schwager & Pöschel, Phys. Rev. E 75, 051304 (2007), Eq. 22 with β = α ω₀: the
    contact ends when the force (not the overlap) vanishes. For α → 0 this tends
    to the classical e = exp(−απ/√(1−α²)).
    """
    if alpha <= 0.0:
        return 1.0
    if alpha < 1.0:
        s = math.sqrt(1.0 - alpha * alpha)
        phase = math.atan2(2.0 * alpha * s, 1.0 - 2.0 * alpha * alpha)
        return math.exp(-alpha / s * (math.pi - phase))  # atan2 covers both α < and > 1/√2
    if alpha == 1.0:
        return math.exp(-2.0)
    s = math.sqrt(alpha * alpha - 1.0)
    return math.exp(-alpha / s * math.atanh(2.0 * alpha * s / (2.0 * alpha * alpha - 1.0)))


@functools.lru_cache(maxsize=256)
def damping_ratio(restitution: float) -> float:
    """Damping ratio α of c_n = 2α√(m* k_n) that gives the restitution e (docs/design.md §2.5, §8.1).

    The starting reference's α = −ln e/√(π² + ln² e) assumes the dashpot may pull at the end of
    the contact; with the binding no-tension rule (f_n ≥ 0) that α gives a larger
    rebound (e.g. 0.25 instead of 0.1). We therefore solve
    :func:`restitution_of_damping_ratio` (α) = e by bisection, starting from the
    classical value; for e ≥ 0.9 the two differ by < 0.3 %.
    """
    return _bisect_damping_ratio(restitution_of_damping_ratio, restitution, iterations=200)


def _bisect_damping_ratio(restitution_of, restitution, iterations):
    """The α ≥ 0 with ``restitution_of(α) = e`` (decreasing in α), by bisection."""
    if restitution >= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while restitution_of(hi) > restitution:
        hi *= 2.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if restitution_of(mid) > restitution:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@njit(cache=True)
def restitution_of_hertz_damping_ratio(alpha):
    """Restitution of the Hertz contact with the dashpot c_n = 2α√(m* k_n), k_n = dF/dδ.

    In units where the impact speed, m* and 4/3 E*√R* are 1 the motion is
    x'' = −x^{3/2} − 2√1.5 α x^{1/4} x' (force clipped to ≥ 0), x(0) = 0, x'(0) = 1,
    independent of speed and stiffness (Tsuji et al. 1992 form); integrated by RK4.
    """
    c = 2.0 * math.sqrt(1.5) * alpha
    h = 2e-4
    x = 0.0
    v = 1.0
    while True:
        k1x = v
        k1v = min(0.0, -max(x, 0.0) ** 1.5 - c * max(x, 0.0) ** 0.25 * v)
        x2 = x + 0.5 * h * k1x
        v2 = v + 0.5 * h * k1v
        k2x = v2
        k2v = min(0.0, -max(x2, 0.0) ** 1.5 - c * max(x2, 0.0) ** 0.25 * v2)
        x3 = x + 0.5 * h * k2x
        v3 = v + 0.5 * h * k2v
        k3x = v3
        k3v = min(0.0, -max(x3, 0.0) ** 1.5 - c * max(x3, 0.0) ** 0.25 * v3)
        x4 = x + h * k3x
        v4 = v + h * k3v
        k4x = v4
        k4v = min(0.0, -max(x4, 0.0) ** 1.5 - c * max(x4, 0.0) ** 0.25 * v4)
        x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        if x <= 0.0:
            return -v
        if v >= 0.0 and x < 1e-12:  # stuck (overdamped): no rebound
            return 0.0


@functools.lru_cache(maxsize=256)
def damping_ratio_hertz(restitution: float) -> float:
    """α giving the restitution e with the Hertz law (bisection on
    :func:`restitution_of_hertz_damping_ratio`)."""
    return _bisect_damping_ratio(restitution_of_hertz_damping_ratio, restitution, iterations=60)


def material_arrays(materials):
    """Per-material arrays ``(density, young, poisson)`` as float64."""
    density = np.array([m.density for m in materials], dtype=np.float64)
    young = np.array([m.young for m in materials], dtype=np.float64)
    poisson = np.array([m.poisson for m in materials], dtype=np.float64)
    return density, young, poisson


def pair_table(materials) -> np.ndarray:
    """Dense ``(n_mat, n_mat, N_PAIR)`` table of pair parameters (mixing rules above)."""
    n = len(materials)
    if n == 0:
        raise ValueError("materials: at least one Material is required")
    table = np.zeros((n, n, N_PAIR))
    for a, ma in enumerate(materials):
        for b, mb in enumerate(materials):
            row = table[a, b]
            row[PAIR_FRICTION] = min(ma.friction, mb.friction)
            row[PAIR_DAMPING_RATIO] = damping_ratio(min(ma.restitution, mb.restitution))
            row[PAIR_DAMPING_RATIO_HERTZ] = damping_ratio_hertz(min(ma.restitution, mb.restitution))
            row[PAIR_STIFFNESS_RATIO] = 0.5 * (ma.stiffness_ratio + mb.stiffness_ratio)
            row[PAIR_ROLLING_STIFFNESS] = 0.5 * (ma.rolling_stiffness + mb.rolling_stiffness)
            row[PAIR_ROLLING_FRICTION] = 0.5 * (ma.rolling_friction + mb.rolling_friction)
            row[PAIR_E_STAR] = 1.0 / ((1 - ma.poisson**2) / ma.young + (1 - mb.poisson**2) / mb.young)
            row[PAIR_G_STAR] = 1.0 / (
                2 * (2 - ma.poisson) * (1 + ma.poisson) / ma.young
                + 2 * (2 - mb.poisson) * (1 + mb.poisson) / mb.young
            )
    return table
