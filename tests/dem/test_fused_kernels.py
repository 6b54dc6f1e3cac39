"""The fused multi-step kernels (de_domain.fused): particle states, contact
histories, wall and facet forces are bit-identical for 1 and 2 threads and for any
Verlet skin (rebuild frequency), and the two storage paths (in place through
``perm`` for short runs, spatially sorted copies for long ones) agree in everything,
energy books included."""
import numba
import numpy as np
import pytest

from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall

STATE = ("pos", "vel", "angvel", "force", "torque")


def loose_pile(seed=3, rolling=True, comm=None):
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
                  viscous_damping=1.0, comm=comm)


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


def split_box_pile(seed=1, comm=None):
    """448 spheres in the split shear box (two facet meshes, the upper one moving)
    between a fixed bottom plane and a descending lid: facet face, edge and vertex
    contacts, rolling resistance, background damping."""
    from cosim.lab.shear_box import ShearBoxGeometry
    rng = np.random.default_rng(seed)
    L = 0.01
    geometry = ShearBoxGeometry(L, 0.008, 0.002)
    grid = np.stack(np.meshgrid(np.arange(8), np.arange(8), np.arange(7), indexing="ij"), -1).reshape(-1, 3)
    pos = (grid + 0.5) * 1.2e-3 + 0.3e-3 + rng.uniform(-0.05e-3, 0.05e-3, grid.shape)
    radii = rng.uniform(0.45e-3, 0.55e-3, len(pos))
    mats = [Material(density=2650.0, young=5e7, friction=0.5, restitution=0.5, rolling_stiffness=0.3,
                     rolling_friction=0.1), Material(density=7000.0, young=5e7, friction=0.3)]
    p = Particles.from_spheres(pos, radii, np.zeros(len(radii), np.int32), mats,
                               velocities=rng.normal(0, 0.5, pos.shape))
    lower = FacetMesh(*geometry.lower_half(), material=1)
    upper = FacetMesh(*geometry.upper_half(), material=1)
    upper.velocity = (0.05, 0.0, 0.0)
    walls = [PlaneWall((0, 0, 0), (0, 0, 1), 1), PlaneWall((0, 0, 0.0095), (0, 0, -1), 1, velocity=(0, 0, -0.05))]
    return Engine(p, mats, walls=walls, facets=[lower, upper], gravity=(0, 0, -9.81), dt=5e-7, local_damping=0.1,
                  comm=comm)


def facet_snapshot(engine):
    out = fused_snapshot(engine)
    for k, mesh in enumerate(engine.facets):
        out.update({f"facet{k}_vertices": mesh.vertices.copy(), f"facet{k}_force": mesh.vertex_force.copy(),
                    f"facet{k}_impulse": mesh.vertex_impulse.copy()})
    out["facet_history"] = engine.neighbors.facet_history.copy()
    return out


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 Numba threads")
@pytest.mark.parametrize("make", [loose_pile, split_box_pile])
def test_bit_identical_for_1_and_2_threads(make):
    snaps = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        engine = make()
        engine.run(3000)
        snaps.append(facet_snapshot(engine))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    for k in snaps[0]:
        assert np.array_equal(snaps[0][k], snaps[1][k]), k


@pytest.mark.parametrize("make", [loose_pile, split_box_pile])
def test_bit_identical_for_any_skin(make):
    """A thinner skin rebuilds the lists more often (and orders the particles on another
    grid); every state and force is the same to the bit, the energy books to round-off."""
    a = make()
    b = make()
    b.neighbors.skin = 0.25 * a.neighbors.skin
    a.run(3000)
    b.run(3000)
    assert b.neighbors.n_builds > 2 * a.neighbors.n_builds
    sa, sb = facet_snapshot(a), facet_snapshot(b)
    for k in sa:
        if k.startswith("history") or k == "facet_history" or k == "wall_history":
            continue  # the lists hold different candidates; live histories compared below
        assert np.array_equal(sa[k], sb[k]), k
    assert np.array_equal(sa["history"], sb["history"]) and np.array_equal(sa["history_keys"], sb["history_keys"])
    ea, eb = a.energy(), b.energy()
    for k in ea:
        assert ea[k] == pytest.approx(eb[k], rel=1e-12, abs=1e-18), k


