"""Specimen generation to a target void ratio (docs/design.md §3.2).

Two methods, both in a box of sides ``L`` (x) and ``L_y`` (y; default L) and final height
``H`` with frictionless
side walls, a rough bottom and a rough compaction plate on top:

* :func:`under_compaction` — multi-layer under-compaction (Jiang, Konrad & Leroueil
  2003; thesis §4.2.1): the solid volume V_s = L L_y H / (1 + e) is split into N layers
  of equal solid volume. Each layer is generated as a non-overlapping cloud just above
  the current surface, falls under gravity and is pushed down by the plate until the
  layer top reaches

      z_k = (H / N) [ (k − 1) + (1 + U_k) ],   U_k = U_1 (N − k) / (N − 1),

  i.e. lower layers are left slightly looser ("under-compacted", U_1 > 0) because the
  layers above compact them further; the last layer is pushed to exactly H. The plate
  then holds its height until the unbalanced force ratio is below 0.01 and the next
  layer starts. The number of layers follows from the target: a cloud may hold at most
  ``cloud_solid_fraction`` of solids over a generation height H, so
  N = ⌈V_s / (cloud_solid_fraction · L L_y H)⌉ = ⌈1 / ((1 + e) cloud_solid_fraction)⌉,
  capped so that a layer is at least 1.5 of the largest grains thick: a thinner layer
  is mostly the loose zones along the plates below and above it and cannot be pushed
  to the mean void ratio (full-size thesis sand, 1.3 d_max layers: > 300 kPa at μ = 0.1).
  If the plate stress exceeds ``plate_stress_limit`` before the plate reaches z_k, the
  particle friction is multiplied by ``friction_reduction`` (default ½; below 0.02 it
  drops to 0) and the engine rebuilt from the current state,
  so dense targets stay reachable (YADE's "compaction friction" idea); every layer
  starts again at the deposition friction, so one hard layer does not make all the
  layers above it denser. Loose targets use a high deposition friction and rolling
  resistance (``rolling_friction`` η_r, ``rolling_stiffness`` β_r, generation only;
  η_r is lowered in proportion to μ; ``hold_friction`` restores the friction once the plate
  holds the layer at its height, so that the layer does not creep below it): rolling
  resistance keeps a frictional deposit from collapsing into the denser packings that
  rolling spheres find (e.g. Jiang, Yu & Harris, Géotechnique 2005; Wensrich &
  Katterfeld, Powder Technol. 2012).
* :func:`radius_expansion` — the spheres of the whole specimen are placed at reduced
  radii in the closed box (L × L_y × H) and grown to full size in small increments
  without gravity; the void ratio is then exact by construction if the grains jam in
  the box, and otherwise the specimen settles under gravity and is re-measured.

In both methods the achieved void ratio is measured with the plate in contact (seated
at ``seat_stress``): e = (L L_y z_plate − V_s) / V_s.

Mass scaling: during generation only, every density is multiplied by ``density_scale``
s (dt grows by √s) and gravity is divided by s, so the weight of every grain — and the
self-weight stresses of the specimen — stay the real ones. Grains then fall slowly,
but the compaction plate, moving at ``plate_velocity``, sweeps each cloud down; the
time to build a layer is set by the plate, not by free fall.

Engines are rebuilt from the current arrays between stages (new particles, changed
friction or radii); contact history is not carried over, which only matters while
the specimen is being built.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .packing import SIEVE_PRESETS, SieveCurve, random_cloud


# --------------------------------------------------------------------------- size distribution
def truncated_above(curve, d_max):
    """Drop the grains coarser than ``d_max`` and renormalise the remaining mass to 1."""
    d, f = curve.diameters, curve.passing
    if not d[0] < d_max <= d[-1]:
        raise ValueError(f"coarse truncation diameter {d_max} outside the curve ({d[0]}, {d[-1]}]")
    f_cut = np.interp(d_max, d, f)
    if f_cut <= 0:
        raise ValueError(f"no mass below the coarse truncation diameter {d_max}")
    keep = d < d_max
    return SieveCurve(np.concatenate([d[keep], [d_max]]), np.concatenate([f[keep], [f_cut]]) / f_cut)


def specimen_curve(preset="thesis_sand", diameters=None, passing=None, scale=1.0, truncate_below=None,
                   truncate_above=None):
    """The sieve curve of a specimen: a preset or a custom curve, scaled, then truncated
    at the fine end (``truncate_below``) and the coarse end (``truncate_above``), both
    given as scaled diameters [m]."""
    if diameters is not None:
        curve = SieveCurve(np.asarray(diameters, float), np.asarray(passing, float))
    else:
        if preset not in SIEVE_PRESETS:
            raise ValueError(f"unknown sieve preset {preset!r}; allowed: {sorted(SIEVE_PRESETS)}")
        curve = SIEVE_PRESETS[preset]
    curve = curve.scaled(scale)
    # sieves with zero passing at the fine end carry no mass: start at the last zero
    first = max(0, int(np.searchsorted(curve.passing, 0.0, side="right")) - 1)
    curve = SieveCurve(curve.diameters[first:], curve.passing[first:])
    if truncate_below is not None:
        curve = curve.truncated(truncate_below)
    if truncate_above is not None:
        curve = truncated_above(curve, truncate_above)
    return curve


def diameters_for_solid_volume(curve, solid_volume, rng):
    """Diameters drawn from ``curve`` until their sphere volume reaches ``solid_volume``.

    The last grain is kept whole, so the solid volume overshoots by less than one grain.
    """
    mean_volume = float(np.mean(np.pi / 6 * curve.sample_diameters(4096, rng) ** 3))
    out = []
    total = 0.0
    while total < solid_volume:
        batch = curve.sample_diameters(max(64, int(1.2 * (solid_volume - total) / mean_volume)), rng)
        vol = np.cumsum(np.pi / 6 * batch**3) + total
        stop = int(np.searchsorted(vol, solid_volume)) + 1
        out.append(batch[:stop])
        total = vol[min(stop, len(vol)) - 1]
    return np.concatenate(out)


def solid_volume_for(void_ratio, volume):
    """V_s = V / (1 + e)."""
    return volume / (1.0 + void_ratio)


def layer_count(void_ratio, cloud_solid_fraction, height=None, d_max=None):
    """N = ⌈1 / ((1 + e) · cloud_solid_fraction)⌉: each layer's cloud fits in a
    generation height equal to the specimen height (module docstring); capped so that a
    layer is at least 1.5 of the largest grains thick, N ≤ ⌊H / (1.5 d_max)⌋."""
    n = max(1, math.ceil(1.0 / ((1.0 + void_ratio) * cloud_solid_fraction) - 1e-9))
    if height is not None and d_max is not None:
        n = min(n, max(1, int(height // (1.5 * d_max))))
    return n


def layer_tops(n_layers, height, undercompaction):
    """Plate heights z_k = (H/N)[(k − 1) + (1 + U_k)], U_k = U_1 (N − k)/(N − 1) (Jiang et al. 2003)."""
    k = np.arange(1, n_layers + 1)
    u = undercompaction * (n_layers - k) / max(n_layers - 1, 1)
    return height / n_layers * ((k - 1) + (1 + u))


def split_into_layers(diameters, n_layers, rng):
    """Random, equal-solid-volume groups of grains (each layer gets the same PSD)."""
    order = rng.permutation(len(diameters))
    vol = np.cumsum(np.pi / 6 * diameters[order] ** 3)
    cuts = np.searchsorted(vol, vol[-1] * np.arange(1, n_layers) / n_layers)
    return [diameters[part] for part in np.split(order, cuts)]


def void_ratio_of_box(area, height, radii):
    """e = (A h − V_s) / V_s with V_s the volume of the spheres."""
    solid = float(np.sum(4.0 / 3.0 * np.pi * np.asarray(radii) ** 3))
    return (area * height - solid) / solid


# --------------------------------------------------------------------------- settings and result
@dataclass
class GenerationSettings:
    """Inputs shared by both methods (units: m, s, Pa)."""

    box_length: float                 # L, along x
    height: float
    void_ratio: float
    sand: object                      # de_domain.Material of the grains (real density)
    wall: object                      # material of the (frictionless) side walls
    plate: object                     # material of the bottom and the compaction plate
    friction: float | None = None     # grain friction during generation; None = sand's
    rolling_friction: float | None = None   # grain η_r during generation; None = sand's
    rolling_stiffness: float | None = None  # grain β_r during generation; None = sand's (1 if 0 and η_r > 0)
    density_scale: float = 100.0
    gravity: tuple = (0.0, 0.0, -9.81)
    local_damping: float = 0.5
    safety_factor: float = 0.3
    contact_law: str = "linear"
    unbalanced_force: float = 0.01
    plate_velocity: float = 0.3
    plate_stress_limit: float = 20e3
    friction_reduction: float = 0.5
    hold_friction: float | None = None  # grain friction while the plate holds a layer; None = as reached
    seat_stress: float = 500.0
    layers: int | None = None
    undercompaction: float = 0.03
    cloud_solid_fraction: float = 0.2
    max_steps_per_layer: int = 200000
    seed: int = 0
    check_every: int = 50
    box_width: float | None = None    # L_y, along y; None = box_length (a square box)
    release_stress: float | None = None  # raise the plate at the end until it carries at most this (Pa)

    @property
    def sides(self):
        """(L, L_y) of the box."""
        return self.box_length, self.box_length if self.box_width is None else self.box_width

    @property
    def area(self):
        return self.sides[0] * self.sides[1]


@dataclass
class Specimen:
    """A generated specimen: sphere centres and radii (m; a clumped specimen's member spheres),
    the plate height at the end (the specimen height) and the achieved void ratio, with a
    per-stage log; ``clumps`` (:class:`~de_domain.clumps.ClumpPacking`) the grains the spheres
    make up, or None."""

    positions: np.ndarray
    radii: np.ndarray
    height: float
    void_ratio: float
    method: str
    steps: int = 0
    log: list = field(default_factory=list)
    clumps: object = None

    def metadata(self):
        return {"height": self.height, "void_ratio": self.void_ratio, "method": self.method}

    def grain_radii(self):
        """The equal-volume radius of every grain (a clump's: of its union)."""
        return self.radii if self.clumps is None else self.clumps.equivalent_radii()

    def bodies(self, materials, material):
        """(particles, clumps or None) for an Engine: the grains at rest, of ``material``."""
        grains = SpherePacking(self.positions, self.radii) if self.clumps is None else self.clumps
        return grains.bodies(materials, material)


@dataclass
class SpherePacking:
    """Spheres as the generation holds them between engines; the same interface as
    :class:`~de_domain.clumps.ClumpPacking` (a clumped specimen's state)."""

    centres: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray = None
    angular_velocities: np.ndarray = None

    def __post_init__(self):
        for name in ("velocities", "angular_velocities"):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros_like(self.centres))

    def volumes(self):
        return 4.0 / 3.0 * np.pi * self.radii**3

    def enclosing_radii(self):
        return self.radii

    def bodies(self, materials, material=0, size=1.0):
        """(particles, None) for an Engine, radii × ``size``."""
        from . import Particles
        p = Particles.from_spheres(self.centres, self.radii * size, np.full(self.radii.size, material, np.int32),
                                   materials, velocities=self.velocities)
        p.angvel[:] = self.angular_velocities
        return p, None

    def moved(self, engine):
        """These spheres at the state of ``engine`` (collective when distributed)."""
        grains = engine.global_particles()
        return replace(self, centres=grains.pos.copy(), velocities=grains.vel.copy(),
                       angular_velocities=grains.angvel.copy())

    def resized(self, factor):
        """These spheres with their radii × ``factor``."""
        return replace(self, radii=self.radii * factor)

    def joined(self, other):
        both = lambda name: np.concatenate([getattr(self, name), getattr(other, name)])  # noqa: E731
        return SpherePacking(*(both(k) for k in ("centres", "radii", "velocities", "angular_velocities")))

    def members(self):
        return self.centres, self.radii


def _cloud(diameters, template_of, lo, hi, seed, shapes, rng, size=1.0):
    """The grains of ``diameters`` (equal-volume diameters) at random non-overlapping places in
    the box [lo, hi], at rest, placed at ``size`` × their size and kept at full size (largest
    first): spheres, or with ``shapes`` clumps of the templates ``template_of``, their
    orientations drawn from ``rng``. Raises ValueError if they do not fit."""
    radii = 0.5 * np.asarray(diameters, float)
    if shapes is None:
        pos, _ = random_cloud(radii * size, lo, hi, seed=seed)
        return SpherePacking(pos, radii[np.argsort(-radii, kind="stable")])  # random_cloud's order
    from .clumps import clump_cloud
    placed = clump_cloud(shapes.templates, template_of, np.asarray(diameters, float) * size, lo, hi, seed, rng)
    return replace(placed, scale=placed.scale / size)


@dataclass(frozen=True)
class GrainShapes:
    """Clumped grains: ``templates`` (:class:`~de_domain.clumps.ClumpTemplate`) drawn by number
    ``shares``; each grain is its template enlarged to the sieve curve's diameter (equal volume)."""

    templates: list
    shares: tuple

    def draw(self, count, rng):
        """The template of each of ``count`` grains."""
        share = np.asarray(self.shares, float)
        return rng.choice(len(self.templates), size=count, p=share / share.sum())

    def at_diameter(self, diameter):
        """One grain of each template at the equal-volume ``diameter``, apart from each other
        (the grains that set the critical time step at the smallest sieve size)."""
        from .clumps import ClumpPacking
        n = len(self.templates)
        scale = np.array([0.5 * diameter / t.equivalent_radius() for t in self.templates])
        spacing = 4.0 * float(np.max(scale * self.reach_ratios())) * 0.5 * diameter
        centres = np.column_stack([spacing * np.arange(n), np.zeros(n), np.zeros(n)])
        return ClumpPacking(self.templates, np.arange(n), scale, centres, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))

    def reach_ratios(self):
        """Each template's enclosing radius over its equal-volume radius (≥ 1)."""
        return np.array([t.reach() / t.equivalent_radius() for t in self.templates])


