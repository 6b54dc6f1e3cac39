"""Clump templates (de_domain.clumps): mass properties of the union of the members against
closed forms, invariance under a rigid motion of the input, and the template rules."""
import math

import numpy as np
import pytest
from numpy.polynomial import Polynomial

from de_domain.clumps import ClumpTemplate


def axial_closed_form(centres_x, radii):
    """(volume, I_axis, I_perpendicular about the centroid) per unit density of the union of
    spheres centred on the x-axis: a solid of revolution whose section radius² at x is
    ρ²(x) = max_k (r_k² − (x − c_k)²), each piece a polynomial integrated exactly:
    V = π∫ρ², I_x = π/2 ∫ρ⁴, I_y = π∫(ρ⁴/4 + ρ²(x − x̄)²)."""
    c = np.asarray(centres_x, float)
    r = np.asarray(radii, float)
    pieces = [Polynomial([rk * rk - ck * ck, 2 * ck, -1.0]) for ck, rk in zip(c, r, strict=True)]  # r² − (x − c)²
    breaks = set(np.concatenate([c - r, c + r]).tolist())
    for a in range(c.size):
        for b in range(a + 1, c.size):  # where two sections are equal: linear in x
            diff = pieces[a] - pieces[b]
            if abs(diff.coef[1]) > 0:
                breaks.add(-diff.coef[0] / diff.coef[1])
    breaks = sorted(x for x in breaks if (c - r).min() <= x <= (c + r).max())
    segments = []
    for lo, hi in zip(breaks[:-1], breaks[1:], strict=True):
        mid = 0.5 * (lo + hi)
        best = max(range(c.size), key=lambda k: pieces[k](mid))
        if pieces[best](mid) > 0:
            segments.append((lo, hi, pieces[best]))

    def integral(f):
        return sum((f(p).integ()(hi) - f(p).integ()(lo)) for lo, hi, p in segments)

    volume = math.pi * integral(lambda p: p)
    xbar = math.pi * integral(lambda p: p * Polynomial([0, 1])) / volume
    i_axis = 0.5 * math.pi * integral(lambda p: p * p)
    i_perp = math.pi * integral(lambda p: 0.25 * p * p + p * Polynomial([-xbar, 1]) ** 2)
    return volume, i_axis, i_perp


@pytest.mark.parametrize("centres, radii", [
    ([0.0], [1.0]),                      # one sphere
    ([-0.5, 0.5], [1.0, 1.0]),           # two equal spheres, centres one radius apart
    ([-0.6, 0.0, 0.6], [0.5, 0.5, 0.5]),  # a line of three
    ([0.0, 1.0], [1.0, 0.6]),            # two unequal spheres
    ([0.0, 1.9], [1.0, 1.0]),            # two barely overlapping
])
def test_volume_and_inertia_of_the_union_match_the_closed_form(centres, radii):
    template = ClumpTemplate(np.column_stack([centres, np.zeros(len(centres)), np.zeros(len(centres))]), radii)
    volume, i_axis, i_perp = axial_closed_form(centres, radii)
    assert template.volume == pytest.approx(volume, rel=1e-4)
    assert template.moments[0] == pytest.approx(i_axis, rel=1e-4)  # the axis of revolution: smallest
    assert template.moments[1] == pytest.approx(i_perp, rel=1e-4)
    assert template.moments[2] == pytest.approx(i_perp, rel=1e-4)


