"""Shear box geometry, servo law and measurement helpers without the engine."""
import numpy as np
import pytest

from cosim.lab.shear_box import (
    ShearBoxGeometry,
    corrected_area,
    inertial_number,
    mass_median_diameter,
    rectangle,
    servo_velocity,
    velocity_for_inertial_number,
)


def test_rectangle_is_two_triangles_covering_it():
    v, t = rectangle((0, 0, 0), (2, 0, 0), (0, 3, 0))
    area = sum(0.5 * np.linalg.norm(np.cross(v[b] - v[a], v[c] - v[a])) for a, b, c in t)
    assert area == pytest.approx(6.0)


def test_box_halves_meet_at_the_split_plane():
    g = ShearBoxGeometry(0.06, 0.025, lip_length=0.012)
    lower, _ = g.lower_half()
    upper, _ = g.upper_half()
    assert lower[:, 2].min() == 0.0 and lower[:, 2].max() == pytest.approx(0.0125)
    assert upper[:, 2].min() == pytest.approx(0.0125) and upper[:, 2].max() == pytest.approx(1.6 * 0.025)
    # walls at x = 0 and x = L in both halves, lips outside the box on the trailing sides
    assert {0.0, 0.06} <= set(np.round(lower[:, 0], 12)) and lower[:, 0].max() == pytest.approx(0.06 + 0.012 + 0.006)
    assert upper[:, 0].min() == pytest.approx(-0.012 - 0.006)


def test_corrected_area_is_the_overlap_of_the_halves():
    assert corrected_area(0.06, 0.0) == pytest.approx(0.0036)
    assert corrected_area(0.06, 0.009) == pytest.approx(0.06 * 0.051)


def test_servo_converges_on_a_spring_without_overshoot():
    """Plate on a linear spring bed: σ = k (z0 − z)/A. Gain g removes g of the error per step."""
    k, area, dt, target = 2e6, 0.0036, 1e-6, 100e3
    z0, z = 0.025, 0.025
    history = []
    for _ in range(60):
        sigma = max(0.0, k * (z0 - z) / area)
        v = servo_velocity(sigma, target, area, k, dt, gain=0.3, max_velocity=1e3)
        z += v * dt
        history.append(max(0.0, k * (z0 - z) / area))
    assert history[-1] == pytest.approx(target, rel=1e-6)
    assert max(history) <= target * (1 + 1e-9)


def test_servo_approaches_without_contacts_and_respects_the_speed_limit():
    assert servo_velocity(0.0, 1e5, 0.0036, 0.0, 1e-6, 0.3, 0.05) == -0.05
    assert servo_velocity(2e5, 1e5, 0.0036, 1.0, 1e-6, 0.3, 0.05) == 0.05


def test_inertial_number_inverse():
    v = velocity_for_inertial_number(1e-3, 0.025, 0.004, 2650.0, 100e3)
    assert inertial_number(v, 0.025, 0.004, 2650.0, 100e3) == pytest.approx(1e-3)
    assert v == pytest.approx(1e-3 * 0.025 / (0.004 * np.sqrt(2650 / 100e3)))


def test_mass_median_diameter():
    radii = np.array([1.0] * 8 + [2.0])          # equal mass in the two sizes (8 × 1³ = 2³)
    assert 2.0 <= mass_median_diameter(radii) <= 4.0
    assert mass_median_diameter(np.full(5, 0.5)) == pytest.approx(1.0)
