"""A direct shear test driven step by step from Python, on a tiny specimen.

``cosim run`` does all of this from a case file (kind ``direct_shear``); here every stage
is a visible call, so you can change one (another servo law, a different shear path,
your own measurements) without touching the rest:

1. materials and a sieve curve; grains of total solid volume L² h / (1 + e);
2. the specimen, by multi-layer under-compaction (``de_domain.deposition``);
3. the split shear box around it (``cosim.apps.direct_shear.ShearTest``: two facet-mesh
   halves, a rough bottom plane, a servo-controlled top plate);
4. consolidation to σ_n;
5. shearing: the upper half moves at the velocity of the inertial number I, the servo
   holds σ_n, and we record τ, σ_n, vertical displacement and void ratios ourselves;
6. the summary (peak and residual friction angles) and the standard PNG plots.

The box is 20 × 20 × 10 mm with ~600 grains of 1.6–2.4 mm, sheared by 1.5 mm: a toy
(five grains over the height is all boundary layer), sized to run in well under a minute.
The real-size cases are ``runs/direct_shear_*.toml``.

Run::

    .venv/bin/python examples/direct_shear_steps.py [OUT_DIR]

``OUT_DIR`` (default: a new temporary folder) receives ``series.csv``, ``specimen.npz`` and
``shear_stress.png``, ``vertical_displacement.png``, ``void_ratio.png``. The last line
printed is ``servo held sigma_n within X % of 100 kPa`` (the script fails with an
AssertionError if X > 3).
"""
import csv
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.apps.direct_shear import ShearTest, materials
from cosim.case.schema import Case
from cosim.lab.shear_box import inertial_number, velocity_for_inertial_number
from cosim.lab.shear_report import plot_run, summarize
from de_domain.deposition import (
    GenerationSettings,
    diameters_for_solid_volume,
    generate,
    solid_volume_for,
    specimen_curve,
)
from de_domain.packing import save_packing

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="direct_shear_steps_"))
out.mkdir(parents=True, exist_ok=True)
t_start = time.perf_counter()

# 1. The test's parameters, as the validated case object ShearTest reads (the same keys as
#    the [dem] and [direct_shear] tables of a case file; `cosim schema` lists them all).
L, H = 0.02, 0.01          # box side and specimen height [m]
SIGMA_N = 100e3            # normal stress [Pa]
SHEAR_DISTANCE = 1.5e-3    # [m]
case = Case.model_validate({
    "case": {"name": "direct_shear_steps", "kind": "direct_shear", "seed": 11},
    "time": {"safety_factor": 0.3},
    "dem": {"local_damping": 0.3, "materials": [
        {"name": "sand", "density": 2650.0, "young": 5e7, "friction": 0.5, "stiffness_ratio": 1.5},
        {"name": "side_wall", "density": 7480.0, "young": 5e7, "friction": 0.0},   # frictionless box
        {"name": "plate", "density": 7480.0, "young": 5e7, "friction": 0.8}]},      # rough plates
    "direct_shear": {"box_length": L, "sample_height": H, "normal_stress": SIGMA_N,
                     "shear_distance": SHEAR_DISTANCE, "inertial_number": 1.5e-3, "band_thickness": 4e-3},
})
ds = case.direct_shear
mats, sand, side_wall, plate = materials(case)   # de_domain Materials and the ids of the three roles

# 2. The specimen: a uniform 1.6-2.4 mm sieve curve, enough grains for e = 0.70 in L x L x H,
#    deposited in layers and pushed down by a plate (low friction while compacting, mass scaling).
curve = specimen_curve(diameters=[1.6e-3, 2.4e-3], passing=[0.0, 1.0])
rng = np.random.default_rng(case.case.seed)
diameters = diameters_for_solid_volume(curve, solid_volume_for(0.70, L * L * H), rng)
settings = GenerationSettings(box_length=L, height=H, void_ratio=0.70, sand=mats[sand], wall=mats[side_wall],
                              plate=mats[plate], friction=0.3, seed=case.case.seed)
specimen = generate("under_compaction", diameters, settings, log=lambda text: print(f"  {text}"))
print(f"specimen: {len(specimen.radii)} grains, h = {specimen.height * 1e3:.3f} mm, e = {specimen.void_ratio:.4f} "
      f"(target 0.70), {time.perf_counter() - t_start:.0f} s")
save_packing(out / "specimen.npz", specimen.positions, specimen.radii, **specimen.metadata())

