"""de_domain against LIGGGHTS 3.8 and YADE on the W1 settled-bed work, side by side.

    .venv/bin/python benchmarks/compare_peers.py                   # 5k and 20k beds
    .venv/bin/python benchmarks/compare_peers.py --sizes 20000 --repeats 3

Needs the Debian packages ``liggghts`` and ``yade`` (``make bench-peers`` installs
them). Every peer runs via subprocess in a temporary directory holding copies of the
W1 decks (``../shared/benchmarks/w1``: ``in.bed``, ``yade_bed.py``, the beds):

* LIGGGHTS, 1 and 2 MPI ranks: ``in.bed`` settles its own bed of N spheres (same
  box, radii, stiffnesses, friction, Δt; ``-var seed 86028121``) and then times
  ``run 2000``; the rate is N·2000 / (its last "Loop time").
* YADE ``-j1`` / ``-j2``: ``yade_bed.py N 2000`` loads ``bed_N.dump``, runs 1000
  steps, then times 2000 (it prints particle-steps/s).
* de_domain, 1 and 2 Numba threads: ``dem_throughput.measure`` (the same dump,
  2000 steps after one untimed step).

Each configuration runs ``--repeats`` times (median). The table prints the rates
and the ratios ours/LIGGGHTS and ours/YADE at equal core count, and the machine's
load average before and after.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

BASE_ENV = dict(os.environ)  # the peers get the environment as it was, without de_domain's threading defaults
sys.path.insert(0, str(Path(__file__).resolve().parent))
import dem_throughput as ours  # noqa: E402

W1 = ours.W1
STEPS = 2000
BOX = {5000: 0.038, 20000: 0.076}
SEED = 86028121
ENV = dict(BASE_ENV, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")


def liggghts(workdir, n, ranks):
    L = BOX[n]
    cmd = ["liggghts", "-echo", "none", "-var", "N", str(n), "-var", "L", str(L), "-var", "Lm", f"{L - 0.0013:.4f}",
           "-var", "seed", str(SEED), "-in", "in.bed", "-log", f"log.{n}.{ranks}"]
    if ranks > 1:
        cmd = ["mpirun", "--allow-run-as-root", "-np", str(ranks)] + cmd
    subprocess.run(cmd, cwd=workdir, env=dict(ENV, OMP_NUM_THREADS="1"), check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.STDOUT)
    loops = re.findall(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps",
                       (Path(workdir) / f"log.{n}.{ranks}").read_text())
    seconds, steps = loops[-1]
    assert int(steps) == STEPS, loops
    return n * STEPS / float(seconds)


def yade(workdir, n, threads):
    out = subprocess.run(["yade", f"-j{threads}", "-x", "yade_bed.py", str(n), str(STEPS)], cwd=workdir, env=ENV,
                         check=True, capture_output=True, text=True).stdout
    return float(re.search(r"particle-steps/s=([0-9.eE+-]+)", out).group(1))


def de_domain(n, threads):
    return ours.measure(n, threads)["rate"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--peers", nargs="+", default=["liggghts", "yade"])
    args = ap.parse_args(argv)
    for exe in args.peers:
        if shutil.which(exe) is None:
            sys.exit(f"compare_peers: '{exe}' is not installed (make bench-peers installs liggghts and yade)")
    from de_domain import threading as dthreading

    load0 = os.getloadavg()
    print(f"# W1 peers, {STEPS} timed steps; de_domain threading {dthreading.describe()}")
    print(f"# load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    ours.jit_time()  # compile / load the cache before timing
    rows = []
    with tempfile.TemporaryDirectory(prefix="w1_peers_") as tmp:
        for name in ("in.bed", "yade_bed.py", "bed_5000.dump", "bed_20000.dump"):
            shutil.copy(W1 / name, tmp)
        for n in args.sizes:
            for cores in (1, 2):
                rate = {}
                runs = {"de_domain": lambda: de_domain(n, cores)}
                if "liggghts" in args.peers:
                    runs["LIGGGHTS"] = lambda: liggghts(tmp, n, cores)
                if "yade" in args.peers:
                    runs["YADE"] = lambda: yade(tmp, n, cores)
                samples = {k: [] for k in runs}
                for _ in range(args.repeats):  # interleaved, so load changes hit every code alike
                    for k, f in runs.items():
                        samples[k].append(f())
                rate = {k: statistics.median(v) for k, v in samples.items()}
                rows.append((n, cores, rate, samples))
                print(f"  N={n} cores={cores}: " + ", ".join(f"{k} {v:.3e}" for k, v in rate.items()), flush=True)
    load1 = os.getloadavg()
    print()
    print(f"{'N':>6} {'cores':>5} {'de_domain':>11} {'LIGGGHTS':>11} {'YADE':>11} {'ours/LIGGGHTS':>13} "
          f"{'ours/YADE':>9}   particle-steps/s, median of {args.repeats}")
    for n, cores, rate, _ in rows:
        lig = rate.get("LIGGGHTS", float("nan"))
        yad = rate.get("YADE", float("nan"))
        print(f"{n:>6} {cores:>5} {rate['de_domain']:>11.3e} {lig:>11.3e} {yad:>11.3e} "
              f"{rate['de_domain'] / lig:>13.2f} {rate['de_domain'] / yad:>9.2f}")
    for n in args.sizes:
        r = {c: rate for nn, c, rate, _ in rows if nn == n}
        if 1 in r and 2 in r and "LIGGGHTS" in r[1]:
            print(f"N={n}: de_domain 2 threads / LIGGGHTS 1 rank = {r[2]['de_domain'] / r[1]['LIGGGHTS']:.2f} "
                  f"(target >= 1.8); de_domain 1 thread / LIGGGHTS 1 rank = "
                  f"{r[1]['de_domain'] / r[1]['LIGGGHTS']:.2f} (target >= 1)")
    print(f"# load average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
