"""The fused multi-step kernels (de_domain.fused) against the step-by-step reference
kernels (sphere_contacts, walls.plane_wall_contacts, integrate.leapfrog): particle
states, contact histories and wall forces must be bit-identical; and the two fused
paths (in place through ``perm`` for short runs, spatially sorted copies for long
ones) must agree in everything, energy books included."""
import numba
import numpy as np
import pytest

from de_domain import Engine, Material, Particles, PlaneWall
from de_domain.integrate import BLOCK as INTEGRATE_BLOCK
from de_domain.integrate import N_ENERGY as INTEGRATE_N_ENERGY
from de_domain.integrate import leapfrog
from de_domain.neighbors import build_j_csr, build_pair_list, transfer_history
from de_domain.sphere_contacts import BLOCK as PAIR_BLOCK
from de_domain.sphere_contacts import N_ENERGY as PAIR_N_ENERGY
from de_domain.sphere_contacts import sphere_pair_forces, sum_pair_forces
from de_domain.walls import BLOCK as WALL_BLOCK
from de_domain.walls import N_ENERGY as WALL_N_ENERGY
from de_domain.walls import plane_wall_contacts

STATE = ("pos", "vel", "angvel", "force", "torque")


def loose_pile(seed=3, rolling=True):
    """384 polydisperse spheres on a jittered lattice at about their contact distance
    in a box: contacts open and close, the lid moves, gravity acts."""
    rng = np.random.default_rng(seed)
    h = 1.4e-3
    grid = np.stack(np.meshgrid(np.arange(8), np.arange(8), np.arange(6), indexing="ij"), -1).reshape(-1, 3)
    pos = (grid + 0.5) * h + 0.6e-3 + rng.uniform(-0.05e-3, 0.05e-3, grid.shape)
    radii = rng.uniform(0.6e-3, 0.8e-3, len(pos))
    mat = [Material(density=2650.0, young=5e7, friction=0.5, restitution=0.5, stiffness_ratio=4.0,
                    rolling_stiffness=0.5 if rolling else 0.0, rolling_friction=0.1 if rolling else 0.0)]
    p = Particles.from_spheres(pos, radii, materials=mat, velocities=rng.normal(0, 0.05, pos.shape))
    p.angvel[:] = rng.normal(0, 50.0, pos.shape)
    top = pos.max(axis=0) + 0.7e-3
    walls = []
    for d in range(3):
        normal = np.zeros(3)
        normal[d] = 1.0
        walls += [PlaneWall(np.zeros(3), normal), PlaneWall(normal * top[d], -normal)]
    walls[5].velocity = (0.0, 0.0, -0.3)
    return Engine(p, mat, walls=walls, gravity=(0, 0, -9.81), dt=2e-6, local_damping=0.05,
                  viscous_damping=1.0)