def test_one_sphere_is_a_sphere():
    template = ClumpTemplate([[0.3, -0.2, 0.1]], [0.5])
    assert template.volume == pytest.approx(4 / 3 * math.pi * 0.5**3, rel=1e-4)
    assert np.allclose(template.moments, 0.4 * template.volume * 0.25, rtol=1e-4)
    assert np.allclose(template.origin, [0.3, -0.2, 0.1], atol=1e-6)
    assert template.equivalent_radius() == pytest.approx(0.5, rel=1e-4)


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_mass_properties_do_not_depend_on_the_frame_of_the_input():
    """An L-shaped grain of three unequal members, given as is and moved by a random rotation and
    translation: the same volume and principal moments, the members in the principal frame
    the same up to the axes' signs, and the input recovered as origin + axes · member."""
    rng = np.random.default_rng(5)
    centres = np.array([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0], [0.0, 0.7, 0.1]])
    radii = np.array([0.6, 0.5, 0.4])
    a = ClumpTemplate(centres, radii)
    rotation = random_rotation(rng)
    moved = centres @ rotation.T + rng.normal(size=3)
    b = ClumpTemplate(moved, radii)
    assert b.volume == pytest.approx(a.volume, rel=2e-4)
    assert np.allclose(b.moments, a.moments, rtol=5e-4)
    assert np.allclose(np.abs(b.members), np.abs(a.members), atol=2e-3)
    assert np.allclose(b.origin + b.members @ b.axes.T, moved, atol=1e-12)
    assert np.linalg.det(b.axes) == pytest.approx(1.0)
    # the centroid of the principal frame is the origin: the union's first moment there vanishes
    back = ClumpTemplate(b.members, radii)
    assert np.allclose(back.origin, 0.0, atol=1e-4 * radii.max())
    assert np.allclose(np.abs(back.axes), np.eye(3), atol=1e-3)


def test_line_aspect_ratio():
    """Length over width of the grain as asked; the members evenly spaced on the principal axis of
    least inertia, symmetric about the centroid."""
    for count, ratio in ((2, 1.5), (3, 2.0), (2, 2.0), (1, 1.0)):
        template = ClumpTemplate.line(count, ratio, radius=0.5)
        extent = np.ptp(template.members, axis=0) + 2 * 0.5
        assert extent.max() == pytest.approx(ratio * 1.0)
        assert template.count == count
        along = template.members[:, 0]  # the first principal axis: the line
        assert np.allclose(np.sort(along), -np.sort(along)[::-1], atol=1e-4)
        assert np.allclose(template.members[:, 1:], 0.0, atol=1e-4)
        if count > 2:
            assert np.allclose(np.diff(np.sort(along)), np.diff(np.sort(along))[0], atol=1e-4)


@pytest.mark.parametrize("centres, radii, words", [
    (np.zeros((0, 3)), [], "at least one member"),
    ([[0, 0, 0], [1, 0, 0]], [0.6, 0.0], "member 1 of the clump template has radius 0.0"),
    ([[0, 0, 0], [1, 0, 0]], [-0.6, 0.6], "member 0 of the clump template has radius -0.6"),
    ([[0, 0, 0], [1, 0, 0]], [0.6, float("nan")], "radius nan"),
    ([[0, 0, 0], [1, 0, 0], [5, 0, 0]], [0.6, 0.6, 0.6], "member 2 of the clump template does not touch"),
    ([[0, 0, 0]], [0.6, 0.6], "1 centres and 2 radii"),
])
def test_bad_templates_are_refused_with_the_member_named(centres, radii, words):
    with pytest.raises(ValueError, match=words):
        ClumpTemplate(centres, radii)


def test_touching_members_are_one_body():
    template = ClumpTemplate([[0, 0, 0], [1.2, 0, 0]], [0.6, 0.6])
    assert template.volume == pytest.approx(2 * 4 / 3 * math.pi * 0.6**3, rel=1e-4)
    with pytest.raises(ValueError, match="aspect ratio"):
        ClumpTemplate.line(2, 2.5)


def test_placed_clumps_scale_as_their_size():
    """A template placed twice as large: members at twice the distances and radii, 8 × the mass and
    32 × the moments of inertia — the same as a template built twice as large."""
    from de_domain import Material
    from de_domain.clumps import Clumps

    materials = [Material(density=2000.0)]
    small = ClumpTemplate([[0, 0, 0], [1.0, 0, 0]], [0.7, 0.5])
    large = ClumpTemplate([[0, 0, 0], [2.0, 0, 0]], [1.4, 1.0])
    particles, clumps = Clumps.place([small], [0], [[0, 0, 0]], [[1, 0, 0, 0]], materials, scales=[2.0])
    assert clumps.mass[0] == pytest.approx(large.mass(2000.0), rel=1e-4)
    assert np.allclose(clumps.moments[0], large.inertia(2000.0), rtol=1e-4)
    assert np.allclose(particles.radius, [1.4, 1.0])
    assert np.allclose(clumps.member_body, large.members, atol=1e-3)
    assert small.reach() * 2 == pytest.approx(large.reach(), rel=1e-3)
