"""The full-size footing (runs/footing_full.toml), coupled against all-DEM over several packings (issue 15 item 4;
docs/design.md §7.4).

Runs ``runs/footing_full.toml`` (B = 40 mm = 16 d50, ~31,000 grains in the DEM zone of the
coupled model, ~123,000 in the all-DEM block) with each seed, both models, under
``mpirun -n RANKS`` (about 4 + 11 minutes a seed on 2 cores), unless a seed's summaries exist.
Each seed is a different packing, generated independently in the zone and in the block. Writes
in ``runs/out/footing_full_seeds/``: a table of q at s/B = 2, 5, 10 % and of the mean q over
s/B = 1–10 % for each seed and for the mean over the seeds, with the coupled/all-DEM
differences and the wall-clock of each run, and a plot of the curves (also ``docs/``); and
the bearing capacity factor the runs reach, N_γ = q / (½ γ B) with γ = ρ_s g / (1 + e) of each
fill, against Meyerhof's and Vesić's N_γ for φ of the same sand measured by a triaxial series
(``studies/retaining_wall_seeds.py``'s, run if missing), and the φ Meyerhof's N_γ would need:

    N_q = e^(π tan φ) tan²(45° + φ/2),  N_γ = (N_q − 1) tan(1.4 φ)  (Meyerhof 1963),
    N_γ = 2 (N_q + 1) tan φ  (Vesić 1973)

(surface strip footing, no surcharge: q_u = ½ γ B N_γ).

    python studies/footing_full_seeds.py [--seeds 11 12 13] [--ranks 2]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cosim.apps.footing import SETTLEMENT_LEVELS, bearing_pressure_at  # noqa: E402
from cosim.lab.shear_report import read_series  # noqa: E402

CASE = ROOT / "runs" / "footing_full.toml"
OUT = ROOT / "runs" / "out" / "footing_full_seeds"
MODELS = ("coupled", "dem")
MEAN_RANGE = (0.01, 0.10)  # s/B over which the mean bearing pressure is taken
G = 9.81
GRID = np.linspace(0.0, 0.1, 201)


def run(seed, model, ranks):
    """(series, summary) of one model of one seed, run unless its summary exists."""
    out = OUT / f"seed{seed}"
    summary = out / model / "summary.json"
    if not summary.exists():
        cmd = ["mpirun", "-n", str(ranks), "--bind-to", "none", sys.executable, "-m", "cosim.cli", "run", str(CASE),
               "--out", str(out), "--set", f"case.seed={seed}", "--set", f"footing.model=\"{model}\""]
        subprocess.run(cmd, check=True, cwd=ROOT, env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    return read_series(out / model / "load_settlement.csv"), json.loads(summary.read_text())


def levels(series):
    """q at the settlement levels, then the mean q over MEAN_RANGE (Pa)."""
    at = [bearing_pressure_at(series)[k] for k in SETTLEMENT_LEVELS]
    grid = np.linspace(*MEAN_RANGE, 91)
    return np.array(at + [np.interp(grid, series["settlement_ratio"], series["bearing_pressure"]).mean()])


def table(rows):
    """Markdown: per seed and for the mean over the seeds, each model's q and the difference."""
    names = [f"q at s/B = {100 * k:.0f} %" for k in SETTLEMENT_LEVELS] + ["mean q, s/B = 1–10 %"]
    lines = ["| seed | model | grains | " + " | ".join(f"{n} [kPa]" for n in names) + " | wall-clock [s] |",
             "|---|---|---|" + "---|" * len(names) + "---|"]
    for seed, r in rows.items():
        for model in MODELS:
            q, info = r[model]
            cells = [f"{v / 1e3:.2f}" for v in q]
            if model == "coupled":
                cells = [f"{c} ({100 * (v / w - 1):+.1f} %)" for c, v, w in zip(cells, q, r["dem"][0], strict=True)]
            grains = f"{info['grains']:,}" if info else ""
            wall = f"{info['wall_clock_s']['total_s']:.0f}" if info else ""
            lines.append(f"| {seed} | {'all-DEM' if model == 'dem' else model} | {grains} | " + " | ".join(cells)
                         + f" | {wall} |")
    return "\n".join(lines)


def n_q(phi):
    """N_q = e^(π tan φ) tan²(45° + φ/2) (Prandtl, Reissner), φ in degrees."""
    p = math.radians(phi)
    return math.exp(math.pi * math.tan(p)) * math.tan(math.pi / 4 + p / 2) ** 2


