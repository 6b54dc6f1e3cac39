"""The small retaining wall (runs/retaining_wall_small.toml), coupled against all-DEM over
several packings, and both against Rankine's and Coulomb's active thrust with the friction
angle measured on the same sand (issue 36 item 4b; docs/guide/own-geometry.md).

Runs the case with each seed, both models, unless a seed's summaries exist (about 3 + 8
minutes a seed on 2 cores), and the triaxial series of the same sand
(``runs/triaxial_wall_sand.toml`` at 0.5, 1 and 2 kPa, about the backfill's stresses) unless
its Mohr–Coulomb fit exists. Per model and seed: the horizontal thrust F_x once active (the
mean over the rows where the wall has moved at least ACTIVE_FROM), its coefficient
K_h = 2 F_x / (γ H² L_y) with γ = ρ_s g / (1 + e) of that model's fill, the height of the
resultant above the toe, the mobilised wall friction δ = atan(F_z / F_x), and the wall-clock.
Against them: Rankine K_a = tan²(45° − φ/2), and Coulomb's horizontal K_a cos δ with

    K_a = cos²φ / (cos δ (1 + √(sin(φ + δ) sin φ / cos δ))²)

(vertical wall, level backfill; e.g. Craig's Soil Mechanics, §11.4), for φ = the series' peak
and critical-state angles. Writes ``runs/out/retaining_wall_seeds/table.md`` and the plot
``docs/retaining_wall_seeds.png``.

Also the wall's travel needed to mobilise the active state: the first row where the thrust
has made MOBILISED (90 %) of its drop from the thrust at rest (row 0) to its active value,
over H, against the Δ/H ≈ 0.001
(dense), 0.002 (medium dense), 0.004 (loose sand) of Clough & Duncan (1991, *Foundation
Engineering Handbook*, ch. 6, table 6.2) for a wall translating or rotating about its toe.

With ``--rotation`` the wall rotates about its toe instead (``runs/retaining_wall_rotation.toml``,
its top moving as far as the translating wall), into ``runs/out/retaining_wall_rotation_seeds/``
and ``docs/retaining_wall_rotation_seeds.png``; the wall's travel is that of its top. With
``--full`` the full-size translating wall (``runs/retaining_wall_full.toml``, H = 120 mm, the
backfill 5 H long: about 9,000 grains in the zone, 55,000 in the all-DEM twin; about 15 and 60
minutes a seed on one core each), into ``runs/out/retaining_wall_full_seeds/`` and
``docs/retaining_wall_full_seeds.png``. The study runs one case at a time; for the wall-clocks
quoted in the docs the two models of a seed ran side by side, one thread each
(``NUMBA_NUM_THREADS=1``, one ``cosim run`` per model into the same folders).

    python studies/retaining_wall_seeds.py [--seeds 11 12 13] [--rotation | --full]
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cosim.lab.shear_report import read_series  # noqa: E402

TRIAXIAL = ROOT / "runs" / "triaxial_wall_sand.toml"
TRIAXIAL_OUT = ROOT / "runs" / "out" / "retaining_wall_seeds" / "triaxial"
MODELS = ("coupled", "dem")
LY, RHO_S, G = 0.01, 2650.0, 9.81
ACTIVE_FROM = 0.005  # of H: the wall top's travel after which the thrust is taken as active
MOBILISED = 0.9      # this fraction of the thrust's drop from rest to active made: the active state mobilised


@dataclass(frozen=True)
class Variant:
    """One wall study: its case, output folder, wall height H (m), picture name and title."""
    case: Path
    out: Path
    height: float
    picture: str
    title: str


VARIANTS = {
    "translating": Variant(ROOT / "runs" / "retaining_wall_small.toml", ROOT / "runs" / "out" / "retaining_wall_seeds",
                           0.06, "retaining_wall_seeds", "small (H = 60 mm, 10 mm slice), translating"),
    "rotating": Variant(ROOT / "runs" / "retaining_wall_rotation.toml",
                        ROOT / "runs" / "out" / "retaining_wall_rotation_seeds", 0.06, "retaining_wall_rotation_seeds",
                        "small (H = 60 mm, 10 mm slice), rotating about its toe"),
    "full": Variant(ROOT / "runs" / "retaining_wall_full.toml", ROOT / "runs" / "out" / "retaining_wall_full_seeds",
                    0.12, "retaining_wall_full_seeds",
                    "full size (H = 120 mm, backfill 5 H, 10 mm slice), translating"),
}


def run(seed, model, variant):
    out, case = variant.out / f"seed{seed}", variant.case
    summary = out / model / "summary.json"
    if not summary.exists():
        subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(case), "--out", str(out), "--set",
                        f"case.seed={seed}", "--set", f"embedded.model=\"{model}\""], check=True, cwd=ROOT)
    return read_series(out / model / "series.csv"), json.loads(summary.read_text())


def travel(series, height):
    """How far the wall's top has moved away from the backfill (m): its translation plus its
    rotation about the toe times H."""
    return series["wall_displacement"] + height * series["wall_rotation"]


def friction_angles():
    """{"peak": φ, "residual": φ (the critical state)} in degrees, of the triaxial series of the
    wall's sand (its Mohr–Coulomb fit, ``mohr_coulomb.csv``)."""
    out = TRIAXIAL_OUT
    fit = out / "mohr_coulomb.csv"
    if not fit.exists():
        subprocess.run([sys.executable, "-m", "cosim.cli", "series", str(TRIAXIAL), "--stresses", "500", "1000",
                        "2000", "--out", str(out)], check=True, cwd=ROOT)
    header, *rows = [line.split(",") for line in fit.read_text().splitlines() if line]
    return {row[header.index("strength")]: float(row[header.index("phi_deg")]) for row in rows}


