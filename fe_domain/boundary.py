"""Boundary conditions, loads and damping laws, addressed by physical-group name.

These are plain parameter records: the solver (``explicit.py``) turns them into
node/dof index arrays and nodal force vectors once, at construction.  A time
``amplitude`` multiplies a load or a prescribed velocity (default: constant 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np


def constant(t: float) -> float:
    """Unit amplitude at all times."""
    return 1.0


def ramp(duration: float) -> Callable[[float], float]:
    """Amplitude rising linearly from 0 to 1 over ``duration`` s, then held."""
    if duration <= 0:
        raise ValueError(f"ramp duration = {duration!r}: must be > 0 (s)")
    return lambda t: min(t / duration, 1.0)


@dataclass(frozen=True)
class Fixed:
    """u = v = 0 on the nodes of facet group ``boundary`` for ``components`` (0=x, 1=y, 2=z)."""

    boundary: str
    components: Sequence[int] = (0, 1, 2)


@dataclass(frozen=True)
class PrescribedVelocity:
    """v = amplitude(t) · velocity on the nodes of ``boundary``; None leaves a component free."""

    boundary: str
    velocity: Sequence[float | None]
    amplitude: Callable[[float], float] = constant


@dataclass(frozen=True)
class Traction:
    """Surface traction t (Pa, a constant vector) on ``boundary``, times amplitude(t)."""

    boundary: str
    traction: Sequence[float]
    amplitude: Callable[[float], float] = constant


@dataclass(frozen=True)
class NormalPressure:
    """Pressure (Pa, > 0 compressive) normal to ``boundary``, times amplitude(t)."""

    boundary: str
    pressure: float
    amplitude: Callable[[float], float] = constant


@dataclass(frozen=True)
class BodyForce:
    """Body force per unit mass b (m/s², e.g. gravity (0, 0, −9.81)), times amplitude(t)."""

    acceleration: Sequence[float]
    amplitude: Callable[[float], float] = constant


@dataclass(frozen=True)
class GeostaticStress:
    """Initial (in-situ) stress of the cells of the volume ``groups``, at rest under gravity
    ``acceleration`` below a level ground surface through ``ground``, with the earth pressure
    coefficient at rest ``K0``:

        σ0 = σ_v [K0 (I − ĝ ĝᵀ) + ĝ ĝᵀ],   σ_v = −ρ g d,   d = (x − x_ground)·ĝ

    (tension positive, ĝ = g / ``|g|``, ρ the cells' density; e.g. Potts & Zdravković, *Finite element
    analysis in geotechnical engineering*, vol. 1, §11.2). It satisfies div σ0 + ρ g = 0 with no
    traction on the ground surface; the solver adds −∫ ∇w : σ0 dx to the external force, so a
    body of soil given its own weight and this stress starts in equilibrium and u, p, the von
    Mises field are measured from it. Without it, a soil loaded by gravity from zero stress
    between roller sides settles to K0 = ν / (1 − ν)."""

    acceleration: Sequence[float]
    ground: Sequence[float]
    K0: float
    groups: Sequence[str]

    def __post_init__(self):
        if not self.K0 > 0:
            raise ValueError(f"GeostaticStress.K0 = {self.K0!r}: must be > 0")
        if not np.linalg.norm(self.acceleration) > 0:
            raise ValueError(f"GeostaticStress.acceleration = {list(self.acceleration)!r}: must not be zero")


@dataclass(frozen=True)
class UniformStress:
    """A uniform initial stress ``stress`` (3 × 3, Pa, tension positive) of the cells of
    ``groups``: the in-situ stress of deep ground, where its change over the model's height is
    small (the closed-form solutions of tunnel linings assume it). Load −∫ σ0 : ∇w, as
    :class:`GeostaticStress`, times amplitude(t) (e.g. a ramp: the excavation's unloading
    applied gradually)."""

    stress: Sequence[Sequence[float]]
    groups: Sequence[str]
    amplitude: Callable[[float], float] = constant


@dataclass(frozen=True)
class Contraction:
    """A shrinking of the cells of ``groups`` in the plane normal to ``axis`` (a tunnel lining's
    section), the eigenstrain ε* = −c (I − â âᵀ) with c = amplitude(t) · ``strain``: the
    "contraction" of a lining that models a tunnel's volume loss (e.g. Vermeer & Brinkgreve,
    PLAXIS manual; Potts & Zdravković vol. 2, §2.4). A free ring shrinks its radius by the
    fraction c and its area by about 2c, so c = V_L / 2 for a volume loss V_L; the ground
    around it holds it back. It enters as the initial stress σ* = −C:ε* = c (2G (I − â âᵀ) + 2λ I),
    λ = K − 2G/3 of each cell (the solver's constant load −∫ σ* : ∇w, times the amplitude)."""

    strain: float
    axis: Sequence[float]
    groups: Sequence[str]
    amplitude: Callable[[float], float] = constant

    def __post_init__(self):
        if not 0 < self.strain < 0.5:
            raise ValueError(f"Contraction.strain = {self.strain!r}: must lie in (0, 0.5)")
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError(f"Contraction.axis = {list(self.axis)!r}: must not be zero")


@dataclass(frozen=True)
class MassProportionalDamping:
    """f_damp = α M v^{n−½}, α in 1/s (critical for a mode ω when α = 2ω)."""

    alpha: float

    def force(self, unbalanced: np.ndarray, velocity: np.ndarray, mass: np.ndarray) -> np.ndarray:
        return self.alpha * mass * velocity


@dataclass(frozen=True)
class LocalNonViscousDamping:
    """Cundall local damping (docs/design.md §2.13 and §4.7, per component): ``f_damp = α |F| sign(v^{n−½})``.

    F is the unbalanced nodal force f_ext − f_int; 0 ≤ α < 1 (0.7 is usual).
    """

    alpha: float

    def force(self, unbalanced: np.ndarray, velocity: np.ndarray, mass: np.ndarray) -> np.ndarray:
        return self.alpha * np.abs(unbalanced) * np.sign(velocity)


@dataclass(frozen=True)
class Material:
    """Isotropic linear elasticity: Young's modulus E (Pa), Poisson ratio ν, density ρ (kg/m³).
    ``inertia_scale`` S ≥ 1 scales the material's inertia (its lumped mass) but not its weight
    (gravity, the geostatic stress): mass scaling for a quasi-static problem, which raises its
    critical time step by √S (a stiff structure in soft ground, e.g. a tunnel lining)."""

    E: float
    nu: float
    rho: float
    inertia_scale: float = 1.0
    shear_modulus: float = field(init=False)
    bulk_modulus: float = field(init=False)

    def __post_init__(self):
        if not self.E > 0:
            raise ValueError(f"Material.E = {self.E!r}: must be > 0 (Pa)")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"Material.nu = {self.nu!r}: must lie in (-1, 0.5)")
        if not self.rho > 0:
            raise ValueError(f"Material.rho = {self.rho!r}: must be > 0 (kg/m^3)")
        if not self.inertia_scale >= 1.0:
            raise ValueError(f"Material.inertia_scale = {self.inertia_scale!r}: must be >= 1")
        object.__setattr__(self, "shear_modulus", self.E / (2.0 * (1.0 + self.nu)))
        object.__setattr__(self, "bulk_modulus", self.E / (3.0 * (1.0 - 2.0 * self.nu)))

    @property
    def p_wave_speed(self) -> float:
        """c_p = √((K + 4G/3)/(S ρ)), S the inertia scale."""
        return float(np.sqrt((self.bulk_modulus + 4.0 * self.shear_modulus / 3.0) / (self.inertia_scale * self.rho)))