def n_gamma_meyerhof(phi):
    return (n_q(phi) - 1.0) * math.tan(math.radians(1.4 * phi))


def n_gamma_vesic(phi):
    return 2.0 * (n_q(phi) + 1.0) * math.tan(math.radians(phi))


def phi_for(n_gamma, factor=n_gamma_meyerhof):
    """The φ (deg) at which ``factor`` gives ``n_gamma`` (bisection; the factors grow with φ)."""
    lo, hi = 1.0, 60.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if factor(mid) < n_gamma else (lo, mid)
    return 0.5 * (lo + hi)


def bearing_capacity(rows, seeds):
    """Markdown: per model the mean N_γ = q / (½ γ B) the runs reach (q the mean over 1–10 % and
    at 10 %), the φ Meyerhof's factor needs for it, and Meyerhof's and Vesić's N_γ at the
    triaxial series' φ."""
    from retaining_wall_seeds import friction_angles

    from cosim.case import load_case
    case, _ = load_case(CASE, [])
    width = case.footing.width
    sand = [m for m in case.dem.materials if m.name == case.footing.sand_material][0]
    lines = ["| model | e | N_γ from the mean q over 1–10 % | φ for it, Meyerhof [deg] | N_γ from q at 10 % | "
             "φ for it, Meyerhof [deg] |", "|---|---|---|---|---|---|"]
    for model in MODELS:
        e = np.mean([rows[s][model][1]["fill"]["void_ratio"] for s in seeds])
        half_gamma_b = 0.5 * sand.density * G / (1.0 + e) * width
        mean_q, at_10 = rows["mean"][model][0][-1], rows["mean"][model][0][SETTLEMENT_LEVELS.index(0.10)]
        lines.append(f"| {'all-DEM' if model == 'dem' else model} | {e:.3f} | {mean_q / half_gamma_b:.1f} | "
                     f"{phi_for(mean_q / half_gamma_b):.1f} | {at_10 / half_gamma_b:.1f} | "
                     f"{phi_for(at_10 / half_gamma_b):.1f} |")
    lines += ["", "| φ from the triaxial series (0.5–2 kPa) | φ [deg] | N_γ Meyerhof | N_γ Vesić |",
              "|---|---|---|---|"]
    for strength, phi in friction_angles().items():
        lines.append(f"| {strength} | {phi:.1f} | {n_gamma_meyerhof(phi):.1f} | {n_gamma_vesic(phi):.1f} |")
    return "\n".join(lines)


def plot(curves, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for model, color in zip(MODELS, ("tab:blue", "tab:orange"), strict=True):
        label = "coupled (DEM zone + FE)" if model == "coupled" else "all-DEM"
        c = np.array(curves[model])
        for one in c:
            ax.plot(100 * GRID, one / 1e3, color=color, lw=0.6, alpha=0.45)
        ax.plot(100 * GRID, c.mean(axis=0) / 1e3, color=color, lw=2.2, label=f"{label}, mean of {len(c)} seeds")
    for level in SETTLEMENT_LEVELS:
        ax.axvline(100 * level, color="0.85", lw=0.8, zorder=0)
    ax.set_xlabel("settlement s / B [%]")
    ax.set_ylabel("bearing pressure q [kPa]")
    ax.set_title("strip footing, full size (B/d50 = 16): coupled against all-DEM\nthin lines: one packing each")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    parser.add_argument("--ranks", type=int, default=2)
    args = parser.parse_args()
    rows, curves = {}, {model: [] for model in MODELS}
    for seed in args.seeds:
        rows[seed] = {}
        for model in MODELS:
            series, info = run(seed, model, args.ranks)
            rows[seed][model] = (levels(series), info)
            curves[model].append(np.interp(GRID, series["settlement_ratio"], series["bearing_pressure"]))
    rows["mean"] = {model: (np.mean([rows[s][model][0] for s in args.seeds], axis=0), None) for model in MODELS}
    text = table(rows) + "\n\n" + bearing_capacity(rows, args.seeds) + "\n"
    print(text)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "table.md").write_text(text)
    plot(curves, OUT / "load_settlement.png")
    plot(curves, ROOT / "docs" / "footing_full_seeds.png")


if __name__ == "__main__":
    main()
