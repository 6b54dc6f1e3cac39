"""The W1 benchmark beds, made by de_domain itself and cached in ``benchmarks/out/w1/``.

    .venv/bin/python benchmarks/beds.py                  # make (or check) the 5,000 and 20,000 beds
    .venv/bin/python benchmarks/beds.py --sizes 5000 --force

W1 work (used by ``dem_throughput.py`` and ``compare_peers.py``): N spheres in a box
[0, L]² × [0, 0.06] m of six plane walls, L = 0.038 m for N = 5,000 and 0.076 m for
N = 20,000 (the 80,000 bed is the 20,000 bed tiled 2 × 2, see :func:`bed`); radii
r ∈ {0.8, 0.9, 1.0, 1.1, 1.2} mm, 20 % of the solid mass each (so the numbers go as
r⁻³: 1727 / 1213 / 884 / 664 / 512 spheres for N = 5,000, largest-remainder
rounding), ρ = 2650 kg/m³; linear contact law with k_n = 2 E r* = 1e5 N/m at r = 1 mm
(E = 5e7 Pa, ν = 0.25), k_t = k_n / 4, μ = 0.5, restitution 0.5, no background
damping; Verlet skin 0.2 mm; timed work: 2,000 steps of Δt = 2e-6 s under gravity
−9.81 m/s² z.

Settle (the protocol of the original LIGGGHTS W1 deck, run by de_domain on the same
engine the benchmark times):

1. random sequential, non-overlapping insertion (:func:`de_domain.packing.random_cloud`,
   seed ``SEED``) of the N spheres inside [1.3 mm, L − 1.3 mm]² × [1.3, 58.7] mm,
   i.e. a loose cloud filling the box (solid fraction 0.31 of that region);
2. 12,000 steps of Δt = 5e-6 s under 100 m/s² (−z): the cloud falls and packs (0.06 s);
3. 3,000 steps of Δt = 2e-6 s under −9.81 m/s² (the engine rebuilt from the state,
   contact history dropped): the bed relaxes to its real weight.

A loose-ish, not fully quiet bed: top at 24.3 mm (5,000) / 24.9 mm (20,000), the
fastest sphere still at 0.11 / 0.20 m/s when it is written; de_domain then counts
4.2 contacts per sphere (2 × sphere pairs + wall contacts) on the 5,000 bed.

The positions (9 significant digits), radii and box go to ``bed_N.dump``, a LIGGGHTS
dump (9 header lines, then ``id type radius x y z``, SI units; the TIMESTEP line is
the 15,000 settle steps), the format LIGGGHTS' ``read_dump ... x y z radius add yes``
reads (it needs the ``type`` column), so the same file feeds de_domain, LIGGGHTS and
YADE (``compare_peers.py`` writes their inputs beside it). ``bed_N.json`` records the
parameters; a bed whose record differs from the ones below is made again
(``--force`` makes it again anyway).

Deterministic: the cloud comes from a seeded NumPy generator and de_domain's steps are
bit-identical for any Numba thread count (checked: 1 and 2 threads give the same
file), so the dump has the same bytes every time on the same machine. One catch,
handled in :func:`bed_file`: a process that compiled the kernels itself gave a
different (equally valid) bed from one that loaded them from Numba's on-disk cache,
reproducibly; so the settle runs in a child process after another child has
compiled the kernels, and is repeated if it still compiled any.

Time on the project's 2-core machine, kernels already compiled: 16 s for the
5,000 bed when the machine was otherwise idle; 200–240 s for the 20,000 bed, with the
machine shared with other jobs (load 2–4). A first ever run adds 1–2 min of Numba
compilation (the warm-up child).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "w1"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

BOX = {5000: 0.038, 20000: 0.076}  # box side L [m] per bed size
TILED = {80000: (2, 2), 320000: (4, 4), 1000000: (10, 5)}  # beds tiled kx × ky from the 20k bed
HEIGHT = 0.06                      # box height [m]
RADII = (0.0008, 0.0009, 0.0010, 0.0011, 0.0012)  # equal mass fractions
MATERIAL = dict(density=2650.0, young=5e7, poisson=0.25, friction=0.5, restitution=0.5, stiffness_ratio=4.0)
DT = 2e-6                          # the timed work's step [s]
GRAVITY = -9.81
SKIN = 2e-4
SEED = 86028121
INSERT_MARGIN = 0.0013             # insertion region: [margin, L − margin]² × [margin, H − margin]
SETTLE = ((12000, 5e-6, -100.0), (3000, 2e-6, GRAVITY))  # (steps, dt [s], gravity z [m/s²]) per stage
SETTLE_STEPS = sum(stage[0] for stage in SETTLE)
FORMAT_VERSION = 1


def spec(n):
    """Everything the bed of ``n`` spheres depends on (recorded as ``bed_n.json``)."""
    return {"format": FORMAT_VERSION, "n": n, "box": [BOX[n], BOX[n], HEIGHT], "radii": list(RADII),
            "counts": counts(n).tolist(), "material": MATERIAL, "skin": SKIN, "seed": SEED,
            "insert_margin": INSERT_MARGIN, "settle": [list(stage) for stage in SETTLE]}


def counts(n):
    """Number of spheres of each radius: equal solid mass per radius, largest-remainder rounding."""
    share = np.asarray(RADII) ** -3.0
    exact = n * share / share.sum()
    out = np.floor(exact).astype(np.int64)
    out[np.argsort(out - exact, kind="stable")[: n - out.sum()]] += 1
    return out


def liggghts_contacts(side_x, side_y, height):
    """The W1 contact law and the six walls of the box [0, side_x] × [0, side_y] × [0, height] as
    LIGGGHTS 3.8 commands (``hooke/stiffness``: k_n = 1e5 N/m, k_t = k_n / 4, the normal dashpot
    ``gamman``, μ; the sides may be LIGGGHTS variables such as ``${L}``)."""
    m = MATERIAL
    lines = ["fix m1 all property/global kn peratomtypepair 1 1.0e5",
             "fix m2 all property/global kt peratomtypepair 1 2.5e4",
             "fix m3 all property/global gamman peratomtypepair 1 2.0e4",
             "fix m4 all property/global gammat peratomtypepair 1 0.0",
             f"fix m5 all property/global coefficientFriction peratomtypepair 1 {m['friction']:g}",
             "fix m6 all property/global youngsModulus peratomtype 1.0e8",
             f"fix m7 all property/global poissonsRatio peratomtype {m['poisson']:g}",
             f"fix m8 all property/global coefficientRestitution peratomtypepair 1 {m['restitution']:g}",
             "",
             "pair_style gran model hooke/stiffness tangential history limitForce on tangential_damping off",
             "pair_coeff * *",
             ""]
    for name, axis, at in (("xw1", "x", "0.0"), ("xw2", "x", side_x), ("yw1", "y", "0.0"), ("yw2", "y", side_y),
                           ("zw1", "z", "0.0"), ("zw2", "z", height)):
        at = f"{at:g}" if isinstance(at, float) else at
        lines.append(f"fix {name} all wall/gran model hooke/stiffness tangential history primitive type 1 "
                     f"{axis}plane {at} &\n    limitForce on tangential_damping off")
    return "\n".join(lines)


def materials():
    from de_domain import Material

    return [Material(**MATERIAL)]


def make_engine(pos, radius, L, dt=DT, gravity=GRAVITY, vel=None, angvel=None, comm=None):
    """The W1 engine: the spheres in the box [0, L]² × [0, HEIGHT] (``L`` a pair: [0, Lx] ×
    [0, Ly] × [0, HEIGHT]) of six plane walls (over the ranks of ``comm``, if given)."""
    from de_domain import Engine, Particles, PlaneWall

    Lx, Ly = (L, L) if np.isscalar(L) else L

    mat = materials()
    p = Particles.from_spheres(pos, radius, materials=mat, velocities=vel)
    if angvel is not None:
        p.angvel[:] = angvel
    walls = [PlaneWall((0, 0, 0), (1, 0, 0)), PlaneWall((Lx, 0, 0), (-1, 0, 0)),
             PlaneWall((0, 0, 0), (0, 1, 0)), PlaneWall((0, Ly, 0), (0, -1, 0)),
             PlaneWall((0, 0, 0), (0, 0, 1)), PlaneWall((0, 0, HEIGHT), (0, 0, -1))]
    return Engine(p, mat, walls=walls, gravity=(0.0, 0.0, gravity), dt=dt, skin=SKIN, comm=comm)


def settle(n, log=None):
    """Insert and settle the W1 bed of ``n`` spheres (module docstring) → (pos, radius, L)."""
    from de_domain.packing import random_cloud

    L = BOX[n]
    radius = np.repeat(np.asarray(RADII), counts(n))
    m = INSERT_MARGIN
    pos, radius = random_cloud(radius, (m, m, m), (L - m, L - m, HEIGHT - m), seed=SEED)
    vel = angvel = None
    for steps, dt, gravity in SETTLE:
        engine = make_engine(pos, radius, L, dt=dt, gravity=gravity, vel=vel, angvel=angvel)
        t0 = time.perf_counter()
        engine.run(steps)
        p = engine.particles
        pos, vel, angvel = p.pos.copy(), p.vel.copy(), p.angvel.copy()
        if log is not None:
            log(f"  {steps} steps of {dt:g} s at g = {gravity:g} m/s^2: {time.perf_counter() - t0:.1f} s, "
                f"bed top {np.max(pos[:, 2] + radius) * 1e3:.2f} mm, max |v| {np.abs(vel).max():.3g} m/s")
    if not np.all((pos > 0.0) & (pos < np.array([L, L, HEIGHT]))):
        raise RuntimeError(f"W1 bed of {n}: spheres left the box while settling")
    return pos, radius, L


def write_dump(path, pos, radius, L, timestep=SETTLE_STEPS):
    """LIGGGHTS dump of one snapshot: ``id type radius x y z`` (type 1), box [0, L]² × [0, HEIGHT]."""
    rows = "".join(f"{i + 1} 1 {r:.9g} {x:.9g} {y:.9g} {z:.9g}\n"
                   for i, (r, (x, y, z)) in enumerate(zip(radius.tolist(), pos.tolist(), strict=True)))
    header = (f"ITEM: TIMESTEP\n{timestep}\nITEM: NUMBER OF ATOMS\n{len(radius)}\nITEM: BOX BOUNDS ff ff ff\n"
              f"0 {L:g}\n0 {L:g}\n0 {HEIGHT:g}\nITEM: ATOMS id type radius x y z\n")
    Path(path).write_text(header + rows)


def load_dump(path):
    """(pos, radius, L) of a bed dump: the spheres as any packing file
    (``de_domain.packing.load_packing``), L from the dump's x box bounds."""
    from de_domain.packing import load_packing
    pos, radius = load_packing(path)
    L = float(Path(path).read_text().split("\n", 6)[5].split()[1])
    return pos, radius, L


