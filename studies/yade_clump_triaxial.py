"""A triaxial test of clumped grains here and in YADE 2023.02a, side by side (issue 40 item 3).

One specimen of two-sphere rods (aspect ratio 1.5; 1.6–2.4 mm equal-volume diameters, e = 0.62
by radius expansion, a 20 mm cube) is generated here (``cosim run``, kind ``triaxial``) and
tested twice from the same grains: here, and in YADE from the exported ``specimen.npz`` (every
clump's members, ``O.bodies.appendClumped``). Both consolidate isotropically to σ₃ = 100 kPa
between six frictionless walls and compress axially at the same strain rate to ε₁ = 20 %,
the lateral walls holding σ₃ (here: the project's servo; YADE: ``TriaxialStressController``,
stressMask 3).

The same contact model on both sides: linear springs with Coulomb friction and no contact
dashpot (YADE's ``Law2_ScGeom_FrictPhys_CundallStrack``; here ``restitution = 1``). YADE's
``FrictPhys`` takes k_n = E r* where this project takes 2 E r* (docs/design.md §2): YADE's
``young`` is twice ours; its ``poisson`` is k_t/k_n = 1/κ. Local damping 0.3 on both (YADE's
``NewtonIntegrator(damping=0.3)``), gravity on both, the same time step (ours). YADE computes a
clump's mass and inertia from its members on a grid (``discretization``); the union's volume
differs from the exact one by < 0.5 %.

Reported for both: φ_peak = asin(max (σ₁ − σ₃)/(σ₁ + σ₃)) and φ_cs from the mean σ₁ and σ₃
over the last 20 % of ε₁ (the triaxial kind's definitions), ε_v, the wall-clock of the test
(consolidation and compression, one core each: indicative only, the runs are not interleaved); the curves in
``docs/yade_clump_triaxial.png``; the table in ``runs/out/yade_clump_triaxial/table.md``.
Needs the Debian package ``yade``.

    python studies/yade_clump_triaxial.py [--seeds 1 2 3] [--aspect 1.5]
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cosim.specimen import read_specimen  # noqa: E402
from de_domain.clumps import ClumpTemplate  # noqa: E402

OUT = ROOT / "runs" / "out" / "yade_clump_triaxial"
PNG = ROOT / "docs" / "yade_clump_triaxial.png"
YOUNG, KAPPA, FRICTION, DENSITY, DAMPING = 5.0e7, 1.5, 0.5, 2650.0, 0.3
SIGMA_3, STRAIN, SIZE, RESIDUAL = 100e3, 0.20, 0.02, 0.2

CASE = """\
[case]
name = "yade_pair"
kind = "triaxial"
seed = {seed}

[time]
safety_factor = 0.3

[output]
vtk = false
progress_interval = 60.0

[dem]
local_damping = {damping}

[[dem.materials]]
name = "sand"
density = {density}
young = {young}
friction = {friction}
stiffness_ratio = {kappa}
restitution = 1.0            # no contact dashpot: YADE's CundallStrack law has none

[[dem.materials]]
name = "side_wall"
density = 7480.0
young = {young}
friction = 0.0
stiffness_ratio = {kappa}
restitution = 1.0

[[dem.materials]]
name = "plate"
density = 7480.0
young = {young}
friction = 0.8

[specimen]
grains = "clumps"
method = "radius_expansion"
sieve_diameters = [1.6e-3, 2.4e-3]
sieve_passing = [0.0, 1.0]
void_ratio = 0.62
deposition_friction = 0.1

[triaxial]
size = {size}
cell_pressure = {sigma_3}
axial_strain = {strain}
residual_fraction = {residual}
rows = 100

[[dem.clumps]]   # two equal spheres, length / width = {aspect}
members = [{members}]
"""

# YADE side (run with ``yade -j1 -x``); @NAME@ filled in by yade(). YADE's triaxial
# controller compresses along its y axis: a point (x, y, z) here is (y, z, x) there (a rotation),
# gravity along -y.
YADE_SCRIPT = """\
# Written by studies/yade_clump_triaxial.py: the specimen of the run beside it, in YADE.
import math, time
grain = O.materials.append(FrictMat(young=@YOUNG_YADE@, poisson=@POISSON@, frictionAngle=math.atan(@FRICTION@),
                                    density=@DENSITY@))
side = O.materials.append(FrictMat(young=@YOUNG_YADE@, poisson=@POISSON@, frictionAngle=0.0, density=7480.0))
O.bodies.append(aabbWalls([(0, 0, 0), (@SIZE@, @HEIGHT@, @SIZE@)], thickness=0, material=side))
clumps = {}
for line in open('clumps.txt'):
    c, x, y, z, r = line.split()
    clumps.setdefault(int(c), []).append(((float(y), float(z), float(x)), float(r)))
for c in sorted(clumps):
    O.bodies.appendClumped([sphere(p, r, material=grain) for p, r in clumps[c]], discretization=@GRID@)
