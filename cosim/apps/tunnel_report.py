"""What a tunnelling engineer reads from an ``embedded`` run with linings (docs/guide/tunnel.md):
the settlement trough against the Gaussian trough of Peck (1969), and the lining's thrust and
bending moment around the ring as polar plots. Runs on rank 0, from the files of a model's
output folder (``settlement_trough.csv``, ``<volume>_sections.csv``), so that a study can
read several runs the same way."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class PeckTrough:
    """The Gaussian trough S(x) = S_max exp(−x² / 2i²) of Peck (1969), x across the tunnel from
    its axis: S_max (m), i (m, the distance of the inflection point), and over the tunnel's
    axis depth z0 the trough-width parameter K = i / z0 (O'Reilly & New 1982: 0.25–0.45 in
    sands and gravels). The trough's volume per metre of tunnel is V_s = √(2π) i S_max; over
    the tunnel's area A = π D² / 4 it is the surface volume loss."""
    s_max: float
    i: float
    z0: float

    @property
    def K(self) -> float:
        return self.i / self.z0

    def volume(self) -> float:
        """V_s (m³ per m of tunnel, both sides of the axis)."""
        return math.sqrt(2.0 * math.pi) * self.i * self.s_max

    def __call__(self, x):
        return self.s_max * np.exp(-np.asarray(x, float) ** 2 / (2.0 * self.i**2))


def fit_peck(x, settlement, z0) -> PeckTrough:
    """Least-squares fit of S_max and i to the settlements (m, down +) at offsets ``x`` (m)
    from the tunnel's axis (scipy's curve_fit on x / z0 and S / max S, started from the
    largest settlement and K = 1/3)."""
    from scipy.optimize import curve_fit
    x, settlement = np.abs(np.asarray(x, float)) / z0, np.asarray(settlement, float)
    scale = float(np.abs(settlement).max()) or 1.0       # fitted in units of order one
    (s_max, k), _ = curve_fit(lambda x, s, k: s * np.exp(-x**2 / (2.0 * k**2)), x, settlement / scale,
                              p0=[1.0, 1.0 / 3.0], bounds=([0.0, 1e-6], [np.inf, 10.0]))
    return PeckTrough(float(s_max) * scale, float(k) * z0, float(z0))


def read_trough(path, axis_x):
    """(offsets from the axis, settlements) of a ``settlement_trough.csv``, every source."""
    rows = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding=None)
    return np.abs(rows["x"] - axis_x), rows["settlement"]


def read_sections(path):
    """{column: array} of a ``<volume>_sections.csv``."""
    rows = np.genfromtxt(path, delimiter=",", names=True)
    return {name: rows[name] for name in rows.dtype.names}


def trough_summary(trough: PeckTrough, outer_diameter: float, volume_loss: float) -> dict:
    """The fitted trough for summary.json: S_max, i, K and the surface volume loss V_s / A
    against the lining's applied V_L."""
    area = math.pi * outer_diameter**2 / 4.0
    return {"s_max_m": trough.s_max, "i_m": trough.i, "z0_m": trough.z0, "K": trough.K,
            "surface_volume_loss": trough.volume() / area, "lining_volume_loss": volume_loss}


def plot_polar(sections, path, title):
    """N(θ) and M(θ) around the ring as a tunnelling program draws them: the ring a dashed circle
    (the zero line), each value an offset from it along the radius, outward for compression (N)
    and for the intrados in tension (M), scaled by the largest magnitude; θ from the crown,
    clockwise. One curve per entry of ``sections`` ({label: (angles_deg, thrust N/m, moment
    N·m/m)}); a half model's half ring is mirrored about the axis."""
    from cosim.plots import plt
    fig, axes = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(10.0, 5.2))
    circle = np.linspace(0.0, 2.0 * np.pi, 181)
    for ax, column, heading in zip(axes, (1, 2), ("thrust N [N/m], compression outward",
                                                    "bending moment M [N·m/m], intrados in tension outward"),
                                   strict=True):
        scale = max(float(np.abs(entry[column]).max()) for entry in sections.values()) or 1.0
        for label, entry in sections.items():
            theta, values = _whole_ring(np.radians(entry[0]), entry[column])
            ax.plot(theta, 1.0 + values / scale, label=label)
        ax.plot(circle, np.ones_like(circle), "k--", linewidth=0.8)
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        ax.set_ylim(0.0, 2.0)
        ax.set_yticks([0.0, 1.0, 2.0])
        ax.set_yticklabels([f"{-scale:.3g}", "0", f"{scale:.3g}"])
        ax.set_title(heading, fontsize=10)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=len(sections), fontsize=9)
    fig.suptitle(title)
    fig.tight_layout(rect=(0.0, 0.06, 1.0, 1.0))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _whole_ring(theta, values):
    """Angles and values around the whole ring, closed: a half ring (θ within [0, π]) mirrored
    about the axis."""
    if theta.min() >= 0.0:
        theta, values = np.concatenate([theta, 2.0 * np.pi - theta[::-1]]), np.concatenate([values, values[::-1]])
    order = np.argsort(theta % (2.0 * np.pi))
    return np.append(theta[order], theta[order][0]), np.append(values[order], values[order][0])


