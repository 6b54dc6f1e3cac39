"""Clump templates: rigid grains made of overlapping member spheres, and their mass properties.

A template is a list of member spheres (centre, radius) in any frame. Its volume, centre and
inertia are those of the **union** of the members (a region covered by two members counts
once), integrated numerically (:func:`union_moments`); the template is then stored in its
principal frame: centre at the origin, axes along the principal axes of inertia, moments
I1 ≤ I2 ≤ I3 per unit density (docs/design.md §2.19).

Integration of the union. On an N × N grid of (y, z) points (midpoints of cells covering the
members' bounding box), each member whose disc covers the point gives an interval of x; the
intervals are merged and ∫1, ∫x, ∫x² over their union are exact. The (y, z) sum is the
midpoint rule, whose error at the members' rims falls as N^{-3/2}: at N = 400 the volume and
inertia of one sphere, of two overlapping spheres and of a line of three are within 1e-4 of
their closed forms (tests/dem/test_clumps.py).
"""
from dataclasses import dataclass, field

import numpy as np
from numba import njit

#: grid points per side of the (y, z) integration
GRID = 400


@njit(cache=True)
def _union_line_moments(y, z, centres, radii):
    """∫1, ∫x, ∫x² over the x-extent of the union of the members at the point (y, z)."""
    n = radii.size
    lo = np.empty(n)
    hi = np.empty(n)
    m = 0
    for k in range(n):
        rho2 = (y - centres[k, 1]) ** 2 + (z - centres[k, 2]) ** 2
        r2 = radii[k] * radii[k]
        if rho2 < r2:
            half = np.sqrt(r2 - rho2)
            lo[m] = centres[k, 0] - half
            hi[m] = centres[k, 0] + half
            m += 1
    if m == 0:
        return 0.0, 0.0, 0.0
    order = np.argsort(lo[:m])
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    a = lo[order[0]]
    b = hi[order[0]]
    for t in range(1, m + 1):
        if t < m and lo[order[t]] <= b:  # overlaps the current run: extend it
            b = max(b, hi[order[t]])
            continue
        m0 += b - a
        m1 += 0.5 * (b * b - a * a)
        m2 += (b * b * b - a * a * a) / 3.0
        if t < m:
            a = lo[order[t]]
            b = hi[order[t]]
    return m0, m1, m2


@njit(cache=True)
def _grid_moments(centres, radii, y0, z0, h, n):
    """Volume, first moments (3) and second moments ∫x_a x_b (xx, yy, zz, xy, xz, yz) of the union."""
    out = np.zeros(10)
    area = h * h
    for iy in range(n):
        y = y0 + (iy + 0.5) * h
        for iz in range(n):
            z = z0 + (iz + 0.5) * h
            m0, m1, m2 = _union_line_moments(y, z, centres, radii)
            if m0 == 0.0:
                continue
            out[0] += m0 * area
            out[1] += m1 * area
            out[2] += y * m0 * area
            out[3] += z * m0 * area
            out[4] += m2 * area
            out[5] += y * y * m0 * area
            out[6] += z * z * m0 * area
            out[7] += y * m1 * area
            out[8] += z * m1 * area
            out[9] += y * z * m0 * area
    return out


