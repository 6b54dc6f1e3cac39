"""Two-body contact laws against closed forms (docs/design.md §2.3–§2.7)."""
import math

import numpy as np
import pytest

from de_domain import Engine, Material, Particles
from de_domain.materials import damping_ratio

R = 1e-3
YOUNG = 5e7  # k_n = 2 E r = 1e5 N/m for two equal spheres


def head_on(restitution, speed=0.1):
    """Two equal spheres approaching at ±speed; returns (rebound ratio, contact duration, expected π/ω_d)."""
    mat = [Material(density=2650.0, young=YOUNG, restitution=restitution, friction=0.0)]
    p = Particles.from_spheres([[0, 0, 0], [2 * R + 1e-7, 0, 0]], R, materials=mat,
                               velocities=[[speed, 0, 0], [-speed, 0, 0]])
    m_eff = p.mass[0] / 2
    k_n = 2 * YOUNG * R
    alpha = damping_ratio(restitution)
    omega_d = math.sqrt(k_n / m_eff) * math.sqrt(max(1 - alpha**2, 0.0))
    period = math.pi * math.sqrt(m_eff / k_n)
    engine = Engine(p, mat, gravity=(0, 0, 0), dt=period / 2000)
    in_contact, touched = 0, False
    while True:
        engine.step()
        if engine.pair_overlap.size and engine.pair_overlap[0] > 0:
            in_contact += 1
            touched = True
        elif touched:
            break
    engine.run(3)
    ratio = (p.vel[1, 0] - p.vel[0, 0]) / (2 * speed)
    expected = math.pi / omega_d if alpha < 1 else math.nan
    return ratio, in_contact * engine.dt, expected


@pytest.mark.parametrize("restitution", [0.1, 0.15, 0.2, 0.3, 0.5, 0.7, 0.9])
def test_rebound_ratio_equals_restitution(restitution):
    ratio, _, _ = head_on(restitution)
    assert ratio == pytest.approx(restitution, rel=0.01)


@pytest.mark.parametrize("restitution", [0.5, 0.7, 0.9, 1.0])
def test_contact_duration_equals_half_damped_period(restitution):
    """t_c = π/ω_d, ω_d = ω₀√(1 − α²). With the no-tension rule the contact ends when
    the force vanishes, earlier than π/ω_d; below e ≈ 0.5 that shift exceeds 1 %
    (3 % at e = 0.3; overdamped at e = 0.1), so those are checked by the rebound test."""
    _, duration, expected = head_on(restitution)
    assert duration == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("overlap", [1e-7, 1e-6, 1e-5])
def test_hertz_force_overlap_closed_form(overlap):
    """F_n = 4/3 E* √R* δ^{3/2} (Hertz), at rest (no damping force)."""
    mat = [Material(young=7e10, poisson=0.3, restitution=0.5)]
    r1, r2 = 1e-3, 2e-3
    p = Particles.from_spheres([[0, 0, 0], [r1 + r2 - overlap, 0, 0]], [r1, r2], materials=mat)
    engine = Engine(p, mat, contact_law="hertz", gravity=(0, 0, 0), dt=1e-12)
    engine.step()
    e_star = 1 / (2 * (1 - 0.3**2) / 7e10)
    r_star = r1 * r2 / (r1 + r2)
    expected = 4 / 3 * e_star * math.sqrt(r_star) * overlap**1.5
    assert -engine.pair_force[0, 0] == pytest.approx(expected, rel=1e-9)
    assert p.force[1, 0] == pytest.approx(expected, rel=1e-9)


def test_no_tensile_normal_force():
    """Fast separation with strong damping: the dashpot never pulls (f_n ≥ 0)."""
    mat = [Material(young=YOUNG, restitution=0.1)]
    p = Particles.from_spheres([[0, 0, 0], [2 * R - 1e-6, 0, 0]], R, materials=mat,
                               velocities=[[-1.0, 0, 0], [1.0, 0, 0]])
    engine = Engine(p, mat, gravity=(0, 0, 0), dt=1e-9)
    engine.step()
    assert engine.pair_force[0, 0] == 0.0


def hertz_head_on(restitution, speed=0.1):
    mat = [Material(young=7e10, poisson=0.3, restitution=restitution, friction=0.0)]
    p = Particles.from_spheres([[0, 0, 0], [2 * R + 1e-8, 0, 0]], R, materials=mat,
                               velocities=[[speed, 0, 0], [-speed, 0, 0]])
    engine = Engine(p, mat, contact_law="hertz", gravity=(0, 0, 0), safety_factor=0.01)
    steps, touched = 0, False
    while True:
        engine.step()
        if engine.pair_overlap[0] > 0:
            steps += 1
            touched = True
        elif touched:
            break
    engine.run(3)
    m_eff, r_star = p.mass[0] / 2, R / 2
    e_star = 7e10 / (2 * (1 - 0.3**2))
    v = 2 * speed
    max_overlap = (15 * m_eff * v**2 / (16 * e_star * math.sqrt(r_star))) ** 0.4
    return (p.vel[1, 0] - p.vel[0, 0]) / v, steps * engine.dt, 2.94320 * max_overlap / v


def test_hertz_impact_duration_closed_form():
    """Elastic Hertz impact: t_c = 2.9432 δ_max/v, δ_max = (15 m* v²/(16 E* √R*))^{2/5}."""
    ratio, duration, expected = hertz_head_on(1.0)
    assert ratio == pytest.approx(1.0, abs=1e-6)
    assert duration == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("restitution", [0.3, 0.7])
def test_hertz_rebound_ratio_equals_restitution(restitution):
    ratio, _, _ = hertz_head_on(restitution)
    assert ratio == pytest.approx(restitution, rel=0.01)


def test_no_tension_restitution_is_continuous_and_decreasing_in_damping_ratio():
    """Schwager & Pöschel's e(α) has no jump at α = 1/√2 or α = 1 (closed form at α = 1: e⁻²)."""
    from de_domain.materials import restitution_of_damping_ratio
    alphas = np.linspace(1e-3, 3.0, 3001)
    e = np.array([restitution_of_damping_ratio(a) for a in alphas])
    assert np.all(np.diff(e) < 0)
    assert np.max(np.abs(np.diff(e))) < 5e-3
    assert restitution_of_damping_ratio(1.0 - 1e-9) == pytest.approx(np.exp(-2.0), rel=1e-6)
    assert restitution_of_damping_ratio(np.sqrt(0.5)) == pytest.approx(np.exp(-np.pi / 2), rel=1e-12)


@pytest.mark.parametrize("tilt", [1e-5, 1e-3, 0.3, 1.2])  # series branch (q < 1e-6) and exact branch
def test_spring_rotation_keeps_magnitude_and_lies_in_the_new_tangent_plane(tilt):
    from de_domain.contact_laws import rotate_into_plane
    rng = np.random.default_rng(7)
    n = np.array([0.0, 0.0, 1.0])
    for _ in range(20):
        t = rng.normal(size=2)
        ft = np.array([t[0], t[1], 0.0]) * 3.7 + n * np.tan(tilt) * np.hypot(*t) * 3.7  # tilted off the plane
        x, y, z, old2 = rotate_into_plane(*ft, *n)
        assert old2 == pytest.approx(ft @ ft, rel=1e-15)
        assert np.hypot(np.hypot(x, y), z) == pytest.approx(np.linalg.norm(ft), rel=2e-15)
        assert abs(z) <= 1e-15 * np.linalg.norm(ft)
