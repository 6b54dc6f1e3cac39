"""Clumps stepped by the engine (docs/design.md §2.19): against the free rigid body, closed forms
on an incline, at rest on a floor, and bit-identical for any thread count, storage path and
checkpoint."""
import math

import numba
import numpy as np
import pytest

from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall
from de_domain.clumps import Clumps, ClumpTemplate
from de_domain.rigid import rotational_leapfrog, to_space

R = 1e-3
G = 9.81
MU = 0.5
MATERIALS = [Material(density=2650.0, young=5e7, friction=MU, restitution=0.5)]
ODD = ClumpTemplate([[0, 0, 0], [1.2 * R, 0, 0], [0, 0.9 * R, 0.3 * R]], [R, 0.8 * R, 0.7 * R])  # asymmetric
ROD = ClumpTemplate.line(2, 1.5, radius=R)  # two equal spheres, length 1.5 × width, along x


def unit(q):
    q = np.asarray(q, float)
    return q / np.linalg.norm(q)


def test_a_free_clump_moves_as_the_rigid_body_scheme_says():
    """No gravity, no contact: the centre moves at constant velocity, the orientation is NO_SQUISH's
    step after step (the same operations: equal to the last bit), the members stay rigid and
    the space-frame angular momentum is kept exactly."""
    q0 = unit([0.9, 0.1, -0.3, 0.2])
    spin = np.array([30.0, -50.0, 80.0])
    particles, clumps = Clumps.place([ODD], [0], [[0.0, 0.0, 0.01]], [q0], MATERIALS, angular_velocities=[spin],
                                     velocities=[[0.01, -0.02, 0.0]])
    engine = Engine(particles, MATERIALS, gravity=(0, 0, 0), clumps=clumps)
    big_l = tuple(clumps.angmom[0])
    q = tuple(q0)
    for _ in range(3):
        engine.run(500)
        for _ in range(500):
            q, big_l, _ = rotational_leapfrog(q, big_l, (0.0, 0.0, 0.0), tuple(clumps.moments[0]), engine.dt)
        assert tuple(clumps.quat[0]) == q
    assert engine.neighbors.pair_js.size == 0  # members of one clump are never a pair
    assert np.array_equal(clumps.angmom[0], np.array(big_l))
    assert np.allclose(clumps.pos[0], [0.01 * engine.time, -0.02 * engine.time, 0.01], rtol=0, atol=1e-15)
    p = engine.particles
    for a in range(3):
        for b in range(a + 1, 3):
            assert np.linalg.norm(p.pos[a] - p.pos[b]) == pytest.approx(np.linalg.norm(ODD.members[a] - ODD.members[b]),
                                                                         rel=1e-12)
    assert np.allclose(p.angvel, clumps.angular_velocity()[0], rtol=1e-12)


@pytest.mark.parametrize("floor", ["wall", "facets"])
def test_a_clump_dropped_on_a_floor_rests_on_it_with_its_weight(floor):
    """Dropped in any orientation on a plane wall or a triangle mesh, it bounces, turns and comes
    to rest: the floor carries its weight and the energy books close."""
    particles, clumps = Clumps.place([ODD], [0], [[0.0, 0.0, 5 * R]], [unit([0.9, 0.1, -0.3, 0.2])], MATERIALS)
    size = 20 * R
    boundary = dict(walls=[PlaneWall((0, 0, 0), (0, 0, 1))]) if floor == "wall" else dict(facets=[FacetMesh(
        [[-size, -size, 0], [size, -size, 0], [-size, size, 0], [size, size, 0]], [[0, 1, 3], [0, 3, 2]])])
    engine = Engine(particles, MATERIALS, gravity=(0, 0, -G), clumps=clumps, local_damping=0.3, **boundary)
    engine.run(60_000)
    weight = clumps.mass[0] * G
    carried = engine.walls[0].force[2] if floor == "wall" else engine.facets[0].force[2]
    assert carried == pytest.approx(-weight, rel=1e-9)
    assert np.abs(clumps.vel).max() < 1e-9 and np.abs(clumps.angular_velocity()).max() < 1e-6
    assert engine.particles.pos[:, 2].min() == pytest.approx(0.8 * R, rel=0.2)  # lying on its side
    energy = engine.energy()
    assert abs(energy["residual"]) < 0.01 * energy["dissipated"]


def slide(theta_deg):
    """The rod lying along the slope (the plane z = 0, gravity tilted by θ): its downhill
    acceleration, fitted over 2,000 steps after 500, and the largest tilt of its axis out of
    the plane over them (rad)."""
    theta = math.radians(theta_deg)
    particles, clumps = Clumps.place([ROD], [0], [[0.0, 0.0, R]], [[1, 0, 0, 0]], MATERIALS)
    squeeze = clumps.mass[0] * G * math.cos(theta) / 2 / (2 * 5e7 * R)  # each member's static overlap
    clumps.pos[0, 2] -= squeeze
    particles.pos[:, 2] -= squeeze
    engine = Engine(particles, MATERIALS, walls=[PlaneWall((0, 0, 0), (0, 0, 1))],
                    gravity=(G * math.sin(theta), 0.0, -G * math.cos(theta)), clumps=clumps)
    engine.run(500)
    times, speeds, tilt = [], [], 0.0
    for _ in range(40):
        engine.run(50)
        times.append(engine.time)
        speeds.append(clumps.vel[0, 0])
        axis = np.array(to_space(tuple(clumps.quat[0]), 1.0, 0.0, 0.0))
        tilt = max(tilt, abs(math.asin(axis[2])))
    return np.polyfit(times, speeds, 1)[0], tilt


