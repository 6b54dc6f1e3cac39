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
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from .materials import material_arrays
from .particles import ARRAY_FIELDS, Particles
from .rigid import to_body, to_space

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

    def reach(self):
        """Radius of the smallest sphere about the centroid that holds every member."""
        return float(np.max(np.linalg.norm(self.members, axis=1) + self.radii))


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


def member_layout(templates, template_of, scales):
    """The members of clumps of ``templates[template_of[c]]`` enlarged ``scales[c]`` times, clump by
    clump in template order: (``member_start`` (nc + 1,), the clump of each member, member centres in
    the clump's principal frame (m, 3), member radii (m,))."""
    counts = np.array([templates[t].count for t in template_of], np.int64)
    member_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    owner = np.repeat(np.arange(template_of.size), counts)
    body = (np.concatenate([templates[t].members for t in template_of]) if template_of.size
            else np.zeros((0, 3))) * scales[owner, None]
    radius = (np.concatenate([templates[t].radii for t in template_of]) if template_of.size
              else np.zeros(0)) * scales[owner]
    return member_start, owner, body, radius


class Clumps:
    """Rigid clumps of member spheres (docs/design.md §2.19), over the rows of a
    :class:`~de_domain.Particles` set in its public order; the engine steps them
    (``Engine(..., clumps=...)``). Build with :meth:`place`.

    ``member_of`` (n,) the clump of each particle (−1: a free sphere); the members of clump c
    are the particles ``member_index[member_start[c]:member_start[c + 1]]`` (template order) at
    ``member_body`` (their centres in the clump's principal frame). State: ``pos`` (nc, 3) the
    centres of mass, ``vel`` (nc, 3) v^{n−½}, ``quat`` (nc, 4) orientations (principal frame →
    space, :mod:`de_domain.rigid`), ``angmom`` (nc, 3) L^{n−½} in the space frame; ``mass`` (nc,),
    ``moments`` (nc, 3) principal moments; ``force``/``torque`` (nc, 3) the last step's resultant.
    ``sphere_mass`` (n,): each member's mass as a sphere of its own (the critical time step
    reads it; a member particle's ``mass`` is its clump's, for the contact dashpot)."""

    FIELDS = ("member_of", "member_start", "member_index", "member_body", "pos", "vel", "quat", "angmom", "mass",
              "moments", "force", "torque", "sphere_mass")

    def __init__(self, **arrays):
        for name in self.FIELDS:
            setattr(self, name, np.array(arrays[name]))

    @classmethod
    def none(cls, n_particles):
        """No clump over ``n_particles`` free spheres."""
        return cls(member_of=np.full(n_particles, -1, np.int32), member_start=np.zeros(1, np.int64),
                   member_index=np.zeros(0, np.int64), member_body=np.zeros((0, 3)), pos=np.zeros((0, 3)),
                   vel=np.zeros((0, 3)), quat=np.zeros((0, 4)), angmom=np.zeros((0, 3)), mass=np.zeros(0),
                   moments=np.zeros((0, 3)), force=np.zeros((0, 3)), torque=np.zeros((0, 3)),
                   sphere_mass=np.zeros(n_particles))

    @property
    def count(self):
        """Number of clumps."""
        return self.mass.size

    @classmethod
    def place(cls, templates, template_of, centres, orientations, materials, material_of=None, velocities=None,
              angular_velocities=None, spheres=None, scales=None):
        """Clumps of ``templates`` (:class:`ClumpTemplate`): clump c is ``templates[template_of[c]]``
        enlarged ``scales[c]`` times (default 1: lengths × s, volume × s³, inertia × s⁵) with its
        centroid at ``centres[c]``, turned by the unit quaternion ``orientations[c]`` (principal
        frame → space), of material ``material_of[c]`` (default 0; the density is the
        material's), moving at ``velocities[c]`` and spinning at ``angular_velocities[c]`` (space
        frame). Returns (particles, clumps): the members, clump by clump in template order, then
        the free ``spheres`` (a Particles set) if given."""
        template_of = np.asarray(template_of, np.int64).reshape(-1)
        nc = template_of.size
        centres = np.asarray(centres, float).reshape(nc, 3)
        quat = np.asarray(orientations, float).reshape(nc, 4)
        quat = quat / np.linalg.norm(quat, axis=1)[:, None]
        material_of = np.zeros(nc, np.int32) if material_of is None else np.asarray(material_of, np.int32).reshape(nc)
        vel = np.zeros((nc, 3)) if velocities is None else np.asarray(velocities, float).reshape(nc, 3)
        spin = np.zeros((nc, 3)) if angular_velocities is None else np.asarray(angular_velocities, float).reshape(nc, 3)
        scales = np.ones(nc) if scales is None else np.asarray(scales, float).reshape(nc)
        density, _, _ = material_arrays(materials)
        member_start, owner, member_body, radius = member_layout(templates, template_of, scales)
        m = int(member_start[-1])
        chosen = [templates[t] for t in template_of]
        mass = np.array([t.mass(density[k]) for t, k in zip(chosen, material_of, strict=True)]) * scales**3
        moments = np.array([t.inertia(density[k]) for t, k in zip(chosen, material_of, strict=True)]).reshape(nc, 3) \
            * (scales**5)[:, None]
        pos, member_vel, angmom = _rigid_motion(quat, centres, vel, spin, moments, member_start, member_body)
        sphere_mass = density[material_of[owner]] * 4.0 / 3.0 * np.pi * radius**3
        members = Particles(pos, radius, mass[owner], inertia=0.4 * sphere_mass * radius**2, vel=member_vel,
                            angvel=spin[owner], material=material_of[owner])
        member_of = owner.astype(np.int32)
        if spheres is not None:
            members = Particles.from_arrays({k: np.concatenate([getattr(members, k), getattr(spheres, k)])
                                             for k in ARRAY_FIELDS}, members.n + spheres.n)
            member_of = np.concatenate([member_of, np.full(spheres.n, -1, np.int32)])
            sphere_mass = np.concatenate([sphere_mass, spheres.mass])
        clumps = cls(member_of=member_of, member_start=member_start, member_index=np.arange(m, dtype=np.int64),
                     member_body=member_body, pos=centres, vel=vel, quat=quat, angmom=angmom, mass=mass,
                     moments=moments, force=np.zeros((nc, 3)), torque=np.zeros((nc, 3)), sphere_mass=sphere_mass)
        return members, clumps

    def clump_of_members(self):
        """The clump of each member, in template order (m,)."""
        return np.repeat(np.arange(self.count), np.diff(self.member_start))

    def critical_mass(self, radius):
        """Each particle's mass for the critical time step (docs/design.md §2.19), given every
        particle's ``radius``: a member's is the smaller of its mass as a sphere of its own and
        I_min / (0.4 ρ² n) of its clump (I_min its smallest principal moment, ρ its reach from the
        centre, n its members): a sphere's own mass for a one-member clump (I = 0.4 m r²), less for
        a clump that a tangential force at its far end turns more easily, and whose members carry
        more contacts together. Other particles: ``sphere_mass``."""
        count = np.diff(self.member_start)
        owner = self.clump_of_members()
        reach = np.zeros(self.count)
        np.maximum.at(reach, owner, np.linalg.norm(self.member_body, axis=1) + radius[self.member_index])
        rotational = np.min(self.moments, axis=1) / (0.4 * reach**2 * count)
        mass = self.sphere_mass.copy()
        mass[self.member_index] = np.minimum(mass[self.member_index], rotational[owner])
        return mass

    def arrays(self):
        """Every array, by name (for a checkpoint)."""
        return {name: getattr(self, name) for name in self.FIELDS}

    def angular_velocity(self):
        """ω^{n−½} of each clump in the space frame, R I⁻¹ Rᵀ L (nc, 3)."""
        return _angular_velocities(self.quat, self.angmom, self.moments)


