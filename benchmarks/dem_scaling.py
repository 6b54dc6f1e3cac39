"""DEM over MPI ranks on the W1 bed (issue 13): particle-steps/s, ghosts, bytes, memory.

    .venv/bin/python benchmarks/dem_scaling.py                      # 80k and 320k, ours and LIGGGHTS
    .venv/bin/python benchmarks/dem_scaling.py --sizes 80000 --repeats 1 --no-liggghts

Work: the 20,000-sphere W1 bed (benchmarks/beds.py, settled by de_domain) tiled
2 × 2 (80,000) and 4 × 4 (320,000) in x and y, walls on the outer faces, gravity,
the W1 contact parameters and Δt = 2e-6 s (benchmarks/dem_throughput.py says which); also
10 × 5 (1,000,000).
Configurations, interleaved (A/B/C…, then again, ``--repeats`` times; median):

* ours 1 rank × 1 thread and 1 rank × 2 threads: the serial engine (``comm=None``,
  whole blocks of steps in one compiled call);
* ours 2 ranks × 1 thread: ``mpirun --bind-to core -n 2``, ``Engine(..., comm=COMM_WORLD)``,
  and the same with ``--bind-to none`` (the ranks free to move between cores);
* LIGGGHTS 3.8 at 1 and 2 ranks (``mpirun --bind-to core -n 2 liggghts``, the deck of
  benchmarks/compare_peers.py reading the same tiled bed), when installed.

Each run takes one untimed step (list build, cache load), then times ``--steps``
steps. Printed per configuration: particle-steps/s, speed-up against ours 1 × 1,
ghosts per rank, bytes each rank sends per step (ghost exchange), list builds, and
memory per particle including ghosts (``Engine.memory_bytes()`` summed over the
ranks, / N); then the set-up (bed loaded and tiled, ``Engine`` made and, at 2 ranks,
distributed), the first step (the first list build and the kernels loaded), the mean
list build inside the timed steps (rank 0's), and one ParaView frame
(:func:`de_domain.io.write_frame`; distributed: one piece a rank and a ``.pvtu``): seconds and MB.
The 1,000,000 bed (the 20k bed tiled 10 × 5) is not square: LIGGGHTS's deck is not run on it.
The machine's load average is printed before and after.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
import beds  # noqa: E402
import mpi_launch  # noqa: E402

ENV = mpi_launch.mpi_env()  # OpenMPI's run-as-root and oversubscribe permissions where unset
CORES = os.cpu_count() or 1


def mpirun(ranks, bound=True):
    """``mpirun -n ranks`` with each rank bound to a core while there are cores enough
    (OpenMPI's own default for 2 ranks), unbound and oversubscribed beyond."""
    binding = ["--bind-to", "core"] if bound and ranks <= CORES else ["--oversubscribe", "--bind-to", "none"]
    return ["mpirun", *binding, "-n", str(ranks)]
TIMEOUT = 3600


def worker(n, steps, threads):
    """One configuration, in this process (rank 0 prints one JSON line)."""
    import numba
    from dem_budget import Stopwatch
    from mpi4py import MPI

    import de_domain  # noqa: F401  (threading defaults first)
    from de_domain.io import write_frame
    from de_domain.neighbors import NeighborList

    comm = MPI.COMM_WORLD
    numba.set_num_threads(threads)
    t_setup = time.perf_counter()
    pos, radius, L = beds.bed(n, log=lambda text: None)
    engine = beds.make_engine(pos, radius, L, comm=comm if comm.size > 1 else None)
    comm.Barrier()
    t_first = time.perf_counter()
    engine.run(1)
    comm.Barrier()
    t0 = time.perf_counter()
    builds_timed = Stopwatch(NeighborList, "build")  # the list builds inside the timed steps
    engine.run(steps)
    comm.Barrier()
    wall = time.perf_counter() - t0
    builds_timed.restore()
    with tempfile.TemporaryDirectory(prefix="dem_frame_") as tmp:
        directory = comm.bcast(tmp)  # rank 0's folder (the ranks share the machine)
        tf = time.perf_counter()
        paths = write_frame(directory, engine, 0)
        frame = time.perf_counter() - tf
        frame_bytes = sum(p.stat().st_size for p in Path(paths[0]).parent.iterdir()) if comm.rank == 0 else 0
        comm.Barrier()
    memory = comm.allreduce(sum(engine.memory_bytes().values()))
    domain = engine.domain
    ghosts = comm.gather(0 if domain is None else domain.exchange.n_ghosts)
    sent = comm.gather(0 if domain is None else domain.exchange.bytes_sent)
    builds = engine.neighbors.n_builds
    if comm.rank == 0:
        print(json.dumps({"rate": n * steps / wall, "wall": wall, "ghosts": ghosts, "sent": sent,
                          "bytes_per_particle": memory / n, "builds": builds, "setup": t_first - t_setup,
                          "first_step": t0 - t_first, "build_seconds": builds_timed.seconds,
                          "timed_builds": builds_timed.calls,
                          "frame": frame, "frame_bytes": frame_bytes}), flush=True)


def ours(n, steps, ranks, threads, bound=True):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(n), str(steps), str(threads)]
    if ranks > 1:
        cmd = mpirun(ranks, bound) + cmd
    # the worker's JSON line, wherever mpirun's escape sequences or trailing text put it; a
    # failed worker ends the benchmark with mpirun's exit code and stderr, once
    return mpi_launch.run_json(cmd, env=ENV, timeout=TIMEOUT)


