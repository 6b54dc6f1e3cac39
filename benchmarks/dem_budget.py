"""Where a DEM step's time goes: the ns-per-particle budget of the W1 bed, next to a bare floor.

    .venv/bin/python benchmarks/dem_budget.py                   # 20,000 and 80,000, one thread
    .venv/bin/python benchmarks/dem_budget.py --sizes 20000 --threads 2

One engine per size on the W1 bed (``benchmarks/beds.py``, the work of ``dem_throughput.py``),
``SORTED_MIN_STEPS`` untimed steps (the lists built, every kernel loaded), then:

* **whole run**: ``engine.run(STEPS)`` timed, with the time spent in the list builds
  (``NeighborList.build``) and in the gathers/scatters between the public arrays and the
  spatially sorted copies measured inside it (their functions wrapped by timers); the rest
  is the fused steps (:func:`de_domain.fused.advance`) and the Python between kernel calls.
* **the step's parts alone**, each ``PART_STEPS`` times over every block on the state the
  run left (sorted copies, the lists of its last build; the state is restored after each
  part): region 1 (the pair loop, :func:`de_domain.fused._pair_block`), and region 2 cut
  into its passes — the j-side gather (:func:`de_domain.fused.gather_j_side`), the plane walls
  (:func:`de_domain.walls.plane_wall_contacts`), the leapfrog
  (:func:`de_domain.integrate.integrate_block`) and the displacement scan. Run alone,
  each part has the caches to itself: the parts add up to less than the fused step.
* **floor**: the least a step on this list can cost in Numba — one serial sweep over the
  same half list and the same sorted arrays computing a linear spring-dashpot normal force
  only (no tangential spring, no torque, no history, no walls, no energy), added to i and
  j at once (Newton's third law), then a leapfrog of x and v.

Printed per size: ns per particle-step of each item, its share of the whole run, and ns
per list pair and per contact for the pair loop. ``--threads`` sets Numba's thread count
for the whole run (the parts run serially on one thread).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import de_domain  # noqa: E402,F401  (threading defaults before Numba starts its threads)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from beds import bed, make_engine  # noqa: E402
from numba import njit  # noqa: E402

from de_domain import fused, neighbors  # noqa: E402
from de_domain.engine import SORTED_MIN_STEPS  # noqa: E402
from de_domain.integrate import IntegrationTerms, integrate_block  # noqa: E402
from de_domain.state import N_CONTACT_ENERGY, N_WALL_ENERGY  # noqa: E402
from de_domain.walls import plane_wall_contacts  # noqa: E402

STEPS = 2000
PART_STEPS = 200


@njit(cache=True)
def _region1(k, settings, particles, params, pairs):
    nb = (pairs.perm.size + fused.PBLOCK - 1) // fused.PBLOCK
    e1 = np.zeros((nb, N_CONTACT_ENERGY))
    for _ in range(k):
        for b in range(nb):
            fused._pair_block(b, settings, particles, params, pairs, e1)


@njit(cache=True)
def _gather(k, particles, pairs):
    n = pairs.perm.size
    for _ in range(k):
        for first in range(0, n, fused.PBLOCK):
            fused.gather_j_side(first, min(first + fused.PBLOCK, n), True, particles, pairs)


@njit(cache=True)
def _walls(k, settings, particles, params, pairs, walls):
    n = pairs.perm.size
    we = np.zeros(N_WALL_ENERGY)
    for _ in range(k):
        for first in range(0, n, fused.PBLOCK):
            plane_wall_contacts(first, min(first + fused.PBLOCK, n), settings, particles, params, pairs.perm, walls,
                                we)


@njit(cache=True)
def _leapfrog(k, settings, particles, pairs, clumps):
    n = pairs.perm.size
    for _ in range(k):
        for first in range(0, n, fused.PBLOCK):
            integrate_block(first, min(first + fused.PBLOCK, n), settings, particles, pairs.perm, clumps.member_of,
                            IntegrationTerms(0.0, 0.0, 0.0, 0.0, 0.0))


@njit(cache=True)
def _displacement(k, particles):
    pos, ref_pos = particles.pos, particles.ref_pos
    worst = 0.0
    for _ in range(k):
        for s in range(pos.shape[0]):
            ex = pos[s, 0] - ref_pos[s, 0]
            ey = pos[s, 1] - ref_pos[s, 1]
            ez = pos[s, 2] - ref_pos[s, 2]
            worst = max(worst, ex * ex + ey * ey + ez * ez)
    return worst


@njit(cache=True)
def _floor(k, pos, vel, radius, mass, i_start, pair_js, stiffness, damping, dt):
    n = pos.shape[0]
    force = np.zeros((n, 3))
    for _ in range(k):
        force[:, :] = 0.0
        for i in range(n):
            ri = radius[i]
            for p in range(i_start[i], i_start[i + 1]):
                j = np.uint64(pair_js[p])
                dx = pos[j, 0] - pos[i, 0]
                dy = pos[j, 1] - pos[i, 1]
                dz = pos[j, 2] - pos[i, 2]
                d2 = dx * dx + dy * dy + dz * dz
                cut = ri + radius[j]
                if d2 >= cut * cut:
                    continue
                dist = np.sqrt(d2)
                nx = dx / dist; ny = dy / dist; nz = dz / dist
                vn = (vel[j, 0] - vel[i, 0]) * nx + (vel[j, 1] - vel[i, 1]) * ny + (vel[j, 2] - vel[i, 2]) * nz
                fn = -stiffness * (cut - dist) + damping * vn
                force[i, 0] += fn * nx; force[i, 1] += fn * ny; force[i, 2] += fn * nz
                force[j, 0] -= fn * nx; force[j, 1] -= fn * ny; force[j, 2] -= fn * nz
        for i in range(n):
            inv = 1.0 / mass[i]
            for d in range(3):
                vel[i, d] += dt * force[i, d] * inv
                pos[i, d] += dt * vel[i, d]


class Stopwatch:
    """Replaces ``owner.name`` (a module's function or a class's method) by a wrapper that adds
    the wall time of its calls to ``self.seconds`` and counts them in ``self.calls``."""

    def __init__(self, owner, name):
        self.owner, self.name, self.inner, self.seconds, self.calls = owner, name, getattr(owner, name), 0.0, 0

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return self.inner(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0
                self.calls += 1

        setattr(owner, name, timed)

    def restore(self):
        setattr(self.owner, self.name, self.inner)


def _timed(fn, *args):
    fn(1, *args)  # compile / load
    t0 = time.perf_counter()
    fn(PART_STEPS, *args)
    return (time.perf_counter() - t0) / PART_STEPS


def _snapshot(particles, pairs):
    return [a.copy() for a in (*particles, pairs.tangential, pairs.overlap, pairs.j_record)]


def _restore(saved, particles, pairs):
    for dst, src in zip((*particles, pairs.tangential, pairs.overlap, pairs.j_record), saved, strict=True):
        dst[...] = src


def budget(n, threads):
    import numba

    numba.set_num_threads(threads)
    pos, radius, L = bed(n)
    engine = make_engine(pos, radius, L)
    engine.run(SORTED_MIN_STEPS)  # the lists, and every kernel of a run on sorted copies loaded
    watches = [Stopwatch(neighbors.NeighborList, "build"), Stopwatch(fused, "gather_in_order"),
               Stopwatch(fused, "scatter_in_order")]
    builds0 = engine.neighbors.n_builds
    t0 = time.perf_counter()
    engine.run(STEPS)
    whole = (time.perf_counter() - t0) / STEPS
    for w in watches:
        w.restore()
    builds = engine.neighbors.n_builds - builds0
    build_s, gather_s, scatter_s = (w.seconds / STEPS for w in watches)

    numba.set_num_threads(1)
    engine.keep_sorted = True
    (settings, particles, params, pairs, walls, _, _, clumps), _, _ = engine.start_external_run()
    m = pairs.pair_js.size
    contacts = int(np.count_nonzero(pairs.overlap > 0.0))
    saved = _snapshot(particles, pairs)
    parts = {}
    for name, fn, args in (("region 1: pair loop", _region1, (settings, particles, params, pairs)),
                           ("region 2: j-side gather", _gather, (particles, pairs)),
                           ("region 2: plane walls", _walls, (settings, particles, params, pairs, walls)),
                           ("region 2: leapfrog", _leapfrog, (settings, particles, pairs, clumps)),
                           ("region 2: displacement scan", _displacement, (particles,))):
        parts[name] = _timed(fn, *args)
        _restore(saved, particles, pairs)
    k_n = 1e5
    floor = _timed(_floor, particles.pos.copy(), particles.vel.copy(), particles.radius, particles.mass,
                   pairs.i_start, pairs.pair_js, k_n, 2.0 * 0.2 * np.sqrt(k_n * 1e-5), settings.dt)

    ns = 1e9 / n
    print(f"\n## N = {n:,}, {threads} thread(s): {m:,} list pairs ({m / n:.2f} per particle), {contacts:,} in "
          f"contact ({contacts / n:.2f}), {builds} list builds in {STEPS} steps")
    print(f"{'item':<34} {'ns/particle-step':>17} {'share of run':>13}")
    rows = [("whole run (per step)", whole),
            ("  list builds (amortised)", build_s),
            ("  gather + scatter of the copies", gather_s + scatter_s),
            ("  fused steps + Python", whole - build_s - gather_s - scatter_s)]
    rows += [(f"  {k} (alone)", v) for k, v in parts.items()]
    rows += [("  parts alone, summed", sum(parts.values())),
             ("floor: bare normal-force sweep", floor)]
    for name, seconds in rows:
        print(f"{name:<34} {seconds * ns:>17.1f} {seconds / whole:>12.0%}")
    r1 = parts["region 1: pair loop"]
    print(f"pair loop: {r1 * 1e9 / m:.1f} ns per list pair, {r1 * 1e9 / max(contacts, 1):.1f} ns per contact; "
          f"floor {floor * 1e9 / m:.1f} ns per list pair")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[20000, 80000], choices=[5000, 20000, 80000])
    ap.add_argument("--threads", type=int, default=1, help="Numba threads for the whole run (default: 1)")
    args = ap.parse_args(argv)
    for n in args.sizes:
        budget(n, args.threads)


if __name__ == "__main__":
    main()