def union_moments(centres, radii, grid=GRID):
    """(volume, centroid (3,), inertia tensor (3, 3) about the centroid, per unit density) of the
    union of spheres (module docstring)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    lo = (centres - radii[:, None]).min(axis=0)
    hi = (centres + radii[:, None]).max(axis=0)
    side = max(hi[1] - lo[1], hi[2] - lo[2])
    h = side / grid
    m = _grid_moments(centres, radii, lo[1], lo[2], h, grid)
    volume = m[0]
    centroid = m[1:4] / volume
    second = np.array([[m[4], m[7], m[8]], [m[7], m[5], m[9]], [m[8], m[9], m[6]]])  # ∫ x xᵀ
    second -= volume * np.outer(centroid, centroid)  # about the centroid
    inertia = np.trace(second) * np.eye(3) - second   # I = ∫ (|x|² 1 − x xᵀ)
    return volume, centroid, inertia


@dataclass(frozen=True)
class ClumpTemplate:
    """A rigid grain of overlapping spheres: ``centres`` (k, 3) and ``radii`` (k,) of its members
    in any frame. Stored in its principal frame (module docstring): ``members`` (k, 3) the
    member centres there, ``volume`` of the union, ``moments`` (3,) the principal moments of
    inertia per unit density, ascending, and ``axes`` (3, 3) the principal axes in the input
    frame (columns) and ``origin`` the union's centroid there — to place the template where
    it was given, x = origin + axes · member.

    Raises ValueError for a template without members, with a radius that is not positive or
    finite, or whose members do not form one connected body (each member must overlap or
    touch another)."""
    centres: np.ndarray
    radii: np.ndarray
    grid: int = GRID
    members: np.ndarray = field(init=False, repr=False)
    volume: float = field(init=False)
    moments: np.ndarray = field(init=False)
    axes: np.ndarray = field(init=False, repr=False)
    origin: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        centres = np.array(self.centres, dtype=float).reshape(-1, 3)
        radii = np.array(self.radii, dtype=float).reshape(-1)
        check_members(centres, radii)
        volume, centroid, inertia = union_moments(centres, radii, self.grid)
        moments, axes = np.linalg.eigh(inertia)
        if np.linalg.det(axes) < 0:  # a proper rotation
            axes[:, 2] *= -1.0
        set_ = object.__setattr__
        set_(self, "centres", centres)
        set_(self, "radii", radii)
        set_(self, "volume", float(volume))
        set_(self, "moments", moments)
        set_(self, "axes", axes)
        set_(self, "origin", centroid)
        set_(self, "members", (centres - centroid) @ axes)

    @classmethod
    def line(cls, count, aspect_ratio, radius=1.0, grid=GRID):
        """``count`` equal spheres of ``radius`` evenly spaced along x, the whole grain's length over
        its width (2 r) being ``aspect_ratio`` (1 ≤ aspect ratio ≤ count: touching spheres at most)."""
        if count < 1 or not 1.0 <= aspect_ratio <= count:
            raise ValueError(f"a line of {count} equal spheres has an aspect ratio in [1, {count}], "
                             f"not {aspect_ratio}")
        spacing = 0.0 if count == 1 else 2.0 * radius * (aspect_ratio - 1.0) / (count - 1)
        x = (np.arange(count) - 0.5 * (count - 1)) * spacing
        return cls(np.column_stack([x, np.zeros(count), np.zeros(count)]), np.full(count, radius), grid)

    @property
    def count(self):
        """Number of member spheres."""
        return self.radii.size

    def mass(self, density):
        """Mass of the grain of this ``density``."""
        return density * self.volume

    def inertia(self, density):
        """Principal moments of inertia of the grain of this ``density`` (3,)."""
        return density * self.moments

    def equivalent_radius(self):
        """Radius of the sphere of the same volume."""
        return (3.0 * self.volume / (4.0 * np.pi)) ** (1.0 / 3.0)


def check_members(centres, radii):
    """The template rules of :class:`ClumpTemplate` (ValueError naming the member at fault)."""
    if radii.size == 0:
        raise ValueError("a clump template needs at least one member sphere")
    if centres.shape[0] != radii.size:
        raise ValueError(f"a clump template has {centres.shape[0]} centres and {radii.size} radii")
    for k, r in enumerate(radii):
        if not (np.isfinite(r) and r > 0.0):
            raise ValueError(f"member {k} of the clump template has radius {r}: radii must be positive")
    if not np.all(np.isfinite(centres)):
        raise ValueError("a clump template's member centres must be finite numbers")
    # connected: grow the body from member 0 through members that overlap or touch it
    reached = np.zeros(radii.size, dtype=bool)
    reached[0] = True
    frontier = [0]
    while frontier:
        k = frontier.pop()
        gap = np.linalg.norm(centres - centres[k], axis=1) - (radii + radii[k])
        new = (gap <= 1e-12 * radii.max()) & ~reached
        reached |= new
        frontier.extend(np.flatnonzero(new).tolist())
    if not reached.all():
        apart = int(np.flatnonzero(~reached)[0])
        raise ValueError(f"member {apart} of the clump template does not touch the others: the members of a "
                         "clump must overlap or touch, as one body")
