"""Does the coupled footing model give the all-DEM answer, and how does the gap shrink as the
DEM zone grows? (issue 15 item 4; docs/design.md §7.4)

Runs the all-DEM reference of ``runs/footing_small.toml`` and its coupled model with DEM zones
of growing size in the same soil block (and, on the largest zone, with half the FE stiffness
and with a frictionless interface; with the zone's grains carved out of the all-DEM
specimen: what the gap is sensitive to), each with several seeds (a
different packing each: with ~6 grains under the footing, one packing's curve is far from the
mean). Writes, in
``runs/out/footing_zone_size/`` and ``docs/``: a table of the bearing pressure at s/B = 2, 5,
10 % (mean over the seeds with its standard error, and the coupled/all-DEM difference of the
means), the wall-clock of each, and the mean load-settlement curves with their seed ranges.

    python studies/footing_zone_size.py [--seeds 11 12 ... 18] [--variant-seeds 3] [--ranks N] [--largest-only]

(``--largest-only``: the all-DEM reference and the largest zone, without the variants. The
layered under-compaction rows of docs/validation.md were measured before the footing kind
became a preset of the embedded kind, whose fill is radius expansion only.)
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
    return read_series(out / model / "load_settlement.csv"), json.loads(summary.read_text())


def carved_case(seed, width, depth):
    """A case whose zone holds the grains of the all-DEM specimen of ``seed`` that lie wholly
    inside the zone (the same grains, with the same generation history, in both models; the
    grains cut by the zone's faces are left out, and the zone settles into their room at rest)."""
    from cosim.apps.footing import Geometry
    from cosim.case import load_case
    case, _ = load_case(CASE, [f"zone.width={width}", f"zone.depth={depth}"])
    g = Geometry.of(case)
    with np.load(OUT / f"all_dem_seed{seed}" / "dem" / "specimen.npz") as data:
        pos, radii = data["positions"], data["radii"]
    inside = ((pos[:, 0] - radii >= g.zone_x0) & (pos[:, 0] + radii <= g.zone_x0 + g.zone_width)
              & (pos[:, 2] - radii >= g.zone_bottom))
    packing = OUT / f"carved_seed{seed}.npz"
    np.savez(packing, positions=pos[inside], radii=radii[inside])  # the model's coordinates
    head, rest = CASE.read_text().split("[specimen]", 1)
    path = OUT / f"carved_seed{seed}.toml"
    path.write_text(head + f'[specimen]\nsource = "file"\nfile = "{packing}"\n\n' + rest[rest.index("[footing]"):])
    return path


def statistics(runs):
    """Mean over seeds of q at each level and its standard error s/√n, the mean curve and its
    range, grains, wall-clock and rest balance."""
    q = np.array([[bearing_pressure_at(s)[k] for k in SETTLEMENT_LEVELS] for s, _ in runs])
    curves = np.array([np.interp(GRID, s["settlement_ratio"], s["bearing_pressure"]) for s, _ in runs])
    balance = [i["rest"]["interface_force_over_weight"] for _, i in runs]
    error = q.std(axis=0, ddof=1) / np.sqrt(len(q)) if len(q) > 1 else np.zeros(q.shape[1])
    return {"q": q.mean(axis=0), "error": error, "seeds": len(q), "curve": curves.mean(axis=0),
            "low": curves.min(axis=0), "high": curves.max(axis=0), "grains": np.mean([i["grains"] for _, i in runs]),
            "wall": np.mean([i["wall_clock_s"]["total_s"] for _, i in runs]),
            "balance": None if balance[0] is None else (min(balance), max(balance))}


def table(results, references):
    """Markdown table; each row's (±%) and wall-clock ratio are against its reference row
    ``references[name]`` (the all-DEM rows are their own)."""
    head = ("| model | seeds | grains | interface force / weight at rest | "
            + " | ".join(f"q at s/B = {100 * k:.0f} % [kPa]" for k in SETTLEMENT_LEVELS)
            + " | wall-clock [s] (all-DEM / this) |")
    lines = [head, "|" + "---|" * (5 + len(SETTLEMENT_LEVELS))]
    for name, r in results.items():
        reference = results[references[name]]
        cells = []
        for i in range(len(SETTLEMENT_LEVELS)):
            cell = f"{r['q'][i] / 1e3:.2f} ± {r['error'][i] / 1e3:.2f}"
            if r is not reference:
                cell += f" ({100 * (r['q'][i] - reference['q'][i]) / reference['q'][i]:+.0f} %)"
            cells.append(cell)
        balance = "-" if r["balance"] is None else f"{r['balance'][0]:.4f} – {r['balance'][1]:.4f}"
        ratio = "" if r is reference else f" ({reference['wall'] / r['wall']:.1f}x)"
        lines.append(f"| {name} | {r['seeds']} | {r['grains']:.0f} | {balance} | " + " | ".join(cells)
                     + f" | {r['wall']:.0f}{ratio} |")
    return "\n".join(lines)


def plot(results, references, path):
    """Two panels of mean load-settlement curves with their seed ranges: the zone sizes against
    all-DEM, and the variants against their all-DEM references."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sizes = [name for name in results if references[name] == "all-DEM" and "mm," not in name]
    variants = ["all-DEM", sizes[-1]] + [name for name in results if name not in sizes]
    fig, axes = plt.subplots(1, 2, figsize=(12.0, 4.6), sharey=True)
    for ax, names, title in ((axes[0], sizes, "DEM zones of growing size"),
                             (axes[1], variants, "on the 105 x 40 mm zone: what the gap depends on")):
        for name in names:
            r = results[name]
            reference = references[name] == name
            line, = ax.plot(100 * GRID, r["curve"] / 1e3, lw=2.2 if reference else 1.4,
                            ls="--" if reference and name != "all-DEM" else "-", label=f"{name} ({r['seeds']} seeds)")
            ax.fill_between(100 * GRID, r["low"] / 1e3, r["high"] / 1e3, color=line.get_color(), alpha=0.12, lw=0)
        for level in SETTLEMENT_LEVELS:
            ax.axvline(100 * level, color="0.85", lw=0.8, zorder=0)
        ax.set_xlabel("settlement s / B [%]")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("bearing pressure q [kPa]")
    fig.suptitle("strip footing, B/d50 = 6: coupled (DEM zone + FE) against all-DEM; mean over seeds, band = range")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(11, 19)),
                        help="seeds of the all-DEM model and the zone sizes")
    parser.add_argument("--variant-seeds", type=int, default=3,
                        help="the variants (E/2, frictionless, carved, layered) take the first N seeds")
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--largest-only", action="store_true", help="all-DEM and the largest zone only")
    args = parser.parse_args()
    results, references = {}, {}
    results["all-DEM"] = statistics([run("all_dem", seed, args.ranks, "dem") for seed in args.seeds])
    for width, depth in ZONES[-1:] if args.largest_only else ZONES:
        label = f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm"
        runs = [run(label, seed, args.ranks, "coupled", "--set", f"zone.width={width}", "--set", f"zone.depth={depth}")
                for seed in args.seeds]
        results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm"] = statistics(runs)
    width, depth = ZONES[-1]
    few = [] if args.largest_only else args.seeds[:args.variant_seeds]
    for name, extra in VARIANTS if few else []:
        label = f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm_{name.replace(' ', '_').replace('/', '_')}"
        runs = [run(label, seed, args.ranks, "coupled", "--set", f"zone.width={width}", "--set", f"zone.depth={depth}",
                    *extra) for seed in few]
        results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm, {name}"] = statistics(runs)
    if few:
        runs = [run(f"zone_{1e3 * width:.0f}x{1e3 * depth:.0f}mm_carved", seed, args.ranks, "coupled", "--set",
                    f"zone.width={width}", "--set", f"zone.depth={depth}", case=carved_case(seed, width, depth))
                for seed in few]
        results[f"coupled, zone {1e3 * width:.0f} x {1e3 * depth:.0f} mm, grains carved from the all-DEM's"] = \
            statistics(runs)
    for name in results:
        references[name] = "all-DEM"
    text = table(results, references)
    text += (f"\n\nseeds {args.seeds} (variants: {few}); q: mean ± its standard error s/√n over the seeds; "
             "(±%): the coupled mean against its all-DEM mean\n")
    print(text)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "table.md").write_text(text)
    plot(results, references, OUT / "load_settlement.png")
    picture = "footing_small_seeds.png" if args.largest_only else "footing_zone_size.png"
    plot(results, references, ROOT / "docs" / picture)


if __name__ == "__main__":
    main()