# --------------------------------------------------------------------------- engine plumbing
def _start_friction(s):
    return s.sand.friction if s.friction is None else s.friction


def _materials(s, friction):
    """Generation materials: densities × ``density_scale``; the grains get the generation
    friction and rolling resistance, the rolling friction η_r lowered in proportion to μ."""
    mu0 = _start_friction(s)
    eta = s.sand.rolling_friction if s.rolling_friction is None else s.rolling_friction
    beta = s.sand.rolling_stiffness if s.rolling_stiffness is None else s.rolling_stiffness
    if s.rolling_stiffness is None and beta == 0.0 and eta > 0.0:
        beta = 1.0  # a rolling friction needs a rolling spring
    sand = replace(s.sand, density=s.sand.density * s.density_scale, friction=friction,
                   rolling_friction=eta * (friction / mu0 if mu0 > 0 else 1.0), rolling_stiffness=beta)
    wall = replace(s.wall, density=s.wall.density * s.density_scale)
    plate = replace(s.plate, density=s.plate.density * s.density_scale)
    return [sand, wall, plate]


def _box_walls(s, plate_z):
    from . import PlaneWall
    L, Ly = s.sides
    walls = [PlaneWall((0, 0, 0), (1, 0, 0), 1), PlaneWall((L, 0, 0), (-1, 0, 0), 1),
             PlaneWall((0, 0, 0), (0, 1, 0), 1), PlaneWall((0, Ly, 0), (0, -1, 0), 1),
             PlaneWall((0, 0, 0), (0, 0, 1), 2), PlaneWall((0, 0, plate_z), (0, 0, -1), 2)]
    return walls


