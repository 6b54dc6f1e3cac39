"""Clumps against spheres, on one process and over MPI ranks: member-sphere-steps/s on settled beds.

    .venv/bin/python benchmarks/clump_scaling.py                    # 1 rank (threads: NUMBA_NUM_THREADS)
    mpirun --bind-to none -n 2 .venv/bin/python benchmarks/clump_scaling.py

Two beds of the same number of spheres in the same box, made by one process on first use and
cached in ``benchmarks/out/clumps/`` (``--force`` makes them again):

* **clumps**: ``N_CLUMPS`` rods of two equal overlapping spheres (aspect ratio 1.5), equal-volume
  radii uniform in [0.9, 1.1] mm, random orientations (:func:`de_domain.clumps.clump_cloud`:
  enclosing spheres not overlapping, in the box above the floor);
* **spheres**: as many free spheres as the rods have members, of the members' radii, placed the
  same way (:func:`de_domain.packing.random_cloud`).

Box [0, 0.04]² × [0, 0.16] m of six plane walls; the W1 material (``beds.py``: k_n = 1e5 N/m at
r = 1 mm, μ = 0.5, restitution 0.5), local damping 0.1. Settled for ``SETTLE_TIME`` under
``SETTLE_GRAVITY`` (−100 m/s²: the cloud falls and packs) with local damping 0.4, then
``RELAX_TIME`` under −9.81 m/s² with 0.1 (engine made again between them); Δt = 0.3 × the
engine's critical step (a rod's members take the rod's critical mass, docs/design.md §2.19: its
Δt is the smaller, and it takes more steps).

Timed: one untimed step (lists, kernels), then ``--steps`` steps under −9.81 m/s², twice
(``--repeats``), the median printed. Printed per bed (on rank 0): member-sphere-steps/s (spheres
× steps / s), Δt, contacts per sphere (pairs × 2 / spheres), and with clumps over ranks the
share of the time spent gathering the members' loads (``Domain.share_member_loads``) and the
clumps that straddle the ranks. A clump step costs more than a sphere step for the same spheres
by its third region (the clumps advanced, their members placed) and, over ranks, by the gather
of every member's load on every rank each step.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import de_domain  # noqa: E402,F401  (threading defaults before Numba starts its threads)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beds import MATERIAL  # noqa: E402

OUT = Path(__file__).resolve().parent / "out" / "clumps"
N_CLUMPS = 4000
SIDE = 0.04
HEIGHT = 0.16
SEED = 11
SETTLE_TIME = 0.1  # s: the cloud falls 0.15 m in 0.055 s at 100 m/s^2
SETTLE_GRAVITY = -100.0
SETTLE_DAMPING = 0.4
RELAX_TIME = 0.01
LOCAL_DAMPING = 0.1


def _materials():
    from de_domain import Material

    return [Material(**MATERIAL)]


def _walls():
    from de_domain import PlaneWall

    return [PlaneWall((0, 0, 0), (1, 0, 0)), PlaneWall((SIDE, 0, 0), (-1, 0, 0)),
            PlaneWall((0, 0, 0), (0, 1, 0)), PlaneWall((0, SIDE, 0), (0, -1, 0)),
            PlaneWall((0, 0, 0), (0, 0, 1)), PlaneWall((0, 0, HEIGHT), (0, 0, -1))]


def _rod():
    from de_domain.clumps import ClumpTemplate

    return ClumpTemplate.line(2, 1.5)


def clump_engine(state, gravity, comm=None, damping=LOCAL_DAMPING):
    """An engine of the rods at ``state`` (a ClumpPacking)."""
    from de_domain import Engine

    particles, clumps = state.bodies(_materials())
    return Engine(particles, _materials(), walls=_walls(), gravity=(0.0, 0.0, gravity), local_damping=damping,
                  clumps=clumps, comm=comm)


def sphere_engine(state, gravity, comm=None, damping=LOCAL_DAMPING):
    """An engine of the free spheres at ``state`` (a dict: pos, radius, vel, angvel)."""
    from de_domain import Engine, Particles

    particles = Particles.from_spheres(state["pos"], state["radius"], materials=_materials(), velocities=state["vel"])
    particles.angvel[:] = state["angvel"]
    return Engine(particles, _materials(), walls=_walls(), gravity=(0.0, 0.0, gravity), local_damping=damping,
                  comm=comm)


def make_beds(log=print):
    """Insert and settle both beds (module docstring); write them to ``OUT``."""
    from de_domain.clumps import clump_cloud
    from de_domain.packing import random_cloud

    rng = np.random.default_rng(SEED)
    diameters = rng.uniform(1.8e-3, 2.2e-3, N_CLUMPS)
    margin = 2.0e-3
    lo, hi = (margin, margin, margin), (SIDE - margin, SIDE - margin, HEIGHT - margin)
    rods = clump_cloud([_rod()], np.zeros(N_CLUMPS, np.int64), diameters, lo, hi, SEED, rng)
    _, member_radius = rods.members()
    pos, radius = random_cloud(np.sort(member_radius)[::-1], lo, hi, seed=SEED)
    spheres = {"pos": pos, "radius": radius, "vel": np.zeros_like(pos), "angvel": np.zeros_like(pos)}
    stages = ((SETTLE_TIME, SETTLE_GRAVITY, SETTLE_DAMPING), (RELAX_TIME, -9.81, LOCAL_DAMPING))
    for duration, gravity, damping in stages:
        t0 = time.perf_counter()
        engine = clump_engine(rods, gravity, damping=damping)
        engine.run(round(duration / engine.dt))
        rods = rods.moved(engine)
        engine = sphere_engine(spheres, gravity, damping=damping)
        engine.run(round(duration / engine.dt))
        p = engine.particles
        spheres = {"pos": p.pos.copy(), "radius": p.radius.copy(), "vel": p.vel.copy(), "angvel": p.angvel.copy()}
        log(f"  {duration} s at g = {gravity:g} m/s^2: {time.perf_counter() - t0:.0f} s")
    OUT.mkdir(parents=True, exist_ok=True)
    arrays = {f"rods_{k}": v for k, v in rods.arrays().items()}
    arrays.update(rods_velocities=rods.velocities, rods_angular_velocities=rods.angular_velocities)
    np.savez(OUT / "beds.npz", **arrays, **{f"spheres_{k}": v for k, v in spheres.items()},
             n_clumps=np.int64(N_CLUMPS))


def load_beds():
    from dataclasses import replace

    from de_domain.clumps import ClumpPacking

    with np.load(OUT / "beds.npz") as f:
        d = {k: f[k] for k in f.files}
    rods = ClumpPacking.from_arrays({k[5:]: v for k, v in d.items() if k.startswith("rods_")})
    rods = replace(rods, velocities=d["rods_velocities"], angular_velocities=d["rods_angular_velocities"])
    spheres = {k[8:]: v for k, v in d.items() if k.startswith("spheres_")}
    return rods, spheres


class _Timed:
    """A callable that adds its time to ``seconds``."""

    def __init__(self, call):
        self.call, self.seconds = call, 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        self.call(*args)
        self.seconds += time.perf_counter() - t0


def time_bed(build, steps, comm):
    """(seconds for ``steps`` steps, Δt, contacts per sphere, gather seconds, straddling clumps)."""
    engine = build(comm)
    engine.run(1)
    gather = None
    if engine.domain is not None and engine.clumps.count:
        gather = engine.domain.share_member_loads = _Timed(engine.domain.share_member_loads)
    engine.runner.barrier()
    t0 = time.perf_counter()
    engine.run(steps)
    engine.runner.barrier()
    seconds = time.perf_counter() - t0
    p = engine.particles
    live = engine.pair_overlap > 0.0
    owned_i = p.owned[engine.neighbors.pair_i[live]]  # a pair between two ranks: counted by its i's owner
    contacts = int(np.sum(engine.runner.concatenate(np.array([np.count_nonzero(owned_i)]))))
    spheres = int(np.sum(engine.runner.concatenate(np.array([p.n_owned]))))
    straddling = 0
    if engine.clumps.count and engine.domain is not None:
        member_of, _ = engine.clump_rows()
        ranks = engine.runner.concatenate(np.unique(member_of[p.owned & (member_of >= 0)]))
        straddling = int(np.count_nonzero(np.bincount(ranks, minlength=engine.clumps.count) > 1))
    return seconds, engine.dt, 2.0 * contacts / spheres, (gather.seconds if gather else 0.0), straddling


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--force", action="store_true", help="make the beds again")
    args = ap.parse_args(argv)
    import numba
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    if comm.rank == 0 and (args.force or not (OUT / "beds.npz").exists()):
        print(f"making the beds ({N_CLUMPS} rods, {2 * N_CLUMPS} spheres) in {OUT}")
        make_beds()
    comm.Barrier()
    rods, spheres = load_beds()
    distributed = comm if comm.size > 1 else None
    builds = {"spheres": lambda c: sphere_engine(spheres, -9.81, c), "clumps": lambda c: clump_engine(rods, -9.81, c)}
    results = {name: [] for name in builds}
    for _ in range(args.repeats):  # interleaved
        for name, build in builds.items():
            results[name].append(time_bed(build, args.steps, distributed))
    if comm.rank != 0:
        return
    print(f"{comm.size} rank(s) x {numba.get_num_threads()} thread(s), {args.steps} steps, median of {args.repeats}")
    rate = {}
    for name, rows in results.items():
        seconds = statistics.median(r[0] for r in rows)
        _, dt, z, gather, straddling = rows[0]
        rate[name] = 2 * N_CLUMPS * args.steps / seconds
        line = f"  {name:8s} {rate[name]:.3e} member-sphere-steps/s, dt {dt:.3g} s, {z:.2f} contacts per sphere"
        if name == "clumps" and comm.size > 1:
            line += (f", member-load gather {statistics.median(r[3] for r in rows) / seconds:.1%} of the time, "
                     f"{straddling} of {N_CLUMPS} clumps straddle the ranks")
        print(line)
    print(f"  clump step / sphere step per member-sphere-step: {rate['clumps'] / rate['spheres']:.2f}")


if __name__ == "__main__":
    main()
