"""A tunnel lining in elastic ground against the closed form of Einstein & Schwartz (1979),
FE only (issue 39 item 3; docs/guide/tunnel.md when it lands).

A quarter model (meshes/ring.geo with ground: planes of symmetry x = 0 and z = 0; at x = L
and z = L the in-situ traction σ0·n, so that far away the ground stays at its in-situ stress
and is free to move) of a lining of mid-radius R and thickness t in ground with the uniform
in-situ stress σ_v = −p, σ_h = −K p; the lining carries none ("wished in place": the
excavation loading of the closed form), the ground's unbalanced stress at the opening loads
it, ramped, and local damping brings the model to rest. Thrust and moment around the ring
(fe_domain.lining, the "nodal force" section forces) against the no-slip solution of Einstein
& Schwartz (1979; the lining tied to the ground), ``fe_domain.lining.einstein_schwartz``.

With ``--static`` the FE model is solved statically instead (the P1 displacement formulation,
its assembled stiffness and a direct solve, fe_domain.static): the discretisation's error
alone, without the explicit run's approach to rest.

    python studies/lining_closed_form.py [--L 0.5] [--h 0.0025] [--steps 20000] [--K 0.5] [--static]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fe_domain.boundary import (  # noqa: E402
    Fixed,
    LocalNonViscousDamping,
    Material,
    Traction,
    UniformStress,
    constant,
    ramp,
)
from fe_domain.explicit import ExplicitSolid  # noqa: E402
from fe_domain.lining import LinedTunnel, Ring, einstein_schwartz, section_forces  # noqa: E402
from fe_domain.mesh import load_geo  # noqa: E402
from fe_domain.static import solve_static  # noqa: E402

RI, RO = 0.045, 0.05                 # m: t = 5 mm, R = 47.5 mm
GROUND = dict(E=50e6, nu=0.3, rho=2000.0)
LINING = dict(E=30e9, nu=0.2)        # concrete: F* ≈ 18, C* ≈ 0.017
P = 1e5


def lined_tunnel(L, h, steps, K, static=False, formulation="mixed"):
    """The quarter model at rest (or solved statically); its section forces at 5° to 85° from the crown."""
    tagged = load_geo("ring", max(h, 0.05), MPI.COMM_SELF, {"Ri": RI, "Ro": RO, "L": L, "h": h, "h_far": 0.05,
                                                            "Ly": h})
    ground = Material(**GROUND)
    c_ground = ground.p_wave_speed
    lining = Material(E=LINING["E"], nu=LINING["nu"], rho=1.0)   # mass-scaled below: a static problem
    lining = Material(E=LINING["E"], nu=LINING["nu"], rho=lining.p_wave_speed**2 / c_ground**2)
    stress = -P * np.diag([K, GROUND["nu"] / (1 - GROUND["nu"]) * (1 + K) / 2, 1.0])
    supports = [Fixed("x0", (0,)), Fixed("z0", (2,)), Fixed("sides", (1,))]
    probe = ExplicitSolid(tagged, {"ring": lining, "ground": ground}, boundary_conditions=supports)
    amplitude = constant if static else ramp(steps // 4 * probe.dt)
    in_situ = [UniformStress(stress, ("ground",), amplitude), Traction("far_x", stress[:, 0].tolist(), amplitude),
               Traction("far_z", stress[:, 2].tolist(), amplitude)]
    solid = ExplicitSolid(tagged, {"ring": lining, "ground": ground}, boundary_conditions=supports,
                          loads=in_situ, damping=LocalNonViscousDamping(0.7),
                          formulation="displacement" if static else formulation)
    t0 = time.perf_counter()
    if static:
        solve_static(solid)
    else:
        solid.run(steps)
    angles = np.arange(5.0, 90.0, 5.0)
    ring = Ring((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), RI, RO)
    forces = section_forces(solid, "ring", ring, angles)
    return forces, len(solid.h_cells), time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--L", type=float, default=0.5, help="the ground's extent from the axis [m]")
    parser.add_argument("--h", type=float, default=0.0025, help="element size at the lining [m]")
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--K", type=float, default=0.5, help="σ_h / σ_v of the in-situ stress")
    parser.add_argument("--static", action="store_true", help="a static solve instead of the explicit run")
    parser.add_argument("--formulation", choices=("mixed", "displacement"), default="mixed",
                        help="of the explicit run")
    args = parser.parse_args()
    forces, cells, seconds = lined_tunnel(args.L, args.h, args.steps, args.K, args.static, args.formulation)
    tunnel = LinedTunnel(0.5 * (RI + RO), RO - RI, GROUND["E"], GROUND["nu"], LINING["E"], LINING["nu"], P, args.K)
    thrust, moment, c, f = einstein_schwartz(tunnel, forces.angle_deg)
    how = "a static solve" if args.static else f"{args.steps} steps"
    print(f"C* = {c:.4f}, F* = {f:.2f}; {cells:,} cells, L = {args.L} m, h = {args.h} m, {how}, {seconds:.0f} s")
    print("| θ from crown [deg] | T FE [N/m] | T E&S [N/m] | diff | M FE [N·m/m] | M E&S [N·m/m] | diff / max M |")
    print("|---|---|---|---|---|---|---|")
    scale = max(np.abs(moment).max(), 1e-3 * P * 0.0475**2)
    for k, angle in enumerate(forces.angle_deg):
        fe_m = forces.moment[k]
        difference = 100 * (forces.thrust[k] / thrust[k] - 1)
        print(f"| {angle:.0f} | {forces.thrust[k]:.1f} | {thrust[k]:.1f} | {difference:+.1f} % | {fe_m:.3f} | "
              f"{moment[k]:.3f} | {100 * (fe_m - moment[k]) / scale:+.1f} % |")


if __name__ == "__main__":
    main()
