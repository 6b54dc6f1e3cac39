"""Sieve-curve sampling, random clouds and packing files (DESIGN.md §3)."""
from pathlib import Path

import numpy as np
import pytest

from de_domain.packing import THESIS_SAND, SieveCurve, load_packing, random_cloud, save_packing

W1 = Path(__file__).parents[3] / "shared" / "benchmarks" / "w1" / "bed_5000.dump"


def test_sampled_mass_distribution_follows_the_sieve_curve():
    curve = THESIS_SAND.scaled(4.0).truncated(1.2e-3)
    d = curve.sample_diameters(200_000, np.random.default_rng(3))
    assert d.min() >= curve.diameters[0] and d.max() <= curve.diameters[-1]
    # mass passing at each sieve equals the curve (sampling error of a mass-weighted
    # histogram of 2e5 grains dominated by few coarse ones: ~1e-2)
    np.testing.assert_allclose(curve.mass_passing(d), curve.passing, atol=0.02)


def test_truncation_renormalises_and_scaling_keeps_fractions():
    scaled = THESIS_SAND.scaled(4.0)
    np.testing.assert_allclose(scaled.diameters, THESIS_SAND.diameters * 4)
    np.testing.assert_array_equal(scaled.passing, THESIS_SAND.passing)
    cut = scaled.truncated(1.2e-3)
    assert cut.diameters[0] == 1.2e-3 and cut.passing[0] == 0.0 and cut.passing[-1] == 1.0
    f_cut = np.interp(1.2e-3, scaled.diameters, scaled.passing)
    i = np.searchsorted(cut.diameters, 2.4e-3)
    assert cut.passing[i] == pytest.approx((np.interp(2.4e-3, scaled.diameters, scaled.passing) - f_cut) / (1 - f_cut))


def test_invalid_curves_are_rejected():
    with pytest.raises(ValueError, match="increasing"):
        SieveCurve([1e-3, 0.5e-3], [0.0, 1.0])
    with pytest.raises(ValueError, match="non-decreasing"):
        SieveCurve([1e-3, 2e-3, 3e-3], [0.0, 0.6, 0.5])


def test_random_cloud_has_no_overlap_and_stays_in_the_box_and_is_reproducible():
    rng = np.random.default_rng(0)
    radii = rng.uniform(0.8e-3, 1.2e-3, 3000)
    lo, hi = np.zeros(3), np.array([0.03, 0.03, 0.08])
    pos, r = random_cloud(radii, lo, hi, seed=7)
    assert len(r) == 3000
    assert np.all(pos - r[:, None] >= lo - 1e-15) and np.all(pos + r[:, None] <= hi + 1e-15)
    from scipy.spatial import cKDTree
    pairs = np.array(sorted(cKDTree(pos).query_pairs(2 * r.max())))
    gap = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
    assert gap.min() >= 0.0
    pos2, _ = random_cloud(radii, lo, hi, seed=7)
    np.testing.assert_array_equal(pos, pos2)


def test_random_cloud_too_dense_is_a_clear_error():
    with pytest.raises(ValueError, match="could place only"):
        random_cloud(np.full(2000, 1e-3), np.zeros(3), np.full(3, 0.02), seed=1)


@pytest.mark.parametrize("suffix", [".npz", ".txt"])
def test_packing_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(1)
    pos, r = rng.random((50, 3)), rng.uniform(1e-3, 2e-3, 50)
    save_packing(tmp_path / f"p{suffix}", pos, r, void_ratio=0.65)
    pos2, r2 = load_packing(tmp_path / f"p{suffix}")
    np.testing.assert_allclose(pos2, pos, rtol=1e-9)
    np.testing.assert_allclose(r2, r, rtol=1e-9)


@pytest.mark.skipif(not W1.exists(), reason="shared/benchmarks/w1 is not beside this checkout")
def test_reads_liggghts_dump():
    pos, r = load_packing(W1)
    assert pos.shape == (5000, 3) and r.shape == (5000,)
    assert set(np.round(np.unique(r) * 1e4).astype(int)) <= {8, 9, 10, 11, 12}
    assert np.all(pos[:, :2] > 0) and np.all(pos[:, :2] < 0.038)
