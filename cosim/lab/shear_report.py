"""Direct shear results: the run summary, the standard plots and the Mohr–Coulomb fit
(docs/design.md §3.6–§3.7). Pure post-processing of the CSV columns; no engine here."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np


def read_series(path):
    """CSV → dict of float arrays by column name."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]} if rows else {}


def friction_angle(stress_ratio):
    """φ = atan(τ/σ_n) in degrees."""
    return math.degrees(math.atan(stress_ratio))


def summarize(delta, tau, sigma, dz, residual_fraction=0.2):
    """Peak and residual τ/σ_n with their friction angles, and the volume change sign.

    ``delta`` shear displacement [m], ``tau``/``sigma`` stresses [Pa], ``dz`` vertical
    displacement of the top plate [m] (up = dilation). Residual = mean over the last
    ``residual_fraction`` of the shear displacement.
    """
    delta, tau, sigma, dz = (np.asarray(a, float) for a in (delta, tau, sigma, dz))
    ratio = tau / sigma
    k = int(np.argmax(ratio))
    last = delta >= delta[-1] - residual_fraction * (delta[-1] - delta[0])
    peak, residual = float(ratio[k]), float(np.mean(ratio[last]))
    return {
        "peak_stress_ratio": peak, "peak_friction_angle_deg": friction_angle(peak),
        "peak_shear_displacement": float(delta[k]), "peak_shear_stress": float(tau[k]),
        "residual_stress_ratio": residual, "residual_friction_angle_deg": friction_angle(residual),
        "residual_shear_stress": float(np.mean(tau[last])),
        "vertical_displacement_end": float(dz[-1]), "vertical_displacement_min": float(np.min(dz)),
        "vertical_displacement_max": float(np.max(dz)),
        "volume_change": "dilation" if dz[-1] > 0 else "contraction",
        "softening": bool(peak > 1.05 * residual and not last[k]),  # a peak before the residual window
    }


def mohr_coulomb_fit(normal_stress, shear_stress):
    """Least-squares τ = c + σ_n tan φ; returns (φ [deg], c [Pa], R²).

    With a single point the envelope goes through the origin (c = 0)."""
    s, t = np.asarray(normal_stress, float), np.asarray(shear_stress, float)
    if len(s) == 1:
        return friction_angle(t[0] / s[0]), 0.0, 1.0
    slope, c = np.polyfit(s, t, 1)
    pred = c + slope * s
    ss = float(np.sum((t - t.mean()) ** 2))
    r2 = 1.0 - float(np.sum((t - pred) ** 2)) / ss if ss > 0 else 1.0
    return math.degrees(math.atan(slope)), float(c), r2


def mohr_coulomb_fit_circles(centre, radius):
    """The Mohr–Coulomb envelope τ = c + σ tan φ tangent to Mohr circles of centres
    s = (σ₁ + σ₃)/2 and radii t = (σ₁ − σ₃)/2: least-squares t = c cos φ + s sin φ;
    returns (φ [deg], c [Pa], R² of that line). One circle: through the origin (c = 0)."""
    s, t = np.asarray(centre, float), np.asarray(radius, float)
    if len(s) == 1:
        return math.degrees(math.asin(t[0] / s[0])), 0.0, 1.0
    slope, intercept = np.polyfit(s, t, 1)
    pred = intercept + slope * s
    ss = float(np.sum((t - t.mean()) ** 2))
    r2 = 1.0 - float(np.sum((t - pred) ** 2)) / ss if ss > 0 else 1.0
    phi = math.asin(slope)
    return math.degrees(phi), float(intercept / math.cos(phi)), r2


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_run(series, out_dir, title):
    """shear_stress.png (τ–δ), vertical_displacement.png, void_ratio.png (e–δ) in ``out_dir``."""
    plt = _plt()
    out_dir = Path(out_dir)
    d = series["shear_displacement"] * 1e3
    paths = []
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(d, series["shear_stress"] / 1e3, label="τ (shear force / A_c)")
    ax.plot(d, series["normal_stress"] / 1e3, "--", lw=0.8, label="σ_n (servo)")
    ax.set(xlabel="shear displacement δ [mm]", ylabel="stress [kPa]", title=title)
    ax.grid(True, alpha=0.3)
    ax.legend()
    paths.append(_save(fig, out_dir / "shear_stress.png"))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(d, series["vertical_displacement"] * 1e3)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel="shear displacement δ [mm]", ylabel="vertical displacement of the top plate [mm] (+ = dilation)",
           title=title)
    ax.grid(True, alpha=0.3)
    paths.append(_save(fig, out_dir / "vertical_displacement.png"))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(d, series["void_ratio"], label="whole sample")
    ax.plot(d, series["void_ratio_sphere_045h"], label="measuring sphere r = 0.45 h")
    ax.plot(d, series["void_ratio_sphere_020h"], label="measuring sphere r = 0.20 h (shear zone)")
    ax.set(xlabel="shear displacement δ [mm]", ylabel="void ratio e [-]", title=title)
    ax.grid(True, alpha=0.3)
    ax.legend()
    paths.append(_save(fig, out_dir / "void_ratio.png"))
    return paths


