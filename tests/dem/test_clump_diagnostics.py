"""The diagnostics count a clump as one grain (de_domain.diagnostics, docs/design.md §2.19):
kinetic energy and unbalanced force of the rigid bodies, solid volume of the members' union,
coordination per grain, Love–Weber branch vectors from the clumps' centres."""
import numpy as np
import pytest

from de_domain import Engine, Material, Particles, PlaneWall
from de_domain.clumps import Clumps, ClumpTemplate
from de_domain.diagnostics import (
    BoxRegion,
    SphereRegion,
    coordination_number,
    kinetic_energy,
    love_weber_stress,
    solid_volume,
    unbalanced_force_ratio,
    void_ratio,
)

R = 1e-3
MATERIALS = [Material(density=2650.0, young=5e7, friction=0.5, restitution=0.5)]
ROD = ClumpTemplate.line(2, 1.5, radius=R)            # two equal spheres along x, overlapping
ODD = ClumpTemplate([[0, 0, 0], [1.2 * R, 0, 0], [0, 0.9 * R, 0.3 * R]], [R, 0.8 * R, 0.7 * R])
UPRIGHT = np.array([np.cos(np.pi / 4), 0.0, -np.sin(np.pi / 4), 0.0])  # the rod's x axis turned onto z


def test_kinetic_energy_is_the_rigid_bodies():
    """½ M v² + ½ Σ I_k ω_k² (principal frame) of a moving, spinning clump, not its members' sum."""
    q = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
    v, w = np.array([0.1, -0.2, 0.05]), np.array([30.0, -50.0, 80.0])
    particles, clumps = Clumps.place([ODD], [0], [[0, 0, 0]], [q], MATERIALS, velocities=[v], angular_velocities=[w])
    engine = Engine(particles, MATERIALS, gravity=(0, 0, 0), clumps=clumps)
    from de_domain.rigid import to_body
    w_body = np.array(to_body(tuple(q), *w))
    expected = 0.5 * clumps.mass[0] * v @ v + 0.5 * np.sum(clumps.moments[0] * w_body**2)
    assert kinetic_energy(engine) == pytest.approx(expected, rel=1e-12)


def test_solid_volume_counts_a_clumps_union_once():
    """Clumps wholly inside a box or a sphere region: the union volumes (the members overlap),
    and the void ratio of the box from them; a free sphere beside them counts as before."""
    sphere = Particles.from_spheres([[8 * R, 0, 0]], [R], materials=MATERIALS)
    particles, clumps = Clumps.place([ROD, ODD], [0, 1], [[0, 0, 0], [0, 4 * R, 0]], [[1, 0, 0, 0], UPRIGHT],
                                     MATERIALS, spheres=sphere)
    engine = Engine(particles, MATERIALS, gravity=(0, 0, 0), clumps=clumps)
    union = ROD.volume + ODD.volume + 4 / 3 * np.pi * R**3
    members = np.sum(4 / 3 * np.pi * particles.radius**3)
    assert members > 1.1 * union  # the overlaps are not small: counting members would be wrong
    box = BoxRegion((-5 * R, -5 * R, -5 * R), (12 * R, 10 * R, 5 * R))
    assert solid_volume(engine, box) == pytest.approx(union, rel=1e-12)
    assert void_ratio(engine, box) == pytest.approx((box.volume - union) / union, rel=1e-12)
    assert solid_volume(engine, SphereRegion((2 * R, 2 * R, 0), 20 * R)) == pytest.approx(union, rel=1e-12)


def _column(gap):
    """Two upright rods stacked between a floor and a lid ``gap`` apart, pressed (no gravity) in a
    square tube that keeps them upright (frictionless sides 2 % wider than the rods), brought to
    rest: the rods' lower members touch the floor or the lower rod, their upper ones the upper rod
    or the lid."""
    length = 2 * ROD.reach()
    particles, clumps = Clumps.place([ROD, ROD], [0, 0], [[0, 0, 0.5 * length], [0, 0, 1.5 * length]],
                                     [UPRIGHT, UPRIGHT], MATERIALS)
    side = 1.02 * R
    sides = (((-side, 0, 0), (1, 0, 0)), ((side, 0, 0), (-1, 0, 0)), ((0, -side, 0), (0, 1, 0)),
             ((0, side, 0), (0, -1, 0)))
    walls = [PlaneWall((0, 0, 0), (0, 0, 1)), PlaneWall((0, 0, gap), (0, 0, -1))] + [
        PlaneWall(point, normal, material=1) for point, normal in sides]
    materials = MATERIALS + [Material(density=2650.0, young=5e7, friction=0.0, restitution=0.5)]
    engine = Engine(particles, materials, walls=walls, gravity=(0, 0, 0), local_damping=0.7, clumps=clumps)
    while engine.step_count < 40000:  # to rest: the rods' resultants below 1e-4 of the contact forces
        engine.run(1000)
        if engine.step_count >= 4000 and unbalanced_force_ratio(engine) < 1e-4:
            break
    return engine


def test_unbalanced_force_and_coordination_of_clumps_at_rest():
    """Pressed at rest, each rod's members carry the column's force (their own resultants are
    that force, not zero) while the rods' resultants vanish: the ratio is the rods'. Per grain,
    each rod touches the other rod once, and the walls (floor or lid, and a side it leans on) as
    often as the wall contacts say."""
    engine = _column(gap=4 * ROD.reach() * 0.99)
    members = np.linalg.norm(engine.particles.force, axis=1)
    contact = np.mean(np.linalg.norm(engine.contacts()["force"], axis=1))
    assert np.all(members > 0.5 * contact)
    assert unbalanced_force_ratio(engine) < 1e-4 and engine.step_count < 40000
    assert coordination_number(engine) == pytest.approx(1.0)
    walls = len(engine.contacts()["wall_particle"])
    assert walls >= 2
    assert coordination_number(engine, include_walls=True) == pytest.approx(1.0 + walls / 2)


def test_love_weber_stress_of_a_column_of_clumps():
    """σ_zz V = F H over the column, H between the floor's and the lid's contact points (branch
    vectors from the rods' centres: the sum telescopes floor → rod → rod → lid); from the members'
    centres it would miss each rod's member spacing (a third of H)."""
    gap = 4 * ROD.reach() * 0.99
    engine = _column(gap)
    region = BoxRegion((-5 * R, -5 * R, -R), (5 * R, 5 * R, gap + R))
    force = float(engine.walls[1].force[2])
    assert force > 0
    points = engine.contacts()["wall_point"][:, 2]  # the overlaps' midpoints, just outside floor and lid
    height = points.max() - points.min()
    assert height == pytest.approx(gap, rel=0.01)
    sigma = love_weber_stress(engine, region)
    assert sigma[2, 2] * region.volume == pytest.approx(force * height, rel=1e-6)
