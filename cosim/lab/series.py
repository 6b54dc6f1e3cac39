"""``cosim series``: the same specimen(s) sheared at several normal stresses (direct_shear
cases) or compressed at several cell pressures σ₃ (triaxial cases), and the Mohr–Coulomb
envelope τ = c + σ tan φ fitted per specimen, for peak and residual (critical-state)
strength (docs/design.md §3.7, §3.10).

Direct shear: τ = c + σ_n tan φ by least squares through the (σ_n, τ) points. Triaxial: the
envelope touching the Mohr circles, from the line t = c cos φ + s sin φ fitted through the
circles' centres s = (σ₁ + σ₃)/2 and radii t = (σ₁ − σ₃)/2.

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


#: the key a series sets in each kind of lab case
STRESS_KEY = {"direct_shear": "direct_shear.normal_stress", "triaxial": "triaxial.cell_pressure"}


def lab_app(kind):
    """The app module of a lab case kind."""
    import importlib
    return importlib.import_module(f"cosim.apps.{kind}")


def validate_series(case_paths, stresses, out_root, overrides=()):
    """Every (case, stress) run of the series, validated before any of them runs: a list of
    (label, stress, Prepared)."""
    from cosim.apps import Prepared
    from cosim.case import load_case
    from cosim.errors import CaseError
    from cosim.outputs import check_output_folder

    out_root = Path(out_root)
    check_output_folder(out_root)
    jobs = []
    for path in case_paths:
        kind = load_case(path, list(overrides))[0].case.kind
        if kind not in STRESS_KEY:
            raise CaseError(path, "case.kind", kind, f"cosim series runs cases of kind {' or '.join(STRESS_KEY)}")
        app = lab_app(kind)
        for stress in stresses:
            case, resolved = load_case(path, list(overrides) + [f"{STRESS_KEY[kind]}={float(stress)!r}"])
            out_dir = out_root / case.case.name / f"{stress / 1e3:g}kPa"
            built = app.prepare(case, path, out_dir, False)
            jobs.append((case.case.name, stress, Prepared(case, resolved, Path(path), out_dir, False, built)))
    return jobs


def run_series(jobs, out_root):
    """Run the validated ``jobs`` (:func:`validate_series`), reusing finished runs, and fit
    the Mohr–Coulomb envelopes."""
    from cosim.lab.shear_report import plot_series, plot_series_curves, read_series

    out_root = Path(out_root)
    t0 = time.perf_counter()
    results, curves = {}, {}
    for label, stress, prepared in jobs:
        out_dir = prepared.out_dir
        out_dir.mkdir(parents=True, exist_ok=True)
        if finished(out_dir, prepared.resolved):
            say(f"[series] {label} at {stress / 1e3:g} kPa: reusing the finished run in {out_dir}")
        else:
            say(f"[series] {label} at {stress / 1e3:g} kPa -> {out_dir}")
            lab_app(prepared.case.case.kind).run(prepared, specimen_cache=out_root / label / "specimen.npz")
        summary = json.loads((out_dir / "summary.json").read_text())
        results.setdefault(label, []).append(summary)
        curves[f"{label} {stress / 1e3:g} kPa"] = read_series(out_dir / "series.csv")
    fits, rows = {}, []
    for label, runs in results.items():
        fits[label] = {strength: envelope(runs, strength) for strength in ("peak", "residual")}
        for strength, (phi, c, r2) in fits[label].items():
            rows.append({"specimen": label, "strength": strength, "phi_deg": round(phi, 2), "c_kPa": round(c / 1e3, 2),
                         "R2": round(r2, 4), "stresses_kPa": " ".join(f"{test_stress(r) / 1e3:g}" for r in runs),
                         "void_ratio_generated": runs[0].get("void_ratio_generated")})
    with open(out_root / "mohr_coulomb.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = ["| specimen | strength | φ [°] | c [kPa] | R² | σ_n or σ₃ [kPa] | e generated |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        e = r["void_ratio_generated"]
        table.append(f"| {r['specimen']} | {r['strength']} | {r['phi_deg']:.1f} | {r['c_kPa']:.1f} | {r['R2']:.3f} | "
                     f"{r['stresses_kPa']} | {e if e is None else format(e, '.3f')} |")
    runs_table = ["",
                  "| run | e consolidated | φ_peak [°] (at) | φ_res [°] | volume change at the end | I | "
                  "wall clock [s] |",
                  "|---|---|---|---|---|---|---|"]
    for label, runs in results.items():
        for r in runs:
            runs_table.append(
                f"| {label} {test_stress(r) / 1e3:g} kPa | {r['void_ratio_consolidated']:.3f} | "
                f"{r['peak_friction_angle_deg']:.1f} ({_peak_at(r)}) | {r['residual_friction_angle_deg']:.1f} | "
                f"{_volume_change(r)} | {r['inertial_number']:.1e} | {r['wall_clock_total_s']:.0f} |")
    wall = time.perf_counter() - t0
    text = "\n".join(table + runs_table + ["", f"series wall clock: {wall:.0f} s"]) + "\n"
    atomic_write_text(out_root / "mohr_coulomb.md", text)
    plot_series(results, fits, out_root / "mohr_coulomb.png")
    plot_series_curves(curves, out_root / "series_curves.png")
    say(text)
    return fits


def test_stress(summary):
    """σ_n of a direct shear run, σ₃ of a triaxial one."""
    return summary["normal_stress"] if "normal_stress" in summary else summary["cell_pressure"]


def envelope(runs, strength):
    """(φ [deg], c [Pa], R²) of one specimen's runs, for 'peak' or 'residual' (module docstring)."""
    from cosim.lab.shear_report import mohr_coulomb_fit, mohr_coulomb_fit_circles
    if "normal_stress" in runs[0]:
        return mohr_coulomb_fit([r["normal_stress"] for r in runs], [r[f"{strength}_shear_stress"] for r in runs])
    return mohr_coulomb_fit_circles([r[f"{strength}_normal_stress"] for r in runs],
                                    [r[f"{strength}_shear_stress"] for r in runs])


def _peak_at(r):
    if "peak_shear_displacement" in r:
        return f"δ = {r['peak_shear_displacement'] * 1e3:.1f} mm"
    return f"ε₁ = {100 * r['peak_axial_strain']:.1f} %"


def _volume_change(r):
    if "vertical_displacement_end" in r:
        return f"Δz {r['vertical_displacement_end'] * 1e3:+.3f} mm"
    return f"ε_v {100 * r['volumetric_strain_end']:+.2f} % (contraction +)"