@dataclass
class ClumpPacking:
    """Clumps as a packing holds them between engines (a specimen being generated, a specimen
    file): ``templates`` (:class:`ClumpTemplate`), and per clump its template ``template_of``,
    its enlargement ``scale`` (lengths × s), centre of mass ``centres`` (nc, 3), orientation
    ``orientations`` (nc, 4; principal frame → space), velocity and angular velocity (nc, 3)."""
    templates: list
    template_of: np.ndarray
    scale: np.ndarray
    centres: np.ndarray
    orientations: np.ndarray
    velocities: np.ndarray = None
    angular_velocities: np.ndarray = None

    def __post_init__(self):
        nc = np.asarray(self.template_of).size
        self.template_of = np.asarray(self.template_of, np.int64).reshape(nc)
        self.scale = np.asarray(self.scale, float).reshape(nc)
        self.centres = np.asarray(self.centres, float).reshape(nc, 3)
        self.orientations = np.asarray(self.orientations, float).reshape(nc, 4)
        for name in ("velocities", "angular_velocities"):
            value = getattr(self, name)
            setattr(self, name, np.zeros((nc, 3)) if value is None else np.asarray(value, float).reshape(nc, 3))

    @property
    def count(self):
        return self.template_of.size

    def volumes(self):
        """The union volume of each clump (nc,)."""
        return np.array([t.volume for t in self.templates])[self.template_of] * self.scale**3

    def equivalent_radii(self):
        """The radius of the sphere of each clump's volume (nc,)."""
        return (3.0 * self.volumes() / (4.0 * np.pi)) ** (1.0 / 3.0)

    def enclosing_radii(self):
        """The radius of each clump's smallest enclosing sphere about its centre (nc,)."""
        return np.array([t.reach() for t in self.templates])[self.template_of] * self.scale

    def bodies(self, materials, material=0, size=1.0):
        """(particles, clumps) for an Engine (:meth:`Clumps.place`), every clump of ``material`` and
        enlarged a further ``size`` times about its centre."""
        return Clumps.place(self.templates, self.template_of, self.centres, self.orientations, materials,
                            np.full(self.count, material, np.int32), self.velocities, self.angular_velocities,
                            scales=self.scale * size)

    def moved(self, engine):
        """This packing at the state of ``engine``'s clumps (built from :meth:`bodies`)."""
        c = engine.clumps
        return replace(self, centres=c.pos.copy(), orientations=c.quat.copy(), velocities=c.vel.copy(),
                       angular_velocities=c.angular_velocity())

    def resized(self, factor):
        """These clumps enlarged ``factor`` times about their centres."""
        return replace(self, scale=self.scale * factor)

    def joined(self, other):
        """This packing followed by ``other`` (the same templates)."""
        both = lambda name: np.concatenate([getattr(self, name), getattr(other, name)])  # noqa: E731
        return ClumpPacking(self.templates, *(both(k) for k in ("template_of", "scale", "centres", "orientations",
                                                                  "velocities", "angular_velocities")))

    def members(self):
        """(positions, radii) of every member sphere, clump by clump in template order."""
        start, _, body, radii = member_layout(self.templates, self.template_of, self.scale)
        quat = self.orientations / np.linalg.norm(self.orientations, axis=1)[:, None]
        pos, _, _ = _rigid_motion(quat, self.centres, self.velocities, self.angular_velocities,
                                  np.ones((self.count, 3)), start, body)
        return pos, radii

    def arrays(self):
        """The packing as named arrays (a specimen file's ``clump_*`` entries): the templates'
        members as given (``template_members`` (k, 4): x, y, z, r; ``template_start``) and the
        per-clump arrays."""
        return {"template_members": np.concatenate([np.column_stack([t.centres, t.radii]) for t in self.templates]),
                "template_start": np.concatenate([[0], np.cumsum([t.count for t in self.templates])]),
                "template_of": self.template_of, "scale": self.scale, "centres": self.centres,
                "orientations": self.orientations}

    @classmethod
    def from_arrays(cls, arrays):
        """The packing of :meth:`arrays` (at rest)."""
        members, start = np.asarray(arrays["template_members"], float), np.asarray(arrays["template_start"])
        templates = [ClumpTemplate(members[a:b, :3], members[a:b, 3])
                     for a, b in zip(start[:-1], start[1:], strict=True)]
        return cls(templates, arrays["template_of"], arrays["scale"], arrays["centres"], arrays["orientations"])


