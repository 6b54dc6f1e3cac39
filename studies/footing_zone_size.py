"""Does the coupled footing model give the all-DEM answer, and how does the gap shrink as the
DEM zone grows? (issue 15 item 4; docs/design.md §7.4)

Runs the all-DEM reference of ``runs/footing_small.toml`` and its coupled model with DEM zones
of growing size in the same soil block (and, on the largest zone, with half the FE stiffness
and with a frictionless interface; and with the zone's grains carved out of the all-DEM
specimen: what the gap is sensitive to), each with several seeds (a
different packing each: with ~6 grains under the footing, one packing's curve is far from the
mean). Writes, in
``runs/out/footing_zone_size/`` and ``docs/``: a table of the bearing pressure at s/B = 2, 5,
10 % (mean over the seeds, with the seeds' spread, and the coupled/all-DEM difference of the
means), the wall-clock of each, and the mean load-settlement curves with their seed ranges.

    python studies/footing_zone_size.py [--seeds 11 12 13] [--ranks N]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cosim.apps.footing import SETTLEMENT_LEVELS, bearing_pressure_at  # noqa: E402
from cosim.lab.shear_report import read_series  # noqa: E402

CASE = ROOT / "runs" / "footing_small.toml"
OUT = ROOT / "runs" / "out" / "footing_zone_size"
ZONES = [(0.045, 0.020), (0.075, 0.030), (0.105, 0.040)]  # (width, depth) of the DEM zone [m]: 2, 3, 4 layers
# what the gap to all-DEM is sensitive to, on the largest zone: (label, overrides)
VARIANTS = [("E/2", ["--set", "soil.E=1.0e6"]),
            ("frictionless interface", ["--set", "zone.interface_material=\"side_wall\""])]
GRID = np.linspace(0.0, 0.1, 101)  # s/B of the mean curves


def run(label, seed, ranks, model, *overrides, case=CASE):
    """(series, summary) of one run, made unless its summary exists."""
    out = OUT / f"{label}_seed{seed}"
    summary = out / model / "summary.json"
    if not summary.exists():
        cmd = [sys.executable, "-m", "cosim.cli", "run", str(case), "--out", str(out), "--set", f"case.seed={seed}",
               "--set", f"footing.model=\"{model}\"", *overrides]
        if ranks > 1:
            cmd = ["mpirun", "-n", str(ranks), "--bind-to", "none", *cmd]
        subprocess.run(cmd, check=True, cwd=ROOT)
    return read_series(out / model / "series.csv"), json.loads(summary.read_text())


def carved_case(seed, width, depth):
    """A case whose zone holds the grains of the all-DEM specimen of ``seed`` that lie wholly
    inside the zone (the same grains, with the same generation history, in both models; the
    grains cut by the zone's faces are left out, and the zone settles into their room at rest)."""
    from cosim.apps.footing import Geometry
    from cosim.case import load_case
    case, _ = load_case(CASE, [f"zone.width={width}", f"zone.depth={depth}"])
    g = Geometry.of(case)
    with np.load(OUT / f"all_dem_seed{seed}" / "dem" / "specimen.npz") as data:
        pos, radii, height = data["positions"], data["radii"], float(data["height"])
    inside = ((pos[:, 0] - radii >= g.zone_x0) & (pos[:, 0] + radii <= g.zone_x0 + g.zone_width)
              & (pos[:, 2] - radii >= g.zone_bottom))
    packing = OUT / f"carved_seed{seed}.npz"
    np.savez(packing, positions=pos[inside] - [g.zone_x0, 0.0, g.zone_bottom], radii=radii[inside],
             height=height - g.zone_bottom)
    head, rest = CASE.read_text().split("[specimen]", 1)
    path = OUT / f"carved_seed{seed}.toml"
    path.write_text(head + f'[specimen]\nsource = "file"\nfile = "{packing}"\n\n' + rest[rest.index("[footing]"):])
    return path


def statistics(runs):
    """Mean and half-range over seeds of q at each level, the mean curve and its range, grains,
    wall-clock and rest balance."""
    q = np.array([[bearing_pressure_at(s)[k] for k in SETTLEMENT_LEVELS] for s, _ in runs])
    curves = np.array([np.interp(GRID, s["settlement_ratio"], s["bearing_pressure"]) for s, _ in runs])
    balance = [i["rest"]["interface_force_over_weight"] for _, i in runs]
    return {"q": q.mean(axis=0), "spread": 0.5 * (q.max(axis=0) - q.min(axis=0)), "curve": curves.mean(axis=0),
            "low": curves.min(axis=0), "high": curves.max(axis=0), "grains": np.mean([i["grains"] for _, i in runs]),
            "wall": np.mean([i["wall_clock_s"]["total_s"] for _, i in runs]),
            "balance": None if balance[0] is None else (min(balance), max(balance))}


def table(results, reference):
    head = ("| model | grains | interface force / weight at rest | "
            + " | ".join(f"q at s/B = {100 * k:.0f} % [kPa]" for k in SETTLEMENT_LEVELS)
            + " | wall-clock [s] (all-DEM / this) |")
    lines = [head, "|" + "---|" * (4 + len(SETTLEMENT_LEVELS))]
    for name, r in results.items():
        cells = []
        for i in range(len(SETTLEMENT_LEVELS)):
            cell = f"{r['q'][i] / 1e3:.2f} ± {r['spread'][i] / 1e3:.2f}"
            if r is not reference:
                cell += f" ({100 * (r['q'][i] - reference['q'][i]) / reference['q'][i]:+.0f} %)"
            cells.append(cell)
        balance = "-" if r["balance"] is None else f"{r['balance'][0]:.4f} – {r['balance'][1]:.4f}"
        ratio = "" if r is reference else f" ({reference['wall'] / r['wall']:.1f}x)"
        lines.append(f"| {name} | {r['grains']:.0f} | {balance} | " + " | ".join(cells)
                     + f" | {r['wall']:.0f}{ratio} |")
    return "\n".join(lines)


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    for name, r in results.items():
        line, = ax.plot(100 * GRID, r["curve"] / 1e3, lw=2.0 if name == "all-DEM" else 1.4, label=name)
        ax.fill_between(100 * GRID, r["low"] / 1e3, r["high"] / 1e3, color=line.get_color(), alpha=0.15, lw=0)
    for level in SETTLEMENT_LEVELS:
        ax.axvline(100 * level, color="0.85", lw=0.8, zorder=0)
    ax.set_xlabel("settlement s / B [%]")
    ax.set_ylabel("bearing pressure q [kPa]")
    ax.set_title("strip footing: coupled (DEM zone + FE) against all-DEM\nmean over seeds, band = seed range")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    parser.add_argument("--ranks", type=int, default=1)
    args = parser.parse_args()
    results = {}
    results["all-DEM"] = statistics([run("all_dem", seed, args.ranks, "dem") for seed in args.seeds])
    for width, depth in ZONES:
        label = f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm"
        runs = [run(label, seed, args.ranks, "coupled", "--set", f"zone.width={width}", "--set", f"zone.depth={depth}")
                for seed in args.seeds]
        results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm"] = statistics(runs)
    width, depth = ZONES[-1]
    for name, extra in VARIANTS:
        label = f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm_{name.replace(' ', '_').replace('/', '_')}"
        runs = [run(label, seed, args.ranks, "coupled", "--set", f"zone.width={width}", "--set", f"zone.depth={depth}",
                    *extra) for seed in args.seeds]
        results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm, {name}"] = statistics(runs)
    runs = [run(f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm_carved", seed, args.ranks, "coupled", "--set",
                f"zone.width={width}", "--set", f"zone.depth={depth}", case=carved_case(seed, width, depth))
            for seed in args.seeds]
    results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm, grains carved from the all-DEM's"] = \
        statistics(runs)
    text = table(results, results["all-DEM"])
    text += (f"\n\nseeds {args.seeds}; q: mean ± half the range over the seeds; (±%): the coupled mean against "
             "the all-DEM mean\n")
    print(text)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "table.md").write_text(text)
    plot(results, OUT / "load_settlement.png")
    plot(results, ROOT / "docs" / "footing_zone_size.png")


if __name__ == "__main__":
    main()