def _engine(s, grains, friction, plate_z, gravity, dt=None, comm=None, size=1.0):
    """The generation's engine of ``grains`` (:class:`SpherePacking` or clumps), enlarged ``size`` times."""
    from . import Engine
    mats = _materials(s, friction)
    gravity = tuple(np.asarray(gravity, float) / s.density_scale)  # real weights (module docstring)
    particles, clumps = grains.bodies(mats, 0, size)
    return Engine(particles, mats, walls=_box_walls(s, plate_z), contact_law=s.contact_law, gravity=gravity,
                  dt=dt, safety_factor=s.safety_factor, local_damping=s.local_damping, comm=comm, clumps=clumps)


def _plate_stress(engine, s):
    return float(engine.walls[5].force[2]) / s.area


def _unbalanced(engine):
    from .diagnostics import unbalanced_force_ratio
    return unbalanced_force_ratio(engine)


def _rebuild(engine, grains, s, friction, gravity):
    """A new engine of ``grains`` (those ``engine`` was built from) where ``engine`` left them."""
    return _engine(s, grains.moved(engine), friction, engine.walls[5].point[2], gravity, engine.dt, _comm(engine))


def _top_of_grains(engine):
    """max(z + r) over every grain (collective when distributed)."""
    p = engine.particles
    top = float(np.max(p.pos[p.owned, 2] + p.radius[p.owned], initial=-np.inf))
    return engine.runner.maximum(top)