triax = TriaxialStressController(thickness=0, stressMask=7, internalCompaction=False,
                                 goal1=-@SIGMA_3@, goal2=-@SIGMA_3@, goal3=-@SIGMA_3@)
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb()]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom()],
                    [Ip2_FrictMat_FrictMat_FrictPhys()],
                    [Law2_ScGeom_FrictPhys_CundallStrack()]),
    triax,
    NewtonIntegrator(damping=@DAMPING@, gravity=(0, -9.81, 0)),
]
O.dt = @DT@


def stresses():
    \"\"\"(sigma_axial, sigma_x, sigma_y) here: YADE's y (top), z (front) and x (right) walls; compression > 0.\"\"\"
    return (-triax.stress(triax.wall_top_id)[1], -triax.stress(triax.wall_front_id)[2],
            -triax.stress(triax.wall_right_id)[0])


def box():
    \"\"\"(height, width x, width y) here from YADE's walls.\"\"\"
    p = lambda w: O.bodies[getattr(triax, 'wall_%s_id' % w)].state.pos
    return p('top')[1] - p('bottom')[1], p('front')[2] - p('back')[2], p('right')[0] - p('left')[0]


t0 = time.time()
while True:  # isotropic consolidation: every wall within 1 % of sigma_3, unbalanced force < 0.02
    O.run(200, True)
    if max(abs(s - @SIGMA_3@) for s in stresses()) < 0.01 * @SIGMA_3@ and unbalancedForce() < 0.02:
        break
consolidated = O.iter
h0, a0, b0 = box()
triax.stressMask = 5  # the lateral walls hold sigma_3; the top moves at the strain rate
triax.goal2 = -@STRAIN_RATE@
rows = [('axial_strain', 'volumetric_strain', 'sigma_1', 'sigma_x', 'sigma_y', 'step'),
        (0.0, 0.0) + stresses() + (O.iter,)]
step_rows = max(1, int(@STRAIN@ / @STRAIN_RATE@ / O.dt / 100))
while True:
    O.run(step_rows, True)
    h, a, b = box()
    e1 = (h0 - h) / h0
    rows.append((e1, 1.0 - h * a * b / (h0 * a0 * b0)) + stresses() + (O.iter,))
    if e1 >= @STRAIN@:
        break
with open('yade_series.csv', 'w') as f:
    f.write('\\n'.join(','.join(str(v) for v in r) for r in rows) + '\\n')
with open('yade_run.json', 'w') as f:
    f.write('{"consolidation_steps": %d, "steps": %d, "wall_clock_s": %.1f, "clumps": %d, "mass": %.9e}'
            % (consolidated, O.iter, time.time() - t0, len(clumps), sum(b.state.mass for b in O.bodies if b.isClump)))
"""


def rod_members(aspect):
    rod = ClumpTemplate.line(2, aspect)
    return ", ".join(f"[{x:.6g}, 0.0, 0.0, 1.0]" for x in rod.centres[:, 0])


def case_text(seed, aspect):
    return CASE.format(seed=seed, damping=DAMPING, density=DENSITY, young=YOUNG, friction=FRICTION, kappa=KAPPA,
                       size=SIZE, sigma_3=SIGMA_3, strain=STRAIN, residual=RESIDUAL, aspect=aspect,
                       members=rod_members(aspect))


def ours(folder, seed, aspect):
    """This project's run (made unless its summary exists): (summary, series rows)."""
    summary = folder / "summary.json"
    if not summary.exists():
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "case.toml").write_text(case_text(seed, aspect))
        subprocess.run([str(Path(sys.executable).parent / "cosim"), "run", str(folder / "case.toml"), "--out",
                        str(folder)], check=True)
    with open(folder / "series.csv") as f:
        rows = list(csv.DictReader(f))
    return json.loads(summary.read_text()), rows


def yade(folder, ours_folder, summary):
    """YADE's run of the same specimen (made unless its series exists): (rows, run facts)."""
    series = folder / "yade_series.csv"
    if not series.exists():
        folder.mkdir(parents=True, exist_ok=True)
        specimen = read_specimen(ours_folder / "specimen.npz")
        positions, radii = specimen.clumps.members()
        counts = np.array([t.count for t in specimen.clumps.templates])[specimen.clumps.template_of]
        clump = np.repeat(np.arange(specimen.clumps.count), counts)
        np.savetxt(folder / "clumps.txt", np.column_stack([clump, positions, radii]), fmt="%d %.17g %.17g %.17g %.17g")
        values = {"YOUNG_YADE": 2.0 * YOUNG, "POISSON": 1.0 / KAPPA, "FRICTION": FRICTION, "DENSITY": DENSITY,
                  "SIZE": SIZE, "HEIGHT": specimen.height, "GRID": 40, "SIGMA_3": SIGMA_3, "DAMPING": DAMPING,
                  "DT": summary["dt"], "STRAIN_RATE": summary["strain_rate"], "STRAIN": STRAIN}
        script = YADE_SCRIPT
        for key, value in values.items():
            script = script.replace(f"@{key}@", repr(value))
        assert "@" not in script
        (folder / "yade_triax.py").write_text(script)
        subprocess.run(["yade", "-j1", "-x", "yade_triax.py"], cwd=folder, check=True, capture_output=True)
    with open(series) as f:
        rows = list(csv.DictReader(f))
    return rows, json.loads((folder / "yade_run.json").read_text())


