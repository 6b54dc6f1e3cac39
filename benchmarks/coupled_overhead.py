"""Coupling overhead: a coupled FE step against its parts, timed alone in the same process.

    .venv/bin/python benchmarks/coupled_overhead.py                    # both cases, 1 and 2 ranks
    .venv/bin/python benchmarks/coupled_overhead.py --cases flagship --ranks 1

Cases (``cosim`` coupled cases, built from ``runs/coupled_footing_on_sand.toml``):

* ``flagship``: the case itself, 3,000 grains, an interface of 108 triangles;
* ``large``: the same elastic plate, 60 × 60 × 5 mm with 2 mm elements, on the W1 bed of
  20,000 grains (``benchmarks/beds.py``, box 76 × 76 mm): an interface of 2,892 triangles (1,507 vertices).

each with 1 and 10 DEM substeps per FE step (``coupling.subcycles``), and on several ranks with
the FE replicated on each (``coupling.fe_partition``, the default) or partitioned over them
(``--fe-partition replicated distributed`` for both). For each case, substep count, rank count
and FE partition the driver runs itself as a worker
(``mpirun -n N python benchmarks/coupled_overhead.py --worker ...``, 1 Numba thread per
rank). A worker prepares the case as ``cosim run`` does, warms up, then times, REPEATS
times interleaved, each of the three first in turn (so that the machine's drift and the
order hit all three alike):

* ``coupled``: BLOCK coupled FE steps as ``cosim run`` makes them
  (``cosim.compiled_coupling.CoupledStepper``, ``cosim.apps.coupled.PROGRESS_CHUNK`` FE
  steps a call: compiled calls on one rank; on several, with the FE replicated, each FE step
  and its interface motion in one compiled call; with the FE partitioned, step by step);
* ``step by step``: the same from Python (``cosim.apps.coupled.coupled_step``,
  what several ranks run with the FE partitioned), with the time split into FE step, interface out (vertex
  positions and velocities to the DEM), DEM window, interface in (impulse to FE forces);
* ``DEM alone``: the same engine for BLOCK × subcycles DEM steps in one ``Engine.run`` call,
  against the interface as fixed facets (vertex velocities zero);
* ``FE alone``: ``ExplicitSolid.run(BLOCK)`` (one compiled call on one rank).

and prints the medians per FE step and ``overhead = coupled / (DEM alone + FE alone)``
(target ≤ 1.10), with particle-steps/s and the neighbour-list builds per 1,000 DEM steps in
the coupled and the DEM-alone blocks (the moving interface stirs the grains: more builds); the rows also go to
``benchmarks/out/coupled_overhead.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
import mpi_launch  # noqa: E402

OUT = ROOT / "benchmarks" / "out"
FLAGSHIP = ROOT / "runs" / "coupled_footing_on_sand.toml"
REPEATS = 5
MIN_SECONDS = 0.3      # per timed block, roughly: BLOCK is chosen from a trial coupled step
LARGE_BED = 20000
LARGE_OVERRIDES = [
    "fe.mesh_size=0.002",
    "fe.geometry_parameters.Lx=0.06", "fe.geometry_parameters.Ly=0.06", "fe.geometry_parameters.Lz=0.005",
    "fe.geometry_parameters.x0=0.008", "fe.geometry_parameters.y0=0.008",
    "dem.walls[2].point=[0.076, 0.0, 0.0]", "dem.walls[4].point=[0.0, 0.076, 0.0]",
]


def case_overrides(case, subcycles, fe_partition="replicated"):
    """``--set`` overrides that make ``case`` (flagship | large) from the flagship file."""
    overrides = [f"coupling.subcycles={subcycles}", f"coupling.fe_partition={fe_partition}", "output.vtk=false"]
    if case == "large":
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from beds import bed_file, load_dump
        path = bed_file(LARGE_BED)
        top = float((load_dump(path)[0][:, 2] + load_dump(path)[1]).max())
        overrides += LARGE_OVERRIDES + [f"dem.particles.file={path}", f"fe.geometry_parameters.z0={top + 2e-4}"]
    return overrides


def median(values):
    """The middle value (the upper one of an even count)."""
    values = sorted(values)
    return values[len(values) // 2]


def run_worker(script, ranks, worker_args):
    """``mpirun -n ranks python script --worker worker_args`` with 1 Numba thread per rank;
    exits with the worker's output if it fails."""
    env = mpi_launch.mpi_env(NUMBA_NUM_THREADS="1")  # and OpenMPI's root/oversubscribe permissions where unset
    cmd = ["mpirun", "--bind-to", "none", "-n", str(ranks), sys.executable, str(script), "--worker",
           *map(str, worker_args)]
    mpi_launch.run(cmd, env=env, cwd=ROOT, timeout=1800)  # a failure: exit code and stderr, once