def clump_cloud(templates, template_of, diameters, lo, hi, seed, rng):
    """Clumps of ``templates[template_of[c]]``, each enlarged to the equal-volume ``diameters[c]``,
    at random places in the box [lo, hi] where their enclosing spheres do not overlap
    (:func:`de_domain.packing.random_cloud`, largest first, with ``seed``), in random orientations
    (uniform unit quaternions drawn from ``rng``), at rest. Raises ValueError if they do not fit."""
    from .packing import random_cloud
    template_of = np.asarray(template_of, np.int64)
    scale = scales_to_diameters(templates, template_of, diameters)
    enclosing = scale * np.array([t.reach() for t in templates])[template_of]
    order = np.argsort(enclosing, kind="stable")[::-1]  # random_cloud places the largest first
    centres, _ = random_cloud(enclosing[order], lo, hi, seed=seed)
    orientations = random_orientations(template_of.size, rng)
    return ClumpPacking(templates, template_of[order], scale[order], centres, orientations)


def scales_to_diameters(templates, template_of, diameters):
    """The enlargement of each clump ``templates[template_of[c]]`` to the equal-volume ``diameters[c]``."""
    return 0.5 * np.asarray(diameters, float) / np.array([t.equivalent_radius() for t in templates])[template_of]


def random_orientations(count, rng):
    """``count`` unit quaternions uniform over the rotations (normalised 4-D normal draws,
    Marsaglia 1972), (count, 4)."""
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