def _comm(engine):
    return engine.domain.comm if engine.domain is not None else None


def _say(log, text):
    if log is not None:
        log(text)


def _compact_to(engine, grains, s, z_target, friction, log, label, max_steps):
    """Move the plate down to ``z_target`` (lowering friction if the stress exceeds the
    limit), hold it there until the unbalanced force ratio is below the threshold.
    Returns (engine, friction, steps)."""
    plate = engine.walls[5]
    plate.velocity = np.array([0.0, 0.0, -s.plate_velocity])
    steps = 0
    held = False
    while steps < max_steps:
        engine.run(s.check_every)
        steps += s.check_every
        plate = engine.walls[5]
        if not held and plate.point[2] <= z_target:
            plate.point[2] = z_target
            plate.velocity = np.zeros(3)
            held = True
            if s.hold_friction is not None and s.hold_friction != friction:
                _relaxes(engine, s)  # first shed the arriving plate's dynamic overstress
                friction = s.hold_friction
                engine.set_materials(_materials(s, friction))  # contact history kept
                _say(log, f"{label}: plate at its height; grain friction set to {friction:.3g} while it holds")
        if not held and _plate_stress(engine, s) > s.plate_stress_limit and not _relaxes(engine, s):
            friction = 0.0 if friction < 0.02 else s.friction_reduction * friction
            _say(log, f"{label}: plate stress {_plate_stress(engine, s):.3g} Pa above the limit at "
                      f"z = {plate.point[2] * 1e3:.2f} mm; grain friction lowered to {friction:.3g}")
            engine = _rebuild(engine, grains, s, friction, s.gravity)
            engine.walls[5].velocity = np.array([0.0, 0.0, -s.plate_velocity])
            if friction == 0.0:
                s_limit = s.plate_stress_limit
                s = replace(s, plate_stress_limit=math.inf)  # nothing left to lower: push on
                _say(log, f"{label}: friction is 0; pushing on past {s_limit:.3g} Pa")
        if held and _unbalanced(engine) < s.unbalanced_force:
            break
    return engine, friction, steps


