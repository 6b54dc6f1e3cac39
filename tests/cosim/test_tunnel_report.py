"""The tunnel's report (cosim.apps.tunnel_report): Peck's trough fitted to settlements, its
volume, and the polar plots of the lining's forces."""
import math

import numpy as np
import pytest

from cosim.apps.tunnel_report import PeckTrough, fit_peck, plot_polar, trough_summary


def test_the_fit_recovers_a_gaussian_trough_and_its_volume():
    """Settlements drawn from S_max exp(−x²/2i²) with 5 % noise: S_max and i back within 3 %;
    V_s = √(2π) i S_max is the trough's integral over the whole width."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 0.2, 120)
    exact = PeckTrough(s_max=2.6e-4, i=0.032, z0=0.09)
    fit = fit_peck(x, exact(x) * (1.0 + 0.05 * rng.standard_normal(len(x))), 0.09)
    assert fit.s_max == pytest.approx(exact.s_max, rel=0.03) and fit.i == pytest.approx(exact.i, rel=0.03)
    assert fit.K == pytest.approx(0.032 / 0.09, rel=0.03)
    grid = np.linspace(-0.5, 0.5, 200001)
    assert exact.volume() == pytest.approx(np.trapz(exact(grid), grid), rel=1e-9)
    summary = trough_summary(exact, 0.06, 0.01)
    assert summary["surface_volume_loss"] == pytest.approx(exact.volume() / (math.pi * 0.06**2 / 4))


def test_the_fit_takes_offsets_on_either_side_of_the_axis():
    x = np.linspace(-0.1, 0.1, 81)
    exact = PeckTrough(s_max=1e-4, i=0.02, z0=0.05)
    fit = fit_peck(x, exact(x), 0.05)
    assert fit.s_max == pytest.approx(1e-4, rel=1e-6) and fit.i == pytest.approx(0.02, rel=1e-6)


def test_polar_plots_of_a_half_ring_and_a_whole_one(tmp_path):
    """A half ring (0–180° from the crown) is mirrored; a whole one (−180–180°) is drawn as it is;
    negative thrust (tension) is drawn inside the zero circle."""
    half = np.arange(2.5, 180.0, 5.0)
    whole = np.arange(-177.5, 180.0, 5.0)
    plot_polar({"half": (half, 10.0 + np.cos(np.radians(2 * half)), 0.01 * np.cos(np.radians(2 * half))),
                "whole": (whole, -5.0 + 0 * whole, 0.02 * np.sin(np.radians(whole)))},
               tmp_path / "polar.png", "test")
    assert (tmp_path / "polar.png").stat().st_size > 10_000


def test_the_troughs_grains_are_the_top_layer_even_when_it_settled_below_the_surface(tmp_path):
    """write_trough takes the grains within a largest grain's diameter of the ground surface;
    where grains alone make the ground (the all-DEM twin) and settled further below it (a fill
    under its weight at full size), from the highest grain's centre instead; under FE ground
    (a closed ring) none; an FE lining off the surface (the all-DEM twin's) is no FE ground."""
    from types import SimpleNamespace

    from cosim.apps.embedded_report import write_trough
    surface = np.array([[[0.0, 0.0, 0.1], [1.0, 0.0, 0.1], [0.0, 1.0, 0.1]]])
    radius = np.full(4, 0.001)
    for top, kept in ((0.099, [0.099, 0.0985]), (0.09, [0.09, 0.0895])):  # at the surface; 10 mm below it
        start = np.array([[0.1, 0.0, top], [0.2, 0.0, top - 0.0005], [0.3, 0.0, top - 0.0025], [0.4, 0.0, 0.05]])
        end = SimpleNamespace(pos=start - [0.0, 0.0, 1e-4], radius=radius)
        write_trough(surface, (0.0, 0.0, -9.81), tmp_path / "trough.csv", grains=(start, end))
        rows = np.genfromtxt(tmp_path / "trough.csv", delimiter=",", names=True, dtype=None, encoding=None)
        assert np.allclose(start[np.isin(start[:, 0], rows["x"]), 2], kept)
        assert np.allclose(rows["settlement"], 1e-4)
    fe = (surface[0], np.zeros((3, 3)))  # the FE ground's nodes: the grains 10 mm below are not its surface
    write_trough(surface, (0.0, 0.0, -9.81), tmp_path / "trough.csv", fe_motion=fe, grains=(start, end))
    rows = np.genfromtxt(tmp_path / "trough.csv", delimiter=",", names=True, dtype=None, encoding=None)
    assert set(rows["source"]) == {"fe"}
    lining = (np.array([[0.5, 0.5, 0.05]]), np.zeros((1, 3)))  # an FE node, not on the ground surface
    write_trough(surface, (0.0, 0.0, -9.81), tmp_path / "trough.csv", fe_motion=lining, grains=(start, end))
    rows = np.genfromtxt(tmp_path / "trough.csv", delimiter=",", names=True, dtype=None, encoding=None)
    assert set(rows["source"]) == {"dem"} and np.allclose(np.sort(rows["x"]), [0.1, 0.2])
