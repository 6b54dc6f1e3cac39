"""Interface tractions against the FE mesh size: a grain layer resting on, then pressed into,
an elastic FE block, with interface meshes h, h/2, h/4 (issue: the DE–FE interface stress
of some couplings depends on the FE mesh and is too small on coarse meshes).

    .venv/bin/python studies/interface_traction.py [OUT_DIR]        # h = 5, 2.5, 1.25 mm
    .venv/bin/python studies/interface_traction.py OUT --sizes 0.005 0.0025                 # quicker

The problem. An elastic block L × L × H (L = 20 mm, H = 10 mm; E = 50 MPa, ν = 0.3,
ρ = 2000 kg/m³; bottom fixed; Cundall local damping 0.7 so that it comes to rest) whose top
face is the coupling interface, meshed by gmsh with element size h. On it a layer of grains
(r = 0.9–1.1 mm, ρ = 2650 kg/m³, E = 50 MPa, μ = 0.5; local damping 0.5), laterally held by
four frictionless plane walls at the block's sides, so that no wall carries any of the
layer's weight. The grains are made once (a cloud settled by the DEM alone on a plane at
the block's top) and the same packing is put on every mesh.

1. **At rest**: the coupled model runs until the unbalanced force ratio of the grains is
   below 1e-3; then the total interface force must equal the grains' weight W.
2. **Pressed**: a rigid plane wall on top of the layer is driven by a servo to a force
   P = 2 kPa × L² (0.8 N) and held there until the unbalanced force ratio is below 1e-3
   again; then the interface force must equal P + W (within 1 %).
3. **Noise** (finest-but-one mesh): the wall then presses on slowly (NOISE_SPEED) for
   NOISE_STEPS FE steps; the per-node interface force's standard deviation about a fitted
   straight line, over its mean (median over the nodes with a force), and the total
   force's; for the smoothing (``coupling.smoothing_time``) off and with τ = TAUS FE steps,
   each measured after NOISE_STEPS steps that let the switch's transient pass.

For each mesh the nodal normal traction t_a = f_a,z / A_a (the ``interface_traction``
field) gives a mean (Σ f / Σ A) and a distribution; the traction averaged over fixed
10 × 10 mm patches (a measure that does not depend on h) is compared between the
meshes. Printed as a table; ``traction_convergence.png`` has the nodal distributions and
the patch tractions; ``traction_convergence.json`` the numbers.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from cosim.apps.coupled import coupled_step, time_steps
from cosim.interface import Interface, nodal_areas
from de_domain import Engine, Material, Particles, PlaneWall, diagnostics
from de_domain.packing import random_cloud
from fe_domain.build import build_solid
from fe_domain.explicit import stable_alpha_tau

L, H = 0.02, 0.01                      # block [m]
PRESSURE = 2.0e3                       # Pa on the top wall
PATCH = 0.01                           # m: the side of the averaging patches (the block's quarters)
UNBALANCED = 1e-3
NOISE_STEPS = 2000
NOISE_SPEED = 2e-4                     # m/s: the wall presses on slowly while the noise is measured
TAUS = (0, 2, 20)                      # smoothing time constants, in FE steps (0: off)
GRAIN = Material(density=2650.0, young=5.0e7, poisson=0.25, friction=0.5, restitution=0.5)
SMOOTH_WALL = Material(density=2650.0, young=5.0e7, poisson=0.25, friction=0.0, restitution=0.5)
MATERIALS = [GRAIN, SMOOTH_WALL]       # 0: grains and the interface, 1: the side walls
FE_MATERIAL = {"E": 5.0e7, "nu": 0.3, "rho": 2000.0}


def side_walls():
    return [PlaneWall((0, 0, 0), (1, 0, 0), 1), PlaneWall((L, 0, 0), (-1, 0, 0), 1),
            PlaneWall((0, 0, 0), (0, 1, 0), 1), PlaneWall((0, L, 0), (0, -1, 0), 1)]


def packing(n_grains, seed=11):
    """The layer: a cloud settled by the DEM alone on a plane at z = H, to rest."""
    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.9e-3, 1.1e-3, n_grains)
    height = n_grains * (4 / 3) * np.pi * 1.1e-9 / (L * L * 0.12)  # a cloud of solid fraction ≈ 0.12
    pos, radii = random_cloud(radii, (0.0011, 0.0011, H + 0.0011), (L - 0.0011, L - 0.0011, H + height), seed=seed)
    particles = Particles.from_spheres(pos, radii, materials=[GRAIN])
    engine = Engine(particles, MATERIALS, walls=side_walls() + [PlaneWall((0, 0, H), (0, 0, 1), 0)],
                    local_damping=0.5, safety_factor=0.3)
    while True:
        engine.run(2000)
        if diagnostics.unbalanced_force_ratio(engine) < UNBALANCED and engine.time > 0.05:
            return engine.particles.pos.copy(), engine.particles.radius.copy()


def settle(solid, engine, interface, n_sub, top=None, max_time=0.5):
    """Coupled steps until the grains' unbalanced force ratio is below UNBALANCED (and, with
    a top wall, its force within 0.1 % of P): the servo moves the wall at a speed
    proportional to the force error."""
    target = PRESSURE * L * L
    while solid.time < max_time:
        for _ in range(200):
            if top is not None:
                error = (target - top.force[2]) / target
                top.velocity = (0.0, 0.0, -float(np.clip(0.01 * error, -0.005, 0.005)))
            coupled_step(solid, engine, interface, n_sub)
        ufr = diagnostics.unbalanced_force_ratio(engine)
        if ufr < UNBALANCED and (top is None or abs(top.force[2] - target) < 1e-3 * target):
            if top is not None:
                top.velocity = (0.0, 0.0, 0.0)
            return ufr
    raise RuntimeError(f"no rest within {max_time} s (unbalanced force ratio {ufr:.2e})")


def traction_state(interface):
    """(x, y, downward force the grains put on the node, lumped area) of the interface nodes (one rank)."""
    vertices = interface.facets.vertices
    area = nodal_areas(vertices, interface.facets.triangles)
    force = -interface.released[:, 2] / interface.solid.dt
    return vertices[:, 0], vertices[:, 1], force, area


def _patch_shares(coordinate, n):
    """(patch index, share) pairs per node along one axis: a node on the border between two
    patches counts half in each."""
    k = coordinate / PATCH
    nearest = np.rint(k)
    on_border = (np.abs(k - nearest) < 1e-6) & (nearest > 0) & (nearest < n)
    low = np.where(on_border, nearest - 1, np.minimum(np.floor(k), n - 1)).astype(int)
    high = np.where(on_border, nearest, low).astype(int)
    share = np.where(on_border, 0.5, 1.0)
    return [(low, share), (high, 1.0 - share)]


def patch_tractions(x, y, force, area):
    """Σ f_a / Σ A_a over the nodes of each PATCH × PATCH square (a fixed, h-independent
    averaging area; a node on a patch border counts half in each neighbour)."""
    n = int(round(L / PATCH))
    forces, areas = np.zeros((n, n)), np.zeros((n, n))
    for ix, sx in _patch_shares(x, n):
        for iy, sy in _patch_shares(y, n):
            np.add.at(forces, (ix, iy), sx * sy * force)
            np.add.at(areas, (ix, iy), sx * sy * area)
    return forces / areas


def noise(solid, engine, interface, n_sub, top, steps):
    """Press on at a constant wall speed (the load rises by ≈ 10 % over ``steps``); (median over
    the loaded nodes of std/mean of the nodal z-force, the same for the total force), the std
    taken about a straight line fitted to each history (the rise is not noise)."""
    top.velocity = (0.0, 0.0, -NOISE_SPEED)
    history = np.empty((steps, len(interface.facets.vertices)))
    for n in range(steps):
        coupled_step(solid, engine, interface, n_sub)
        history[n] = -interface.released[:, 2]
    top.velocity = (0.0, 0.0, 0.0)
    t = np.arange(steps)
    total = history.sum(axis=1)
    fits = np.polynomial.polynomial.polyfit(t, np.column_stack([history, total]), 1)
    residual = np.column_stack([history, total]) - np.polynomial.polynomial.polyval(t, fits).T
    mean, std = history.mean(axis=0), residual[:, :-1].std(axis=0)
    loaded = mean > 0.05 * mean.max()
    return float(np.median(std[loaded] / mean[loaded])), float(residual[:, -1].std() / total.mean())


def run_mesh(h, pos, radii, noise_too):
    start = time.perf_counter()
    solid = build_solid("block.geo", h, material=FE_MATERIAL, geometry_parameters={"Lx": L, "Ly": L, "Lz": H},
                        boundary_conditions=[{"type": "fixed", "boundary": "bottom"}],
                        damping={"type": "local", "alpha": 0.7}, formulation="mixed",
                        alpha_tau=stable_alpha_tau(FE_MATERIAL["nu"]))
    interface = Interface(solid, ["top"], material=0)
    top = PlaneWall((0, 0, float((pos[:, 2] + radii).max()) + 2e-5), (0, 0, -1), 0)
    particles = Particles.from_spheres(pos, radii, materials=[GRAIN])
    engine = Engine(particles, MATERIALS, walls=side_walls() + [top], facets=[interface.facets],
                    local_damping=0.5, safety_factor=0.3)
    fe_dt, dem_dt, n_sub = time_steps(engine.dt, 0.3 * solid.dt_critical)
    solid.dt, engine.dt = fe_dt, dem_dt
    weight = float(np.sum(particles.mass) * 9.81)
    row = {"h": h, "facets": int(len(interface.facets.triangles)), "nodes": int(len(interface.facets.vertices)),
           "fe_dt": fe_dt, "subcycles": n_sub, "weight": weight, "load": PRESSURE * L * L}
    for phase, wall in (("rest", None), ("pressed", top)):
        row[f"{phase}_ufr"] = settle(solid, engine, interface, n_sub, wall)
        x, y, force, area = traction_state(interface)
        expected = weight + (top.force[2] if wall is not None else 0.0)
        row[f"{phase}_force"] = float(force.sum())
        row[f"{phase}_expected"] = float(expected)
        row[f"{phase}_error"] = float(force.sum() / expected - 1.0)
        traction = force / area
        row[f"{phase}_mean_traction"] = float(force.sum() / area.sum())
        row[f"{phase}_traction_cv"] = float(np.sqrt(np.average((traction - traction.mean()) ** 2, weights=area))
                                            / row[f"{phase}_mean_traction"])
        row[f"{phase}_patches"] = patch_tractions(x, y, force, area).tolist()
        row[f"{phase}_nodal"] = traction.tolist()
    if noise_too:
        row["noise"] = {}
        for tau in TAUS:
            interface.smoothing_time = tau * solid.dt
            noise(solid, engine, interface, n_sub, top, NOISE_STEPS)  # the switch's transient passes
            row["noise"][tau] = noise(solid, engine, interface, n_sub, top, NOISE_STEPS)
    row["wall_s"] = time.perf_counter() - start
    return row


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for row in rows:
        nodal = np.sort(np.array(row["pressed_nodal"])) / 1e3
        left.plot(nodal, np.linspace(0, 1, len(nodal)), label=f"h = {1e3 * row['h']:.2f} mm ({row['nodes']} nodes)")
        patches = np.array(row["pressed_patches"]).ravel() / 1e3
        right.plot(np.arange(len(patches)), patches, "o-", label=f"h = {1e3 * row['h']:.2f} mm")
    mean = (rows[0]["pressed_expected"]) / (L * L) / 1e3
    left.axvline(mean, color="k", lw=0.8, ls="--", label=f"(P + W) / A = {mean:.2f} kPa")
    left.set_xscale("symlog", linthresh=0.01)
    left.set_xlim(left=0.0)
    left.set_xlabel("nodal normal traction f_a / A_a [kPa] (linear below 0.01)")
    left.set_ylabel("fraction of interface nodes")
    left.set_title("pressed: distribution of the nodal traction")
    left.legend(fontsize=8)
    right.axhline(mean, color="k", lw=0.8, ls="--")
    right.set_xlabel(f"{PATCH * 1e3:.0f} x {PATCH * 1e3:.0f} mm patch (row by row)")
    right.set_ylabel("patch traction [kPa]")
    right.set_title("pressed: traction averaged over fixed patches")
    right.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", default="runs/out/interface_traction")
    parser.add_argument("--sizes", nargs="+", type=float, default=[0.005, 0.0025, 0.00125], help="h [m]")
    parser.add_argument("--grains", type=int, default=150)
    parser.add_argument("--no-noise", action="store_true", help="skip the noise measurement")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pos, radii = packing(args.grains)
    print(f"{len(radii)} grains, weight {np.sum(GRAIN.density * 4 / 3 * np.pi * radii ** 3) * 9.81:.4e} N; "
          f"load P = {PRESSURE * L * L:.3f} N", flush=True)
    rows = []
    for k, h in enumerate(args.sizes):
        noise_too = not args.no_noise and k == max(0, len(args.sizes) - 2)
        rows.append(run_mesh(h, pos, radii, noise_too))
        r = rows[-1]
        print(f"h = {1e3 * h:5.2f} mm ({r['facets']:4d} facets, {r['subcycles']} substep(s)): "
              f"at rest F/W - 1 = {r['rest_error']:+.2e} (UFR {r['rest_ufr']:.1e}); pressed F/(P + W) - 1 = "
              f"{r['pressed_error']:+.2e} (UFR {r['pressed_ufr']:.1e}); mean traction {r['pressed_mean_traction']:.1f} "
              f"Pa, nodal CV {r['pressed_traction_cv']:.2f}; {r['wall_s']:.0f} s", flush=True)
    finest = np.array(rows[-1]["pressed_patches"])
    for r in rows:
        r["patch_difference_to_finest"] = float(np.abs(np.array(r["pressed_patches"]) - finest).max()
                                                / (r["pressed_expected"] / (L * L)))
    print("\n| h [mm] | facets | F/W − 1 at rest | F/(P+W) − 1 pressed | mean traction [Pa] | nodal CV | "
          "max patch difference to finest / mean |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {1e3 * r['h']:.2f} | {r['facets']} | {r['rest_error']:+.1e} | {r['pressed_error']:+.1e} | "
              f"{r['pressed_mean_traction']:.1f} | {r['pressed_traction_cv']:.2f} | "
              f"{100 * r['patch_difference_to_finest']:.1f} % |")
    for r in rows:
        for tau, (node, total) in r.get("noise", {}).items():
            print(f"noise while pressing on (h = {1e3 * r['h']:.2f} mm, {NOISE_STEPS} FE steps), smoothing "
                  f"tau = {tau} FE steps: nodal force std/mean (median over nodes) {node:.2e}, total {total:.2e}")
    plot(rows, out / "traction_convergence.png")
    (out / "traction_convergence.json").write_text(json.dumps(rows))
    worst = max(max(abs(r["rest_error"]), abs(r["pressed_error"])) for r in rows)
    print(f"\nlargest force-balance error {100 * worst:.2f} %; outputs in {out}")
    return 0 if worst < 0.01 else 1


if __name__ == "__main__":
    sys.exit(main())