def reference_run(engine, steps):
    """The pre-fusion step: canonical (i, j) list rebuilt every step, per-pair forces,
    per-particle sums, dense wall history, leapfrog."""
    p = engine.particles
    n, nw = p.n, len(engine.walls)
    pair_i = np.empty(0, np.int32)
    pair_j = np.empty(0, np.int32)
    history = np.zeros((0, 6))
    wall_history = np.zeros((n, nw, 6))
    wall_fn = np.zeros((n, nw))
    accel = np.zeros((n, 3))
    wall_force = None
    for _ in range(steps):
        new_i, new_j, i_start, _ = build_pair_list(p.pos, p.radius, n, engine.neighbors.skin, 8 * n)
        history = transfer_history(pair_i.astype(np.int64) * n + pair_j, history, new_i.astype(np.int64) * n + new_j)
        pair_i, pair_j = new_i, new_j
        j_start, j_pairs = build_j_csr(pair_j, n)
        m = pair_i.size
        pf, ti, tj, ov = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m)
        sphere_pair_forces(engine.law, engine.dt, p.pos, p.vel, accel, p.angvel, p.radius, p.mass, p.material,
                           engine.young, engine.pair_params, pair_i, pair_j, history, pf, ti, tj, ov,
                           np.zeros(((m + PAIR_BLOCK - 1) // PAIR_BLOCK, PAIR_N_ENERGY)))
        sum_pair_forces(n, i_start, j_start, j_pairs, pf, ti, tj, p.force, p.torque)
        nb = (n + WALL_BLOCK - 1) // WALL_BLOCK
        wall_force = np.zeros((nb, nw, 3))
        plane_wall_contacts(engine.law, engine.dt, p.pos, p.vel, accel, p.angvel, p.radius, p.mass, p.material, n,
                            engine.young, engine.pair_params, np.array([w.point for w in engine.walls]),
                            np.array([w.normal for w in engine.walls]), np.array([w.velocity for w in engine.walls]),
                            np.array([w.material for w in engine.walls], np.int32), wall_history, wall_fn,
                            p.force, p.torque, wall_force, np.zeros((nb, WALL_N_ENERGY)))
        leapfrog(engine.dt, engine.gravity, engine.local_damping, engine.viscous_damping, n, p.pos, p.vel, accel,
                 p.angvel, p.mass, p.inertia, p.blocked, p.prescribed, p.prescribed_velocity, p.force, p.torque,
                 np.zeros(((n + INTEGRATE_BLOCK - 1) // INTEGRATE_BLOCK, INTEGRATE_N_ENERGY)))
        for wall in engine.walls:
            wall.point = wall.point + wall.velocity * engine.dt
    keys = pair_i.astype(np.int64) * n + pair_j
    live = np.any(history != 0.0, axis=1)
    return {**{k: getattr(p, k).copy() for k in STATE}, "history_keys": keys[live], "history": history[live],
            "wall_history": wall_history, "wall_force": wall_force.sum(axis=0),
            "wall_point": np.array([w.point for w in engine.walls])}


def fused_snapshot(engine):
    p = engine.particles
    nl = engine.neighbors
    keys = nl.pair_i.astype(np.int64) * p.n + nl.pair_j
    live = np.any(nl.history != 0.0, axis=1)
    order = np.argsort(keys[live])
    return {**{k: getattr(p, k).copy() for k in STATE}, "history_keys": keys[live][order],
            "history": nl.history[live][order], "wall_history": engine.wall_history,
            "wall_force": np.array([w.force for w in engine.walls]),
            "wall_point": np.array([w.point for w in engine.walls])}


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("rolling", [True, False])
def test_fused_engine_bit_identical_to_reference_kernels(threads, rolling):
    if threads > numba.config.NUMBA_NUM_THREADS:
        pytest.skip("needs 2 Numba threads")
    numba.set_num_threads(threads)
    steps = 400
    reference = reference_run(loose_pile(rolling=rolling), steps)
    engine = loose_pile(rolling=rolling)
    engine.run(steps)
    fused = fused_snapshot(engine)
    assert fused["history"].shape[0] > 50  # many live contacts
    for k in reference:
        assert reference[k].shape == fused[k].shape, k
        assert np.array_equal(reference[k], fused[k]), k


def test_in_place_and_sorted_paths_identical():
    """step() by step (in place through perm) == run(n) (sorted copies), energies included."""
    a = loose_pile()
    b = loose_pile()
    a.run(300)
    for _ in range(300):
        b.step()
    sa, sb = fused_snapshot(a), fused_snapshot(b)
    for k in sa:
        assert np.array_equal(sa[k], sb[k]), k
    assert a.energy() == b.energy()
    assert a.time == b.time and a.step_count == b.step_count == 300


def test_memory_per_particle_counts_every_array():
    engine = loose_pile()
    engine.run(20)
    mem = engine.memory_bytes()
    assert "neighbors.ht" in mem and "run.sorted_copies" in mem and "particles.pos" in mem
    assert sum(mem.values()) / engine.particles.n < 1024


def test_checkpoint_of_fused_engine_continues_bit_identically(tmp_path):
    engine = loose_pile()
    engine.run(150)
    engine.save_checkpoint(tmp_path / "ck.npz")
    engine.run(150)
    restored = Engine.load_checkpoint(tmp_path / "ck.npz")
    restored.run(150)
    a, b = fused_snapshot(engine), fused_snapshot(restored)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    assert engine.energy() == restored.energy()
