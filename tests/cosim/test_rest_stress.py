"""The grains' stress at rest by depth (``rest_stress.csv`` of the embedded kind,
cosim/apps/embedded_model.py): the bands' volumes cut exactly from the tetrahedra, and the
Love–Weber stress of columns of spheres standing on a floor against its closed form — each
contact carries the weight of the spheres above it, nothing pushes sideways (K = 0)."""
import numpy as np
import pytest

from cosim.apps.embedded_model import rest_stress, stress_bands, volume_below
from de_domain import Engine, Particles, PlaneWall
from de_domain.materials import Material
from de_domain.zone_fill import tets_volume


def box_tets(x, y, z):
    """The box [0, x] × [0, y] × [0, z] as the 6 tetrahedra about its diagonal."""
    c = np.array([[i * x, j * y, k * z] for k in (0, 1) for j in (0, 1) for i in (0, 1)], float)
    return np.array([c[[0, 1, 3, 7]], c[[0, 1, 5, 7]], c[[0, 2, 3, 7]], c[[0, 2, 6, 7]], c[[0, 4, 5, 7]],
                     c[[0, 4, 6, 7]]])


def test_the_volume_below_a_plane_is_cut_exactly():
    corner = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]], float)
    upside_down = corner * [1, 1, -1] + [0, 0, 1]
    for level in (-0.5, 0.0, 0.3, 0.5, 0.9, 1.0, 2.0):
        c = min(max(level, 0.0), 1.0)  # three corners below: 1/6 (1 − (1 − c)³); one: c³/6
        assert volume_below(corner, level) == pytest.approx((1.0 - (1.0 - c) ** 3) / 6.0, abs=1e-15)
        assert volume_below(upside_down, level) == pytest.approx(c**3 / 6.0, abs=1e-15)
    tets = box_tets(2.0, 3.0, 5.0)  # corners on the planes, and two corners below of each kind
    for level in (0.0, 1.0, 2.5, 5.0):
        assert volume_below(tets, level) == pytest.approx(6.0 * level, rel=1e-12, abs=1e-12)
    tilted = np.random.default_rng(0).random((50, 4, 3))
    bands = stress_bands(tilted, 0.1)
    assert sum(b.volume for b in bands) == pytest.approx(tets_volume(tilted), rel=1e-12)
    assert bands[0].top == np.inf and bands[-1].bottom == -np.inf


def test_columns_of_spheres_carry_their_weight_and_push_nothing_sideways():
    """3 × 2 columns of 10 spheres (r = 1 mm) standing on a floor, 3 mm apart, in a box whose
    tetrahedra give the bands: in each band σ_zz = 1/V Σ W l over its contacts, W = m g × the
    spheres above the contact and l its branch length (2 r between spheres, r to the floor),
    σ_xx = σ_yy = 0."""
    r, n, g = 1e-3, 10, 9.81
    sand = Material(density=2650.0, young=1e9, poisson=0.25, friction=0.5, restitution=0.5)
    xy = [(1.5e-3 + 3e-3 * i, 1.5e-3 + 3e-3 * j) for i in range(3) for j in range(2)]
    pos = np.array([[x, y, r + 2 * r * k] for x, y in xy for k in range(n)])
    particles = Particles.from_spheres(pos, np.full(len(pos), r), materials=[sand])
    engine = Engine(particles, [sand], walls=[PlaneWall((0, 0, 0), (0, 0, 1))], gravity=(0, 0, -g),
                    local_damping=0.7)
    engine.run(20000)
    tets = box_tets(9e-3, 6e-3, 2 * r * n + 1e-3)  # the bands' cuts, 5.25 mm apart, clear of the contacts
    bands = stress_bands(tets, 5e-3)
    rows, overall = rest_stress(engine, bands)
    weight = 4.0 / 3.0 * np.pi * r**3 * sand.density * g
    levels = [(0.0, n * weight * r)] + [(2 * r * j, (n - j) * weight * 2 * r) for j in range(1, n)]
    assert len(rows) == 4
    for row, band in zip(rows, bands, strict=True):
        expected = len(xy) * sum(wl for z, wl in levels if band.bottom <= z < band.top) / band.volume
        assert row[5] == pytest.approx(expected, rel=1e-3)          # σ_zz (overlaps shorten l by < 1e-3)
        assert abs(row[3]) < 1e-9 * expected and abs(row[4]) < 1e-9 * expected
    assert overall["K_x"] == pytest.approx(0.0, abs=1e-9)
    total = len(xy) * sum(wl for _, wl in levels) / tets_volume(tets)
    assert overall["sigma_zz_Pa"] == pytest.approx(total, rel=1e-3)