def _relaxes(engine, s):
    """Stop the plate and let the layer relax: True if the plate stress falls below the
    limit (it was the dynamic stress of the moving plate), False if the layer really
    resists at this height. The plate resumes its motion afterwards."""
    plate = engine.walls[5]
    velocity = plate.velocity.copy()
    plate.velocity = np.zeros(3)
    for _ in range(20):
        engine.run(s.check_every)
        if _plate_stress(engine, s) < 0.5 * s.plate_stress_limit:
            plate.velocity = velocity
            return True
        if _unbalanced(engine) < 10 * s.unbalanced_force:
            break
    plate.velocity = velocity
    return _plate_stress(engine, s) < s.plate_stress_limit


def _seat_plate(engine, s, log, label, max_steps):
    """Lower the plate slowly until it carries ``seat_stress`` (measures the height of a
    specimen that is denser than its target), then let it come to rest."""
    steps = 0
    if _plate_stress(engine, s) >= s.seat_stress:
        return engine, steps
    # nothing to touch above the highest grain: the plate jumps onto it (grains that did
    # not jam settled far below the box's top; at 0.1 x plate_velocity it never got there)
    plate = engine.walls[5]
    plate.point[2] = min(float(plate.point[2]), _top_of_grains(engine))
    steps = _move_plate_then_rest(engine, s, -0.1 * s.plate_velocity,
                                  lambda: _plate_stress(engine, s) < s.seat_stress, steps, max_steps)
    _say(log, f"{label}: plate seated at {engine.walls[5].point[2] * 1e3:.3f} mm "
              f"({_plate_stress(engine, s):.3g} Pa)")
    return engine, steps


