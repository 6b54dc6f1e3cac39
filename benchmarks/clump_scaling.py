"""Clumps against spheres and against LIGGGHTS's ``fix multisphere``, on one rank and over MPI ranks.

    .venv/bin/python benchmarks/clump_scaling.py                      # 1 and 2 ranks, ours
    .venv/bin/python benchmarks/clump_scaling.py --liggghts           # and LIGGGHTS 3.8 in each round

Two beds of the same number of spheres in the same box, made by this script on first use and
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

Each configuration is a worker process (``mpirun -n R`` for R > 1 ranks, ``--threads`` Numba threads
a rank, 1 by default): one untimed step, then ``--steps`` steps timed; ``--repeats`` rounds, every configuration in each
(interleaved). Printed: member-sphere-steps/s (spheres × steps / s; median and each round),
contacts per sphere (pairs × 2 / spheres; pairs within a rod are not contacts), with clumps over
ranks the share of the time in the gather of the members' loads (``Domain.share_member_loads``)
and the clumps that straddle the ranks; then clumps / spheres and clumps / LIGGGHTS, round by round.

``--liggghts``: LIGGGHTS 3.8 (Debian's ``liggghts``; ``make bench-peers`` installs it) on the
same number of rods of the bed's shape and mean size (``LIGGGHTS_DECK``: ``particletemplate/
multisphere`` of the two members, ``insert/pack`` at random in the box, ``fix multisphere``,
the linear ``hooke/stiffness`` law with k_n = 1e5 N/m), settled as the bed (under the same
gravities and times, at our clumps' Δt; LIGGGHTS has no local damping), then the same timed steps.
It is a bed of the same grains, not the same bed (LIGGGHTS's ``fix multisphere`` cannot be given
our positions and orientations); its contacts per sphere are printed beside ours.
"""
from __future__ import annotations

import argparse
import json
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
    """Rate and counts of ``steps`` steps of the engine ``build(comm)`` after one untimed step:
    a dict (member-sphere-steps/s, Δt, contacts per sphere, the gather's share, straddling clumps)."""
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
    return {"rate": spheres * steps / seconds, "dt": engine.dt, "contacts": 2.0 * contacts / spheres,
            "gather": (gather.seconds / seconds if gather else 0.0), "straddling": straddling}


def worker(kind, steps):
    """One configuration, under ``mpirun`` or alone: prints its :func:`time_bed` dict as JSON on rank 0."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rods, spheres = load_beds()
    def build(c):
        return clump_engine(rods, -9.81, c) if kind == "clumps" else sphere_engine(spheres, -9.81, c)

    result = time_bed(build, steps, comm if comm.size > 1 else None)
    if comm.rank == 0:
        print("RESULT " + json.dumps(result))


# LIGGGHTS 3.8 deck: rods of the clumps bed's shape and mean size (equal-volume radius 1.0 mm, members
# 0.84 mm at ±0.42 mm), as many as the bed, in its box, inserted at random (insert/pack), settled as the
# bed (no local damping in LIGGGHTS: a longer settle), then timed. ${...}: LIGGGHTS variables.
LIGGGHTS_DECK = """\
atom_style\tsphere
atom_modify\tmap array
boundary\tf f f
newton\t\toff
communicate\tsingle vel yes
units\t\tsi
region\t\tbox block 0 @SIDE@ 0 @SIDE@ 0 @HEIGHT@ units box
create_box\t1 box
neighbor\t0.00016 bin
neigh_modify\tdelay 0
@CONTACTS@
fix pts1 all particletemplate/multisphere 15485863 atom_type 1 density constant @DENSITY@ nspheres 2 ntry 1000000 &
    spheres -0.00042 0 0 0.00084 0.00042 0 0 0.00084 type 1
fix pdd1 all particledistribution/discrete 32452843 1 pts1 1.0
region ins block 0.002 @INNER@ 0.002 @INNER@ 0.002 @TOP@ units box
fix ins all insert/pack seed 49979687 distributiontemplate pdd1 vel constant 0 0 0 orientation random &
    insert_every once overlapcheck yes all_in yes particles_in_region @N_CLUMPS@ region ins
