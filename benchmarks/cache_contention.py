"""Cache contention: how much slower a DEM step runs when other bytes pass through the cache between steps.

    .venv/bin/python benchmarks/cache_contention.py               # 1 and 2 ranks
    .venv/bin/python benchmarks/cache_contention.py --ranks 2

With one DEM substep per FE step a coupled run alternates a DEM step and an FE step, and
each evicts the other's arrays from the cache they share (README, "Coupling overhead").
This script measures the DEM side of that alone, on the large case of
``benchmarks/coupled_overhead.py`` (20,000 grains under the 3,157-node plate, the interface
as fixed facets): one-step DEM windows, as a coupled run makes them, each preceded on every
rank by a read of S MB of another array (``numpy.sum``), for S = 0, 1, 2, 4, 8, 16 and for
the bytes an FE step of the plate reads and writes (its compiled operators and nodal
arrays, ``fe``). The read is also timed alone, and

    slowdown(S) = (t(window after a read of S MB) − t(read of S MB alone)) / t(window alone)

is printed per S: medians of REPEATS rounds, the blocks interleaved, each first in turn,
1 Numba thread per rank (ranks run as ``mpirun -n N ... --worker``).
"""
from __future__ import annotations

import argparse
import json
import time

from coupled_overhead import FLAGSHIP, OUT, case_overrides, median, run_on_every_rank, run_worker

REPEATS = 7
WINDOWS = 200            # one-step DEM windows per timed block
STREAM_MB = (0, 1, 2, 4, 8, 16)


def worker(out_json):
    import numpy as np
    from mpi4py import MPI

    from cosim.apps import coupled
    from cosim.apps import dem as dem_app
    from cosim.case import load_case

    comm = MPI.COMM_WORLD
    loaded, _ = load_case(FLAGSHIP, case_overrides("large", 1))
    built = coupled.prepare(loaded, FLAGSHIP, OUT / "cache_contention_run", resume=False)
    engine, solid = built["engine"], built["solid"]
    built["interface"].facets.vertex_velocity[:] = 0.0  # the interface as fixed facets
    _, _, nodal = solid.compiled_arguments()
    fe_bytes = solid.compiled_operator_bytes() + sum(a.nbytes for a in nodal if isinstance(a, np.ndarray))
    sizes = {f"{mb}": mb * 1_000_000 for mb in STREAM_MB} | {"fe": fe_bytes}
    streams = {key: np.ones(nbytes // 8) for key, nbytes in sizes.items()}

    def elapsed(work):
        comm.Barrier()
        start = time.perf_counter()
        work()
        return comm.allreduce(time.perf_counter() - start, op=MPI.MAX) / WINDOWS

    def windows_after(stream):
        for _ in range(WINDOWS):
            stream.sum()
            dem_app.advance(engine, 1)

    def stream_alone(stream):
        for _ in range(WINDOWS):
            stream.sum()

    dem_app.advance(engine, 10)  # warm up
    keys = list(sizes)
    after = {key: [] for key in keys}
    alone = {key: [] for key in keys}
    for repeat in range(REPEATS):
        for key in keys[repeat % len(keys):] + keys[:repeat % len(keys)]:
            after[key].append(elapsed(lambda key=key: windows_after(streams[key])))
            alone[key].append(elapsed(lambda key=key: stream_alone(streams[key])))
    if comm.rank:
        return
    base = median(after["0"]) - median(alone["0"])
    rows = [{"stream": key, "mb": sizes[key] / 1e6, "window_us": 1e6 * median(after[key]),
             "read_us": 1e6 * median(alone[key]),
             "slowdown": (median(after[key]) - median(alone[key])) / base} for key in keys]
    with open(out_json, "w") as handle:
        json.dump({"ranks": comm.size, "grains": int(engine.domain.n_global if engine.domain else engine.particles.n),
                   "rows": rows}, handle)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--worker", metavar="JSON", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        run_on_every_rank(worker, args.worker)
        return
    OUT.mkdir(parents=True, exist_ok=True)
    case_overrides("large", 1)  # make the 20,000 bed first, if it is missing
    print(f"{'ranks':>5s} {'read [MB]':>11s} | {'window after the read':>21s} {'read alone':>10s} | slowdown")
    results = []
    for ranks in args.ranks:
        out_json = OUT / f"cache_contention_{ranks}.json"
        run_worker(__file__, ranks, [out_json])
        result = json.loads(out_json.read_text())
        results.append(result)
        for row in result["rows"]:
            label = f"{row['mb']:.1f}" + (" (FE)" if row["stream"] == "fe" else "")
            print(f"{ranks:5d} {label:>11s} | {row['window_us']:19.0f}us {row['read_us']:8.0f}us | "
                  f"{row['slowdown']:.3f}", flush=True)
    (OUT / "cache_contention.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
