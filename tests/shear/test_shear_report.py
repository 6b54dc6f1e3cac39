"""Post-processing of a direct shear run: summary, Mohr–Coulomb fit and plots."""
import math

import numpy as np
import pytest

from cosim.lab.shear_report import mohr_coulomb_fit, plot_run, plot_series, summarize


def _dense_like(n=200):
    delta = np.linspace(0, 9e-3, n)
    ratio = (0.6 + 0.3 * np.exp(-((delta - 2e-3) / 1e-3) ** 2) * (delta < 2e-3)
             + 0.3 * np.exp(-(delta - 2e-3) / 2e-3) * (delta >= 2e-3))
    sigma = np.full(n, 100e3)
    return delta, ratio * sigma, sigma, 1e-4 * delta / 9e-3


def test_summary_peak_residual_and_dilation():
    delta, tau, sigma, dz = _dense_like()
    s = summarize(delta, tau, sigma, dz, residual_fraction=0.2)
    assert s["peak_stress_ratio"] == pytest.approx(0.9, rel=1e-3)
    assert s["peak_shear_displacement"] == pytest.approx(2e-3, abs=1e-4)
    assert s["peak_friction_angle_deg"] == pytest.approx(math.degrees(math.atan(0.9)), rel=1e-3)
    assert s["residual_stress_ratio"] < 0.65 and s["softening"]
    assert s["volume_change"] == "dilation"
    assert summarize(delta, tau, sigma, -dz)["volume_change"] == "contraction"
    hardening = summarize(delta, sigma * (0.5 + 0.1 * delta / 9e-3), sigma, -dz)
    assert hardening["peak_shear_displacement"] == pytest.approx(9e-3) and not hardening["softening"]


def test_mohr_coulomb_fit_recovers_phi_and_c():
    sigma = np.array([50e3, 100e3, 200e3])
    tau = 5e3 + sigma * math.tan(math.radians(35.0))
    phi, c, r2 = mohr_coulomb_fit(sigma, tau)
    assert phi == pytest.approx(35.0) and c == pytest.approx(5e3) and r2 == pytest.approx(1.0)
    assert mohr_coulomb_fit([100e3], [70e3])[1] == 0.0


def test_plots_are_written(tmp_path):
    delta, tau, sigma, dz = _dense_like(50)
    series = {"shear_displacement": delta, "shear_stress": tau, "normal_stress": sigma, "vertical_displacement": dz,
              "void_ratio": 0.65 + dz, "void_ratio_sphere_045h": 0.64 + dz, "void_ratio_sphere_020h": 0.66 + dz}
    paths = plot_run(series, tmp_path, "test")
    assert [p.name for p in paths] == ["shear_stress.png", "vertical_displacement.png", "void_ratio.png"]
    assert all(p.stat().st_size > 1000 for p in paths)
    rows = [{"normal_stress": s, "peak_shear_stress": 0.8 * s, "residual_shear_stress": 0.6 * s} for s in (50e3, 1e5)]
    fits = {"dense": {"peak": mohr_coulomb_fit([50e3, 1e5], [40e3, 80e3]),
                      "residual": mohr_coulomb_fit([50e3, 1e5], [30e3, 60e3])}}
    assert plot_series({"dense": rows}, fits, tmp_path / "mc.png").stat().st_size > 1000


def test_mohr_coulomb_fit_of_circles_recovers_phi_and_c():
    """Triaxial failure states on τ = c + σ tan φ: σ₁ = σ₃ N + 2 c √N, N = tan²(45° + φ/2)."""
    from cosim.lab.shear_report import mohr_coulomb_fit_circles
    phi, c = math.radians(32.0), 8e3
    n = math.tan(math.pi / 4 + phi / 2) ** 2
    s3 = np.array([50e3, 100e3, 200e3])
    s1 = s3 * n + 2 * c * math.sqrt(n)
    fit_phi, fit_c, r2 = mohr_coulomb_fit_circles(0.5 * (s1 + s3), 0.5 * (s1 - s3))
    assert fit_phi == pytest.approx(32.0, abs=1e-9) and fit_c == pytest.approx(c, rel=1e-9) and r2 == pytest.approx(1)
