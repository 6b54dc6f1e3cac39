"""The split shear box of the direct shear test (docs/design.md §3.4, thesis §4.2.2).

Geometry (m), box side L, specimen height h, split plane z_s = h/2::

        z ^      upper half (moves +x with the top plate)
          |   +--+========================+--+   <- top plate: PlaneWall, normal -z,
          |   |  |                        |  |      servo-controlled in z
      z_s +===+  +------------------------+  +===   <- lips: horizontal strips at z_s
          |   |  lower half (fixed)       |  |
        0 +---+------------------------------+--> x     bottom: PlaneWall, normal +z
              0                           L

* Each half is one :class:`~de_domain.FacetMesh` of four vertical rectangles (two
  triangles each). Infinite planes cannot represent a split box: the side walls of the
  two halves must end at z_s.
* A horizontal "lip" strip at z_s, as long as the shear distance, is attached to each
  half on its trailing side: the lower half's lip closes the floor under the part of
  the upper half that has moved past x = L, the upper half's lip covers the part of the
  lower half left open at x < δ. Without them grains leak through the opening that a
  real box also has but that real grains, 100 × smaller than the box, rarely use.
* Side walls and lips are frictionless (thesis App. D.2: side-wall friction angle 0);
  the plates are rough.

Corrected area A_c = L (L − δ) (the overlap of the two halves).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def rectangle(origin, u, v):
    """Vertices (4, 3) and triangles (2, 3) of the rectangle origin + a u + b v, a, b ∈ [0, 1]."""
    o, u, v = (np.asarray(a, float) for a in (origin, u, v))
    vertices = np.array([o, o + u, o + u + v, o + v])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    return vertices, triangles


def merge(rectangles):
    """One (vertices, triangles) from several."""
    vs, ts, off = [], [], 0
    for v, t in rectangles:
        vs.append(v)
        ts.append(t + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(ts)


def corrected_area(box_length, displacement):
    """A_c = L (L − δ) [m²]."""
    return box_length * (box_length - abs(displacement))


@dataclass(frozen=True)
class ShearBoxGeometry:
    box_length: float
    sample_height: float
    lip_length: float            # ≥ shear distance
    wall_height_factor: float = 1.6   # upper walls reach this × h
    margin_factor: float = 0.1        # side walls overlap at the corners by this × L

    @property
    def split_height(self):
        return 0.5 * self.sample_height

    def lower_half(self):
        """Four walls from z = 0 to z_s plus the lip at x ∈ [L, L + lip]."""
        L, zs = self.box_length, self.split_height
        m = self.margin_factor * L
        return merge([
            rectangle((0, -m, 0), (0, L + 2 * m, 0), (0, 0, zs)),          # x = 0
            rectangle((L, -m, 0), (0, L + 2 * m, 0), (0, 0, zs)),          # x = L
            rectangle((-m, 0, 0), (L + 2 * m, 0, 0), (0, 0, zs)),          # y = 0
            rectangle((-m, L, 0), (L + 2 * m, 0, 0), (0, 0, zs)),          # y = L
            rectangle((L, -m, zs), (self.lip_length + m, 0, 0), (0, L + 2 * m, 0)),  # lip
        ])

    def upper_half(self):
        """Four walls from z_s up to wall_height_factor × h plus the lip at x ∈ [−lip, 0]."""
        L, zs = self.box_length, self.split_height
        m = self.margin_factor * L
        top = self.wall_height_factor * self.sample_height - zs
        return merge([
            rectangle((0, -m, zs), (0, L + 2 * m, 0), (0, 0, top)),
            rectangle((L, -m, zs), (0, L + 2 * m, 0), (0, 0, top)),
            rectangle((-m, 0, zs), (L + 2 * m, 0, 0), (0, 0, top)),
            rectangle((-m, L, zs), (L + 2 * m, 0, 0), (0, 0, top)),
            rectangle((-self.lip_length - m, -m, zs), (self.lip_length + m, 0, 0), (0, L + 2 * m, 0)),
        ])


def servo_velocity(stress, target, area, stiffness, dt, gain, max_velocity):
    """Vertical velocity of a top plate (normal −z) that removes the fraction ``gain`` of
    the stress error per step (PFC/YADE-style servo)::

        v_z = −gain · A (σ_target − σ) / (k Δt),  |v_z| ≤ v_max,

    with k the summed normal stiffness of the plate's contacts. Without contacts
    (k = 0) the plate approaches at −v_max. Positive v_z moves the plate up.
    """
    if stiffness <= 0.0:
        return -max_velocity if stress < target else 0.0
    v = -gain * area * (target - stress) / (stiffness * dt)
    return float(np.clip(v, -max_velocity, max_velocity))


def fixed_gain_velocity(stress, target, gain, max_velocity):
    """Vertical velocity of a top plate (normal −z) proportional to the relative stress error,
    as the servo of the thesis's YADE script (App. D, ``servoController``)::

        v_z = −gain · (σ_target − σ) / σ_target,  |v_z| ≤ v_max  (positive: up).
    """
    return float(np.clip(-gain * (target - stress) / target, -max_velocity, max_velocity))


def plate_contact_stiffness(particles, radius, young_grain, young_plate):
    """Σ k_n of the plate's contacts with ``particles`` (linear law, docs/design.md §2.3:
    per-body springs k = 4 E r in series, the wall a mirror sphere of radius r)."""
    r = radius[particles]
    k_i = 4.0 * young_grain * r
    k_w = 4.0 * young_plate * r
    return float(np.sum(k_i * k_w / (k_i + k_w)))


def inertial_number(shear_velocity, height, d50, density, normal_stress):
    """I = γ̇ d50 √(ρ/σ_n) with the nominal shear rate γ̇ = v / h (docs/design.md §3.6)."""
    return shear_velocity / height * d50 * np.sqrt(density / normal_stress)


def velocity_for_inertial_number(inertial, height, d50, density, normal_stress):
    """The shear velocity giving inertial number ``inertial`` (inverse of :func:`inertial_number`)."""
    return inertial * height / (d50 * np.sqrt(density / normal_stress))


def mass_median_diameter(radii):
    """d50 by mass: the diameter below which half the solid volume lies."""
    d = np.sort(2.0 * np.asarray(radii))
    vol = np.cumsum(d**3)
    return float(np.interp(0.5 * vol[-1], vol, d))
