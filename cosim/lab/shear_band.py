"""The shear band of a direct shear test, as a picture and as a thickness (thesis §4.3.1).

**Picture.** Before shearing, the thesis paints the specimen in ten vertical stripes along
x (its YADE script, App. D.2; Fig. 4.3b), so that the shear band shows as the place where
the stripes bend (Fig. 4.5). :func:`plot_section` draws the vertical section y = L/2 at a
given shear displacement δ: every grain that the plane cuts is drawn as the circle of the
cut, of radius √(r² − (y − L/2)²). The left panel colours the grains by their stripe, the
right one by their horizontal displacement since shearing began, u_x/δ. The outlines of
the two box halves are drawn on top.

**Thickness.** Away from the box's end walls (start positions x₀ in the central half of
the box), u_x/δ is averaged in horizontal layers of the specimen. This gives the profile
ū(z), from 0 in the fixed lower half to about 1 in the moving upper half. It is fitted with
the displacement across a band whose shear strain is a Gaussian of standard deviation w:

    ū(z) = a + (b − a) · ½ [1 + erf((z − z_c) / (√2 w))]

The reported thickness is the 10–90 % width of that step, t = 2 Φ⁻¹(0.9) w = 2.563 w,
in mm and in d50. Bands in real sands are commonly reported as 10–20 d50 thick (Roscoe
1970). A direct shear box pins the band to its split plane and its height h: with h of
only 5–12 d50 (the cases here), the band reaches the plates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STRIPES = 10  # the thesis's YADE script paints ten stripes of L/10
TEN_NINETY = 2.0 * 1.2815515655446004  # 10–90 % width of a Gaussian step, in standard deviations


def stripe_of(x0, box_length, count=STRIPES):
    """The stripe (0 … count − 1) each grain started in: ⌊count · x₀ / L⌋, clipped."""
    return np.clip(np.floor(count * np.asarray(x0) / box_length), 0, count - 1).astype(int)


def displacement_profile(z, ux, delta, layer):
    """Mean u_x/δ in horizontal layers of thickness ``layer``: (layer centres, means),
    layers holding no grain left out."""
    z, ratio = np.asarray(z, float), np.asarray(ux, float) / delta
    index = np.floor((z - z.min()) / layer).astype(int)
    counts = np.bincount(index)
    sums = np.bincount(index, weights=ratio)
    filled = counts > 0
    centres = z.min() + (np.arange(counts.size) + 0.5) * layer
    return centres[filled], sums[filled] / counts[filled]


@dataclass(frozen=True)
class BandFit:
    """The fitted step ū(z) = a + (b − a) · ½ [1 + erf((z − z_c)/(√2 w))]."""

    lower: float    # a: ū below the band
    upper: float    # b: ū above the band
    centre: float   # z_c [m]
    width: float    # w [m]

    @property
    def thickness(self):
        """10–90 % width of the step [m]."""
        return TEN_NINETY * self.width

    def __call__(self, z):
        return self.lower + (self.upper - self.lower) * 0.5 * (1.0 + _erf((np.asarray(z) - self.centre)
                                                                          / (math.sqrt(2.0) * self.width)))


def _erf(x):
    from scipy.special import erf
    return erf(x)


def fit_band(centres, profile, split_height, smallest_width):
    """Least-squares fit of :class:`BandFit` to a profile (scipy's ``curve_fit``), started
    at a step at ``split_height``; ``w`` is kept at or above ``smallest_width`` (a step
    sharper than a layer cannot be resolved)."""
    from scipy.optimize import curve_fit

    def step(z, a, b, zc, w):
        return BandFit(a, b, zc, w)(z)

    start = (0.0, 1.0, split_height, max(2.0 * smallest_width, 0.05 * np.ptp(centres)))
    bounds = ([-0.5, 0.0, centres.min(), smallest_width], [1.0, 1.5, centres.max(), np.ptp(centres)])
    params, _ = curve_fit(step, centres, profile, p0=start, bounds=bounds)
    return BandFit(*map(float, params))


def measure_band(start, now, delta, box_length, d50, split_height):
    """The band fit of the grains ``now`` against their ``start`` (both with ``pos``), for
    grains that started in the central half of the box; layers of d50/2."""
    central = np.abs(start.pos[:, 0] - 0.5 * box_length) < 0.25 * box_length
    ux = now.pos[central, 0] - start.pos[central, 0]
    layer = 0.5 * d50
    centres, profile = displacement_profile(now.pos[central, 2], ux, delta, layer)
    return fit_band(centres, profile, split_height, 0.25 * layer), (centres, profile)


def band_record(fit, delta, d50):
    """The band's numbers for the summary."""
    return {"shear_displacement": delta, "thickness": fit.thickness, "thickness_d50": fit.thickness / d50,
            "centre_height": fit.centre, "displacement_below": fit.lower, "displacement_above": fit.upper}


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _section(grains, y):
    """Indices and cut radii of the grains the plane at ``y`` cuts."""
    gap = grains.pos[:, 1] - y
    cut = np.abs(gap) < grains.radius
    return np.flatnonzero(cut), np.sqrt(grains.radius[cut] ** 2 - gap[cut] ** 2)


def plot_section(path, start, now, box, fit, profile, title):
    """The section y = L/2 at one shear displacement (module docstring): stripes, u_x/δ,
    and the profile ū(z) with its fit. ``box``: dict with box_length, split_height,
    delta, plate_height."""
    plt = _plt()
    from matplotlib.collections import PatchCollection
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Circle
    L, zs, delta, top = box["box_length"], box["split_height"], box["delta"], box["plate_height"]
    index, cut = _section(now, 0.5 * L)
    stripes = stripe_of(start.pos[index, 0], L)
    ux = (now.pos[index, 0] - start.pos[index, 0]) / delta
    mm = 1e3  # drawn in mm
    L, zs, delta, top, cut, x, z = (mm * L, mm * zs, mm * delta, mm * top, mm * cut, mm * now.pos[index, 0],
                                    mm * now.pos[index, 2])
    width_ratios = [1.0, 1.0, 0.35]
    fig, axes = plt.subplots(1, 3, figsize=(13.0, 13.0 * top / (2.35 * (L + delta)) + 1.4),
                             gridspec_kw={"width_ratios": width_ratios})
    panels = ((axes[0], stripes, ListedColormap(plt.get_cmap("tab10").colors), (-0.5, STRIPES - 0.5),
               "stripe painted before shearing (x₀ in L/10)"),
              (axes[1], ux, plt.get_cmap("viridis"), (0.0, 1.0), "horizontal displacement u_x / δ"))
    for ax, values, cmap, limits, label in panels:
        circles = PatchCollection([Circle((a, b), r) for a, b, r in zip(x, z, cut, strict=True)],
                                  cmap=cmap, linewidths=0)
        circles.set_array(np.asarray(values, float))
        circles.set_clim(*limits)
        ax.add_collection(circles)
        fig.colorbar(circles, ax=ax, label=label, orientation="horizontal", pad=0.18, shrink=0.9)
        # the box halves: the lower one fixed, the upper one moved by δ, the top plate
        ax.plot([0, 0, L, L], [zs, 0, 0, zs], color="0.2", lw=1.5)
        ax.plot([delta, delta, L + delta, L + delta], [top, zs, zs, top], color="0.2", lw=1.5)
        ax.plot([delta, L + delta], [top, top], color="0.2", lw=2.5)
        ax.axhline(mm * fit.centre, color="tab:red", lw=0.8, ls="--")
        for edge in (fit.centre - 0.5 * fit.thickness, fit.centre + 0.5 * fit.thickness):
            ax.axhline(mm * edge, color="tab:red", lw=0.6, ls=":")
        ax.set_xlim(-0.02 * L, L + delta + 0.02 * L)
        ax.set_ylim(-0.02 * top, 1.04 * top)
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
    axes[0].set_ylabel("z [mm]")
    centres, mean = profile
    heights = np.linspace(centres.min(), centres.max(), 200)
    axes[2].plot(mean, mm * centres, "o", ms=3, color="0.3", label="layer mean")
    axes[2].plot(fit(heights), mm * heights, color="tab:red", label=f"fit: t = {mm * fit.thickness:.1f} mm")
    axes[2].set_xlabel("ū_x / δ")
    axes[2].set_ylim(-0.02 * top, 1.04 * top)
    axes[2].legend(loc="upper left", fontsize=8)
    axes[2].grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
