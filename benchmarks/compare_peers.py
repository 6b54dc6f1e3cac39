"""de_domain against LIGGGHTS 3.8 and YADE on the W1 settled-bed work, side by side.

    .venv/bin/python benchmarks/compare_peers.py                   # 5k and 20k beds
    .venv/bin/python benchmarks/compare_peers.py --sizes 20000 --repeats 3
    .venv/bin/python benchmarks/compare_peers.py --sizes 5000 --peers liggghts

Needs the Debian packages ``liggghts`` and ``yade`` (``make bench-peers`` installs
them). Everything the peers read is made here, from the same bed and parameters:
the W1 beds ``bed_N.dump`` (settled by de_domain, ``benchmarks/beds.py``, made once
and cached) and, written on every run beside them into ``benchmarks/out/w1/``, the
LIGGGHTS deck ``in.bed`` and the YADE script ``yade_bed.py``. Every peer runs via
subprocess in a temporary directory holding copies of those files:

* LIGGGHTS, 1 and 2 MPI ranks: ``in.bed`` reads ``bed_N.dump`` (``read_dump``), sets
  ρ = 2650 kg/m³, six wall/gran planes, hooke/stiffness k_n = 1e5 N/m,
  k_t = 2.5e4 N/m, μ = 0.5, gravity −9.81 z, Δt = 2e-6 s, neighbor skin 0.2 mm; one
  untimed step, then ``run 2000``; the rate is N·2000 / (its last "Loop time").
  By hand: ``cd benchmarks/out/w1 && liggghts -echo none -var N 20000 -var L 0.076
  -in in.bed`` (2 ranks: ``mpirun --allow-run-as-root -np 2 liggghts ...``).
* YADE ``-j1`` / ``-j2``: ``yade -x yade_bed.py N 2000`` loads ``bed_N.dump``
  (FrictMat young = 1e8 gives k_n ≈ 1e5 N/m at r = 1 mm, k_t/k_n = poisson = 0.25;
  NewtonIntegrator damping 0.2), runs 1000 steps, then times 2000 (it prints
  particle-steps/s).
* de_domain, 1 and 2 Numba threads: ``dem_throughput.measure`` (the same dump,
  2000 steps after ``SORTED_MIN_STEPS`` untimed ones).

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
import beds  # noqa: E402
import dem_throughput as ours  # noqa: E402
import mpi_launch  # noqa: E402

STEPS = 2000
ENV = mpi_launch.mpi_env(BASE_ENV)  # OpenMPI's run-as-root and oversubscribe permissions where unset

# LIGGGHTS 3.8 deck; @NAME@ is filled in by peer_inputs(), ${N} and ${L} are LIGGGHTS variables.
LIGGGHTS_DECK = """\
# W1 (LIGGGHTS side), written by benchmarks/compare_peers.py: load the de_domain-settled bed
# bed_${N}.dump (benchmarks/beds.py), same walls, stiffness, friction and dt, time a block of steps.
#   liggghts -echo none -var N 20000 -var L 0.076 -in in.bed     (2 ranks: mpirun -np 2 liggghts ...)
# vars: N (spheres), L (box side, m); rate = N * @STEPS@ / (the last "Loop time")
atom_style\tgranular
atom_modify\tmap array
boundary\tf f f
newton\t\toff
communicate\tsingle vel yes
units\t\tsi
region\t\tbox block 0 ${L} 0 ${L} 0 @H@ units box
create_box\t1 box
neighbor\t@SKIN@ bin
neigh_modify\tdelay 0

read_dump\tbed_${N}.dump @TIMESTEP@ x y z radius box no add yes
set\t\tgroup all density @DENSITY@

@CONTACTS@

fix integr all nve/sphere
fix grav all gravity @G@ vector 0.0 0.0 -1.0
compute rke all erotate/sphere
thermo_style custom step atoms ke c_rke
thermo 1000
thermo_modify lost ignore norm no
timestep @DT@
run 1
# timed block
run @STEPS@
"""

# YADE script (run with ``yade -x``); @NAME@ is filled in by peer_inputs().
YADE_SCRIPT = """\
# W1 (YADE side), written by benchmarks/compare_peers.py: load the de_domain-settled bed
# bed_N.dump (benchmarks/beds.py), same stiffness/friction/dt, time a block of steps.
#   yade -j1 -x yade_bed.py 20000 @STEPS@
import sys, time, math
N = int(sys.argv[1]) if len(sys.argv) > 1 else 5000
STEPS = int(sys.argv[2]) if len(sys.argv) > 2 else @STEPS@
lines = open('bed_%d.dump' % N).read().split('\\n')
L = float(lines[5].split()[1]); H = float(lines[7].split()[1])
cols = lines[8].split()[2:]
ir, ix, iy, iz = [cols.index(c) for c in ('radius', 'x', 'y', 'z')]
# young = 1e8 in FrictPhys: k_n = 2 E r1 r2 / (r1 + r2) = 1e5 N/m at r = 1 mm; k_t = poisson * k_n
mat = O.materials.append(FrictMat(young=1e8, poisson=0.25, frictionAngle=math.atan(@FRICTION@), density=@DENSITY@))
for ln in lines[9:]:
    p = ln.split()
    if len(p) < len(cols): continue
    O.bodies.append(sphere((float(p[ix]), float(p[iy]), float(p[iz])), float(p[ir]), material=mat))
