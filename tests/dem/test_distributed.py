"""The DEM over MPI ranks (de_domain.distributed) against the serial engine computed
side by side on every rank: positions, velocities, forces, torques, contact
histories, wall forces and facet vertex forces and impulses are bit-identical for
the rank count this file runs under (`make test`: mpirun -n 2 and -n 3), with 1 or
2 Numba threads per rank; particles and contact histories migrate; checkpoints
resume with another rank count."""
import numba
import numpy as np
import pytest
from dem_scenes import box_gas
from mpi4py import MPI
from test_fused_kernels import loose_pile, split_box_pile

from de_domain import Engine, Material, Particles, PlaneWall
from de_domain.neighbors import record_keys

pytestmark = pytest.mark.mpi
COMM = MPI.COMM_WORLD
STATE = ("pos", "vel", "angvel", "force", "torque")


def snapshot(engine):
    """Everything that must not depend on the rank count, in global-id order (collective)."""
    p = engine.global_particles()
    if engine.domain is None:
        records = engine.neighbors.records()
    else:
        from de_domain.distributed import gather_records
        records = gather_records(engine)
    out = {k: getattr(p, k).copy() for k in STATE}
    for kind in ("pair", "wall", "facet"):
        keys = getattr(records, f"{kind}_keys")
        order = np.argsort(keys, kind="stable")
        out[f"{kind}_keys"] = keys[order]
        out[f"{kind}_history"] = getattr(records, f"{kind}_history")[order]
    out["wall_force"] = np.array([w.force for w in engine.walls])
    out["wall_point"] = np.array([w.point for w in engine.walls])
    for k, mesh in enumerate(engine.facets):
        out[f"facet{k}_vertices"] = mesh.vertices.copy()
        out[f"facet{k}_force"] = mesh.vertex_force.copy()
        out[f"facet{k}_impulse"] = mesh.vertex_impulse.copy()
    return out


def assert_identical(reference, result):
    assert reference.keys() == result.keys()
    different = [k for k in reference if not np.array_equal(reference[k], result[k])]
    assert not different, f"differ on {COMM.size} ranks: {different}"


def run_side_by_side(build, chunks):
    serial = build(None)
    spread = build(COMM)
    for n in chunks:
        serial.run(n)
        spread.run(n)
    return serial, spread


@pytest.mark.parametrize("threads", [1, 2])
def test_frictional_gas_with_walls(threads):
    numba.set_num_threads(threads)

    def build(comm):
        engine = box_gas(n_side=7, friction=0.5, restitution=0.6, speed=0.5, gravity=(0, 0, -9.81), comm=comm)
        engine.walls[1].velocity = (-0.2, 0.0, 0.0)  # the x = L wall moves in
        return engine

    serial, spread = run_side_by_side(build, (1, 37, 200))
    reference = snapshot(serial)
    assert_identical(reference, snapshot(spread))
    assert reference["pair_keys"].size > 0 and np.any(reference["wall_force"] != 0.0)
    if COMM.size > 1:
        assert spread.domain.migrated > 0 or COMM.allreduce(spread.domain.migrated) > 0
    energy, spread_energy = serial.energy(), spread.energy()
    for k in ("total", "kinetic", "elastic_normal", "friction", "work_walls"):
        assert spread_energy[k] == pytest.approx(energy[k], rel=1e-9, abs=1e-18), k


def test_pile_with_rolling_resistance_and_a_moving_lid():
    serial, spread = run_side_by_side(lambda comm: loose_pile(comm=comm), (5, 300))
    reference = snapshot(serial)
    assert_identical(reference, snapshot(spread))
    assert np.any(reference["pair_history"][:, 3:] != 0.0)  # rolling moments carried


def test_grains_on_moving_facet_meshes():
    serial, spread = run_side_by_side(lambda comm: split_box_pile(comm=comm), (3, 1000))
    reference = snapshot(serial)
    assert_identical(reference, snapshot(spread))
    assert np.any(reference["facet0_impulse"] != 0.0) and np.any(reference["facet1_impulse"] != 0.0)


def test_sorted_copies_kept_between_windows():
    """A distributed ``keep_sorted`` engine (the coupling's: the state stays in the sorted
    copies between windows of a few steps, the facets moved from outside between them,
    a read of the particles now and then) == the serial engine of plain runs."""
    serial, spread = split_box_pile(), split_box_pile(comm=COMM)
    spread.keep_sorted = True
    for window in range(160):
        for engine in (serial, spread):
            for mesh in engine.facets:
                mesh.vertices[:, 2] += 1e-7
            engine.run(1 + window % 4)
        if window % 40 == 39:
            assert spread.copies_hold_state
            assert_identical(snapshot(serial), snapshot(spread))
    assert COMM.allreduce(spread.neighbors.n_builds) > COMM.size


