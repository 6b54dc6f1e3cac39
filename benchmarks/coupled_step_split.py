"""Where a coupled step on several ranks spends its time, against the DEM alone: compiled kernels and the rest.

    .venv/bin/python benchmarks/coupled_step_split.py              # large case, 2 ranks, 1 substep
    .venv/bin/python benchmarks/coupled_step_split.py --case flagship

On several ranks with the FE replicated (``coupling.fe_partition``, the default) a coupled
FE step is one compiled call (:func:`cosim.compiled_coupling.fe_step_and_motion`: the last
window's interface forces, the FE step, the interface motion) and a DEM window from Python
(:func:`de_domain.distributed.run`: per step one compiled kernel call, the ghost exchange and
the facet force gather). ``benchmarks/coupled_overhead.py`` compares the whole step with its
parts alone; this script splits both sides, per step, by wrapping the engine's kernel entry
(``Engine._advance_kernel``), the stepper's FE entry, the ghost exchange and
:func:`de_domain.distributed.facet_vertex_forces` with timers (≈ 0.1 µs each):

* ``DEM kernel``: :func:`de_domain.fused.advance`, the compiled DEM step;
* ``FE call``: :func:`fe_step_and_motion` (coupled only);
* ``exchange + facets``: the ghost exchange and the facet contact gather of every step
  (MPI waits for the other rank included);
* ``other``: the rest: Python around the calls — for the coupled step that includes each
  window's prologue (wall and facet arrays, boundary-jump work, rebuild test) that a DEM-alone
  run of many steps pays once.

for ``coupled`` (:class:`cosim.compiled_coupling.CoupledStepper`, as ``cosim run`` steps) and
``DEM alone`` (``Engine.run`` over the same number of steps, the interface as fixed facets),
blocks of STEPS steps interleaved, each first in turn, medians of REPEATS per rank; the FE
alone (``ExplicitSolid.run``) for the overhead ratio of ``coupled_overhead.py``; and both
steps again without the timers, interleaved with the rest, for what the timers cost.
"""
from __future__ import annotations

import argparse
import json
import time

from coupled_overhead import FLAGSHIP, OUT, case_overrides, median, run_on_every_rank, run_worker

REPEATS = 10
STEPS = 200
PARTS = ("dem_kernel", "fe_call", "exchange_facets")


class _Timers:
    """Seconds spent in each wrapped callable since the last :meth:`reset`."""

    def __init__(self):
        self.seconds = dict.fromkeys(PARTS, 0.0)

    def reset(self):
        self.seconds = dict.fromkeys(PARTS, 0.0)

    def wrap(self, part, function):
        def timed(*args):
            start = time.perf_counter()
            result = function(*args)
            self.seconds[part] += time.perf_counter() - start
            return result
        return timed


class _TimedEntry:
    """A :class:`numba_support.dispatch.CachedEntry` whose calls, and its ``entry``'s, are timed."""

    def __init__(self, cached, timers, part):
        self._cached, self._timers, self._part = cached, timers, part

    def __call__(self, *args):
        return self._timers.wrap(self._part, self._cached)(*args)

    @property
    def entry(self):
        return self._timers.wrap(self._part, self._cached.entry)