for ax, pos in ((0, 0.0), (0, L), (1, 0.0), (1, L), (2, 0.0), (2, H)):
    O.bodies.append(wall(pos, axis=ax, sense=0, material=mat))
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()], verletDist=@SKIN@),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
                    [Ip2_FrictMat_FrictMat_FrictPhys()],
                    [Law2_ScGeom_FrictPhys_CundallStrack()]),
    NewtonIntegrator(damping=0.2, gravity=(0, 0, @G@)),
]
O.dt = @DT@
O.run(1000, True)
t = time.time(); O.run(STEPS, True); dt = time.time() - t
nc = sum(1 for i in O.interactions if i.isReal)
print("YADE N=%d steps=%d wall=%.3f s  particle-steps/s=%.3e  real contacts/particle=%.2f threads=%d"
      % (N, STEPS, dt, N * STEPS / dt, 2.0 * nc / N, O.numThreads))
"""


def _fill(template, **values):
    for key, value in values.items():
        template = template.replace(f"@{key}@", str(value))
    assert "@" not in template, template
    return template


def peer_inputs(sizes):
    """Make (if needed) the beds of ``sizes`` and write the LIGGGHTS deck and the YADE script beside them,
    in ``benchmarks/out/w1``; returns the paths of all of them."""
    beds_ = [beds.bed_file(n) for n in sizes]
    m = beds.MATERIAL
    values = dict(STEPS=STEPS, H=f"{beds.HEIGHT:g}", SKIN=f"{beds.SKIN:g}", TIMESTEP=beds.SETTLE_STEPS,
                  DENSITY=f"{m['density']:g}", FRICTION=f"{m['friction']:g}", POISSON=f"{m['poisson']:g}",
                  RESTITUTION=f"{m['restitution']:g}", DT=f"{beds.DT:g}",
                  CONTACTS=beds.liggghts_contacts("${L}", "${L}", beds.HEIGHT))
    deck, script = beds.OUT / "in.bed", beds.OUT / "yade_bed.py"
    deck.write_text(_fill(LIGGGHTS_DECK, G=f"{-beds.GRAVITY:g}", **values))
    script.write_text(_fill(YADE_SCRIPT, G=f"{beds.GRAVITY:g}", **values))
    return [deck, script] + beds_


def liggghts(workdir, n, ranks):
    cmd = ["liggghts", "-echo", "none", "-var", "N", str(n), "-var", "L", f"{beds.BOX[n]:g}", "-in", "in.bed",
           "-log", f"log.{n}.{ranks}"]
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
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=sorted(beds.BOX), choices=sorted(beds.BOX),
                    help="bed sizes (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per configuration, median (default: %(default)s)")
    ap.add_argument("--peers", nargs="+", default=["liggghts", "yade"], choices=["liggghts", "yade"],
                    help="peer codes to run beside de_domain (default: %(default)s)")
    args = ap.parse_args(argv)
    for exe in args.peers:
        if shutil.which(exe) is None:
            sys.exit(f"compare_peers: '{exe}' is not installed (make bench-peers installs liggghts and yade)")
    from de_domain import threading as dthreading

    inputs = peer_inputs(args.sizes)  # the beds are made here on the first run (once)
    beds.bed_file(5000)  # ours.jit_time's bed
    load0 = os.getloadavg()
    print(f"# W1 peers, {STEPS} timed steps; de_domain threading {dthreading.describe()}")
    print(f"# peer inputs: {beds.shown(beds.OUT)}/ ({', '.join(p.name for p in inputs)})")
    print(f"# load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    ours.jit_time()  # compile / load the cache before timing
    rows = []
    with tempfile.TemporaryDirectory(prefix="w1_peers_") as tmp:
        for path in inputs:
            shutil.copy(path, tmp)
        for n in args.sizes:
            for cores in (1, 2):
                rate = {}
                runs = {"de_domain": lambda n=n, cores=cores: de_domain(n, cores)}
                if "liggghts" in args.peers:
                    runs["LIGGGHTS"] = lambda n=n, cores=cores: liggghts(tmp, n, cores)
                if "yade" in args.peers:
                    runs["YADE"] = lambda n=n, cores=cores: yade(tmp, n, cores)
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