@njit(cache=True)
def _rigid_motion(quat, centres, vel, spin, moments, member_start, member_body):
    """Clumps at ``centres`` turned by ``quat`` (principal frame → space), moving at ``vel`` and
    spinning at ``spin``: their members' positions x_c + R b_m and velocities v_c + ω × R b_m, and
    the clumps' angular momenta R I Rᵀ ω."""
    pos = np.empty_like(member_body)
    member_vel = np.empty_like(member_body)
    angmom = np.empty_like(centres)
    for c in range(centres.shape[0]):
        q = (quat[c, 0], quat[c, 1], quat[c, 2], quat[c, 3])
        wx, wy, wz = spin[c, 0], spin[c, 1], spin[c, 2]
        bx, by, bz = to_body(q, wx, wy, wz)
        angmom[c, 0], angmom[c, 1], angmom[c, 2] = to_space(q, bx * moments[c, 0], by * moments[c, 1],
                                                          bz * moments[c, 2])
        for k in range(member_start[c], member_start[c + 1]):
            rx, ry, rz = to_space(q, member_body[k, 0], member_body[k, 1], member_body[k, 2])
            pos[k, 0] = centres[c, 0] + rx
            pos[k, 1] = centres[c, 1] + ry
            pos[k, 2] = centres[c, 2] + rz
            member_vel[k, 0] = vel[c, 0] + wy * rz - wz * ry
            member_vel[k, 1] = vel[c, 1] + wz * rx - wx * rz
            member_vel[k, 2] = vel[c, 2] + wx * ry - wy * rx
    return pos, member_vel, angmom


@njit(cache=True)
def _angular_velocities(quat, angmom, moments):
    """R I⁻¹ Rᵀ L of each clump (space frame)."""
    out = np.empty_like(angmom)
    for c in range(angmom.shape[0]):
        q = (quat[c, 0], quat[c, 1], quat[c, 2], quat[c, 3])
        bx, by, bz = to_body(q, angmom[c, 0], angmom[c, 1], angmom[c, 2])
        out[c, 0], out[c, 1], out[c, 2] = to_space(q, bx / moments[c, 0], by / moments[c, 1], bz / moments[c, 2])
    return out