# 3. The shear box around the specimen; real densities from here on.
test = ShearTest.build(case, specimen)
engine = test.engine   # walls [bottom, top plate], facets [lower half, upper half]
print(f"shear box: {engine.particles.n} grains, d50 = {test.d50 * 1e3:.2f} mm, dt = {engine.dt:.3e} s")

# 4. Consolidation: the servo moves the top plate until sigma_n is reached and the packing is quiet.
test.consolidate(log=lambda text: print(f"  {text}"))
z0, e0 = float(test.plate.point[2]), test.void_ratio()

# 5. Shearing, one servo update (ds.servo_interval DEM steps) at a time. The velocity ramps up
#    over ramp_distance; each CSV row averages tau and sigma_n over the updates since the last row.
v = velocity_for_inertial_number(ds.inertial_number, specimen.height, test.d50, test.density, SIGMA_N)
print(f"shearing at v = {v:.4g} m/s (I = {inertial_number(v, specimen.height, test.d50, test.density, SIGMA_N):.1e}) "
      f"to {SHEAR_DISTANCE * 1e3:.1f} mm")
columns = ["shear_displacement", "shear_stress", "normal_stress", "vertical_displacement", "void_ratio",
           "void_ratio_sphere_045h", "void_ratio_sphere_020h", "lw_normal_stress", "lw_shear_stress"]
rows, sums, n, next_row = [], np.zeros(2), 0, 0.0
while test.displacement < SHEAR_DISTANCE:
    test.shear_velocity = v * min(1.0, max(0.02, test.displacement / ds.ramp_distance))
    test.step(SIGMA_N)                                   # servo law + ds.servo_interval DEM steps
    sums += (test.shear_stress(), test.normal_stress())
    n += 1
    if test.displacement >= next_row or test.displacement >= SHEAR_DISTANCE:
        lw_zz, lw_xz = test.love_weber_slab()            # Love-Weber stress of a slab at the split plane
        rows.append([test.displacement, sums[0] / n, sums[1] / n, float(test.plate.point[2]) - z0,
                     test.void_ratio(), *test.sphere_void_ratios(), lw_zz, lw_xz])
        sums, n, next_row = np.zeros(2), 0, next_row + SHEAR_DISTANCE / 20
        if len(rows) % 5 == 1:
            d, tau, sigma, dz = rows[-1][:4]
            print(f"  delta {d * 1e3:5.2f} mm  tau {tau / 1e3:6.1f} kPa  sigma_n {sigma / 1e3:6.1f} kPa  "
                  f"dz {dz * 1e3:+.3f} mm  e {rows[-1][4]:.4f}")
with open(out / "series.csv", "w", newline="") as f:
    writer = csv.writer(f)
    writer.writerow(columns)
    writer.writerows(rows)

# 6. Summary and plots, with the same post-processing as `cosim run`.
series = {k: np.array([r[c] for r in rows]) for c, k in enumerate(columns)}
s = summarize(series["shear_displacement"], series["shear_stress"], series["normal_stress"],
              series["vertical_displacement"], ds.residual_fraction)
plot_run(series, out, f"direct shear, sigma_n = {SIGMA_N / 1e3:.0f} kPa")
after_ramp = series["shear_displacement"] > ds.ramp_distance
servo_error = float(np.max(np.abs(series["normal_stress"][after_ramp] / SIGMA_N - 1.0)))
lw_ratio = float(np.mean(series["lw_normal_stress"][after_ramp]) / np.mean(series["normal_stress"][after_ramp]))
print(f"e consolidated {e0:.4f}, end {series['void_ratio'][-1]:.4f}; peak phi {s['peak_friction_angle_deg']:.1f} deg "
      f"at {s['peak_shear_displacement'] * 1e3:.2f} mm, residual phi {s['residual_friction_angle_deg']:.1f} deg; "
      f"{s['volume_change']} ({s['vertical_displacement_end'] * 1e3:+.3f} mm); Love-Weber sigma_zz / sigma_n "
      f"{lw_ratio:.2f}")
print(f"outputs in {out}; wall clock {time.perf_counter() - t_start:.0f} s")
assert 10.0 < s["peak_friction_angle_deg"] < 50.0 and math.isfinite(s["residual_friction_angle_deg"])
print(f"servo held sigma_n within {100 * servo_error:.1f} % of {SIGMA_N / 1e3:.0f} kPa")
assert servo_error < 0.03
