"""Sieve-curve sampling, random clouds and packing files (docs/design.md §3.1)."""

import numpy as np
import pytest

from de_domain.packing import THESIS_SAND, SieveCurve, load_packing, random_cloud, save_packing


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


def test_spheres_inserted_block_by_block_land_where_all_at_once_puts_them():
    """The fill draws and places candidate centres a block of spheres at a time (the memory of
    one block); the placement must be the one of every sphere's candidates at once, up to the
    first sphere that does not fit, wherever the blocks are cut."""
    from de_domain.packing import SphereInserter, insert_spheres
    rng = np.random.default_rng(4)
    radii = np.sort(rng.uniform(0.8e-3, 1.2e-3, 1500))[::-1]
    lo, hi = np.zeros(3), np.full(3, 0.018)  # too small for all: the last blocks fail part-way
    candidates = lo + rng.random((1500, 30, 3)) * (hi - lo)
    pos, placed = insert_spheres(radii, candidates, lo, hi)
    assert 100 < placed < 1500
    for cuts in ([0, 1500], [0, 1, 2, 500, 1500], [0, 77, 154, 1000, 1499, 1500]):
        inserter = SphereInserter(radii, lo, hi)
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            inserter.add(candidates[a:b])
        assert inserter.placed == placed and inserter.failed
        np.testing.assert_array_equal(inserter.pos[:placed], pos)


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


def test_reads_liggghts_dump(tmp_path):
    """A LIGGGHTS ``dump custom`` snapshot, columns in another order than ours and atoms
    not sorted by id (as a multi-rank LIGGGHTS run writes them)."""
    rng = np.random.default_rng(5)
    n = 40
    pos, r = rng.uniform(0.0, 0.038, (n, 3)), rng.choice([8e-4, 1e-3, 1.2e-3], n)
    order = rng.permutation(n)
    rows = "".join(f"{r[i]:.9g} {i + 1} {pos[i, 2]:.9g} 1 {pos[i, 0]:.9g} {pos[i, 1]:.9g}\n" for i in order)
    dump = tmp_path / "bed.dump"
    dump.write_text(f"ITEM: TIMESTEP\n15000\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS ff ff ff\n"
                    "0 0.038\n0 0.038\n0 0.038\nITEM: ATOMS radius id z type x y\n" + rows)
    pos2, r2 = load_packing(dump)
    np.testing.assert_allclose(pos2, pos, rtol=1e-8)
    np.testing.assert_allclose(r2, r, rtol=1e-8)


def test_an_empty_npz_packing_is_a_message_naming_the_file(tmp_path):
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.npz: the file is empty \(0 bytes\)"):
        load_packing(empty)
