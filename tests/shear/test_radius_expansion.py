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


def box_of(L, H, e, grain_friction, growth_friction, rng_seed, **settings):
    """(diameters, GenerationSettings) of 1.6–2.4 mm grains for void ratio e in an L × L × H box."""
    curve = specimen_curve(diameters=[1.6e-3, 2.4e-3], passing=[0.0, 1.0])
    d = diameters_for_solid_volume(curve, solid_volume_for(e, L * L * H), np.random.default_rng(rng_seed))
    s = GenerationSettings(box_length=L, height=H, void_ratio=e,
                           sand=Material(density=2650, young=5e7, friction=grain_friction),
                           wall=Material(density=7480, young=5e7, friction=0.0),
                           plate=Material(density=7480, young=5e7, friction=0.8), friction=growth_friction,
                           seed=3, **settings)
    return d, s


@pytest.mark.slow
def test_radius_expansion_reaches_the_void_ratio_in_the_closed_box():
    """Grains grown in a closed 12 × 12 × 8 mm box: the void ratio is fixed by the box
    volume (the grains jam before reaching it, at a stress that depends on the friction)."""
    L, H, e = 0.012, 0.008, 0.70
    d, s = box_of(L, H, e, grain_friction=0.5, growth_friction=0.1, rng_seed=1)
    specimen = generate("radius_expansion", d, s)
    assert specimen.void_ratio == pytest.approx(e, abs=0.01)
    assert specimen.height == pytest.approx(H)
    np.testing.assert_allclose(np.sort(specimen.radii), np.sort(d / 2))


def test_grains_that_do_not_jam_go_straight_to_gravity_and_the_plate_is_seated_on_them():
    """A box grown to a loose target (e = 3, far looser than any jammed packing) holds a gas,
    whose unbalanced force ratio never falls without gravity: the zero-gravity stage ends at
    its first checks (it used to run to max_steps_per_layer). The grains then fall, and the
    plate is seated on them: it jumps onto the highest grain, then comes down slowly (at
    0.1 x plate_velocity all the way from the box's top it did not reach them)."""
    L, H, e = 0.010, 0.016, 3.0
    d, s = box_of(L, H, e, grain_friction=0.3, growth_friction=0.3, rng_seed=2, max_steps_per_layer=20000,
                  density_scale=1.0)
    specimen = generate("radius_expansion", d, s)
    expanded, _ = specimen.log
    assert expanded["stage"] == "expanded" and expanded["steps"] <= 4 * s.check_every  # not 20,000
    top = float(np.max(specimen.positions[:, 2] + specimen.radii))
    assert top < H - d.max()
    assert 0.0 <= specimen.height - top < 0.2 * d.max()