def test_wall_forces_gathered_on_demand_are_the_ones_of_every_run():
    """``wall_forces_each_run = False`` (the coupling's: nothing reads the wall forces between
    its one-step windows) skips the gather after runs; ``update_wall_forces``, a checkpoint
    and a wall moved from outside (its jump is booked with the last step's force) still see
    the serial engine's forces, and the energy books stay the same."""
    serial, eager, spread = (box_gas(friction=0.3, restitution=0.8, gravity=(0.0, 0.0, -9.81), comm=comm)
                             for comm in (None, COMM, COMM))
    spread.wall_forces_each_run = False
    for window in range(120):
        for engine in (serial, eager, spread):
            if window % 30 == 29:
                engine.walls[5].point = engine.walls[5].point + (0.0, 0.0, -1e-5)  # the lid jumps: booked
            engine.run(1 + window % 3)
        if window % 40 == 39:
            assert any(np.any(w.force != 0.0) for w in serial.walls)
            spread.update_wall_forces()
            assert_identical(snapshot(serial), snapshot(spread))
            assert eager.energy() == spread.energy()  # (summed over the ranks: the same rank count)


def test_a_particle_migrates_through_every_subdomain():
    """A small fast grain runs along a lane between the rows of a lattice of grains
    at rest, the length of the domain: its owner changes rank by rank, and its
    trajectory is the serial one."""
    def build(comm):
        spacing = 3e-3
        grid = np.stack(np.meshgrid(np.arange(12), np.arange(3), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
        pos = np.vstack([(grid + 0.5) * spacing, [[0.2e-3, spacing, spacing]]])
        radii = np.append(np.full(len(grid), 1e-3), 0.4e-3)
        material = [Material(density=2650.0, young=5e7, friction=0.3)]
        particles = Particles.from_spheres(pos, radii, materials=material)
        particles.vel[-1] = (8.0, 0.0, 0.0)
        return Engine(particles, material, gravity=(0, 0, 0), comm=comm)

    serial, spread = build(None), build(COMM)
    runner = serial.particles.n - 1
    owners = []
    while serial.particles.pos[runner, 0] < 35e-3:
        serial.run(200)
        spread.run(200)
        here = spread.domain.ids[spread.particles.owned]
        owners.append(COMM.allreduce(COMM.rank if runner in here else -1, op=MPI.MAX))
    assert_identical(snapshot(serial), snapshot(spread))
    visited = [r for k, r in enumerate(owners) if k == 0 or r != owners[k - 1]]
    assert visited == list(range(COMM.size)), owners


def test_a_contact_that_changes_owner_keeps_its_history():
    """Two stacked grains slide along a lane on a floor across the whole domain: the
    floor brakes the lower one, so the pair's tangential spring and both wall springs
    are loaded while their owner changes rank; every spring is the serial one."""
    def build(comm):
        spacing = 3e-3
        grid = np.stack(np.meshgrid(np.arange(12), np.arange(3), indexing="ij"), -1).reshape(-1, 2)
        lattice = np.column_stack([(grid + 0.5) * spacing, np.full(len(grid), 1e-3)])
        pos = np.vstack([lattice, [[0.5e-3, spacing, 0.4e-3], [0.5e-3, spacing, 1.2e-3]]])
        radii = np.append(np.full(len(grid), 1e-3), [0.4e-3, 0.4e-3])
        material = [Material(density=2650.0, young=5e7, friction=0.3, restitution=0.3)]
        particles = Particles.from_spheres(pos, radii, materials=material)
        particles.vel[-2:] = (8.0, 0.0, 0.0)
        floor = PlaneWall((0, 0, 0), (0, 0, 1))
        return Engine(particles, material, walls=[floor], gravity=(0, 0, -9.81), comm=comm)

    serial, spread = build(None), build(COMM)
    lower = serial.particles.n - 2
    stack = int(record_keys(lower, lower + 1))
    owners = []
    while serial.particles.pos[lower, 0] < 34e-3:
        serial.run(200)
        spread.run(200)
        keys, ranks = owner_of_pairs(spread)
        owners.append(ranks[keys.index(stack)] if stack in keys else -1)
    reference = snapshot(serial)
    assert_identical(reference, snapshot(spread))
    live = reference["pair_keys"][np.any(reference["pair_history"] != 0.0, axis=1)]
    assert stack in live.tolist(), "the stack came apart: the test shows nothing"
    assert -1 not in owners and sorted(set(owners)) == list(range(COMM.size)), owners


def owner_of_pairs(engine):
    """(keys, rank booking them) of the pairs with a loaded spring, gathered."""
    records = engine.neighbors.records(owned=engine.particles.owned)
    keys = np.concatenate(COMM.allgather(records.pair_keys))
    ranks = np.concatenate(COMM.allgather(np.full(records.pair_keys.size, COMM.rank)))
    return keys.tolist(), ranks.tolist()


@pytest.mark.parametrize("grains", ["spheres", "clumps"])
def test_checkpoint_resumes_with_another_rank_count(tmp_path_factory, grains):
    """Written by size − 1 ranks (a sub-communicator; 1 rank: the serial engine),
    resumed by all: continues bit-identically to an uninterrupted serial run (the loose pile
    of spheres, and the clump pile: its clumps too)."""
    build, state, before, after = {"spheres": (loose_pile, snapshot, 120, 150),
                                   "clumps": (clump_pile_engine, clump_snapshot, 800, 700)}[grains]
    path = COMM.bcast(str(tmp_path_factory.mktemp("ckpt") / "pile.npz") if COMM.rank == 0 else None)
    writers = COMM.Split(0 if COMM.rank < COMM.size - 1 else MPI.UNDEFINED, COMM.rank)
    serial = build()
    serial.run(before)
    if writers != MPI.COMM_NULL:
        first = build(comm=writers if writers.size > 1 else None)
        first.run(before)
        if writers.size > 1 or writers.rank == 0:
            first.save_checkpoint(path)
        writers.Free()
    COMM.Barrier()
    resumed = Engine.load_checkpoint(path, comm=COMM)
    serial.run(after)
    resumed.run(after)
    assert_identical(state(serial), state(resumed))
    assert resumed.energy()["total"] == pytest.approx(serial.energy()["total"], rel=1e-9)


def test_a_rank_without_particles_runs_correctly():
    """Fewer grains than ranks (the engine allows it; a case file does not): the ranks
    without grains take part in every collective, and the grains move as in serial."""
    def build(comm):
        count = max(COMM.size - 1, 1)
        pos = np.column_stack([np.arange(count) * 2.05e-3 + 1e-3, np.full(count, 1e-3), np.full(count, 1.5e-3)])
        material = [Material(density=2650.0, young=5e7, friction=0.3)]
        velocities = np.zeros((count, 3))
        velocities[:, 0] = np.where(np.arange(count) % 2 == 0, 0.5, -0.5)
        particles = Particles.from_spheres(pos, np.full(count, 1e-3), materials=material, velocities=velocities)
        return Engine(particles, material, walls=[PlaneWall((0, 0, 0), (0, 0, 1))], comm=comm)

    serial, spread = run_side_by_side(build, (1, 400))
    if COMM.size > 1:
        assert COMM.allreduce(int(spread.particles.n_owned == 0)) >= 1
    assert_identical(snapshot(serial), snapshot(spread))


def test_radius_expansion_of_grains_that_do_not_jam_is_the_same_on_every_rank_count():
    """The generation's collective steps (the unjammed zero-gravity stage ends, the lid jumps
    onto the highest grain over all ranks, then is seated) give the serial specimen bit for bit."""
    from de_domain.deposition import (
        GenerationSettings,
        diameters_for_solid_volume,
        generate,
        solid_volume_for,
        specimen_curve,
    )
    L, H, e = 0.010, 0.016, 3.0
    curve = specimen_curve(diameters=[1.6e-3, 2.4e-3], passing=[0.0, 1.0])
    d = diameters_for_solid_volume(curve, solid_volume_for(e, L * L * H), np.random.default_rng(2))
    s = GenerationSettings(box_length=L, height=H, void_ratio=e, sand=Material(density=2650, young=5e7, friction=0.3),
                           wall=Material(density=7480, young=5e7, friction=0.0),
                           plate=Material(density=7480, young=5e7, friction=0.8), friction=0.3, seed=3,
                           max_steps_per_layer=5000, density_scale=1.0)
    serial = generate("radius_expansion", d, s)
    spread = generate("radius_expansion", d, s, comm=COMM)
    assert spread.height == serial.height < H
    np.testing.assert_array_equal(spread.positions, serial.positions)
    np.testing.assert_array_equal(spread.radii, serial.radii)


def clump_pile_engine(comm=None):
    """The clump invariance pile (tests/dem/test_clump_engine.py): 60 rods and odd grains and 40
    spheres thrown about in a box, piling under −1000 m/s²."""
    from test_clump_engine import MATERIALS, clump_pile

    particles, clumps, walls = clump_pile()
    return Engine(particles, MATERIALS, walls=walls, gravity=(0, 0, -1000.0), clumps=clumps, local_damping=0.1,
                  comm=comm)


def clump_snapshot(engine):
    """:func:`snapshot` and the clumps' state (every clump's, current on every rank after a run)."""
    out = snapshot(engine)
    for k in ("pos", "vel", "quat", "angmom", "force", "torque"):
        out[f"clump_{k}"] = getattr(engine.clumps, k).copy()
    return out


def straddling_clumps(engine):
    """The clumps whose members are owned by more than one rank (collective)."""
    member_of, _ = engine.clump_rows()
    owned = engine.particles.owned & (member_of >= 0)
    ranks = np.zeros((engine.clumps.count, COMM.size), np.int64)
    ranks[member_of[owned], COMM.rank] = 1
    COMM.Allreduce(MPI.IN_PLACE, ranks, op=MPI.SUM)
    return np.flatnonzero((ranks > 0).sum(axis=1) > 1)


@pytest.mark.parametrize("threads", [1, 2])
def test_clumps_straddling_subdomains_move_as_in_serial(threads):
    """Clumps whose members sit on different ranks (advanced on each rank that owns a member, from
    the members' loads of all of them; every clump's state on every rank after each run) give the
    serial pile bit for bit: members,
    clumps, contact histories, wall forces; the energy books agree."""
    numba.set_num_threads(threads)
    serial, spread = run_side_by_side(clump_pile_engine, (1, 40, 1500))
    straddling = straddling_clumps(spread)
    reference = clump_snapshot(serial)
    assert_identical(reference, clump_snapshot(spread))
    if COMM.size > 1:
        assert straddling.size > 0
        assert COMM.allreduce(spread.domain.migrated) > 0
    energy, spread_energy = serial.energy(), spread.energy()
    for k in ("total", "kinetic_translational", "kinetic_rotational", "elastic_normal", "friction",
              "background_damping", "residual"):
        assert spread_energy[k] == pytest.approx(energy[k], rel=1e-9, abs=1e-15), k


def test_clump_diagnostics_count_each_grain_once_on_any_rank_count():
    """Kinetic energy, unbalanced force, coordination, solid volume, Love–Weber stress and the
    grains' radii of the clumped pile over the ranks == the serial engine's (a clump held by every
    rank counts once; a member's contacts count for its clump wherever the member is owned)."""
    from de_domain import diagnostics as dg

    serial, spread = run_side_by_side(clump_pile_engine, (1500,))
    box = dg.BoxRegion((2e-3, 2e-3, 0.0), (14e-3, 11e-3, 8e-3))
    for name, value in (("kinetic_energy", lambda e: dg.kinetic_energy(e)),
                        ("unbalanced", lambda e: dg.unbalanced_force_ratio(e)),
                        ("solid_volume", lambda e: dg.solid_volume(e, box)),
                        ("stress", lambda e: dg.love_weber_stress(e, box)),
                        ("grain_radii", lambda e: dg.grain_radii(e))):
        assert value(spread) == pytest.approx(value(serial), rel=1e-12, abs=1e-18), name
    assert dg.coordination_number(spread) == dg.coordination_number(serial)
    assert dg.coordination_number(spread, box, include_walls=True) == \
        dg.coordination_number(serial, box, include_walls=True)


@pytest.mark.parametrize("grains", ["spheres", "clumps"])
def test_a_frame_in_pieces_reads_back_as_the_serial_frame(tmp_path_factory, grains):
    """Each rank writes its owned particles as one piece, the root the ``.pvtu`` naming them:
    read back in global-id order, the points and every field equal the serial frame's, each grain
    once (and each member's clump)."""
    from de_domain.io import read_frame, write_frame

    build = {"spheres": loose_pile, "clumps": clump_pile_engine}[grains]
    folder = COMM.bcast(str(tmp_path_factory.mktemp("frames")) if COMM.rank == 0 else None)
    serial, spread = run_side_by_side(lambda comm: build(comm=comm), (300,))
    paths = write_frame(f"{folder}/spread", spread, 300)
    assert paths[0].name == ("particles_00000300.pvtu" if COMM.size > 1 else "particles_00000300.vtu")
    if COMM.rank == 0:
        points, fields = read_frame(write_frame(f"{folder}/serial", serial, 300)[0])
        spread_points, spread_fields = read_frame(paths[0])
        np.testing.assert_array_equal(points, spread_points)
        assert fields.keys() == spread_fields.keys() and ("clump" in fields) == (grains == "clumps")
        for name in fields:
            np.testing.assert_array_equal(fields[name], spread_fields[name])
        np.testing.assert_array_equal(fields["id"], np.arange(serial.particles.n))
        if COMM.size > 1:
            assert len(list(paths[0].parent.glob("particles_00000300_*.vtu"))) == COMM.size
