"""Radius expansion, the alternative generation method (docs/design.md §3.2)."""
import numpy as np
import pytest

from de_domain import Material
from de_domain.deposition import (
    GenerationSettings,
    diameters_for_solid_volume,
    generate,
    solid_volume_for,
    specimen_curve,
)


@pytest.mark.slow
def test_radius_expansion_reaches_the_void_ratio_in_the_closed_box():
    """Grains grown in a closed 12 × 12 × 8 mm box: the void ratio is fixed by the box
    volume (the grains jam before reaching it, at a stress that depends on the friction)."""
    L, H, e = 0.012, 0.008, 0.70
    curve = specimen_curve(diameters=[1.6e-3, 2.4e-3], passing=[0.0, 1.0])
    d = diameters_for_solid_volume(curve, solid_volume_for(e, L * L * H), np.random.default_rng(1))
    sand = Material(density=2650, young=5e7, friction=0.5)
    s = GenerationSettings(box_length=L, height=H, void_ratio=e, sand=sand,
                           wall=Material(density=7480, young=5e7, friction=0.0),
                           plate=Material(density=7480, young=5e7, friction=0.8), friction=0.1, seed=3)
    specimen = generate("radius_expansion", d, s)
    assert specimen.void_ratio == pytest.approx(e, abs=0.01)
    assert specimen.height == pytest.approx(H)
    np.testing.assert_allclose(np.sort(specimen.radii), np.sort(d / 2))
