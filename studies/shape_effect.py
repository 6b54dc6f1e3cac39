"""The shape effect (issue 40 item 5): the peak and critical-state friction angles of the small
triaxial sand (``runs/triaxial_small.toml``: the thesis sand × 2, 2.36–6 mm, a 40 mm cube,
σ₃ = 100 kPa, compressed to ε₁ = 25 %) made of spheres and of two-sphere grains of aspect
ratio (length over width) 1.2, 1.5 and 2.0 (``ClumpTemplate.line(2, ·)``), over several
packings (case seeds). Every shape takes the same sieve curve (equal-volume diameters), the
same materials and the same generation protocol: the case's dense one, under-compaction to
e = 0.65 with deposition friction 0.05 (a shape that cannot reach it ends looser, and its
consolidated void ratio is reported beside its angles).

Runs each (shape, seed) unless its summary exists (on 2 cores about 1 minute a run of
spheres and 4–8 of clumps: clumps take a smaller time step and generate slower), then
writes ``runs/out/shape_effect/table.md`` (per run and the mean ± standard deviation per shape)
and the plot ``docs/shape_effect.png`` (φ_peak and φ_cs against aspect ratio, every packing a
dot, the means joined).

    python studies/shape_effect.py [--seeds 1 2 3] [--aspects 1.2 1.5 2.0]
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
from de_domain.clumps import ClumpTemplate  # noqa: E402

BASE = ROOT / "runs" / "triaxial_small.toml"
OUT = ROOT / "runs" / "out" / "shape_effect"
PNG = ROOT / "docs" / "shape_effect.png"


def case_text(aspect):
    """The base case, made of two-sphere grains of ``aspect`` (None: spheres), no ParaView frames."""
    text = BASE.read_text().replace('vtk = true ', 'vtk = false')
    if aspect is None:
        return text
    rod = ClumpTemplate.line(2, aspect)
    members = ", ".join(f"[{x:.6g}, 0.0, 0.0, 1.0]" for x in rod.centres[:, 0])
    text = text.replace("[specimen]\n", '[specimen]\ngrains = "clumps"\n', 1)
    return text + f"\n[[dem.clumps]]   # two equal spheres, length / width = {aspect}\nmembers = [{members}]\n"


def run(aspect, seed):
    """The summary of one run (made unless it exists)."""
    name = "spheres" if aspect is None else f"rods_{aspect:g}"
    folder = OUT / f"{name}_seed{seed}"
    summary = folder / "summary.json"
    if not summary.exists():
        folder.mkdir(parents=True, exist_ok=True)
        case = folder / "case.toml"
        case.write_text(case_text(aspect))
        cosim = Path(sys.executable).parent / "cosim"
        subprocess.run([str(cosim), "run", str(case), "--out", str(folder), "--set", f"case.seed={seed}",
                        "--set", f'case.name="shape_{name}_{seed}"'], check=True)
    return json.loads(summary.read_text())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--aspects", type=float, nargs="+", default=[1.2, 1.5, 2.0])
    args = parser.parse_args()
    shapes = [None] + list(args.aspects)
    rows = []
    for aspect in shapes:
        for seed in args.seeds:
            s = run(aspect, seed)
            rows.append({"aspect": 1.0 if aspect is None else aspect, "seed": seed, "grains": s["grains"],
                         "spheres": s.get("spheres", s["grains"]), "e_generated": s["void_ratio_generated"],
                         "e_consolidated": s["void_ratio_consolidated"], "phi_peak": s["peak_friction_angle_deg"],
                         "phi_cs": s["residual_friction_angle_deg"], "eps_v_end": s["volumetric_strain_end"],
                         "wall_clock_s": s["wall_clock_total_s"]})
    write_table(rows)
    plot(rows)


def write_table(rows):
    lines = ["| aspect ratio | seed | grains | spheres | e generated | e consolidated | φ_peak [°] | φ_cs [°] | "
             "ε_v end [%] | wall-clock [s] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['aspect']:g} | {r['seed']} | {r['grains']} | {r['spheres']} | {r['e_generated']:.3f} | "
                     f"{r['e_consolidated']:.3f} | {r['phi_peak']:.1f} | {r['phi_cs']:.1f} | "
                     f"{100 * r['eps_v_end']:+.1f} | {r['wall_clock_s']:.0f} |")
    lines += ["", "| aspect ratio | packings | e consolidated | φ_peak [°] (mean ± sd) | φ_cs [°] (mean ± sd) |",
              "|---|---|---|---|---|"]
    for aspect in sorted({r["aspect"] for r in rows}):
        group = [r for r in rows if r["aspect"] == aspect]
        (e, _), peak, cs = (_mean_sd([r[k] for r in group]) for k in ("e_consolidated", "phi_peak", "phi_cs"))
        lines.append(f"| {aspect:g} | {len(group)} | {e:.3f} | {peak[0]:.1f} ± {peak[1]:.1f} | "
                     f"{cs[0]:.1f} ± {cs[1]:.1f} |")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _mean_sd(values):
    """(mean, sample standard deviation; 0 for one value)."""
    return float(np.mean(values)), float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def plot(rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    aspects = sorted({r["aspect"] for r in rows})
    for key, label, colour in (("phi_peak", "peak", "tab:red"), ("phi_cs", "critical state", "tab:blue")):
        ax.plot([r["aspect"] for r in rows], [r[key] for r in rows], "o", color=colour, alpha=0.45, ms=5)
        means = [np.mean([r[key] for r in rows if r["aspect"] == a]) for a in aspects]
        ax.plot(aspects, means, "-", color=colour, lw=2, label=f"φ {label} (mean over packings)")
    ax.set_xlabel("aspect ratio of the grains (1 = spheres; two-sphere clumps above)")
    ax.set_ylabel("friction angle [°]")
    ax.set_title("Triaxial, σ₃ = 100 kPa, thesis sand × 2 in a 40 mm cube,\nthe same sieve curve and dense protocol "
                 "for every shape", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(PNG, dpi=130)
    print(f"wrote {PNG}")


if __name__ == "__main__":
    main()