def liggghts_inputs(workdir, n, steps):
    """The compare_peers deck (with ``steps``) and the tiled bed as bed_N.dump in ``workdir``."""
    import compare_peers

    m = beds.MATERIAL
    deck = compare_peers._fill(compare_peers.LIGGGHTS_DECK, STEPS=steps, H=f"{beds.HEIGHT:g}",
                               SKIN=f"{beds.SKIN:g}", TIMESTEP=beds.SETTLE_STEPS, DENSITY=f"{m['density']:g}",
                               FRICTION=f"{m['friction']:g}", POISSON=f"{m['poisson']:g}",
                               RESTITUTION=f"{m['restitution']:g}", DT=f"{beds.DT:g}", G=f"{-beds.GRAVITY:g}")
    (Path(workdir) / "in.bed").write_text(deck)
    pos, radius, L = beds.bed(n)
    beds.write_dump(Path(workdir) / f"bed_{n}.dump", pos, radius, L)
    return L


def liggghts(workdir, n, steps, ranks, L):
    log = f"log.{n}.{ranks}"
    cmd = ["liggghts", "-echo", "none", "-var", "N", str(n), "-var", "L", f"{L:g}", "-in", "in.bed", "-log", log]
    if ranks > 1:
        cmd = mpirun(ranks) + cmd
    mpi_launch.run(cmd, cwd=workdir, env=dict(ENV, OMP_NUM_THREADS="1"), timeout=TIMEOUT)
    loops = re.findall(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps", (Path(workdir) / log).read_text())
    seconds, done = loops[-1]
    assert int(done) == steps, loops
    return {"rate": n * steps / float(seconds)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[80000, 320000], choices=sorted(beds.TILED))
    ap.add_argument("--steps", type=int, default=0, help="timed steps (default: 4e7 / N)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-liggghts", action="store_true")
    ap.add_argument("--worker", nargs=3, type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return
    beds.bed_file(20000)
    peers = not args.no_liggghts and subprocess.run(["which", "liggghts"], capture_output=True).returncode == 0
    lig = "yes" if peers else "off (--no-liggghts)" if args.no_liggghts else "not installed"
    print(f"load average before: {os.getloadavg()[0]:.2f}; LIGGGHTS: {lig}")
    for n in args.sizes:
        steps = args.steps or max(20, int(4e7 // n))
        configs = {"ours 1 rank x 1 thread": lambda n=n, s=steps: ours(n, s, 1, 1),
                   "ours 1 rank x 2 threads": lambda n=n, s=steps: ours(n, s, 1, 2),
                   "ours 2 ranks x 1 thread": lambda n=n, s=steps: ours(n, s, 2, 1),
                   "  same, ranks not bound": lambda n=n, s=steps: ours(n, s, 2, 1, bound=False)}
        with tempfile.TemporaryDirectory(prefix="dem_scaling_") as tmp:
            square = len(set(beds.TILED.get(n, (1, 1)))) == 1  # the LIGGGHTS deck's box is square
            if peers and square:
                L = liggghts_inputs(tmp, n, steps)
                configs["LIGGGHTS 1 rank"] = lambda n=n, s=steps, L=L: liggghts(tmp, n, s, 1, L)
                configs["LIGGGHTS 2 ranks"] = lambda n=n, s=steps, L=L: liggghts(tmp, n, s, 2, L)
            runs = {name: [] for name in configs}
            for _ in range(args.repeats):
                for name, run in configs.items():
                    runs[name].append(run())
        base = statistics.median(r["rate"] for r in runs["ours 1 rank x 1 thread"])
        print(f"\nW1 bed N = {n:,}, {steps} timed steps, median of {args.repeats}")
        print(f"{'configuration':26s} {'particle-steps/s':>17s} {'vs ours 1x1':>11s} {'ghosts/rank':>14s} "
              f"{'kB sent/step/rank':>18s} {'B/particle':>10s} {'builds':>6s}  each round (1e6/s)")
        for name, results in runs.items():
            rate = statistics.median(r["rate"] for r in results)
            last = results[-1]
            ghosts = "/".join(str(g) for g in last.get("ghosts", [])) or "-"
            sent = "/".join(f"{b / 1e3:.0f}" for b in last.get("sent", [])) or "-"
            memory = f"{last['bytes_per_particle']:.0f}" if "bytes_per_particle" in last else "-"
            builds = str(last.get("builds", "-"))
            rounds = " ".join(f"{r['rate'] / 1e6:.2f}" for r in results)
            print(f"{name:26s} {rate:17.3e} {rate / base:10.2f}x {ghosts:>14s} {sent:>18s} {memory:>10s} "
                  f"{builds:>6s}  {rounds}")
        print(f"{'configuration':26s} {'set-up [s]':>10s} {'first step [s]':>14s} {'list build [s]':>14s} "
              f"{'frame [s]':>9s} {'frame [MB]':>10s}   (last round; set-up: bed + Engine, first step: its list "
              "build and kernel loading)")
        for name, results in runs.items():
            last = results[-1]
            if "setup" not in last:
                continue
            build = last["build_seconds"] / last["timed_builds"] if last["timed_builds"] else float("nan")
            print(f"{name:26s} {last['setup']:10.2f} {last['first_step']:14.2f} {build:14.2f} {last['frame']:9.2f} "
                  f"{last['frame_bytes'] / 1e6:10.1f}")
        if "LIGGGHTS 2 ranks" in runs:
            lig = statistics.median(r["rate"] for r in runs["LIGGGHTS 2 ranks"])
            two = statistics.median(r["rate"] for r in runs["ours 2 ranks x 1 thread"])
            print(f"ours 2 ranks / LIGGGHTS 2 ranks: {two / lig:.2f}x")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
