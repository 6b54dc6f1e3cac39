"""A sphere on an incline (docs/design.md §2.6 friction + §2.1 rotation): rolling without slip,
a = 5/7 g sin θ, when tan θ < 7/2 μ; sliding, a = g (sin θ − μ cos θ), otherwise.

The plane is z = 0 and gravity is tilted by θ, which is the same mechanics.
"""
import math

import numpy as np
import pytest

from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall

R = 1e-3
G = 9.81
MU = 0.5


def downhill_acceleration(theta_deg, use_facets=False):
    theta = math.radians(theta_deg)
    mat = [Material(young=5e7, friction=MU, restitution=0.3)]
    p = Particles.from_spheres([[0, 0, R]], R, materials=mat)
    gravity = (G * math.sin(theta), 0.0, -G * math.cos(theta))
    if use_facets:
        L = 0.2
        mesh = FacetMesh([[-L, -L, 0], [L, -L, 0], [-L, L, 0], [L, L, 0]], [[0, 1, 3], [0, 3, 2]])
        engine = Engine(p, mat, facets=[mesh], gravity=gravity)
    else:
        engine = Engine(p, mat, walls=[PlaneWall((0, 0, 0), (0, 0, 1))], gravity=gravity)
    p.pos[0, 2] = R - p.mass[0] * G * math.cos(theta) / (2 * 5e7 * R)  # static overlap
    engine.run(500)
    times, speeds = [], []
    for _ in range(40):
        engine.run(50)
        times.append(engine.time)
        speeds.append(p.vel[0, 0])
    return np.polyfit(times, speeds, 1)[0]


@pytest.mark.parametrize("theta_deg", [10.0, 30.0])
def test_sphere_rolls_without_slip(theta_deg):
    assert math.tan(math.radians(theta_deg)) < 3.5 * MU
    expected = 5.0 / 7.0 * G * math.sin(math.radians(theta_deg))
    assert downhill_acceleration(theta_deg) == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("theta_deg", [65.0, 75.0])
def test_sphere_slides(theta_deg):
    theta = math.radians(theta_deg)
    assert math.tan(theta) > 3.5 * MU
    expected = G * (math.sin(theta) - MU * math.cos(theta))
    assert downhill_acceleration(theta_deg) == pytest.approx(expected, rel=0.01)


def test_sphere_rolls_on_inclined_facet_mesh():
    theta = math.radians(20.0)
    assert downhill_acceleration(20.0, use_facets=True) == pytest.approx(5.0 / 7.0 * G * math.sin(theta), rel=0.01)


def test_rolling_resistance_decelerates_at_five_sevenths_eta_g():
    """Rolling on a flat plane with a saturated rolling moment M = η_r f_n r:
    m a = F_t, I α = −F_t r − M, a = α r  ⇒  a = −5/7 η_r g."""
    eta = 0.1
    mat = [Material(young=5e7, friction=MU, restitution=0.3, rolling_stiffness=1.0, rolling_friction=eta)]
    p = Particles.from_spheres([[0, 0, R]], R, materials=mat)
    p.pos[0, 2] = R - p.mass[0] * G / (2 * 5e7 * R)
    p.vel[0] = (0.2, 0, 0)
    p.angvel[0] = (0, 0.2 / R, 0)
    engine = Engine(p, mat, walls=[PlaneWall((0, 0, 0), (0, 0, 1))])
    engine.run(500)
    times, speeds = [], []
    for _ in range(40):
        engine.run(50)
        times.append(engine.time)
        speeds.append(p.vel[0, 0])
    assert speeds[-1] > 0
    assert np.polyfit(times, speeds, 1)[0] == pytest.approx(-5.0 / 7.0 * eta * G, rel=0.01)