def _save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    _plt().close(fig)
    return path


def plot_series(results, fits, path):
    """Mohr–Coulomb envelopes per specimen. Direct shear: peak (filled) and residual (open)
    τ against σ_n. Triaxial: the Mohr circles at the peak (solid) and at the critical
    state (dotted), with their envelopes."""
    plt = _plt()
    from matplotlib.patches import Arc
    fig, ax = plt.subplots(figsize=(6, 4.5))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    top = 0.0
    for k, (label, rows) in enumerate(results.items()):
        c = colors[k % len(colors)]
        triaxial = "cell_pressure" in rows[0]
        if triaxial:
            for r in rows:
                for strength, ls in (("peak", "-"), ("residual", ":")):
                    s, t = r[f"{strength}_normal_stress"] / 1e3, r[f"{strength}_shear_stress"] / 1e3
                    ax.add_patch(Arc((s, 0.0), 2 * t, 2 * t, theta1=0, theta2=180, color=c, ls=ls, lw=0.8))
                    top = max(top, s + t)
        else:
            s = np.array([r["normal_stress"] for r in rows]) / 1e3
            ax.plot(s, [r["peak_shear_stress"] / 1e3 for r in rows], "o", color=c)
            ax.plot(s, [r["residual_shear_stress"] / 1e3 for r in rows], "s", mfc="none", color=c)
            top = max(top, s.max())
        xs = np.linspace(0, top * 1.1, 20)
        for strength, ls in (("peak", "-"), ("residual", ":")):
            phi, coh, _ = fits[label][strength]
            name = "critical state" if triaxial and strength == "residual" else strength
            ax.plot(xs, coh / 1e3 + xs * math.tan(math.radians(phi)), ls, color=c,
                    label=f"{label} {name}: φ = {phi:.1f}°, c = {coh / 1e3:.1f} kPa")
    ax.set(xlabel="normal stress σ [kPa]", ylabel="shear stress τ [kPa]", title="Mohr–Coulomb envelopes")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.set_aspect("equal" if any("cell_pressure" in r[0] for r in results.values()) else "auto")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, Path(path))


def plot_series_curves(curves, path):
    """Every run of a series. Direct shear: τ/σ_n, vertical displacement and shear-zone void
    ratio against δ. Triaxial: mobilised sin φ, ε_v and e against ε₁."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for label, s in curves.items():
        if "axial_strain" in s:
            e1 = 100 * s["axial_strain"]
            axes[0].plot(e1, s["sin_phi_mobilised"], label=label)
            axes[1].plot(e1, 100 * s["volumetric_strain"], label=label)
            axes[2].plot(e1, s["void_ratio"], label=label)
            labels = ("ε₁ [%]", "(σ₁ − σ₃)/(σ₁ + σ₃) = sin φ [-]", "ε_v [%] (contraction +)", "void ratio e [-]")
            continue
        d = s["shear_displacement"] * 1e3
        axes[0].plot(d, s["shear_stress"] / s["normal_stress"], label=label)
        axes[1].plot(d, s["vertical_displacement"] * 1e3, label=label)
        axes[2].plot(d, s["void_ratio_sphere_020h"], label=label)
        labels = ("δ [mm]", "τ/σ_n [-]", "vertical displacement [mm]", "void ratio, sphere 0.20 h [-]")
    for ax, ylabel in zip(axes, labels[1:], strict=True):
        ax.set(xlabel=labels[0], ylabel=ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    return _save(fig, Path(path))
