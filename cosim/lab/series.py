"""``cosim series``: the same specimen(s) sheared at several normal stresses, and the
Mohr–Coulomb envelope τ = c + σ_n tan φ fitted per specimen, for peak and residual
strength (docs/design.md §3.7).

Each case file is one specimen (e.g. dense and loose); the specimen is generated once
per case and reused at every stress, as identical specimens are in the laboratory.
Outputs under ``OUT/``: ``<case>/specimen.npz``, ``<case>/<σ>kPa/`` (a full run each),
``mohr_coulomb.csv`` and ``.md`` (the table of φ and c), ``mohr_coulomb.png`` and
``series_curves.png``. Runs that finished with the same resolved case are reused, so
an interrupted series continues where it stopped (delete a folder to redo it).
"""
from __future__ import annotations

import csv
import json
import time
from pathlib import Path

from cosim.outputs import atomic_write_text, say


def finished(out_dir, resolved):
    """A run finished earlier with the same resolved case (an interrupted series resumes)."""
    import tomllib

    from cosim.outputs import _drop_none
    try:
        return (out_dir / "summary.json").exists() and \
            tomllib.loads((out_dir / "case.resolved.toml").read_text()) == _drop_none(resolved)
    except (OSError, ValueError):
        return False


def validate_series(case_paths, stresses, out_root, overrides=()):
    """Every (case, σ_n) run of the series, validated before any of them runs: a list of
    (label, stress, Prepared)."""
    from cosim.apps import Prepared
    from cosim.apps import direct_shear as app
    from cosim.case import load_case
    from cosim.errors import CaseError
    from cosim.outputs import check_output_folder

    out_root = Path(out_root)
    check_output_folder(out_root)
    jobs = []
    for path in case_paths:
        for stress in stresses:
            case, resolved = load_case(path, list(overrides) + [f"direct_shear.normal_stress={float(stress)!r}"])
            if case.case.kind != "direct_shear":
                raise CaseError(path, "case.kind", case.case.kind, "cosim series runs cases of kind 'direct_shear'")
            out_dir = out_root / case.case.name / f"{stress / 1e3:g}kPa"
            built = app.prepare(case, path, out_dir, False)
            jobs.append((case.case.name, stress, Prepared(case, resolved, Path(path), out_dir, False, built)))
    return jobs


def run_series(jobs, out_root):
    """Run the validated ``jobs`` (:func:`validate_series`), reusing finished runs, and fit
    the Mohr–Coulomb envelopes."""
    from cosim.apps import direct_shear as app
    from cosim.lab.shear_report import mohr_coulomb_fit, plot_series, plot_series_curves, read_series

    out_root = Path(out_root)
    t0 = time.perf_counter()
    results, curves = {}, {}
    for label, stress, prepared in jobs:
        out_dir = prepared.out_dir
        out_dir.mkdir(parents=True, exist_ok=True)
        if finished(out_dir, prepared.resolved):
            say(f"[series] {label} at sigma_n = {stress / 1e3:g} kPa: reusing the finished run in {out_dir}")
        else:
            say(f"[series] {label} at sigma_n = {stress / 1e3:g} kPa -> {out_dir}")
            app.run(prepared, specimen_cache=out_root / label / "specimen.npz")
        summary = json.loads((out_dir / "summary.json").read_text())
        results.setdefault(label, []).append(summary)
        curves[f"{label} {stress / 1e3:g} kPa"] = read_series(out_dir / "series.csv")
    fits, rows = {}, []
    for label, runs in results.items():
        sigma = [r["normal_stress"] for r in runs]
        fits[label] = {kind: mohr_coulomb_fit(sigma, [r[f"{kind}_shear_stress"] for r in runs])
                       for kind in ("peak", "residual")}
        for kind, (phi, c, r2) in fits[label].items():
            rows.append({"specimen": label, "strength": kind, "phi_deg": round(phi, 2), "c_kPa": round(c / 1e3, 2),
                         "R2": round(r2, 4), "stresses_kPa": " ".join(f"{s / 1e3:g}" for s in sigma),
                         "void_ratio_generated": runs[0].get("void_ratio_generated")})
    with open(out_root / "mohr_coulomb.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = ["| specimen | strength | φ [°] | c [kPa] | R² | σ_n [kPa] | e generated |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        e = r["void_ratio_generated"]
        table.append(f"| {r['specimen']} | {r['strength']} | {r['phi_deg']:.1f} | {r['c_kPa']:.1f} | {r['R2']:.3f} | "
                     f"{r['stresses_kPa']} | {e if e is None else format(e, '.3f')} |")
    runs_table = ["",
                  "| run | e consolidated | peak τ/σ_n | φ_peak [°] | residual τ/σ_n | φ_res [°] | "
                  "Δz end [mm] | I | wall clock [s] |",
                  "|---|---|---|---|---|---|---|---|---|"]
    for label, runs in results.items():
        for r in runs:
            runs_table.append(
                f"| {label} {r['normal_stress'] / 1e3:g} kPa | {r['void_ratio_consolidated']:.3f} | "
                f"{r['peak_stress_ratio']:.3f} | {r['peak_friction_angle_deg']:.1f} | "
                f"{r['residual_stress_ratio']:.3f} | "
                f"{r['residual_friction_angle_deg']:.1f} | {r['vertical_displacement_end'] * 1e3:+.3f} | "
                f"{r['inertial_number']:.1e} | {r['wall_clock_total_s']:.0f} |")
    wall = time.perf_counter() - t0
    text = "\n".join(table + runs_table + ["", f"series wall clock: {wall:.0f} s"]) + "\n"
    atomic_write_text(out_root / "mohr_coulomb.md", text)
    plot_series(results, fits, out_root / "mohr_coulomb.png")
    plot_series_curves(curves, out_root / "series_curves.png")
    say(text)
    return fits