def plot_trough(troughs, path, title):
    """Settlement against the offset from the axis, the measured points and the fitted Peck
    trough of each entry of ``troughs`` ({label: (offsets, settlements, PeckTrough)})."""
    from cosim.plots import plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for index, (label, (x, settlement, fit)) in enumerate(troughs.items()):
        colour = f"C{index}"
        ax.plot(1e3 * x, 1e3 * settlement, ".", color=colour, markersize=3, alpha=0.5)
        grid = np.linspace(0.0, float(np.max(x)), 200)
        ax.plot(1e3 * grid, 1e3 * fit(grid), color=colour,
                label=f"{label}: S_max {1e3 * fit.s_max:.3f} mm, i {1e3 * fit.i:.1f} mm, K = i/z0 {fit.K:.2f}")
    low, high = ax.get_ylim()
    ax.set_ylim(max(low, high), min(0.0, low, high))     # settlement down, from zero
    ax.set_xlabel("offset from the tunnel's axis x [mm]")
    ax.set_ylabel("surface settlement [mm]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report_linings(case, out_dir: Path, label: str, outer_radii: dict, ground_height=None) -> dict:
    """For each lining (its outer radius in ``outer_radii``): ``<volume>_polar.png`` (at rest and
    at the end of the loading), its diameters' change over the loading (series.csv) and, with a
    ground surface at ``ground_height`` (m along −g), the Peck fit of the trough
    (``settlement_trough.png``); returns summary.json's "linings" entry."""
    from cosim.lab.shear_report import read_series
    em = case.embedded
    up = -np.asarray(case.dem.gravity, float) / np.linalg.norm(case.dem.gravity)
    series = read_series(out_dir / "series.csv")
    summary = {}
    for lining in em.linings:
        sections = read_sections(out_dir / f"{lining.volume}_sections.csv")
        plot_polar({"at rest": (sections["angle_deg"], sections["thrust_at_rest"], sections["moment_at_rest"]),
                    "end of loading": (sections["angle_deg"], sections["thrust_end"], sections["moment_end"])},
                   out_dir / f"{lining.volume}_polar.png", f"{case.case.name} ({label}): lining '{lining.volume}'")
        entry = {"outer_radius_m": outer_radii[lining.volume],
                 "thrust_at_rest_max": float(sections["thrust_at_rest"].max()),
                 "thrust_end_max": float(sections["thrust_end"].max()),
                 "moment_at_rest_max_abs": float(np.abs(sections["moment_at_rest"]).max()),
                 "moment_end_max_abs": float(np.abs(sections["moment_end"]).max())}
        for direction in ("vertical", "horizontal"):   # during the loading: from row 0 (at rest)
            column = series[f"{lining.volume}_diameter_change_{direction}"]
            entry[f"diameter_change_{direction}_loading"] = float(column[-1] - column[0])
        if ground_height is not None:
            depth = ground_height - float(np.asarray(lining.centre, float) @ up)
            x, settlement = read_trough(out_dir / "settlement_trough.csv", lining.centre[0])
            fit = fit_peck(x, settlement, depth)
            entry["trough"] = trough_summary(fit, 2.0 * outer_radii[lining.volume], lining.volume_loss)
            plot_trough({label: (x, settlement, fit)}, out_dir / "settlement_trough.png",
                        f"{case.case.name} ({label}): settlement trough against Peck (1969)")
        summary[lining.volume] = entry
    return summary


def ground_height(triangles, gravity) -> float:
    """The ground surface's highest point along −g (m)."""
    up = -np.asarray(gravity, float) / np.linalg.norm(gravity)
    return float((triangles.reshape(-1, 3) @ up).max())