def run_on_every_rank(work, *args):
    """``work(*args)`` in a worker; one rank failing ends all (none left waiting in a collective)."""
    try:
        work(*args)
    except BaseException:
        import traceback

        from mpi4py import MPI
        traceback.print_exc()
        MPI.COMM_WORLD.Abort(1)


def worker(case, subcycles, fe_partition, out_json):
    import numpy as np
    from mpi4py import MPI

    from cosim.apps import coupled
    from cosim.apps import dem as dem_app
    from cosim.case import load_case
    from cosim.compiled_coupling import CoupledStepper

    comm = MPI.COMM_WORLD
    loaded, _ = load_case(FLAGSHIP, case_overrides(case, subcycles, fe_partition))
    built = coupled.prepare(loaded, FLAGSHIP, OUT / "coupled_overhead_run", resume=False)
    solid, interface, engine, n_sub = built["solid"], built["interface"], built["engine"], built["subcycles"]

    def elapsed(work):
        comm.Barrier()
        start = time.perf_counter()
        work()
        return comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    parts = np.zeros(4)  # FE step, interface out, DEM window, interface in
    stepper = CoupledStepper(solid, interface=interface, engine=engine, subcycles=n_sub)

    def coupled_block(steps):
        for start in range(0, steps, coupled.PROGRESS_CHUNK):
            stepper.run(min(coupled.PROGRESS_CHUNK, steps - start), coupled.coupled_step)

    def step_by_step_block(steps):
        for _ in range(steps):
            t0 = time.perf_counter()
            solid.step()
            t1 = time.perf_counter()
            interface.send_motion()
            t2 = time.perf_counter()
            dem_app.advance(engine, n_sub)
            t3 = time.perf_counter()
            interface.receive_forces(solid.dt)
            parts[:] += (t1 - t0, t2 - t1, t3 - t2, time.perf_counter() - t3)

    def dem_block(steps):
        interface.facets.vertex_velocity[:] = 0.0  # the interface as fixed facets
        engine.run(steps * n_sub)

    def fe_block(steps):
        solid.run(steps)

    trial = elapsed(lambda: coupled_block(20)) / 20
    block = max(20, int(comm.bcast(MIN_SECONDS / trial, root=0)))
    faster = stepper.compiled or stepper.fe_compiled  # than step by step from Python
    blocks = [("coupled", coupled_block if faster else step_by_step_block), ("dem", dem_block), ("fe", fe_block)]
    if faster:
        blocks.append(("step_by_step", step_by_step_block))
    times = {kind: [] for kind, _ in blocks}
    builds = {"coupled": 0, "dem": 0}  # neighbour-list builds (rank 0) during the timed blocks
    for repeat in range(REPEATS):
        parts[:] = 0.0
        first = repeat % len(blocks)
        for kind, work in blocks[first:] + blocks[:first]:  # each block first in turn
            before = engine.neighbors.n_builds
            times[kind].append(elapsed(lambda work=work: work(block)) / block)
            if kind in builds:
                builds[kind] += engine.neighbors.n_builds - before
    if not faster:  # the coupled block was step by step
        times["step_by_step"] = times["coupled"]
    split = np.zeros(4)
    comm.Allreduce(parts, split, op=MPI.MAX)
    split /= block
    if comm.rank:
        return
    med = {k: median(v) for k, v in times.items()}
    n_grains = engine.domain.n_global if engine.domain is not None else engine.particles.n
    row = {"case": case, "grains": int(n_grains), "facets": int(len(interface.facets.triangles)),
           "fe_cells": int(solid.mesh.topology.index_map(3).size_global), "subcycles": n_sub, "ranks": comm.size,
           "fe_partition": fe_partition if comm.size > 1 else "-",
           "block": block, "coupled_us": 1e6 * med["coupled"], "dem_us": 1e6 * med["dem"], "fe_us": 1e6 * med["fe"],
           "overhead": med["coupled"] / (med["dem"] + med["fe"]), "compiled": stepper.compiled,
           "fe_compiled": stepper.fe_compiled,
           "step_by_step_us": 1e6 * med["step_by_step"],
           "step_by_step_overhead": med["step_by_step"] / (med["dem"] + med["fe"]),
           "split_us": dict(zip(("fe", "out", "dem", "in"), (1e6 * split).tolist(), strict=True)),
           "particle_steps_per_s": n_grains * n_sub / med["coupled"],
           "builds_per_1000_steps": {k: 1000.0 * v / (REPEATS * block * n_sub) for k, v in builds.items()}}
    with open(out_json, "w") as handle:
        json.dump(row, handle)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="+", default=["flagship", "large"], choices=["flagship", "large"])
    parser.add_argument("--subcycles", nargs="+", type=int, default=[1, 10])
    parser.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--fe-partition", nargs="+", default=["replicated"], choices=["replicated", "distributed"],
                        help="FE layouts on several ranks (coupling.fe_partition)")
    parser.add_argument("--worker", nargs=4, metavar=("CASE", "SUBCYCLES", "FE_PARTITION", "JSON"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        case, subcycles, fe_partition, out_json = args.worker
        run_on_every_rank(worker, case, int(subcycles), fe_partition, out_json)
        return
    OUT.mkdir(parents=True, exist_ok=True)
    if "large" in args.cases:
        case_overrides("large", 1)  # make the 20,000 bed first, if it is missing
    rows = []
    print(f"{'case':9s} {'grains':>7s} {'facets':>6s} {'sub':>4s} {'ranks':>5s} {'FE':>11s} | {'coupled':>9s} "
          f"{'DEM alone':>9s} "
          f"{'FE alone':>9s} {'overhead':>8s} | step by step, overhead | split of a step-by-step step: FE / out / "
          "DEM / in [us] | particle-steps/s | list builds per 1000 DEM steps: coupled / DEM alone")
    for case in args.cases:
        for subcycles in args.subcycles:
            for ranks, partition in [(r, p) for r in args.ranks for p in (args.fe_partition if r > 1 else ["-"])]:
                out_json = OUT / f"coupled_overhead_{case}_{subcycles}_{ranks}_{partition}.json"
                run_worker(__file__, ranks,
                           [case, subcycles, "replicated" if partition == "-" else partition, out_json])
                row = json.loads(out_json.read_text())
                rows.append(row)
                s, b = row["split_us"], row["builds_per_1000_steps"]
                print(f"{case:9s} {row['grains']:7d} {row['facets']:6d} {row['subcycles']:4d} {ranks:5d} "
                      f"{row['fe_partition']:>11s} | "
                      f"{row['coupled_us']:7.0f}us {row['dem_us']:7.0f}us {row['fe_us']:7.0f}us "
                      f"{row['overhead']:7.2f}x | {row['step_by_step_us']:7.0f}us "
                      f"{row['step_by_step_overhead']:5.2f}x | "
                      f"{s['fe']:7.0f} / {s['out']:5.0f} / {s['dem']:7.0f} / {s['in']:4.0f}"
                      f" | {row['particle_steps_per_s']:.3g} | {b['coupled']:.1f} / {b['dem']:.1f}", flush=True)
    (OUT / "coupled_overhead.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