def _move_plate_then_rest(engine, s, velocity, moving, steps, max_steps):
    """Move the plate at ``velocity`` (m/s along z) while ``moving()``, checking every
    check_every / 5 steps; stop it and run until the unbalanced force ratio is below the
    threshold. Returns the step count, ``steps`` plus those taken (at most ``max_steps``)."""
    plate = engine.walls[5]
    plate.velocity = np.array([0.0, 0.0, velocity])
    while steps < max_steps and moving():
        engine.run(s.check_every // 5 or 1)
        steps += s.check_every // 5 or 1
    plate.velocity = np.zeros(3)
    while steps < max_steps:
        engine.run(s.check_every)
        steps += s.check_every
        if _unbalanced(engine) < s.unbalanced_force:
            break
    return steps


RELEASE_ROUNDS = 10


def _release_plate(engine, s, log, max_steps):
    """With ``s.release_stress`` set: raise the plate slowly until it carries at most that
    stress, let the specimen come to rest under it, and repeat while it swells back above that
    (at most RELEASE_ROUNDS times): the compaction stress locked in by
    the last layer is released, and the specimen can lose its plate (a free surface) without
    flinging its top grains. Returns (engine, steps)."""
    if s.release_stress is None:
        return engine, 0
    steps = 0
    for _ in range(RELEASE_ROUNDS):  # the specimen swells again while it relaxes: raise, relax, repeat
        if _plate_stress(engine, s) <= s.release_stress:
            break
        steps = _move_plate_then_rest(engine, s, 0.1 * s.plate_velocity,
                                      lambda: _plate_stress(engine, s) > s.release_stress, steps, max_steps)
    _say(log, f"final: plate raised to {engine.walls[5].point[2] * 1e3:.3f} mm, where it carries "
              f"{_plate_stress(engine, s):.3g} Pa (release to <= {s.release_stress:.3g} Pa)")
    return engine, steps


# --------------------------------------------------------------------------- methods
def under_compaction(diameters, s: GenerationSettings, log=None, comm=None, shapes=None):
    """Multi-layer under-compaction (module docstring). ``diameters``: all grains of the
    specimen (their volume fixes V_s); ``shapes`` (:class:`GrainShapes`): clumped grains of
    these equal-volume diameters (default: spheres). Returns a :class:`Specimen`. With ``comm``,
    every stage's DEM is spread over its ranks (collective; the same specimen, bit for bit)."""
    rng = np.random.default_rng(s.seed)
    shape_rng = np.random.default_rng([s.seed, 1])  # the clumps' templates and orientations
    H = s.height
    n_layers = s.layers or layer_count(s.void_ratio, s.cloud_solid_fraction, H, float(np.max(diameters)))
    groups = split_into_layers(np.asarray(diameters, float), n_layers, rng)
    tops = layer_tops(n_layers, H, s.undercompaction)
    start_friction = _start_friction(s)
    dt = s.safety_factor * _critical_dt_all(s, diameters, shapes)  # one dt for every stage
    grains = None
    steps = 0
    stages = []
    for k, (group, z_k) in enumerate(zip(groups, tops, strict=True), start=1):
        surface = float(np.max(grains.centres[:, 2] + grains.enclosing_radii())) if grains is not None else 0.0
        new = _layer_cloud(group, surface, s, k, shapes, shape_rng)
        grains = new if grains is None else grains.joined(new)
        plate_z = float(np.max(new.centres[:, 2] + new.enclosing_radii())) + 1e-4
        engine = _engine(s, grains, start_friction, plate_z, s.gravity, dt, comm)
        label = f"layer {k}/{n_layers}"
        engine, friction, n = _compact_to(engine, grains, s, z_k, start_friction, log, label, s.max_steps_per_layer)
        steps += n
        uf = _unbalanced(engine)
        stages.append({"layer": k, "grains": len(group), "plate_height": float(engine.walls[5].point[2]),
                       "plate_stress": _plate_stress(engine, s), "unbalanced_force": uf, "friction": friction,
                       "steps": n})
        _say(log, f"{label}: {len(group)} grains, plate at {engine.walls[5].point[2] * 1e3:.3f} mm "
                  f"(target {z_k * 1e3:.3f}), stress {_plate_stress(engine, s):.3g} Pa, "
                  f"unbalanced force {uf:.3g}, {n} steps")
        grains = grains.moved(engine)
    engine, n = _seat_plate(engine, s, log, "final", s.max_steps_per_layer)
    steps += n
    engine, n = _release_plate(engine, s, log, s.max_steps_per_layer)
    steps += n
    return _specimen(engine, grains, s, "under_compaction", steps, stages)


def _layer_cloud(group, surface, s, k, shapes, rng):
    """Layer ``k``'s grains (``group``: their diameters) as a non-overlapping cloud just above
    ``surface``, ``cloud_solid_fraction`` of their enclosing spheres' volume over the box's area
    (the box made taller, up to 8 times, until they fit)."""
    L, Ly = s.sides
    template_of = None if shapes is None else shapes.draw(group.size, rng)
    enclosing = group if shapes is None else group * shapes.reach_ratios()[template_of]  # diameters
    cloud_height = np.sum(np.pi / 6 * enclosing**3) / (s.cloud_solid_fraction * s.area)
    lo = np.array([0.0, 0.0, surface])
    for attempt in range(8):
        hi = np.array([L, Ly, surface + cloud_height * 1.25**attempt + np.max(enclosing)])
        try:
            return _cloud(group, template_of, lo, hi, s.seed + k + 1000 * attempt, shapes, rng)
        except ValueError:
            continue
    raise RuntimeError(f"layer {k}: could not place a non-overlapping cloud of {len(group)} grains")


def _specimen(engine, grains, s, method, steps, stages):
    """The :class:`Specimen` of ``grains`` in ``engine`` (collective when distributed); its void
    ratio e = (L L_y h − V_s) / V_s with V_s the grains' volume (a clump's: its union's)."""
    grains = grains.moved(engine)
    height = float(engine.walls[5].point[2])
    solid = float(np.sum(grains.volumes()))
    positions, radii = grains.members()
    clumps = None if isinstance(grains, SpherePacking) else replace(grains, velocities=None, angular_velocities=None)
    return Specimen(positions.copy(), radii.copy(), height, (s.area * height - solid) / solid, method, steps, stages,
                    clumps=clumps)


def radius_expansion(diameters, s: GenerationSettings, log=None, increments=40, steps_per_increment=100, comm=None,
                     shapes=None):
    """Grow the grains from reduced radii to full size in the closed box (module docstring);
    ``comm`` and ``shapes`` as for :func:`under_compaction` (a clump grows about its centre; the
    cloud's solid fraction counts its enclosing sphere)."""
    (L, Ly), H = s.sides, s.height
    shape_rng = np.random.default_rng([s.seed, 1])
    template_of = None if shapes is None else shapes.draw(len(diameters), shape_rng)
    enclosing = 0.5 * np.asarray(diameters, float)
    if shapes is not None:
        enclosing = enclosing * shapes.reach_ratios()[template_of]
    solid_fraction = np.sum(4 / 3 * np.pi * enclosing**3) / (s.area * H)
    shrink = min(1.0, (s.cloud_solid_fraction / solid_fraction) ** (1.0 / 3.0))
    grains = _cloud(diameters, template_of, (0, 0, 0), (L, Ly, H), s.seed, shapes, shape_rng, size=shrink)
    friction = _start_friction(s)
    dt = s.safety_factor * _critical_dt_all(s, diameters, shapes)
    steps = 0
    for k in range(1, increments + 1):
        f = shrink + (1.0 - shrink) * k / increments
        engine = _engine(s, grains, friction, H, (0.0, 0.0, 0.0), dt, comm, size=f)
        engine.run(steps_per_increment)
        steps += steps_per_increment
        grains = grains.moved(engine)
    stages = []
    # equilibrium without gravity, then with gravity
    for label, g in (("expanded", (0.0, 0.0, 0.0)), ("gravity", s.gravity)):
        engine = _engine(s, grains, friction, H, g, dt, comm)
        n = 0
        while n < s.max_steps_per_layer:
            engine.run(s.check_every)
            n += s.check_every
            if _unbalanced(engine) < s.unbalanced_force:
                break
            if label == "expanded" and _plate_stress(engine, s) < s.seat_stress:
                break  # not jammed: a loose gas has no equilibrium to reach without gravity
        steps += n
        stages.append({"stage": label, "plate_stress": _plate_stress(engine, s),
                       "unbalanced_force": _unbalanced(engine), "steps": n})
        _say(log, f"radius expansion ({label}): plate stress {_plate_stress(engine, s):.3g} Pa, "
                  f"unbalanced force {_unbalanced(engine):.3g}, {n} steps")
        grains = grains.moved(engine)
    engine, n = _seat_plate(engine, s, log, "final", s.max_steps_per_layer)
    steps += n
    engine, n = _release_plate(engine, s, log, s.max_steps_per_layer)
    steps += n
    return _specimen(engine, grains, s, "radius_expansion", steps, stages)


def _critical_dt_all(s, diameters, shapes=None):
    """Δt_crit of the smallest grain (linear law, k = 2 E r) with scaled density; with
    ``shapes``, of each template at the smallest diameter, its members by their clump's critical
    mass (:meth:`de_domain.clumps.Clumps.critical_mass`)."""
    r = 0.5 * float(np.min(diameters))
    density = s.sand.density * s.density_scale
    if shapes is None:
        m = density * 4.0 / 3.0 * np.pi * r**3
        return math.sqrt(m / (2.0 * s.sand.young * r))
    particles, clumps = shapes.at_diameter(2.0 * r).bodies([replace(s.sand, density=density)])
    mass = clumps.critical_mass(particles.radius)
    return float(np.min(np.sqrt(mass / (2.0 * s.sand.young * particles.radius))))


def generate(method, diameters, settings, log=None, comm=None, shapes=None):
    """Dispatch to :func:`under_compaction` or :func:`radius_expansion` (with ``comm``: the
    DEM of every stage spread over its ranks, collective; with ``shapes``: clumped grains)."""
    if method == "under_compaction":
        return under_compaction(diameters, settings, log, comm, shapes)
    if method == "radius_expansion":
        return radius_expansion(diameters, settings, log, comm=comm, shapes=shapes)
    raise ValueError(f"unknown generation method {method!r}; allowed: under_compaction, radius_expansion")