def worker(case, out_json):
    from mpi4py import MPI

    import de_domain.distributed as distributed
    from cosim.apps import coupled
    from cosim.case import load_case
    from cosim.compiled_coupling import CoupledStepper

    comm = MPI.COMM_WORLD
    loaded, _ = load_case(FLAGSHIP, case_overrides(case, 1))
    built = coupled.prepare(loaded, FLAGSHIP, OUT / "coupled_step_split_run", resume=False)
    solid, interface, engine = built["solid"], built["interface"], built["engine"]
    stepper = CoupledStepper(solid, interface=interface, engine=engine, subcycles=1)
    if not stepper.fe_compiled:
        raise SystemExit("coupled_step_split.py needs several ranks with the FE replicated (the compiled FE call)")
    stepper.run(20, coupled.coupled_step)  # warm up (compiles on the first run after an edit)
    timers = _Timers()
    exchange = engine.domain.exchange
    plain = (engine._advance_kernel, stepper._fe_step, exchange.exchange, distributed.facet_vertex_forces)
    timed = (timers.wrap("dem_kernel", plain[0]), _TimedEntry(plain[1], timers, "fe_call"),
             timers.wrap("exchange_facets", plain[2]), timers.wrap("exchange_facets", plain[3]))

    def instrument(callables):
        engine._advance_kernel, stepper._fe_step, exchange.exchange, distributed.facet_vertex_forces = callables

    def coupled_block():
        stepper.run(STEPS, coupled.coupled_step)

    def dem_block():
        interface.facets.vertex_velocity[:] = 0.0  # the interface as fixed facets
        engine.run(STEPS)

    def fe_block():
        solid.run(STEPS)

    # the same blocks with and without the timers: what the timers cost shows
    blocks = [("coupled", coupled_block, timed), ("dem_alone", dem_block, timed), ("fe_alone", fe_block, plain),
              ("coupled_plain", coupled_block, plain), ("dem_alone_plain", dem_block, plain)]
    rows = {kind: [] for kind, _, _ in blocks}
    for repeat in range(REPEATS):
        for kind, work, callables in blocks[repeat % len(blocks):] + blocks[:repeat % len(blocks)]:
            instrument(callables)
            timers.reset()
            comm.Barrier()
            start = time.perf_counter()
            work()
            total = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
            parts = {part: seconds / STEPS for part, seconds in timers.seconds.items()}
            parts["other"] = total / STEPS - sum(parts.values())
            rows[kind].append({"step": total / STEPS, **parts})
    per_rank = comm.gather({kind: {key: median([r[key] for r in values]) for key in values[0]}
                            for kind, values in rows.items()}, root=0)
    if comm.rank == 0:
        with open(out_json, "w") as handle:
            json.dump({"case": case, "ranks": comm.size, "per_rank": per_rank}, handle)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="large", choices=["flagship", "large"])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--worker", nargs=2, metavar=("CASE", "JSON"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        run_on_every_rank(worker, *args.worker)
        return
    if args.ranks < 2:
        parser.error("--ranks: at least 2 (on one rank the whole coupled schedule is one compiled call)")
    OUT.mkdir(parents=True, exist_ok=True)
    case_overrides(args.case, 1)  # make the bed first, if it is missing
    out_json = OUT / f"coupled_step_split_{args.case}_{args.ranks}.json"
    run_worker(__file__, args.ranks, [args.case, out_json])
    result = json.loads(out_json.read_text())
    print(f"{args.case}, {args.ranks} ranks, 1 substep, us a step (medians of {REPEATS} blocks of {STEPS} steps)")
    print(f"{'rank':>4s} {'':10s} | {'step':>6s} = {'DEM kernel':>10s} + {'FE call':>7s} + "
          f"{'exchange + facets':>17s} + {'other':>5s} | overhead                | without the timers: step, overhead")
    for rank, kinds in enumerate(result["per_rank"]):
        fe_alone = kinds["fe_alone"]["step"]
        for kind in ("coupled", "dem_alone"):
            r = {key: 1e6 * value for key, value in kinds[kind].items()}
            ratio = kinds["coupled"]["step"] / (kinds["dem_alone"]["step"] + fe_alone)
            plain_ratio = kinds["coupled_plain"]["step"] / (kinds["dem_alone_plain"]["step"] + fe_alone)
            overhead = f"{ratio:.2f} (FE alone {1e6 * fe_alone:.0f} us)" if kind == "coupled" else ""
            print(f"{rank:4d} {kind:10s} | {r['step']:6.0f} = {r['dem_kernel']:10.0f} + {r['fe_call']:7.0f} + "
                  f"{r['exchange_facets']:17.0f} + {r['other']:5.0f} | {overhead:22s} | "
                  f"{1e6 * kinds[kind + '_plain']['step']:6.0f}" + (f" {plain_ratio:.2f}" if kind == "coupled" else ""),
                  flush=True)


if __name__ == "__main__":
    main()
