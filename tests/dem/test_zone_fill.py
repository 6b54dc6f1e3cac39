"""Filling a volume of any shape (de_domain/zone_fill.py): points drawn uniformly in
tetrahedra, and a wedge with a slanted floor filled by radius expansion — every grain ends
inside its walls, none pressed into one beyond an elastic overlap, and the void ratio is that
of the grains whose centre is in the volume."""
import numpy as np
import pytest

from de_domain.deposition import GenerationSettings, diameters_for_solid_volume, solid_volume_for, specimen_curve
from de_domain.materials import Material
from de_domain.zone_fill import ContainerWall, fill_zone, points_in_tets, tets_volume

SAND = Material(density=2650.0, young=2e7, poisson=0.25, friction=0.5, restitution=0.5, stiffness_ratio=1.5)
WALL = Material(density=7480.0, young=2e7, friction=0.5, restitution=0.5, stiffness_ratio=1.5)
X, Z, LY = 0.03, 0.02, 0.009


def test_points_are_uniform_in_a_tetrahedron():
    tet = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]], float)
    p = points_in_tets(tet, 200_000, np.random.default_rng(0))
    assert p.min() >= 0.0 and p.sum(axis=1).max() <= 1.0           # inside: barycentric coordinates >= 0
    assert np.allclose(p.mean(axis=0), 0.25, atol=3e-3)            # the centroid (sigma ≈ 0.43e-3)
    assert np.mean(p[:, 0] < 0.5) == pytest.approx(1 - 0.5**3, abs=3e-3)   # P(x < 1/2) = 1 − (1/2)³


def wedge():
    """A prism along y: the x–z triangle (0, Z), (X, Z), (X, 0) — a horizontal top (the lid), a
    vertical side x = X and a floor sloping down from (0, Z) to (X, 0) — as 3 tetrahedra and its
    faces: (walls, lid) (the lid's triangles oriented into the wedge: the fill orients it)."""
    p = np.array([[0, 0, Z], [X, 0, Z], [X, 0, 0]], float)
    q = p + [0, LY, 0]
    tets = np.array([[p[0], p[1], p[2], q[0]], [p[1], p[2], q[0], q[1]], [p[2], q[0], q[1], q[2]]])
    lid = np.array([[p[0], q[1], p[1]], [p[0], q[0], q[1]]])
    walls = np.array([[p[0], p[1], p[2]], [q[0], q[1], q[2]], [p[1], q[1], q[2]], [p[1], q[2], p[2]],
                      [p[0], p[2], q[2]], [p[0], q[2], q[0]]])
    return tets, walls, lid


@pytest.fixture(scope="module")
def filled():
    tets, walls, lid = wedge()
    curve = specimen_curve(None, [2e-3, 3e-3], [0.0, 1.0])
    diameters = diameters_for_solid_volume(curve, solid_volume_for(0.74, tets_volume(tets)),
                                           np.random.default_rng(3))
    settings = GenerationSettings(box_length=1.0, height=Z, void_ratio=0.74, sand=SAND, wall=WALL, plate=WALL,
                                  friction=0.1, release_stress=5.0, seed=3)
    return fill_zone(tets, [ContainerWall(walls, WALL), ContainerWall(lid, WALL, lid=True)], diameters, settings)


def test_a_wedge_is_filled_with_every_grain_inside_its_walls(filled):
    pos, r = filled.positions, filled.radii
    assert tets_volume(wedge()[0]) == pytest.approx(0.5 * X * Z * LY, rel=1e-12)
    slack = 0.05 * r                                                 # an elastic overlap, no more
    floor = (Z * pos[:, 0] + X * pos[:, 2] - X * Z) / np.hypot(X, Z)  # signed distance above the floor
    assert np.all(floor > r - slack)
    assert np.all(pos[:, 0] < X - r + slack)
    assert np.all((pos[:, 1] > r - slack) & (pos[:, 1] < LY - r + slack))
    assert np.all(pos[:, 2] < Z + 2 * r.max())                       # the lid was lifted a little, not more


def test_the_void_ratio_is_that_of_the_grains_under_the_lid(filled):
    solid = float(np.sum(4 / 3 * np.pi * filled.radii**3))
    volume = tets_volume(wedge()[0])
    assert (volume - solid) / solid == pytest.approx(0.74, abs=0.02)   # the count drawn for the target
    under = filled.positions[:, 2] <= Z
    solid_under = float(np.sum(4 / 3 * np.pi * filled.radii[under] ** 3))
    assert filled.void_ratio == pytest.approx((volume - solid_under) / solid_under, rel=1e-12)
    assert filled.void_ratio >= (volume - solid) / solid              # released: looser, never denser
