"""Specimen recipe: sieve curve, grain volume, layers (docs/design.md §3.1–§3.3), without the engine; and
one small under-compaction of clumped grains."""
import numpy as np
import pytest

from de_domain.deposition import (
    diameters_for_solid_volume,
    layer_count,
    layer_tops,
    solid_volume_for,
    specimen_curve,
    split_into_layers,
    truncated_above,
    void_ratio_of_box,
)
from de_domain.packing import THESIS_SAND


def test_coarse_truncation_keeps_the_curve_shape_below_the_cut():
    cut = truncated_above(THESIS_SAND, 2.0e-3)
    assert cut.diameters[-1] == pytest.approx(2.0e-3) and cut.passing[-1] == pytest.approx(1.0)
    f_cut = np.interp(2.0e-3, THESIS_SAND.diameters, THESIS_SAND.passing)
    np.testing.assert_allclose(cut.passing[:-1], THESIS_SAND.passing[THESIS_SAND.diameters < 2e-3] / f_cut)


def test_specimen_curve_scales_then_truncates_both_ends():
    curve = specimen_curve("thesis_sand", scale=2.0, truncate_below=2.36e-3, truncate_above=6e-3)
    assert curve.diameters[0] == pytest.approx(2.36e-3) and curve.diameters[-1] == pytest.approx(6e-3)
    d = curve.sample_diameters(20000, np.random.default_rng(0))
    assert d.min() >= 2.36e-3 * (1 - 1e-12) and d.max() <= 6e-3 * (1 + 1e-12)
    np.testing.assert_allclose(curve.mass_passing(d), curve.passing, atol=0.02)


def test_unknown_preset_is_refused():
    with pytest.raises(ValueError, match="allowed"):
        specimen_curve("no_such_sand")


def test_grains_fill_the_solid_volume_of_the_target_void_ratio_within_one_grain():
    curve = specimen_curve("thesis_sand", scale=2.0, truncate_below=2.36e-3, truncate_above=6e-3)
    target = solid_volume_for(0.65, 0.06 * 0.06 * 0.025)
    d = diameters_for_solid_volume(curve, target, np.random.default_rng(1))
    solid = np.sum(np.pi / 6 * d**3)
    assert target <= solid < target + np.pi / 6 * d.max() ** 3
    assert void_ratio_of_box(0.06 * 0.06, 0.025, d / 2) == pytest.approx(0.65, abs=0.003)


def test_number_of_layers_follows_from_the_target_void_ratio():
    # a cloud holds cloud_solid_fraction of solids over the specimen height
    assert layer_count(0.65, 0.2) == 4      # 1/(1.65 * 0.2) = 3.03
    assert layer_count(0.84, 0.2) == 3      # 1/(1.84 * 0.2) = 2.72
    assert layer_count(0.65, 0.1) > layer_count(0.65, 0.2)
    # ... but a layer stays at least 1.5 of the largest grains thick
    assert layer_count(0.65, 0.1, height=0.025, d_max=0.006) == 2
    assert layer_count(0.65, 0.2, height=0.025, d_max=0.004) == 4
    assert layer_count(0.84, 0.2, height=0.025, d_max=0.004) == 3


def test_under_compaction_heights_end_at_the_specimen_height():
    z = layer_tops(5, 0.025, 0.1)
    assert z[-1] == pytest.approx(0.025)
    assert z[0] == pytest.approx(0.005 * 1.1)                       # first layer 10 % under-compacted
    nominal = 0.005 * np.arange(1, 6)
    assert np.all(z >= nominal - 1e-15) and np.all(np.diff(z - nominal) <= 1e-15)  # U decreases
    np.testing.assert_allclose(layer_tops(3, 0.03, 0.0), [0.01, 0.02, 0.03])


def test_layers_share_the_solid_volume_equally():
    d = np.random.default_rng(2).uniform(1e-3, 3e-3, 3000)
    groups = split_into_layers(d, 4, np.random.default_rng(3))
    assert sum(len(g) for g in groups) == len(d)
    vols = np.array([np.sum(g**3) for g in groups])
    np.testing.assert_allclose(vols / vols.mean(), 1.0, atol=0.01)


def test_under_compaction_makes_a_specimen_of_clumps():
    """Two layers of two-sphere grains (aspect ratio 1.25) in a 12 × 12 × 8 mm box: every grain
    a clump of its sieve diameter (equal volume), inside the box, and the void ratio counted
    from the clumps' union volumes."""
    from de_domain import Material
    from de_domain.clumps import ClumpTemplate
    from de_domain.deposition import GenerationSettings, GrainShapes, generate
    L, H, e = 0.012, 0.008, 0.8
    curve = specimen_curve(None, [1.6e-3, 2.4e-3], [0.0, 1.0])
    d = diameters_for_solid_volume(curve, solid_volume_for(e, L * L * H), np.random.default_rng(1))
    settings = GenerationSettings(box_length=L, height=H, void_ratio=e, sand=Material(young=5e7, friction=0.3),
                                  wall=Material(young=5e7, friction=0.0), plate=Material(young=5e7, friction=0.5),
                                  layers=2, seed=3)
    specimen = generate("under_compaction", d, settings, shapes=GrainShapes([ClumpTemplate.line(2, 1.25)], (1.0,)))
    clumps = specimen.clumps
    assert clumps.count == d.size and specimen.radii.size == 2 * d.size
    np.testing.assert_allclose(np.sort(2 * clumps.equivalent_radii()), np.sort(d), rtol=1e-9)
    solid = float(np.sum(clumps.volumes()))
    assert specimen.void_ratio == pytest.approx((L * L * specimen.height - solid) / solid, rel=1e-12)
    slack = 0.25 * specimen.radii[:, None]  # elastic overlap with the walls
    pos, r = specimen.positions, specimen.radii[:, None]
    assert np.all(pos - r > -slack) and np.all(pos[:, :2] + r < L + slack)
    assert np.all(pos[:, 2:] + r < specimen.height + slack)