def angles(strain, sigma_1, sigma_3):
    """(φ_peak, φ_cs) in degrees: asin of the largest mobilised (σ₁ − σ₃)/(σ₁ + σ₃), and of the one
    of the mean σ₁ and σ₃ over the last RESIDUAL of the axial strain (the triaxial kind's)."""
    peak = math.degrees(math.asin(np.max((sigma_1 - sigma_3) / (sigma_1 + sigma_3))))
    last = strain >= (1.0 - RESIDUAL) * strain[-1]
    s1, s3 = np.mean(sigma_1[last]), np.mean(sigma_3[last])
    return peak, math.degrees(math.asin((s1 - s3) / (s1 + s3)))


def curves(rows):
    """(ε₁, ε_v, σ₁, σ₃) arrays of a series (either side's columns)."""
    get = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    sigma_3 = 0.5 * (get("sigma_x") + get("sigma_y"))
    return get("axial_strain"), get("volumetric_strain"), get("sigma_1"), sigma_3


def compare(seed, aspect):
    folder = OUT / f"seed{seed}"
    summary, our_rows = ours(folder / "ours", seed, aspect)
    yade_rows, facts = yade(folder / "yade", folder / "ours", summary)
    row = {"seed": seed, "clumps": summary["grains"], "spheres": summary["spheres"], "dt": summary["dt"],
           "e_consolidated": summary["void_ratio_consolidated"]}
    test_clock = summary["wall_clock_consolidation_s"] + summary["wall_clock_compression_s"]
    for side, rows, clock in (("ours", our_rows, test_clock), ("yade", yade_rows, facts["wall_clock_s"])):
        strain, volumetric, s1, s3 = curves(rows)
        peak, cs = angles(strain, s1, s3)
        row.update({f"{side}_phi_peak": peak, f"{side}_phi_cs": cs, f"{side}_eps_v_end": volumetric[-1],
                    f"{side}_wall_clock_s": clock, f"{side}_curves": (strain, volumetric, s1, s3)})
    union = DENSITY * float(np.sum(read_specimen(folder / "ours" / "specimen.npz").clumps.volumes()))
    row["yade_mass_ratio"] = facts["mass"] / union  # YADE's gridded clump masses against the exact unions
    return row


def write_table(rows):
    lines = ["| packing | clumps (spheres) | e consolidated | φ_peak here / YADE | φ_cs here / YADE | "
             "ε_v at the end here / YADE | consolidation + compression, wall-clock here / YADE (1 core) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| seed {r['seed']} | {r['clumps']} ({r['spheres']}) | {r['e_consolidated']:.3f} | "
                     f"{r['ours_phi_peak']:.1f}° / {r['yade_phi_peak']:.1f}° | {r['ours_phi_cs']:.1f}° / "
                     f"{r['yade_phi_cs']:.1f}° | {100 * r['ours_eps_v_end']:.1f} / {100 * r['yade_eps_v_end']:.1f} % | "
                     f"{r['ours_wall_clock_s']:.0f} / {r['yade_wall_clock_s']:.0f} s |")
    for key in ("phi_peak", "phi_cs"):
        d = np.array([r[f"ours_{key}"] - r[f"yade_{key}"] for r in rows])
        lines.append(f"\n{key}: here − YADE = {', '.join(f'{v:+.2f}°' for v in d)} (mean {d.mean():+.2f}°)")
    lines.append("\nYADE's clump masses / the exact unions': " + ", ".join(f"{r['yade_mass_ratio']:.4f}" for r in rows))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def plot(rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
    for r, colour in zip(rows, ("tab:blue", "tab:orange", "tab:green", "tab:red"), strict=False):
        for side, style in (("ours", "-"), ("yade", "--")):
            strain, volumetric, s1, s3 = r[f"{side}_curves"]
            label = f"seed {r['seed']}, {'this project' if side == 'ours' else 'YADE 2023.02a'}"
            top.plot(100 * strain, (s1 - s3) / (s1 + s3), style, color=colour, label=label)
            bottom.plot(100 * strain, 100 * volumetric, style, color=colour)
    top.set_ylabel("sin φ = (σ₁ − σ₃)/(σ₁ + σ₃)")
    top.legend(fontsize=8)
    top.set_title("Rods of aspect 1.5, triaxial, σ₃ = 100 kPa: one specimen, two codes")
    bottom.set_ylabel("ε_v [%] (contraction > 0)")
    bottom.set_xlabel("ε₁ [%]")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(PNG, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--aspect", type=float, default=1.5)
    args = parser.parse_args()
    if shutil.which("yade") is None:
        sys.exit("yade_clump_triaxial: 'yade' is not installed (apt-get install yade: YADE 2023.02a on Debian 12)")
    rows = [compare(seed, args.aspect) for seed in args.seeds]
    write_table(rows)
    plot(rows)


if __name__ == "__main__":
    main()
