"""Standard DEM diagnostics (docs/design.md §2.16). Every function takes the
:class:`~de_domain.engine.Engine` (its particles and last-step contacts) and, where
it makes sense, a region.

Regions: :class:`BoxRegion` (axis-aligned) and :class:`SphereRegion`. Solid volume
in a region counts the part of every sphere inside it:

  * sphere region: exact lens volume of two intersecting spheres;
  * box region: spheres wholly inside/outside exactly; spheres cut by the box
    faces by a 32 × 32 Gauss–Legendre quadrature of the disc ∩ rectangle area
    over height (relative error of the cut volume ≲ 1e-4).

Clumps (docs/design.md §2.19) are grains: a clump's members count once, as one body.
Kinetic energy and the unbalanced force are the clumps' (½ M v² + ½ ω·L; the resultant
M g + Σ F_m), not their members'; the coordination number is contacts per grain (a
contact between members of two clumps counts for both clumps); Love–Weber branch vectors
run from the clumps' centres. Solid volume weights each member's part in the region by
its clump's union volume over the sum of its members' volumes: exact for clumps wholly
inside or outside the region, and within the overlap's share of a cut clump otherwise.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BoxRegion:
    lo: tuple
    hi: tuple

    @property
    def volume(self):
        return float(np.prod(np.asarray(self.hi, float) - np.asarray(self.lo, float)))

    def contains(self, points):
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        return np.all((points >= lo) & (points <= hi), axis=1)


@dataclass(frozen=True)
class SphereRegion:
    center: tuple
    radius: float

    @property
    def volume(self):
        return 4.0 / 3.0 * np.pi * self.radius**3

    def contains(self, points):
        return np.linalg.norm(points - np.asarray(self.center, float), axis=1) <= self.radius


def _domain(engine):
    return getattr(engine, "domain", None)


def _rank_sums(engine, values):
    """``values`` (this rank's partial sums, an array) summed over the ranks of a
    distributed engine in rank order (collective), the same bits on every rank; a
    serial engine's own ``values``."""
    domain = _domain(engine)
    if domain is None:
        return np.asarray(values, dtype=np.float64)
    from .comm import sum_in_rank_order
    return sum_in_rank_order(domain.comm, values)


def _free_spheres(engine):
    """Mask of the owned particles that are free spheres, not members of a clump."""
    p = engine.particles
    return p.owned & (engine.clump_rows()[0] < 0) if engine.clumps.count else p.owned


def _clumps_here(engine):
    """Does this process count the clumps' own terms (the root of a distributed engine: every
    rank holds every clump)?"""
    return engine.runner.is_root


def _member_values(engine, values):
    """``values`` (one per particle row) of each clump member, in template order (collective when
    distributed: each member's from the rank owning it, the others adding zeros: exact)."""
    _, member_row = engine.clump_rows()
    held = member_row >= 0
    out = np.zeros(member_row.size)
    out[held] = values[member_row[held]]
    return out if _domain(engine) is None else _rank_sums(engine, out)


def kinetic_energy(engine):
    """Σ ½ m v² + ½ I ω² over owned free spheres and Σ ½ M v² + ½ ω·L over clumps (current
    half-step velocities); a distributed engine sums over its ranks (collective)."""
    p = engine.particles
    mine = _free_spheres(engine)
    terms = (0.5 * np.sum(p.mass[mine] * np.sum(p.vel[mine] ** 2, axis=1)),
             0.5 * np.sum(p.inertia[mine] * np.sum(p.angvel[mine] ** 2, axis=1)))
    c = engine.clumps
    if c.count and _clumps_here(engine):
        terms = (terms[0] + 0.5 * np.sum(c.mass * np.sum(c.vel**2, axis=1)),
                 terms[1] + 0.5 * np.sum(c.angular_velocity() * c.angmom))
    if _domain(engine) is None:
        return float(terms[0] + terms[1])
    translational, rotational = _rank_sums(engine, terms)
    return float(translational + rotational)


def total_mass(engine):
    """Σ m over owned free spheres and Σ M over clumps (a clump's members carry its mass for
    their contacts' dashpots, so they are not counted), in kg; a distributed engine sums over
    its ranks in rank order (collective)."""
    p = engine.particles
    total = np.array([np.sum(p.mass[_free_spheres(engine)])])
    c = engine.clumps
    if c.count and _clumps_here(engine):
        total = total + np.sum(c.mass)
    return float(_rank_sums(engine, total)[0])


def linear_momentum(engine):
    """Σ m v over owned free spheres and Σ M v over clumps (current half-step velocities;
    a clump's members carry its mass for their contacts' dashpots, so they are not counted),
    a (3,) array in N s; a distributed engine sums over its ranks in rank order (collective)."""
    p = engine.particles
    mine = _free_spheres(engine)
    total = np.sum(p.mass[mine, None] * p.vel[mine], axis=0)
    c = engine.clumps
    if c.count and _clumps_here(engine):
        total = total + np.sum(c.mass[:, None] * c.vel, axis=0)
    return _rank_sums(engine, total)


def _owned_contacts(engine, c):
    """Masks of the contacts this rank counts: sphere pairs whose lower id ``i`` it owns
    (a pair straddling two ranks is listed on both), wall and facet contacts of its
    owned particles. Every contact is counted on exactly one rank."""
    owned = engine.particles.owned
    return owned[c["i"]], owned[c["wall_particle"]], owned[c["facet_particle"]]


def unbalanced_force_ratio(engine):
    """``mean |resultant force| / mean |contact force|`` (YADE ``unbalancedForce``).

    The resultant is contacts + gravity of the last step over free particles and over
    clumps (not their members); 0/0 (no contacts) returns 1.0 ("not in equilibrium"). A
    distributed engine takes the means over all ranks (collective).
    """
    p = engine.particles
    mine = _free_spheres(engine)
    free = ~np.all(p.blocked[mine, :3] | p.prescribed[mine, :3], axis=1)
    resultant = np.linalg.norm(p.force[mine][free], axis=1)
    if engine.clumps.count and _clumps_here(engine):
        resultant = np.concatenate([resultant, np.linalg.norm(engine.clumps.force, axis=1)])
    c = engine.contacts()
    pairs, walls, facets = _owned_contacts(engine, c)
    forces = np.concatenate([np.linalg.norm(c["force"][pairs], axis=1), np.linalg.norm(c["wall_force"][walls], axis=1),
                             np.linalg.norm(c["facet_force"][facets], axis=1)])
    resultant_sum, resultant_count, force_sum, force_count = _rank_sums(
        engine, [np.sum(resultant), resultant.size, np.sum(forces), forces.size])
    if force_count == 0 or resultant_count == 0:
        return 1.0
    mean_contact = force_sum / force_count
    return float((resultant_sum / resultant_count) / mean_contact) if mean_contact > 0 else 1.0


def coordination_number(engine, region=None, include_walls=False):
    """Z = 2 N_c / N_p over grains (centres; a clump's centre of mass) in ``region`` (all if None).

    Grain–grain contacts count for both grains; wall/facet contacts count once
    when ``include_walls``. A distributed engine counts over all ranks (collective).
    """
    p = engine.particles
    mine = p.owned
    c = engine.contacts()
    counts = np.bincount(c["i"], minlength=p.n)[mine] + np.bincount(c["j"], minlength=p.n)[mine]
    if include_walls:
        counts = counts + np.bincount(c["wall_particle"], minlength=p.n)[mine] \
            + np.bincount(c["facet_particle"], minlength=p.n)[mine]
    centres = p.pos[mine]
    clumps = engine.clumps
    if clumps.count:  # per grain: the free spheres, then the clumps (their members' contacts summed)
        every = np.zeros(p.n)
        every[mine] = counts
        per_clump = np.bincount(clumps.clump_of_members(), _member_values(engine, every), clumps.count)
        free = _free_spheres(engine)[mine]
        if _clumps_here(engine):
            counts = np.concatenate([counts[free], per_clump])
            centres = np.concatenate([centres[free], clumps.pos])
        else:
            counts, centres = counts[free], centres[free]
    inside = np.ones(counts.size, bool) if region is None else region.contains(centres)
    contacts, particles = _rank_sums(engine, [counts[inside].sum(), inside.sum()])
    if particles == 0:
        return 0.0
    return float(contacts / particles)


_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(32)


def _sphere_box_volume(center, r, lo, hi):
    """Volume of a sphere inside an axis-aligned box (quadrature, see module docstring)."""
    z0, z1 = max(center[2] - r, lo[2]), min(center[2] + r, hi[2])
    if z1 <= z0:
        return 0.0
    z = 0.5 * (z1 - z0) * _GAUSS_X + 0.5 * (z1 + z0)
    rho = np.sqrt(np.maximum(r * r - (z - center[2]) ** 2, 0.0))
    area = np.zeros_like(z)
    for k in range(z.size):
        x0, x1 = max(center[0] - rho[k], lo[0]), min(center[0] + rho[k], hi[0])
        if x1 <= x0:
            continue
        x = 0.5 * (x1 - x0) * _GAUSS_X + 0.5 * (x1 + x0)
        h = np.sqrt(np.maximum(rho[k] ** 2 - (x - center[0]) ** 2, 0.0))
        chord = np.clip(np.minimum(center[1] + h, hi[1]) - np.maximum(center[1] - h, lo[1]), 0.0, None)
        area[k] = 0.5 * (x1 - x0) * np.dot(_GAUSS_W, chord)
    return 0.5 * (z1 - z0) * float(np.dot(_GAUSS_W, area))


def _sphere_sphere_volume(d, r, big_r):
    """Exact volume of the intersection of spheres (radii r, R) with centre distance d."""
    if d >= r + big_r:
        return 0.0
    if d <= abs(big_r - r):
        return 4.0 / 3.0 * np.pi * min(r, big_r) ** 3
    return (np.pi * (big_r + r - d) ** 2
            * (d * d + 2 * d * r - 3 * r * r + 2 * d * big_r + 6 * r * big_r - 3 * big_r * big_r) / (12 * d))


def solid_volume(engine, region):
    """Volume of the spheres' parts inside ``region`` (owned particles; a distributed
    engine sums over its ranks, collective)."""
    return float(_rank_sums(engine, [_solid_volume(engine, region)])[0])


def _solid_volume(engine, region):
    p = engine.particles
    mine = p.owned
    clumps = engine.clumps
    if not clumps.count:
        return spheres_solid_volume(p.pos[mine], p.radius[mine], region)
    # members weighted by their clump's union volume over its members' summed volume (module docstring)
    member_volume = _member_values(engine, 4.0 / 3.0 * np.pi * p.radius**3)
    ratio = clump_volumes(engine) / np.bincount(clumps.clump_of_members(), member_volume, clumps.count)
    member_of = engine.clump_rows()[0]
    weight = np.ones(p.n)
    members = member_of >= 0
    weight[members] = ratio[member_of[members]]
    return spheres_solid_volume(p.pos[mine], p.radius[mine], region, weight[mine])


def spheres_solid_volume(pos, rad, region, weight=None):
    """Volume of the parts of the spheres (centres ``pos``, radii ``rad``) inside ``region``:
    whole spheres inside, quadrature for those cut by a box face, the exact lens for a sphere;
    each sphere's part times its ``weight`` if given."""
    total = 0.0
    w = np.ones(rad.size) if weight is None else weight
    if isinstance(region, SphereRegion):
        d = np.linalg.norm(pos - np.asarray(region.center, float), axis=1)
        for k in np.nonzero(d < rad + region.radius)[0]:
            total += _sphere_sphere_volume(d[k], rad[k], region.radius) * w[k]
        return float(total)
    lo, hi = np.asarray(region.lo, float), np.asarray(region.hi, float)
    inside = np.all((pos - rad[:, None] >= lo) & (pos + rad[:, None] <= hi), axis=1)
    total += float(np.sum(4.0 / 3.0 * np.pi * rad[inside] ** 3 * w[inside]))
    touching = np.all((pos + rad[:, None] > lo) & (pos - rad[:, None] < hi), axis=1) & ~inside
    for k in np.nonzero(touching)[0]:
        total += _sphere_box_volume(pos[k], rad[k], lo, hi) * w[k]
    return float(total)


def clump_volumes(engine):
    """The union volume of each clump, M / ρ (its members' material's density)."""
    c = engine.clumps
    material = _member_values(engine, engine.particles.material.astype(np.float64))[c.member_start[:-1]]
    return c.mass / np.array([engine.materials[int(k)].density for k in material])


def grain_radii(engine):
    """The equal-volume radius of every grain: the free spheres' radii in global-id order, then
    the clumps' (collective when distributed)."""
    radius = engine.global_particles().radius
    if not engine.clumps.count:
        return radius
    free = radius[engine.clumps.member_of < 0]
    return np.concatenate([free, (3.0 * clump_volumes(engine) / (4.0 * np.pi)) ** (1.0 / 3.0)])


def porosity(engine, region):
    """n = 1 − V_solid / V_region."""
    return 1.0 - solid_volume(engine, region) / region.volume


def void_ratio(engine, region):
    """e = V_voids / V_solids = n / (1 − n) (docs/design.md §3.3)."""
    solid = solid_volume(engine, region)
    return (region.volume - solid) / solid if solid > 0 else np.inf


def love_weber_stress(engine, region):
    """σ = 1/V Σ_c f_c ⊗ l_c over contacts whose contact point lies in ``region``.

    Compression positive: grain pairs f_c = force on j (= −force on i), l_c = x_j − x_i;
    wall/facet contacts f_c = force on the wall, l_c = contact point − x_i, with x the
    grain's centre (a clump's centre of mass for its members). The tensor is symmetrised
    only by equilibrium (returned as computed). A distributed engine sums over its ranks
    (collective).
    """
    p = engine.particles
    c = engine.contacts()
    pairs, walls, facets = _owned_contacts(engine, c)
    sigma = np.zeros((3, 3))
    centre = p.pos
    branch = c["branch"]
    if engine.clumps.count:
        member_of = engine.clump_rows()[0]
        centre = np.where((member_of >= 0)[:, None], engine.clumps.pos[np.maximum(member_of, 0)], p.pos)
        branch = centre[c["j"]] - centre[c["i"]]
    sel = region.contains(c["point"]) & pairs if len(c["i"]) else np.zeros(0, bool)
    sigma += np.einsum("ci,cj->ij", -c["force"][sel], branch[sel])
    if len(c["wall_particle"]):
        sel = region.contains(c["wall_point"]) & walls
        arm = c["wall_point"][sel] - centre[c["wall_particle"][sel]]
        sigma += np.einsum("ci,cj->ij", -c["wall_force"][sel], arm)
    if len(c["facet_particle"]):
        sel = region.contains(c["facet_point"]) & facets
        arm = c["facet_point"][sel] - centre[c["facet_particle"][sel]]
        sigma += np.einsum("ci,cj->ij", -c["facet_force"][sel], arm)
    return _rank_sums(engine, sigma) / region.volume


def energy_balance(engine):
    """The engine's energy books (:meth:`Engine.energy`), including ``residual``."""
    return engine.energy()