def active(series, info, height):
    """K_h, the resultant's height / H, δ (deg) once the wall has moved ACTIVE_FROM H, and the
    travel / H by which the thrust has made MOBILISED of its drop from rest (row 0) to that value."""
    moved = travel(series, height)
    active_rows = moved >= ACTIVE_FROM * height
    fx, fz = -np.mean(series["wall_force_x"][active_rows]), -np.mean(series["wall_force_z"][active_rows])
    my = np.mean(series["wall_moment_y"][active_rows])
    gamma = RHO_S * G / (1.0 + info["fill"]["void_ratio"])
    thrust = -series["wall_force_x"]
    mobilised = moved[np.argmax(thrust <= fx + (1.0 - MOBILISED) * (thrust[0] - fx))] / height
    return {"K_h": 2.0 * fx / (gamma * height**2 * LY), "height": -my / fx / height if fx else float("nan"),
            "delta": math.degrees(math.atan2(fz, fx)), "F_x": fx, "mobilised": mobilised,
            "wall_clock": info["wall_clock_s"]["total_without_compilation_s"], "grains": info["grains"],
            "e": info["fill"]["void_ratio"]}


def rankine(phi):
    return math.tan(math.radians(45.0 - phi / 2.0)) ** 2


def coulomb_horizontal(phi, delta):
    p, d = math.radians(phi), math.radians(delta)
    ka = math.cos(p) ** 2 / (math.cos(d) * (1.0 + math.sqrt(math.sin(p + d) * math.sin(p) / math.cos(d))) ** 2)
    return ka * math.cos(d)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    choice = parser.add_mutually_exclusive_group()
    choice.add_argument("--rotation", action="store_true", help="the small wall rotating about its toe")
    choice.add_argument("--full", action="store_true", help="the full-size translating wall")
    args = parser.parse_args()
    variant = VARIANTS["rotating" if args.rotation else "full" if args.full else "translating"]
    results, curves = {m: [] for m in MODELS}, {m: [] for m in MODELS}
    for seed in args.seeds:
        for model in MODELS:
            series, info = run(seed, model, variant)
            results[model].append(active(series, info, variant.height))
            curves[model].append((travel(series, variant.height), -series["wall_force_x"]))
    lines = ["| seed | model | grains | e | F_x active [N] | K_h | height / H | δ [deg] | Δ/H to active | "
             "wall-clock [s] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for k, seed in enumerate(args.seeds):
        for model in MODELS:
            r = results[model][k]
            lines.append(f"| {seed} | {'all-DEM' if model == 'dem' else model} | {r['grains']:,} | {r['e']:.3f} | "
                         f"{r['F_x']:.4f} | {r['K_h']:.3f} | {r['height']:.2f} | {r['delta']:.1f} | "
                         f"{r['mobilised']:.4f} | {r['wall_clock']:.0f} |")
    mean = {m: {q: float(np.mean([r[q] for r in results[m]])) for q in ("F_x", "K_h", "height", "delta",
                                                                        "mobilised", "wall_clock")} for m in MODELS}
    spread = {m: float(np.std([r["K_h"] for r in results[m]], ddof=1)) if len(args.seeds) > 1 else 0.0
              for m in MODELS}
    for model in MODELS:
        m = mean[model]
        lines.append(f"| mean | {'all-DEM' if model == 'dem' else model} | | | {m['F_x']:.4f} | {m['K_h']:.3f} "
                     f"(± {spread[model]:.3f}) | {m['height']:.2f} | {m['delta']:.1f} | {m['mobilised']:.4f} | "
                     f"{m['wall_clock']:.0f} |")
    difference = mean["coupled"]["K_h"] / mean["dem"]["K_h"] - 1.0
    lines.append(f"\ncoupled against all-DEM, mean K_h: {100 * difference:+.1f} %; wall-clock "
                 f"{mean['dem']['wall_clock'] / mean['coupled']['wall_clock']:.1f}x less for the coupled model")
    fits = friction_angles()
    lines.append("\n| φ from the triaxial series | φ [deg] | Rankine K_a | Coulomb K_a cos δ (δ of each model) |")
    lines.append("|---|---|---|---|")
    for key, phi in fits.items():
        coulomb = ", ".join(f"{coulomb_horizontal(phi, mean[m]['delta']):.3f} ({m})" for m in MODELS)
        name = "critical state" if key == "residual" else key
        lines.append(f"| {name} | {phi:.1f} | {rankine(phi):.3f} | {coulomb} |")
    text = "\n".join(lines) + "\n"
    print(text)
    variant.out.mkdir(parents=True, exist_ok=True)
    (variant.out / "table.md").write_text(text)
    plot(curves, variant)


def plot(curves, variant):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.0, 4.4))
    for model, color in zip(MODELS, ("tab:blue", "tab:orange"), strict=True):
        label = "coupled (DEM zone + FE)" if model == "coupled" else "all-DEM"
        for k, (x, f) in enumerate(curves[model]):
            ax.plot(1e3 * x, f, color=color, lw=1.0, alpha=0.7, label=label if k == 0 else None)
    ax.axvline(1e3 * ACTIVE_FROM * variant.height, color="0.8", lw=0.8, zorder=0)
    ax.set_xlabel("wall top's displacement away from the backfill [mm]")
    ax.set_ylabel("horizontal thrust on the wall F_x [N]")
    ax.set_title(f"retaining wall, {variant.title}\none line per packing", fontsize=10)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / f"{variant.picture}.png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
