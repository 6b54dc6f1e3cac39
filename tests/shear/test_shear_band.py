"""The shear-band measure (cosim.lab.shear_band) against profiles of known thickness."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.special import erf

from cosim.lab.shear_band import TEN_NINETY, displacement_profile, fit_band, measure_band, stripe_of


def test_stripes_are_tenths_of_the_box():
    x = np.array([0.0, 0.0059, 0.006, 0.0301, 0.0599, 0.06, 0.061, -1e-4])
    assert stripe_of(x, 0.06).tolist() == [0, 0, 1, 5, 9, 9, 9, 0]


def test_ten_ninety_width_of_a_gaussian_step():
    """Φ(t/2w) − Φ(−t/2w) = 0.8 for t = TEN_NINETY w."""
    half = TEN_NINETY / 2.0
    assert 0.5 * (erf(half / math.sqrt(2)) - erf(-half / math.sqrt(2))) == pytest.approx(0.8, abs=1e-12)


@pytest.mark.parametrize("width", [1.0e-3, 2.5e-3])
def test_fit_recovers_the_thickness_of_a_noisy_erf_profile(width):
    """Grains at random heights in a 25 mm specimen whose u_x/δ follows an erf step of
    standard deviation ``width`` about z = 12.5 mm, with 5 % scatter per grain."""
    rng = np.random.default_rng(3)
    z = rng.uniform(0.0, 0.025, 4000)
    ux = 0.5 * (1 + erf((z - 0.0125) / (math.sqrt(2) * width))) + 0.05 * rng.standard_normal(z.size)
    centres, profile = displacement_profile(z, ux, 1.0, 1.0e-3)
    fit = fit_band(centres, profile, 0.0125, 2.5e-4)
    assert fit.thickness == pytest.approx(TEN_NINETY * width, rel=0.08)
    assert fit.centre == pytest.approx(0.0125, abs=2e-4)
    assert (fit.lower, fit.upper) == (pytest.approx(0.0, abs=0.02), pytest.approx(1.0, abs=0.02))


def test_rigid_halves_give_a_band_no_thicker_than_a_layer():
    """The upper half translated by δ as a block, the lower one still: a step sharper than
    the layers (d50/2 = 1 mm) cannot be told from one a layer thick."""
    rng = np.random.default_rng(4)
    start = rng.uniform([0, 0, 0], [0.06, 0.06, 0.025], (3000, 3))
    now = start.copy()
    now[start[:, 2] > 0.0125, 0] += 0.003
    fit, _ = measure_band(SimpleNamespace(pos=start), SimpleNamespace(pos=now), 0.003, 0.06, 2e-3, 0.0125)
    assert fit.thickness < 1.0e-3
    assert fit.centre == pytest.approx(0.0125, abs=5e-4)