def test_a_clump_on_an_incline_sticks_below_the_friction_angle():
    """tan θ < μ: it stays (two contacts one behind the other along the slope: it cannot roll)."""
    acceleration, tilt = slide(15.0)
    assert abs(acceleration) < 1e-3 * G * math.sin(math.radians(15.0))
    assert tilt < 1e-5


def test_a_clump_on_an_incline_slides_above_the_friction_angle_as_a_block():
    """tan θ > μ: a = g (sin θ − μ cos θ), the closed form of a sliding block; the friction below
    the centre loads the front member more than the rear one, which tilts the rod only by the
    difference of their overlaps (a fraction of a micrometre over 1.5 mm)."""
    theta = math.radians(35.0)
    acceleration, tilt = slide(35.0)
    assert acceleration == pytest.approx(G * (math.sin(theta) - MU * math.cos(theta)), rel=0.01)
    assert tilt < 1e-3


def clump_pile():
    """60 clumps (rods and odd grains, random orientations and spins) and 40 spheres thrown about in a
    box under a strong gravity (−1000 m/s²: a pile in 3,000 steps): contacts between members of different clumps,
    spheres and walls open and close."""
    rng = np.random.default_rng(7)
    nc = 60
    cells = np.stack(np.meshgrid(np.arange(5), np.arange(4), np.arange(5), indexing="ij"), -1).reshape(-1, 3)
    centres = (cells[:nc] + 0.5) * 3.2 * R + rng.uniform(-0.2 * R, 0.2 * R, (nc, 3))
    spheres_at = (cells[nc:nc + 40] + 0.5) * 3.2 * R + rng.uniform(-0.2 * R, 0.2 * R, (40, 3))
    spheres = Particles.from_spheres(spheres_at, rng.uniform(0.6 * R, 0.9 * R, 40), materials=MATERIALS)
    particles, clumps = Clumps.place([ROD, ODD], rng.integers(0, 2, nc), centres, rng.normal(size=(nc, 4)), MATERIALS,
                                     velocities=rng.normal(0, 0.5, (nc, 3)),
                                     angular_velocities=rng.normal(0, 300.0, (nc, 3)), spheres=spheres)
    spheres_vel = rng.normal(0, 0.5, (40, 3))
    particles.vel[clumps.member_index.size:] = spheres_vel
    top = 16 * 3.2 * R
    walls = [PlaneWall((0, 0, 0), (1, 0, 0)), PlaneWall((16 * R, 0, 0), (-1, 0, 0)),
             PlaneWall((0, 0, 0), (0, 1, 0)), PlaneWall((0, 13 * R, 0), (0, -1, 0)),
             PlaneWall((0, 0, 0), (0, 0, 1)), PlaneWall((0, 0, top), (0, 0, -1))]
    return particles, clumps, walls


def pile_state(threads, chunks, checkpoint_at=None, tmp_path=None):
    numba.set_num_threads(threads)
    try:
        particles, clumps, walls = clump_pile()
        engine = Engine(particles, MATERIALS, walls=walls, gravity=(0, 0, -1000.0), clumps=clumps, local_damping=0.1)
        for k, steps in enumerate(chunks):
            if k == checkpoint_at:
                engine.save_checkpoint(tmp_path / "pile.npz")
                engine = Engine.load_checkpoint(tmp_path / "pile.npz")
            engine.run(steps)
        p = engine.particles
        c = engine.clumps
        return [p.pos, p.vel, p.angvel, p.force, c.pos, c.vel, c.quat, c.angmom, c.force, c.torque,
                np.array(list(engine.energy().values()))]
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


@pytest.fixture(scope="module")
def reference():
    return pile_state(1, [3000])


def test_clump_pile_makes_contacts():
    """The pile the invariance tests run has clumps touching clumps, and no pair of two members of
    one clump is listed."""
    particles, clumps, walls = clump_pile()
    engine = Engine(particles, MATERIALS, walls=walls, gravity=(0, 0, -1000.0), clumps=clumps, local_damping=0.1)
    engine.run(3000)
    i, j = engine.neighbors.pair_i, engine.neighbors.pair_j
    member_of = clumps.member_of
    touching = engine.pair_overlap > 0
    assert np.count_nonzero(touching & (member_of[i] >= 0) & (member_of[j] >= 0)) > 10  # clump on clump
    assert not np.any((member_of[i] >= 0) & (member_of[i] == member_of[j]))


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 Numba threads")
def test_clumps_are_bit_identical_for_any_thread_count(reference):
    for a, b in zip(reference, pile_state(2, [3000]), strict=True):
        assert np.array_equal(a, b)


def test_clumps_are_bit_identical_in_place_and_on_sorted_copies(reference):
    """Runs shorter than the sorted-copy threshold step in place through the spatial order."""
    for a, b in zip(reference, pile_state(1, [7] * 428 + [4]), strict=True):
        assert np.array_equal(a, b)


def test_clump_checkpoint_resumes_bit_identically(reference, tmp_path):
    for a, b in zip(reference, pile_state(1, [1400, 1600], checkpoint_at=1, tmp_path=tmp_path), strict=True):
        assert np.array_equal(a, b)


def test_frames_show_which_clump_each_member_belongs_to(tmp_path):
    import meshio

    from de_domain.io import write_frame

    particles, clumps = Clumps.place([ROD, ODD], [0, 1], [[0, 0, 2 * R], [4 * R, 0, 2 * R]],
                                     [[1, 0, 0, 0], [1, 0, 0, 0]], MATERIALS)
    engine = Engine(particles, MATERIALS, clumps=clumps)
    frame = meshio.read(write_frame(tmp_path, engine, 0)[0])
    assert frame.point_data["clump"].tolist() == [0, 0, 1, 1, 1]
    assert np.allclose(frame.points, engine.particles.pos)