fix ms all multisphere
fix grav all gravity @SETTLE_G@ vector 0.0 0.0 -1.0
compute cn all contact/atom
compute cnsum all reduce sum c_cn
thermo_style custom step atoms c_cnsum
thermo 1000
thermo_modify lost ignore norm no
timestep @DT@
run @SETTLE_STEPS@
unfix grav
fix grav2 all gravity 9.81 vector 0.0 0.0 -1.0
run @RELAX_STEPS@
run 1
run @STEPS@
"""


def liggghts(workdir, ranks, steps, dt):
    """LIGGGHTS on the rods (deck above) on ``ranks`` ranks: member-sphere-steps/s of the timed block and
    contacts per sphere (contact/atom summed, / spheres) after it."""
    import re

    import mpi_launch
    from beds import MATERIAL, liggghts_contacts
    deck = LIGGGHTS_DECK
    values = {"SIDE": SIDE, "HEIGHT": HEIGHT, "INNER": SIDE - 0.002, "TOP": HEIGHT - 0.002, "N_CLUMPS": N_CLUMPS,
              "CONTACTS": liggghts_contacts(SIDE, SIDE, HEIGHT), "DENSITY": MATERIAL["density"],
              "SETTLE_G": -SETTLE_GRAVITY,
              "DT": dt, "SETTLE_STEPS": round(SETTLE_TIME / dt), "RELAX_STEPS": round(RELAX_TIME / dt),
              "STEPS": steps}
    for key, value in values.items():
        deck = deck.replace(f"@{key}@", f"{value:g}" if isinstance(value, float) else str(value))
    (Path(workdir) / "in.rods").write_text(deck)
    cmd = ["liggghts", "-echo", "none", "-in", "in.rods", "-log", f"log.{ranks}"]
    if ranks > 1:
        cmd = ["mpirun", "--bind-to", "none", "-np", str(ranks)] + cmd
    mpi_launch.run(cmd, env=mpi_launch.mpi_env(OMP_NUM_THREADS=1), cwd=workdir, timeout=3600)
    log = (Path(workdir) / f"log.{ranks}").read_text()
    seconds, atoms = re.findall(r"Loop time of ([0-9.eE+-]+) on \d+ procs for \d+ steps with (\d+) atoms", log)[-1]
    contacts = float(re.findall(r"^\s*\d+\s+\d+\s+([0-9.eE+-]+)\s*$", log, re.M)[-1])
    return {"rate": int(atoms) * steps / float(seconds), "contacts": contacts / int(atoms)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=2, help="rounds, every configuration in each (median)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--threads", type=int, default=1, help="Numba threads a rank")
    ap.add_argument("--liggghts", action="store_true", help="LIGGGHTS fix multisphere on rods in each round too")
    ap.add_argument("--force", action="store_true", help="make the beds again")
    ap.add_argument("--worker", choices=["spheres", "clumps"], help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(args.worker, args.steps)
        return
    import tempfile

    import mpi_launch
    if args.force or not (OUT / "beds.npz").exists():
        print(f"making the beds ({N_CLUMPS} rods, {2 * N_CLUMPS} spheres) in {OUT}")
        make_beds()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):  # interleaved
            for ranks in args.ranks:
                for kind in ("spheres", "clumps"):
                    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", kind, "--steps", str(args.steps)]
                    if ranks > 1:
                        cmd = ["mpirun", "--bind-to", "none", "-n", str(ranks)] + cmd
                    env = mpi_launch.mpi_env(NUMBA_NUM_THREADS=args.threads)
                    results.setdefault((kind, ranks), []).append(mpi_launch.run_json(cmd, "RESULT ", env=env,
                                                                                     timeout=1800))
                if args.liggghts:
                    dt = results[("clumps", ranks)][-1]["dt"]
                    results.setdefault(("LIGGGHTS rods", ranks), []).append(liggghts(tmp, ranks, args.steps, dt))
    print(f"member-sphere-steps/s, {args.threads} thread(s) a rank, {args.steps} steps, "
          f"median of {args.repeats} interleaved rounds")
    for (kind, ranks), rows in results.items():
        rate = statistics.median(r["rate"] for r in rows)
        rates = ", ".join(f"{r['rate']:.3e}" for r in rows)
        line = f"  {kind:14s} {ranks} rank(s): {rate:.3e} ({rates}), {rows[0]['contacts']:.2f} contacts per sphere"
        if kind == "clumps" and ranks > 1:
            line += (f", the member-load gather {statistics.median(r['gather'] for r in rows):.1%} of the time, "
                     f"{rows[0]['straddling']} of {N_CLUMPS} clumps straddle the ranks")
        print(line)
    for ranks in args.ranks:
        pairs = zip(results[("clumps", ranks)], results[("spheres", ranks)], strict=True)
        ratio = [c["rate"] / s["rate"] for c, s in pairs]
        print(f"  clumps / spheres at {ranks} rank(s): " + ", ".join(f"{r:.2f}" for r in ratio))
        if args.liggghts:
            pairs = zip(results[("clumps", ranks)], results[("LIGGGHTS rods", ranks)], strict=True)
            print(f"  clumps / LIGGGHTS rods at {ranks} rank(s): " + ", ".join(f"{c['rate'] / g['rate']:.2f}"
                                                                              for c, g in pairs))


if __name__ == "__main__":
    main()