def shown(path):
    """``path`` relative to the repository when inside it (for messages)."""
    path = Path(path).resolve()
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def bed_file(n, force=False, log=print):
    """Path of the cached W1 bed of ``n`` (5000 or 20000) spheres, made first if missing or stale.

    The settle runs in a child process whose de_domain kernels all come from Numba's on-disk cache: a
    first child compiles them on a small bed (``--warm-up``), a second settles (``--settle``) and is run
    again if it still had to compile anything. (A process that compiles the kernels itself was seen to
    produce a different, equally valid, bed than one that loads them from the cache: with this the bytes
    of the bed do not depend on the state of the cache.)"""
    if n not in BOX:
        raise ValueError(f"no W1 bed of {n} spheres ({', '.join(map(str, BOX))})")
    path, record = OUT / f"bed_{n}.dump", OUT / f"bed_{n}.json"
    want = json.dumps(spec(n), indent=1, sort_keys=True) + "\n"
    if not force and path.exists() and record.exists() and record.read_text() == want:
        return path
    OUT.mkdir(parents=True, exist_ok=True)
    if log is not None:
        log(f"# making the W1 bed of {n} spheres into {shown(path)} (once; benchmarks/beds.py)")
    t0 = time.perf_counter()
    record.unlink(missing_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    import de_domain

    child = [sys.executable, str(Path(__file__).resolve()), "--de-domain", str(Path(de_domain.__file__).parents[1])]
    output = None if log is not None else subprocess.DEVNULL
    sys.stdout.flush()
    subprocess.run(child + ["--warm-up"], check=True, stdout=output)
    for attempt in range(3):
        rc = subprocess.run(child + ["--settle", str(n), str(tmp)], stdout=output).returncode
        if rc not in (0, RECOMPILED):
            tmp.unlink(missing_ok=True)
            raise RuntimeError(f"making the W1 bed of {n} spheres failed (exit status {rc}, see above)")
        if rc == 0:
            break
        if log is not None:
            log("  (that process compiled kernels itself" + (": settling again, all from the cache)" if attempt < 2
                                                            else "; kept: the Numba cache does not seem to work)"))
    os.replace(tmp, path)
    record.write_text(want)
    if log is not None:
        log(f"# W1 bed of {n} spheres made in {time.perf_counter() - t0:.1f} s")
    return path


RECOMPILED = 3  # exit status of ``--settle`` (bed written) when a de_domain kernel was compiled in that process


def _fresh_compilations():
    """How many de_domain kernels with an on-disk cache were compiled in this process (not loaded)."""
    from numba.core.registry import CPUDispatcher

    misses = 0
    for name, module in list(sys.modules.items()):
        if name == "de_domain" or name.startswith("de_domain."):
            for obj in vars(module).values():
                if isinstance(obj, CPUDispatcher) and obj.stats.cache_path is not None:
                    misses += sum(obj.stats.cache_misses.values())
    return misses


def _warm_up():
    """Compile (or load) every kernel the settle uses, on 100 spheres and a few steps per stage."""
    from de_domain.packing import random_cloud

    L, m = 0.012, INSERT_MARGIN
    pos, radius = random_cloud(np.repeat(np.asarray(RADII), 20), (m, m, m), (L - m, L - m, HEIGHT - m), seed=SEED)
    for steps, dt, gravity in SETTLE:
        engine = make_engine(pos, radius, L, dt=dt, gravity=gravity)
        engine.run(1)
        engine.run(steps // 100)


def _settle_to(n, path):
    pos, radius, L = settle(n, log=lambda text: print(text, flush=True))
    write_dump(path, pos, radius, L)
    return RECOMPILED if _fresh_compilations() else 0


def bed(n, log=print):
    """(pos, radius, L) of the W1 bed with n = 5000, 20000, 80000, 320000 or 1,000,000 (the 20k bed tiled
    2 × 2, 4 × 4 or 10 × 5: copies shifted by L in x and y, walls only on the outer faces, so the copies
    touch along the former inner walls). ``L``: the box side, or (Lx, Ly) for a bed that is not square."""
    if n in TILED:
        pos, radius, L = load_dump(bed_file(20000, log=log))
        kx, ky = TILED[n]
        tiles = [pos + np.array([ix * L, iy * L, 0.0]) for ix in range(kx) for iy in range(ky)]
        return np.concatenate(tiles), np.tile(radius, kx * ky), (kx * L if kx == ky else (kx * L, ky * L))
    if n not in BOX:
        raise ValueError(f"no W1 bed of {n} spheres ({', '.join(str(k) for k in sorted([*BOX, *TILED]))})")
    return load_dump(bed_file(n, log=log))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="The beds are also made on demand by dem_throughput.py and compare_peers.py.")
    ap.add_argument("--sizes", type=int, nargs="+", default=sorted(BOX), choices=sorted(BOX),
                    help="bed sizes (default: %(default)s)")
    ap.add_argument("--force", action="store_true", help="make the beds again even if cached")
    ap.add_argument("--de-domain", help=argparse.SUPPRESS)  # the child processes of bed_file()
    ap.add_argument("--warm-up", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--settle", nargs=2, metavar=("N", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.de_domain:
        sys.path.insert(0, args.de_domain)
    if args.warm_up:
        return _warm_up()
    if args.settle:
        sys.exit(_settle_to(int(args.settle[0]), args.settle[1]))
    for n in args.sizes:
        print(bed_file(n, force=args.force))


if __name__ == "__main__":
    main()
