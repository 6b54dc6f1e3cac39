"""Filling a volume of any shape with grains by radius expansion (docs/design.md §3.2).

The volume is given by its tetrahedra and closed by triangle walls (its faces: the FE
interface, slice walls, rigid bodies, and a *lid* over what will be a free surface). As in
the box method (:func:`de_domain.deposition.radius_expansion`):

1. the number of grains is the one that gives the target void ratio e in the volume V,
   V_s = V / (1 + e), drawn from the sieve curve by the caller;
2. the grains are placed at random, shrunk to a small solid fraction, by random sequential
   addition at points drawn uniformly in the tetrahedra (a tetrahedron chosen with
   probability ∝ its volume, a point in it by the folded-cube barycentric draw of Rocchini
   & Cignoni, "Generating random points in a tetrahedron", J. Graphics Tools 5, 2000), at
   least a radius from every wall;
3. the radii grow to full size in steps, the walls holding them (gravity off), the grains
   come to rest without gravity (or, when the lid carries less than ``seat_stress``, they
   have not jammed: a loose gas has no equilibrium to reach without gravity, and the
   stage ends), then with it;
4. the lid is moved out along its normal until it carries at most ``release_stress``, then
   removed, and the grains come to rest under gravity with a free surface.

The densities are scaled by ``density_scale`` with the gravity divided by it (real weights,
a larger stable step) as in :mod:`de_domain.deposition`; the caller's model uses the real
densities.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from de_domain.clumps import ClumpPacking, random_orientations, scales_to_diameters
from de_domain.deposition import (
    GenerationSettings,
    SpherePacking,
    _critical_dt_all,
    _materials,
    _start_friction,
    _unbalanced,
)
from de_domain.packing import CANDIDATE_BLOCK, SphereInserter


@dataclass(frozen=True)
class ContainerWall:
    """Triangles (m, 3, 3) closing the volume, of one material (de_domain Material, real
    density); ``lid``: removed at the end, leaving a free surface."""
    triangles: np.ndarray
    material: object
    lid: bool = False


@dataclass
class FilledZone:
    """The grains (centres, radii), the void ratio (V − V_s) / V_s over the volume (V_s of the
    grains whose centre is in it: below the lid's plane once the lid is gone), the steps taken,
    the log, and the void ratio of the bulk, away from the faces, where grains pack looser."""
    positions: np.ndarray
    radii: np.ndarray
    void_ratio: float
    steps: int
    log: list = field(default_factory=list)
    bulk_void_ratio: float = None  # :func:`bulk_void_ratio`, one d_max from the faces; None if nothing is that far
    clumps: object = None  # clumped grains: their :class:`~de_domain.clumps.ClumpPacking` (the spheres are its members)


def points_in_tets(tets, count, rng):
    """``count`` points uniform in the union of the tetrahedra (k, 4, 3) (module docstring)."""
    a, b, c, d = (tets[:, k] for k in range(4))
    volume = np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a))
    which = rng.choice(len(tets), size=count, p=volume / volume.sum())
    s, t, u = rng.random((3, count))
    fold = s + t > 1.0                                    # fold the cube into the tetrahedron
    s[fold], t[fold] = 1.0 - s[fold], 1.0 - t[fold]
    over = t + u > 1.0
    t_old = t.copy()
    t[over], u[over] = 1.0 - u[over], 1.0 - s[over] - t_old[over]
    under = ~over & (s + t + u > 1.0)
    s_old = s.copy()
    s[under], u[under] = 1.0 - t[under] - u[under], s_old[under] + t[under] + u[under] - 1.0
    w = np.stack([1.0 - s - t - u, s, t, u], axis=1)
    return np.einsum("nk,nkd->nd", w, tets[which])


def inside_tets(points, tets, tolerance=1e-9) -> np.ndarray:
    """Whether each point (n, 3) lies in the union of the tetrahedra (k, 4, 3): its barycentric
    coordinates in one of them all ≥ −``tolerance``; the candidates are the tetrahedra whose
    centroid is within the largest centroid-to-corner distance (a k-d tree)."""
    from scipy.spatial import cKDTree
    points = np.asarray(points, float)
    centroid = tets.mean(axis=1)
    reach = float(np.linalg.norm(tets - centroid[:, None], axis=2).max())
    found = np.zeros(len(points), bool)
    for i, candidates in enumerate(cKDTree(centroid).query_ball_point(points, reach)):
        t = tets[candidates]
        edges = np.transpose(t[:, 1:] - t[:, :1], (0, 2, 1))          # columns b − a, c − a, d − a
        w = np.linalg.solve(edges, (points[i] - t[:, 0])[:, :, None])[:, :, 0]
        found[i] = bool(np.any((w >= -tolerance).all(axis=1) & (w.sum(axis=1) <= 1.0 + tolerance)))
    return found


def bulk_void_ratio(tets, faces, positions, radii, margin, rng, samples=200_000):
    """The void ratio (1 − φ) / φ of the volume's bulk: φ is the fraction of ``samples`` random
    points of the tetrahedra, farther than ``margin`` from its ``faces``, that lie inside a
    grain (Monte Carlo, standard error ≈ sqrt(φ (1 − φ) / n) on φ over the n points kept);
    spheres pack looser within about a diameter of a wall, so the bulk is what a target void
    ratio means. None when no point is that far from the faces."""
    from scipy.spatial import cKDTree
    points = points_in_tets(tets, samples, rng)
    points = points[distance_to(faces, tets, 0.25 * margin)(points, upto=margin) > margin]
    if len(points) == 0:
        return None
    near, which = cKDTree(positions).query(points, k=16, distance_upper_bound=float(radii.max()))
    inside = np.zeros(len(points), bool)
    for k in range(near.shape[1]):
        hit = np.isfinite(near[:, k])
        inside[hit] |= near[hit, k] < radii[which[hit, k]]
    phi = float(inside.mean())
    return (1.0 - phi) / phi if phi > 0 else None


def tets_volume(tets) -> float:
    """``Σ |det(b − a, c − a, d − a)| / 6`` over the tetrahedra (k, 4, 3) (m³)."""
    a, b, c, d = (tets[:, k] for k in range(4))
    return float(np.sum(np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a))) / 6.0)


def thickness(tets, faces, spacing, rng, samples_per_tet=8, at_least=np.inf) -> float:
    """Twice the largest distance from a point of the volume (random points, ``samples_per_tet``
    per tetrahedron on average) to its boundary ``faces`` (m, 3, 3) (sampled every ``spacing``):
    about the diameter of the largest sphere that fits, to within ``spacing``; or a value of
    ``at_least`` or more when the volume is that thick (the search for nearer faces stops there)."""
    inside = points_in_tets(tets, samples_per_tet * len(tets), rng)
    return 2.0 * float(distance_to(faces, tets, spacing)(inside, upto=0.5 * at_least).max())


def distance_to(faces, tets, spacing):
    """The function giving the distance (m) from points (n, 3) of the volume ``tets`` to its
    boundary ``faces`` (m, 3, 3): exact to the faces that lie in planes bounding the whole
    volume (:func:`planar_walls`; a point inside is no nearer to any other point of such a
    plane), to within ``spacing`` to the others (sampled, :func:`sample_triangles`, a k-d tree
    built once). ``distance(points, upto)``: a distance of ``upto`` or more may be returned as
    any value at least ``upto`` (infinity): the tree's search stops there, which makes a query
    of points far from the curved faces fast (a thin shell of samples, such as a ring's faces,
    prunes a k-d tree's search poorly: 130 µs a point in the tunnel's ring, 2026-12-06)."""
    from scipy.spatial import cKDTree
    planes, rest = planar_walls(faces, tets, 0)
    tree = cKDTree(sample_triangles(rest, spacing)) if len(rest) else None

    def distance(points, upto=np.inf):
        out = np.full(len(points), np.inf)
        for plane in planes:
            out = np.minimum(out, points @ plane.normal - float(plane.point @ plane.normal))
        if tree is None:
            return out
        bound = upto * (1.0 + 1e-9) if np.isfinite(upto) else np.inf  # exact up to and at upto
        return np.minimum(out, tree.query(points, distance_upper_bound=bound)[0])
    return distance


def sample_triangles(triangles, spacing) -> np.ndarray:
    """Points on the triangles (m, 3, 3), on a barycentric grid no coarser than ``spacing``
    along the longest edge of each, vertices included."""
    triangles = np.asarray(triangles, float)
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(axis=1)
    out = []
    for n in np.unique(np.maximum(1, np.ceil(edges / spacing)).astype(int)):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        w = np.stack([i[keep], j[keep]], axis=1) / n
        these = triangles[np.maximum(1, np.ceil(edges / spacing)).astype(int) == n]
        a = these[:, 0]
        out.append((a[:, None] + w[None, :, :1] * (these[:, 1] - a)[:, None]
                    + w[None, :, 1:] * (these[:, 2] - a)[:, None]).reshape(-1, 3))
    return np.concatenate(out)


def planar_walls(triangles, tets, material, tolerance=1e-9):
    """The triangles (m, 3, 3) as plane walls where they can be: grouped by the plane each lies
    in, a group becomes a PlaneWall of ``material`` (normal towards the grains) when the whole
    grain volume ``tets`` lies on one side of its plane, so that the infinite plane touches no
    grain the triangles would not (a plane contact costs less than a facet's). Returns (the
    PlaneWalls, the triangles of the other groups (k, 3, 3)). ``tolerance``: relative to the
    volume's size, how far from a plane a point may be and still lie in it."""
    from de_domain import PlaneWall
    t = np.asarray(triangles, float).reshape(-1, 3, 3)
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    corners = tets.reshape(-1, 3)
    gap = tolerance * float(np.ptp(corners, axis=0).max())
    planes, others = [], []
    left = np.arange(len(t))
    while len(left):
        n = normal[left[0]]
        offset = float(n @ t[left[0], 0])
        same = (np.abs(normal[left] @ n) > 1.0 - tolerance) & (np.abs(t[left, 0] @ n - offset) < gap)
        side = corners @ n - offset
        if side.min() >= -gap:
            planes.append(PlaneWall(offset * n, n, material))
        elif side.max() <= gap:
            planes.append(PlaneWall(offset * n, -n, material))
        else:
            others.append(t[left[same]])
        left = left[~same]
    return planes, np.concatenate(others) if others else np.zeros((0, 3, 3))


def facet_mesh(triangles, material):
    """A FacetMesh of the triangles (m, 3, 3) with coincident corners merged into shared
    vertices (edges shared by two triangles are one edge for contact)."""
    from de_domain import FacetMesh
    corners = np.asarray(triangles, float).reshape(-1, 3)
    vertices, index = np.unique(corners, axis=0, return_inverse=True)
    return FacetMesh(vertices, index.reshape(-1, 3), material=material)


def fill_zone(tets, walls, diameters, s: GenerationSettings, log=None, comm=None, attempts=400,
              increments=40, steps_per_increment=100, shapes=None, settle=False) -> FilledZone:
    """Grains of ``diameters`` (largest first or not) filling the tetrahedra ``tets`` inside
    ``walls`` (:class:`ContainerWall`), by the steps of the module docstring. ``s`` supplies
    the grain and generation parameters (its box sizes are not used; its ``plate`` material
    is not used either: each wall has its own). ``comm``: the DEM spread over its ranks
    (collective). ``shapes`` (:class:`~de_domain.deposition.GrainShapes`): clumped grains, each
    of a template drawn by share and enlarged to its diameter (equal volume), in a random
    orientation; its enclosing sphere is placed as a sphere is, and it grows about its centre.
    ``settle``: the expansion's stress is let go in every zone, not only a closed one (the grains
    shrunk until their mean stress is at most ``s.release_stress``, or ``s.seat_stress`` if that is
    smaller), and the grains settle under
    gravity with their material's own friction and rolling resistance (not the generation's):
    their stress at rest is their weight's, with the ratio of horizontal to vertical stress of a
    ground laid down under gravity (K0); otherwise a zone under a lid keeps the expansion's
    horizontal stress, the lid lifted off its vertical one.
    Raises ValueError when the cloud does not fit."""
    grains, shrink = _placed_small(tets, walls, diameters, s, attempts, shapes)
    volume = tets_volume(tets)
    materials = _container_materials(s, walls)
    dt = s.safety_factor * _critical_dt_all(s, diameters, shapes)
    friction = _start_friction(s)
    steps, messages = 0, []

    def say(text):
        messages.append(text)
        if log is not None:
            log(text)

    held_planes, held_facets = [], []  # the walls but the lid: planes where they can be, else facets
    for k, w in enumerate(walls):
        if not w.lid:
            these, rest = planar_walls(w.triangles, tets, 1 + k)
            held_planes += [(1 + k, plane.point.copy(), plane.normal.copy()) for plane in these]
            held_facets += [(1 + k, rest)] if len(rest) else []

    def engine_for(grains, gravity, with_lid, size=1.0):
        from de_domain import Engine, PlaneWall
        mats = materials(friction)
        particles, clumps = grains.bodies(mats, 0, size)
        facets = [facet_mesh(w.triangles, 1 + k) for k, w in enumerate(walls) if w.lid and with_lid]  # lid first
        facets += [facet_mesh(rest, k) for k, rest in held_facets]
        planes = [PlaneWall(point, normal, k) for k, point, normal in held_planes]
        return Engine(particles, mats, walls=planes, facets=facets, contact_law=s.contact_law,
                      gravity=tuple(np.asarray(gravity, float) / s.density_scale), dt=dt,
                      safety_factor=s.safety_factor, local_damping=s.local_damping, comm=comm, clumps=clumps)

    for k in range(1, increments + 1):
        engine = engine_for(grains, (0, 0, 0), True, shrink + (1.0 - shrink) * k / increments)
        engine.run(steps_per_increment)
        steps += steps_per_increment
        grains = grains.moved(engine)
    lid = [w for w in walls if w.lid]
    lid_normal, lid_area = _outward(lid, tets.reshape(-1, 3).mean(axis=0))
    if not lid or settle:  # a closed zone has no lid to lift: let the expansion's locked-in stress go here
        target = min(s.seat_stress, s.release_stress) if settle and s.release_stress is not None else s.seat_stress
        engine = engine_for(grains, (0.0, 0.0, 0.0), bool(lid))
        shrink = SETTLE_SHRINK if settle else RELEASE_SHRINK
        grains, factor, used, stress = _release(engine, grains, volume, s, engine_for, target, bool(lid), shrink,
                                                still=settle)
        steps += used
        say(f"zone fill ({'settle' if settle else 'closed zone'}): the grains shrunk by {100.0 * (1.0 - factor):.2f} % "
            f"to let the expansion's stress go: mean stress {stress:.3g} Pa (to at most {target:.3g} Pa, "
            f"shrinking {100.0 * (1.0 - RELEASE_LIMIT):.0f} % at most)")
    if settle:  # the weight's stress is built with the grains' own friction and rolling resistance
        own = replace(s, friction=None, rolling_friction=None, rolling_stiffness=None)
        materials = _container_materials(own, walls)
        friction = s.sand.friction
    for label, gravity in (("expanded", (0.0, 0.0, 0.0)), ("gravity", s.gravity)):
        engine = engine_for(grains, gravity, True)
        loose = (lambda e: _lid_stress(e, walls, lid_normal, lid_area) < s.seat_stress) if label == "expanded" else None
        steps += _rest(engine, s, loose)  # not jammed: a loose gas has no equilibrium to reach without gravity
        say(f"zone fill ({label}): unbalanced force {_unbalanced(engine):.3g}, lid stress "
            f"{_lid_stress(engine, walls, lid_normal, lid_area):.3g} Pa")
        grains = grains.moved(engine)
    lift = 0.0  # how far the lid moved out along its normal (m)
    if lid and s.release_stress is not None:
        engine = engine_for(grains, s.gravity, True)
        lift, used = _lift_lid(engine, walls, lid_normal, lid_area, s)
        steps += used
        say(f"zone fill: lid moved out {lift * 1e3:.3f} mm, where it carries "
            f"{_lid_stress(engine, walls, lid_normal, lid_area):.3g} Pa (release to <= {s.release_stress:.3g} Pa)")
        grains = grains.moved(engine)
    engine = engine_for(grains, s.gravity, False)
    steps += _rest(engine, s)
    grains = grains.moved(engine)
    pos, radii = grains.members()
    faces = np.concatenate([w.triangles for w in walls])
    lo, hi = faces.reshape(-1, 3).min(axis=0), faces.reshape(-1, 3).max(axis=0)
    gone = np.any((pos < lo) | (pos > hi + lift + radii.max()), axis=1)
    if gone.any():
        raise ValueError(f"{int(gone.sum())} grains left the zone when its lid was removed: the zone's faces "
                         "do not close it, or the lid could not be lifted to release the packing")
    inside = np.ones(len(grains.centres), bool)
    if lid:
        plane = np.concatenate([w.triangles for w in lid]).reshape(-1, 3) @ lid_normal
        inside = grains.centres @ lid_normal <= plane.max()
    solids = grains.volumes()
    solid, solid_inside = float(np.sum(solids)), float(np.sum(solids[inside]))
    e = (volume - solid_inside) / solid_inside
    reach = float(np.max(grains.enclosing_radii()))
    bulk = bulk_void_ratio(tets, faces, pos, radii, 2.0 * reach, np.random.default_rng(s.seed))
    say(f"zone fill: {_grains_text(grains)} at rest under gravity, e = {e:.4f} over the zone's volume (the "
        f"{int(inside.sum())} grains with their centre in it; {(volume - solid) / solid:.4f} with all of them), "
        f"{'n/a' if bulk is None else f'{bulk:.4f}'} in its bulk (one d_max from its faces), {steps} steps")
    clumps = None if isinstance(grains, SpherePacking) else replace(grains, velocities=None, angular_velocities=None)
    return FilledZone(pos.copy(), radii.copy(), e, steps, messages, bulk, clumps)


def _grains_text(grains):
    """'N grains' or 'N clumped grains of M spheres'."""
    if isinstance(grains, SpherePacking):
        return f"{len(grains.radii)} grains"
    return f"{grains.count} clumped grains of {len(grains.members()[1])} spheres"


def _placed_small(tets, walls, diameters, s, attempts, shapes):
    """(the grains, ``shrink``): the grains (:class:`~de_domain.deposition.SpherePacking`, or
    :class:`~de_domain.clumps.ClumpPacking` with ``shapes``) at full size, largest enclosing
    sphere first, at the places found for their enclosing spheres shrunk ``shrink`` times to
    ``s.cloud_solid_fraction`` of the volume by random sequential addition (step 2 of the module
    docstring)."""
    diameters = np.sort(np.asarray(diameters, float))[::-1]
    shape_rng = np.random.default_rng([s.seed, 1])  # the clumps' templates and orientations
    template_of = None if shapes is None else shapes.draw(len(diameters), shape_rng)
    enclosing = 0.5 * diameters if shapes is None else 0.5 * diameters * shapes.reach_ratios()[template_of]
    order = np.argsort(-enclosing, kind="stable")  # the inserter places the largest first
    enclosing = enclosing[order]
    volume = tets_volume(tets)
    solid = float(np.sum(4.0 / 3.0 * np.pi * enclosing**3))
    shrink = min(1.0, (s.cloud_solid_fraction * volume / solid) ** (1.0 / 3.0))
    small = enclosing * shrink
    rng = np.random.default_rng(s.seed)
    faces = np.concatenate([w.triangles for w in walls])
    spacing = 0.5 * float(small.min())
    distance = distance_to(faces, tets, spacing)
    lo, hi = faces.reshape(-1, 3).min(axis=0), faces.reshape(-1, 3).max(axis=0)
    inserter = SphereInserter(small, lo, hi)
    for start in range(0, len(small), CANDIDATE_BLOCK):  # drawn and placed a block of grains at a time
        block = slice(start, min(start + CANDIDATE_BLOCK, len(small)))
        drawn = points_in_tets(tets, (block.stop - start) * attempts, rng).reshape(-1, attempts, 3)
        near = float(small[block].max()) + spacing  # only whether a face is nearer than this matters
        blocked = distance(drawn.reshape(-1, 3), upto=near).reshape(-1, attempts) < small[block, None] + spacing
        if inserter.add(_free_first(drawn, blocked)) < block.stop:
            break
    if inserter.placed < len(small):
        raise ValueError(f"could place only {inserter.placed} of {len(small)} shrunk grains in the zone (solid "
                         f"fraction {s.cloud_solid_fraction}): the zone is too thin for its grains, or the target e "
                         "too low")
    centres = inserter.pos[:inserter.placed]
    if shapes is None:
        packing = SpherePacking(centres, enclosing)
    else:
        template_of = template_of[order]
        packing = ClumpPacking(shapes.templates, template_of,
                               scales_to_diameters(shapes.templates, template_of, diameters[order]), centres,
                               random_orientations(len(order), shape_rng))
    return packing, shrink


class _WholeVolume:
    """A region holding every contact point, of the given volume (for love_weber_stress)."""

    def __init__(self, volume):
        self.volume = volume

    @staticmethod
    def contains(points):
        return np.ones(len(points), bool)


RELEASE_SHRINK = 0.995  # the grains' radii times this, a step, while a closed zone's stress is too high
RELEASE_LIMIT = 0.95    # ... down to at most this
SETTLE_SHRINK = 0.999   # the same, in finer steps, when a zone is let settle under its weight (fill_zone's settle)


def _release(engine, grains, volume, s, engine_for, target, with_lid, shrink, still):
    """Shrink every grain by ``shrink`` a step (``still``: stopped before each step), without
    gravity (the lid in place when ``with_lid``), until the mean stress of its contacts, tr σ / 3
    with σ = 1/V Σ f ⊗ l (love_weber_stress over the zone's volume, compression +) is at most
    ``target``, or they have shrunk to RELEASE_LIMIT: a radius
    expansion inside closed faces ends with the grains pressed together (a closed ring around
    a tunnel lining held overlaps of up to 11 % of a radius, stiff enough cages for a light
    grain to chatter at the fill's time step). Returns (the grains shrunk and moved, the factor
    they were shrunk by, steps, the mean stress reached in Pa)."""
    from .diagnostics import love_weber_stress
    factor, steps, region = 1.0, 0, _WholeVolume(volume)
    engine.run(4 * s.check_every)
    steps += 4 * s.check_every

    def mean_stress(engine):  # compression positive
        return np.trace(love_weber_stress(engine, region)) / 3.0

    while mean_stress(engine) > target and factor * shrink >= RELEASE_LIMIT:
        factor *= shrink
        grains = grains.moved(engine)
        if still:  # the elastic energy let go does not keep a gas of grains colliding
            grains = replace(grains, velocities=None, angular_velocities=None)
        engine = engine_for(grains, (0.0, 0.0, 0.0), with_lid, factor)
        engine.run(4 * s.check_every)
        steps += 4 * s.check_every
    return grains.moved(engine).resized(factor), factor, steps, float(mean_stress(engine))


def _lift_lid(engine, walls, normal, area, s):
    """Move the lid out along its outward ``normal`` until it carries at most ``s.release_stress``
    (step 4 of the module docstring); returns (how far it moved in m, the steps)."""
    chunk = max(1, s.check_every // 5)
    speed = 0.1 * s.plate_velocity
    engine.run(chunk)
    lift, lifting = 0.0, 0  # this phase's steps, capped as every phase's

    def held():
        return _lid_stress(engine, walls, normal, area) > s.release_stress

    while True:
        # lift until the lid is released, then let the grains come to rest against it; again
        # while it holds them: a lid moving away from a jammed packing reads released before
        # the grains have caught up with it
        _set_lid_velocity(engine, walls, speed * normal)
        while held() and lifting < s.max_steps_per_layer:
            engine.run(chunk)
            lifting += chunk
            lift += speed * engine.dt * chunk
        _set_lid_velocity(engine, walls, np.zeros(3))
        lifting += _rest(engine, s)
        if not held() or lifting >= s.max_steps_per_layer:
            return lift, lifting + chunk


def _free_first(candidates, blocked):
    """Each grain's candidates closer to a wall than its radius (``blocked``) replaced by its
    first free one (tried again, it is refused again), the others in their order."""
    if np.any(blocked.all(axis=1)):
        raise ValueError("no point of the zone is a shrunk grain's radius away from its faces: the zone is too "
                         "thin for its grains")
    first = candidates[np.arange(len(candidates)), np.argmin(blocked, axis=1)]
    return np.ascontiguousarray(np.where(blocked[:, :, None], first[:, None, :], candidates))


def _container_materials(s, walls):
    """friction -> the generation materials: the grains' (scaled as in deposition), then one
    per wall, its density scaled alike."""
    from dataclasses import replace

    def materials(friction):
        sand = _materials(s, friction)[0]
        return [sand] + [replace(w.material, density=w.material.density * s.density_scale) for w in walls]
    return materials


def _outward(lid, centre):
    """The lid's mean unit normal (area-weighted), pointing away from the volume's ``centre``,
    and its area."""
    if not lid:
        return np.zeros(3), 0.0
    t = np.concatenate([w.triangles for w in lid])
    n = 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n *= np.sign(np.einsum("ij,ij->i", n, t.mean(axis=1) - centre))[:, None]
    total = n.sum(axis=0)
    return total / np.linalg.norm(total), float(np.linalg.norm(n, axis=1).sum())


def _lid_facets(engine, walls):
    """The engine's facet meshes of the lid walls (the first, in the order of ``walls``)."""
    return engine.facets[:sum(w.lid for w in walls)]


def _lid_stress(engine, walls, normal, area):
    """The grains' push on the lid along its outward normal over its area (Pa); 0 without a lid."""
    if area == 0.0:
        return 0.0
    return float(sum(m.force for m in _lid_facets(engine, walls)) @ normal) / area


def _set_lid_velocity(engine, walls, velocity):
    for m in _lid_facets(engine, walls):
        m.velocity = velocity


def _rest(engine, s, stop=None):
    """Run until the unbalanced force ratio is below ``s.unbalanced_force``, or ``stop(engine)``
    (checked every ``s.check_every`` steps, at most ``s.max_steps_per_layer``); returns the
    steps taken."""
    n = 0
    while n < s.max_steps_per_layer:
        engine.run(s.check_every)
        n += s.check_every
        if _unbalanced(engine) < s.unbalanced_force or (stop is not None and stop(engine)):
            break
    return n

