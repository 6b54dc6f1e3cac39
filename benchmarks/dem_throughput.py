"""DEM throughput on the W1 settled bed (issue 3 "Performance").

    .venv/bin/python benchmarks/dem_throughput.py                 # 5k, 20k, 80k; 1 and 2 threads
    .venv/bin/python benchmarks/dem_throughput.py --sizes 5000 --threads 1 --repeats 1

Work: the W1 beds of 5,000 and 20,000 spheres settled by de_domain itself
(``benchmarks/beds.py``: made on the first run into ``benchmarks/out/w1/bed_N.dump``
— 16 s for 5k, a few minutes for 20k on 2 cores — then reused; r 0.8–1.2 mm,
ρ 2650 kg/m³) in a box [0, L]² × [0, 0.06] m of six plane walls, gravity −9.81 z,
linear law with k_n = 2 E r* = 1e5 N/m at r = 1 mm (E = 5e7 Pa), k_t/k_n = 0.25
(κ = 4), μ = 0.5, restitution 0.5 (the LIGGGHTS deck's coefficientRestitution), no
background damping, Δt = 2e-6 s fixed, Verlet skin 0.2 mm (the deck's
``neighbor 0.0002``).
The 80,000 bed is the 20,000 bed tiled 2 × 2 in x and y (copies shifted by L = 0.076 m;
box 0.152 × 0.152 × 0.06 m, walls only on the outer faces: the copies touch along the
former inner walls, a few spheres there start with small overlaps and push apart).

Columns: wall time of the 2,000 steps, the process CPU time spent in them (all
threads; on a shared machine wall > cpu/threads shows time lost to other load),
the rate N·2000/wall, (2 × sphere contacts + wall contacts)/N, bytes per particle,
list builds. Per (N, threads): ``SORTED_MIN_STEPS`` untimed steps (neighbour build, JIT if not yet
done, and the on-disk kernels of a run on sorted copies loaded: left in the timed run they cost
the first configuration of a process 1–2 s at 20,000), then
``engine.run(2000)`` timed; ``REPEATS`` times, median reported (a fresh engine each
time). "JIT" is the time of the first step of a throw-away 5k engine (minus a
second step): once with an empty Numba cache in a subprocess (compilation), once in
this process (normally loading the on-disk cache); both are excluded from the rates.
Memory per particle: ``Engine.memory_bytes()`` (nbytes of every per-particle and
per-contact array the engine holds, including the spatially sorted copies a run
works on) / N. Threading: ``de_domain.threading`` (set on import, before Numba
starts its threads; the line above the table says what is in use).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import de_domain  # noqa: E402,F401  (sets the threading defaults before Numba launches threads)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import beds  # noqa: E402
from beds import DT, bed, make_engine  # noqa: E402

from de_domain.engine import SORTED_MIN_STEPS  # noqa: E402

STEPS = 2000


def jit_time():
    """First step of a throw-away engine: compilation or cache load (+ a 5k build)."""
    pos, radius, L = bed(5000)
    engine = make_engine(pos, radius, L)
    t0 = time.perf_counter()
    engine.run(1)
    t1 = time.perf_counter()
    engine.run(1)
    return (t1 - t0) - (time.perf_counter() - t1)


def cold_jit_time():
    """First step with an empty Numba cache: de_domain copied to a temporary directory
    without __pycache__, timed in a subprocess (the repository's cache is untouched)."""
    import shutil
    import subprocess
    import tempfile

    src = Path(__file__).resolve().parents[1] / "de_domain"
    with tempfile.TemporaryDirectory(prefix="dem_cold_") as tmp:
        shutil.copytree(src, Path(tmp) / "de_domain", ignore=shutil.ignore_patterns("__pycache__"))
        code = ("import sys; sys.path.insert(0, sys.argv[1]); import de_domain; "
                "sys.path.insert(1, sys.argv[2]); import dem_throughput as b; "
                "assert de_domain.__file__.startswith(sys.argv[1]); print(b.jit_time())")
        out = subprocess.run([sys.executable, "-c", code, tmp, str(Path(__file__).resolve().parent)],
                             check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def measure(n, threads, steps=STEPS):
    import numba

    numba.set_num_threads(threads)
    pos, radius, L = bed(n)
    engine = make_engine(pos, radius, L)
    engine.run(SORTED_MIN_STEPS)
    c0 = time.process_time()
    t0 = time.perf_counter()
    engine.run(steps)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    c = engine.contacts()
    contacts = (2 * c["i"].size + c["wall_particle"].size) / n
    mem = sum(engine.memory_bytes().values()) / n if hasattr(engine, "memory_bytes") else float("nan")
    return {"n": n, "threads": threads, "wall": wall, "cpu": cpu, "rate": n * steps / wall, "contacts": contacts,
            "mem": mem, "builds": engine.neighbors.n_builds}


def run_table(sizes, threads_list, repeats, steps=STEPS, out=print, cold=True):
    import numba

    from de_domain import threading as dthreading

    for n in sorted({5000} | {20000 if n == 80000 else n for n in sizes}):
        beds.bed_file(n)  # made once, before any timing (and before the cold-cache subprocess reads it)
    cold_jit = cold_jit_time() if cold else float("nan")
    jit = jit_time()
    out(f"# de_domain W1 throughput: {steps} steps, dt = {DT:g} s; threading {dthreading.describe()}; "
        f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    out(f"# JIT, excluded below: first step with an empty Numba cache (compilation) {cold_jit:.1f} s; "
        f"with the on-disk cache {jit:.2f} s")
    out(f"{'N':>7} {'threads':>7} {'wall [s]':>9} {'cpu [s]':>8} {'particle-steps/s':>17} {'contacts/particle':>17} "
        f"{'bytes/particle':>14} {'rebuilds':>8}   (median of {repeats}; all rates)")
    rows = []
    for n in sizes:
        for threads in threads_list:
            runs = [measure(n, threads, steps) for _ in range(repeats)]
            walls = [r["wall"] for r in runs]
            best = runs[walls.index(statistics.median_low(walls))]
            row = dict(best, wall=statistics.median(walls), rate=n * steps / statistics.median(walls),
                       rates=[r["rate"] for r in runs])
            rows.append(row)
            out(f"{n:>7} {threads:>7} {row['wall']:>9.3f} {row['cpu']:>8.2f} {row['rate']:>17.3e} "
                f"{row['contacts']:>17.2f} {row['mem']:>14.0f} {row['builds']:>8}   "
                + " ".join(f"{r:.2e}" for r in row["rates"]))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 80000], choices=[5000, 20000, 80000],
                    help="bed sizes (default: %(default)s)")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="Numba thread counts (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=3, help="runs per (size, threads), median (default: %(default)s)")
    ap.add_argument("--steps", type=int, default=STEPS, help="timed steps (default: %(default)s)")
    ap.add_argument("--no-cold", action="store_true", help="skip the empty-cache compilation timing")
    args = ap.parse_args(argv)
    run_table(args.sizes, args.threads, args.repeats, args.steps, cold=not args.no_cold)


if __name__ == "__main__":
    main()
