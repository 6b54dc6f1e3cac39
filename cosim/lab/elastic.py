"""Small-strain elastic constants of a packing (``cosim elastic``): what an FE continuum
standing in for the grains should be given (docs/design.md §7.2).

A cubical specimen of the case's grains (``[specimen]`` generation, ``[dem]`` materials) in
a box of six rigid walls, without gravity:

1. **Isotropic compression** — the walls are frictionless; the three walls x = L_x, y = L_y, z = L_z move (the three
   others stay) until the three wall stresses are within 1 % of the mean stress p and the
   unbalanced force ratio is below 1e-4, confirmed by the stresses averaged over
   ``AVERAGE_STEPS`` steps with the walls held still. Each wall moves by the strain
   Δε = g (σ − p) / M₀ per check (a proportional servo; M₀ = k_n / d is a stiffness
   guess, E of the grain material for the linear law, g = 0.5).
2. **Probe** — the walls stop; the top wall moves down by the axial strain ε (default
   2e-5, well below the contacts' elastic overlap strain δ/d at these stresses, ~1e-4) at
   constant speed, the lateral walls held (a constrained, oedometric increment); the
   specimen relaxes (unbalanced force ratio below 1e-4) and the wall stresses are averaged.
   Then the top wall moves back by the same strain (the unloading increment): an elastic
   response gives the stresses back.
3. **Constants** — from Δσ_zz = M ε and Δσ_xx = Δσ_yy = λ ε, Δσ the mean of the loading and
   the unloading increments (a slow drift of the stresses at rest cancels):

       M = λ + 2G,   G = (M − λ)/2,   K = λ + 2G/3 = (M + 2λ)/3,
       E = 9KG / (3K + G),   ν = λ / (M + λ)

   (linear isotropic elasticity, e.g. Jaeger, Cook & Zimmerman, *Fundamentals of Rock
   Mechanics*, §5.3). The lateral stresses of a granular packing respond to an axial
   increment less than an isotropic solid's would if its fabric is anisotropic; the two
   lateral responses are reported apart so the anisotropy shows.

Stresses are the wall forces over the current wall areas, averaged over ``AVERAGE_STEPS``
steps. Densities are scaled by ``specimen.density_scale`` (static results do not depend on
mass; the step grows by its square root).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cosim.errors import CaseError
from cosim.lab.cubical_box import box_lengths, box_walls, wall_stresses
from cosim.outputs import atomic_write_text, say

SERVO_GAIN = 0.5
STRESS_TOLERANCE = 0.01
PROBE_UNBALANCED_FORCE = 1e-4  # at the end of the compression and before each stress reading of the probe
CHECK_STEPS = 100
AVERAGE_STEPS = 400
PROBE_STEPS = 400
SIDES = 10  # default cube side: this many of the largest grains


def roles(case, case_path):
    """(sand, side wall, plate) material names of a direct_shear or footing case."""
    if case.case.kind == "direct_shear":
        ds = case.direct_shear
        return ds.sand_material, ds.side_wall_material, ds.plate_material
    if case.case.kind == "footing":
        return case.footing.sand_material, case.footing.side_wall_material, case.zone.interface_material
    raise CaseError(case_path, "case.kind", case.case.kind,
                    "cosim elastic measures the grains of a 'direct_shear' or 'footing' case ([dem] and [specimen])")


def averaged_stresses(engine, steps=AVERAGE_STEPS, every=10):
    """Wall stresses averaged over ``steps`` steps (read every ``every``)."""
    total = np.zeros(3)
    for _ in range(steps // every):
        engine.run(every)
        total += wall_stresses(engine)
    return total / (steps // every)


def moving_walls(engine):
    return [engine.walls[k] for k in (1, 3, 5)]


def compress(engine, p, stiffness_guess, log, max_steps):
    """Servo the three moving walls to σ = p (isotropic); returns (steps taken, the wall stresses
    averaged at the end with the walls held still)."""
    from de_domain.diagnostics import unbalanced_force_ratio
    steps = 0
    axes = (0, 1, 2)
    while steps < max_steps:
        sigma = wall_stresses(engine)
        ufr = unbalanced_force_ratio(engine)
        if np.all(np.abs(sigma - p) < STRESS_TOLERANCE * p) and ufr < PROBE_UNBALANCED_FORCE:
            for wall in moving_walls(engine):  # confirm on the walls held still, stresses averaged
                wall.velocity = np.zeros(3)
            steps += AVERAGE_STEPS
            held = averaged_stresses(engine)
            if np.all(np.abs(held - p) < STRESS_TOLERANCE * p):
                break
            sigma = wall_stresses(engine)
        lengths = box_lengths(engine)
        for axis, wall in zip(axes, moving_walls(engine), strict=True):
            strain = SERVO_GAIN * (sigma[axis] - p) / stiffness_guess  # > 0: expand
            speed = strain * lengths[axis] / (CHECK_STEPS * engine.dt)
            wall.velocity = np.eye(3)[axis] * speed
        engine.run(CHECK_STEPS)
        steps += CHECK_STEPS
    for wall in moving_walls(engine):
        wall.velocity = np.zeros(3)
    held = averaged_stresses(engine) if steps >= max_steps else held
    log(f"isotropic compression: sigma = {np.array2string(held, precision=4)} Pa (target {p:.4g} Pa), {steps} steps")
    return steps, held


def probe(engine, strain, log):
    """Axial increment ±``strain`` of the top wall (lateral walls held); returns the stresses
    before, after loading and after unloading (each averaged at rest)."""
    from de_domain.diagnostics import unbalanced_force_ratio
    top = engine.walls[5]

    def settle():
        for _ in range(400):
            engine.run(CHECK_STEPS)
            ufr = unbalanced_force_ratio(engine)
            if ufr < PROBE_UNBALANCED_FORCE:
                break
        log(f"probe: at rest to an unbalanced force ratio {ufr:.2g}")
        return averaged_stresses(engine)

    before = settle()
    out = [before]
    for sign in (-1.0, 1.0):  # down (loading), then back up
        top.velocity = np.array([0.0, 0.0, sign * strain * box_lengths(engine)[2] / (PROBE_STEPS * engine.dt)])
        engine.run(PROBE_STEPS)
        top.velocity = np.zeros(3)
        out.append(settle())
    log("probe: sigma before / loaded / unloaded = "
        + " / ".join(np.array2string(s, precision=5) for s in out) + " Pa")
    return out


def constants(d_sigma, strain):
    """Elastic constants from a constrained axial increment (module docstring)."""
    M = d_sigma[2] / strain
    lam = 0.5 * (d_sigma[0] + d_sigma[1]) / strain
    G = 0.5 * (M - lam)
    K = (M + 2.0 * lam) / 3.0
    return {"constrained_modulus_M": M, "lame_lambda": lam, "lambda_x": d_sigma[0] / strain,
            "lambda_y": d_sigma[1] / strain, "shear_modulus_G": G, "bulk_modulus_K": K,
            "young_E": 9.0 * K * G / (3.0 * K + G), "poisson_nu": lam / (M + lam)}


def measure(case, case_path, mean_stress, strain, out_dir, size=None):
    """The whole test; writes ``elastic.json`` in ``out_dir`` and returns its dict."""
    from cosim.apps.dem import materials_of
    from cosim.specimen import SpecimenBox, curve_of, grain_shapes, make_specimen
    from de_domain import Engine
    mats, sand, wall, plate = materials_of(case.dem, *roles(case, case_path))
    if case.specimen.source != "generate":
        raise CaseError(case_path, "specimen.source", case.specimen.source,
                        "cosim elastic generates its own cubical specimen: needs source = 'generate'")
    curve = curve_of(case.specimen)
    side = size or SIDES * float(curve.diameters[-1])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = lambda text: say(f"[{case.case.name} elastic] {text}")  # noqa: E731
    t0 = time.perf_counter()
    box = SpecimenBox(side, side, side, mats, sand, wall, plate)
    specimen, info = make_specimen(case, box, curve, out_dir, label=f"{case.case.name} elastic",
                                   shapes=grain_shapes(case, case_path))
    scale = case.specimen.density_scale
    scaled = [replace(m, density=m.density * scale) for m in mats]
    grains, clumps = specimen.bodies(scaled, sand)
    engine = Engine(grains, scaled, walls=box_walls(side, side, specimen.height, wall),
                    contact_law=case.dem.contact_law, gravity=(0.0, 0.0, 0.0), safety_factor=case.time.safety_factor,
                    local_damping=case.specimen.local_damping, clumps=clumps)
    stiffness_guess = mats[sand].young  # M0 = k_n / d of a pair of equal grains (linear law k_n = 2 E r)
    steps, compressed = compress(engine, mean_stress, stiffness_guess, log, max_steps=2_000_000)
    before, loaded, unloaded = probe(engine, strain, log)
    lengths = box_lengths(engine)
    radii = specimen.grain_radii()
    solid = float(np.sum(4.0 / 3.0 * math.pi * radii**3))
    result = {"mean_stress_Pa": mean_stress, "axial_strain": strain, "grains": int(len(radii)), "side_m": side,
              "void_ratio": float(np.prod(lengths) / solid - 1.0), "compression_steps": steps,
              "stress_compressed_Pa": compressed.tolist(),
              "stress_before_Pa": before.tolist(), "stress_loaded_Pa": loaded.tolist(),
              "stress_unloaded_Pa": unloaded.tolist(),
              "recovered_fraction": float((loaded[2] - unloaded[2]) / (loaded[2] - before[2])),
              **constants(loaded - 0.5 * (before + unloaded), strain), "wall_clock_s": time.perf_counter() - t0,
              "specimen": {k: v for k, v in info.items() if k != "generation_log"}}
    atomic_write_text(out_dir / "elastic.json", json.dumps(result, indent=2) + "\n")
    log(f"at p = {mean_stress:.4g} Pa, e = {result['void_ratio']:.3f}: M = {result['constrained_modulus_M']:.4g} Pa, "
        f"G = {result['shear_modulus_G']:.4g} Pa, K = {result['bulk_modulus_K']:.4g} Pa; "
        f"unloading recovers {100 * result['recovered_fraction']:.0f} % of the loading increment")
    say(f"[soil]\nE = {result['young_E']:.4g}   # Pa, cosim elastic at p = {mean_stress:.4g} Pa\n"
        f"nu = {result['poisson_nu']:.3f}")
    return result