def test_facet_engine_step_by_step_equals_run():
    a = split_box_pile()
    b = split_box_pile()
    a.run(600)
    for _ in range(600):
        b.step()
    sa, sb = facet_snapshot(a), facet_snapshot(b)
    assert np.abs(sa["facet1_impulse"]).max() > 0.0  # the moving half was touched
    for k in sa:
        assert np.array_equal(sa[k], sb[k]), k
    assert a.energy() == b.energy()


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


@pytest.mark.parametrize("make", [loose_pile, split_box_pile])
def test_sorted_copies_kept_between_runs_change_no_bit(make, monkeypatch):
    """``keep_sorted``: windows of 1–7 steps on sorted copies left holding the state
    between them (as the FE–DE coupling runs), through list rebuilds and spatial-order
    refreshes, with the facets moved from outside between windows, reads of the
    particles between some windows and a write into them, == an engine that writes back
    after every run — to the bit, energies included."""
    from de_domain import fused
    monkeypatch.setattr(fused, "PERM_EVERY", 90)  # refresh the spatial order during the test
    plain, kept = make(), make()
    kept.keep_sorted = True
    done = windows = held = 0
    while done < 600:
        n = 1 + windows % 7
        for engine in (plain, kept):
            for mesh in engine.facets:  # the FE's motion of the interface between two windows
                mesh.vertices[:, 2] += 1e-7
            engine.run(n)
        held += kept.copies_hold_state
        done += n
        windows += 1
        if windows % 5 == 0:
            assert np.array_equal(plain.particles.pos, kept.particles.pos)  # read: written back first
        if windows == 40:
            for engine in (plain, kept):
                engine.particles.vel[7] += 0.01  # written into the public arrays: gathered again
    assert held == windows  # every window left the state in the copies
    assert kept.neighbors.n_builds > 2 and kept.step_count > 2 * fused.PERM_EVERY
    sa, sb = facet_snapshot(plain), facet_snapshot(kept)
    for k in sa:
        assert np.array_equal(sa[k], sb[k]), k
    assert np.array_equal(plain.acceleration, kept.acceleration)
    assert plain.energy() == kept.energy()


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


@pytest.mark.parametrize("steps", [1, 200])  # in place through perm, and the sorted copies
def test_diverged_particle_stops_the_run_with_the_cause(steps):
    """A NaN velocity (as from a time step far above the critical one) must not run on
    silently nor size the cell grid from NaN: the next rebuild stops with the cause."""
    engine = loose_pile()
    engine.run(5)
    engine.particles.vel[17, 0] = np.nan
    with pytest.raises(FloatingPointError, match="particle 17"):
        engine.run(steps)
        engine.run(1)  # the rebuild comes at the start of the next call when the run ends on it


def test_the_last_steps_particle_shift_is_the_measured_one():
    """Before a run on sorted copies that hold the state, the rebuild test reads the
    particles' largest displacement from the last step (``Engine.particle_shift``):
    it is what a pass over the particles measures, to the bit, through list rebuilds."""
    from de_domain.neighbors import max_displacement
    engine = loose_pile()
    engine.keep_sorted = True
    shifts = []
    for _ in range(60):
        engine.run(5)
        copies = engine._sorted
        shifts.append(engine.particle_shift)
        assert shifts[-1] == max_displacement(copies.pos, copies.ref_pos, copies.pos.shape[0])
    assert engine.neighbors.n_builds > 2 and min(shifts) >= 0.0 and max(shifts) > 0.0


def test_a_wall_given_to_two_engines_starts_each_run_where_the_last_left_it():
    """A plane wall keeps its state in a row of its engine's arrays (``PlaneWall.bind``);
    given to two engines, each run starts where the other engine's last run left it, and a
    point set from outside is where the next run starts."""
    a, b = loose_pile(), loose_pile()
    lid = a.walls[5]
    b.walls[5] = lid
    start = lid.point.copy()
    step = 0.3 * a.dt  # the lid descends at 0.3 m/s
    a.run(5)
    b.run(5)
    a.run(1)
    assert lid.point[2] == pytest.approx(start[2] - 11 * step, rel=0.0, abs=1e-15)
    assert np.array_equal(a.boundaries().walls[0][5], lid.point)
    lid.point = start
    b.run(2)
    assert lid.point[2] == pytest.approx(start[2] - 2 * step, rel=0.0, abs=1e-15)
    assert np.array_equal(b._walls_state[0][5], lid.point)
