"""The ``[specimen]`` section: a granular specimen generated to a target void ratio in a box
(``de_domain.deposition``, docs/design.md §3.2) or read from a packing file, with an
optional cache file. Used by the ``direct_shear`` kind (the shear box) and the ``footing``
kind (the DEM zone of the coupled model, or the whole all-DEM domain)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.outputs import is_root, say


@dataclass(frozen=True)
class SpecimenBox:
    """The box a specimen is made in: x ∈ [0, length], y ∈ [0, width], final height ``height``
    (m), and the ids of the materials of the grains, the frictionless side walls and the rough
    bottom and compaction plate among ``materials`` (de_domain Materials)."""
    length: float
    width: float
    height: float
    materials: list
    sand: int
    side_wall: int
    plate: int


def curve_of(sp):
    """The sieve curve of a [specimen] section (preset or custom, scaled, truncated)."""
    from de_domain.deposition import specimen_curve
    return specimen_curve(sp.sieve, sp.sieve_diameters, sp.sieve_passing, sp.scale, sp.truncate_below,
                          sp.truncate_above)


CLUMP_PREFIX = "clump_"  # a clumped specimen's entries in specimen.npz (de_domain.clumps.ClumpPacking.arrays)


def read_specimen(path):
    """The :class:`~de_domain.deposition.Specimen` of a packing file (its ``void_ratio`` None when
    the file does not say); the height is the stored plate height (npz made here) or the top of the
    highest grain. A specimen.npz of clumped grains brings its clumps."""
    from de_domain.clumps import ClumpPacking
    from de_domain.deposition import Specimen
    from de_domain.packing import load_packing
    pos, radii = load_packing(path)
    height, e, clumps = None, None, None
    if str(path).endswith(".npz"):
        with np.load(path) as data:
            height = float(data["height"]) if "height" in data else None
            e = float(data["void_ratio"]) if "void_ratio" in data else None
            if CLUMP_PREFIX + "template_of" in data:
                clumps = ClumpPacking.from_arrays({k[len(CLUMP_PREFIX):]: data[k] for k in data
                                                   if k.startswith(CLUMP_PREFIX)})
    if height is None:
        height = float(np.max(pos[:, 2] + radii))
    return Specimen(pos, radii, height, e, "file", clumps=clumps)


def save_specimen(path, specimen):
    """Write a specimen as ``.npz`` (:func:`read_specimen` reads it back, clumps included)."""
    from de_domain.packing import save_packing
    clumps = {} if specimen.clumps is None else {CLUMP_PREFIX + k: v for k, v in specimen.clumps.arrays().items()}
    save_packing(path, specimen.positions, specimen.radii, height=specimen.height, void_ratio=specimen.void_ratio,
                 method=specimen.method, **clumps)


def grain_shapes(case, case_path):
    """The clumped grains of ``[specimen] grains = 'clumps'`` (de_domain.deposition.GrainShapes of
    the [[dem.clumps]] templates), or None for spheres."""
    if case.specimen.grains != "clumps":
        return None
    from cosim.case.validation import clump_templates
    from de_domain.deposition import GrainShapes
    return GrainShapes(clump_templates(case_path, case.dem), tuple(t.share for t in case.dem.clumps))


def grains_text(specimen):
    """'N grains' or 'N clumps of M spheres'."""
    if specimen.clumps is None:
        return f"{len(specimen.radii)} grains"
    return f"{specimen.clumps.count} clumped grains of {len(specimen.radii)} spheres"


def make_specimen(case, box: SpecimenBox, curve, out_dir, cache=None, comm=None, label=None, shapes=None):
    """Generate the specimen of ``case.specimen`` in ``box`` (or read it from ``cache`` if that
    file exists), of clumped grains with ``shapes`` (:func:`grain_shapes`); returns
    (:class:`~de_domain.deposition.Specimen`, info dict). Writes ``specimen.npz`` in ``out_dir``
    (and ``cache``). With ``comm``, collective: the generation's DEM is spread over the ranks,
    rank 0 writes."""
    from de_domain.deposition import GenerationSettings, diameters_for_solid_volume, generate, solid_volume_for
    sp = case.specimen
    name = label or case.case.name
    if cache is not None and Path(cache).exists():
        specimen = read_specimen(cache)
        e = specimen.void_ratio
        say(f"[{name}] specimen from {cache}: {grains_text(specimen)}, h = {specimen.height * 1e3:.3f} mm, "
            f"e = {e:.4f}")
        return specimen, {"source": str(cache), "void_ratio_generated": e, "generation_wall_clock_s": 0.0}
    mats = box.materials
    rng = np.random.default_rng(case.case.seed)
    volume = box.length * box.width * box.height
    diameters = diameters_for_solid_volume(curve, solid_volume_for(sp.void_ratio, volume), rng)
    say(f"[{name}] generating the specimen ({sp.method}) in {box.length * 1e3:.1f} x {box.width * 1e3:.1f} x "
        f"{box.height * 1e3:.1f} mm: {len(diameters)} {'clumped ' if shapes else ''}grains, "
        f"d = {diameters.min() * 1e3:.2f}-{diameters.max() * 1e3:.2f} mm, target e = {sp.void_ratio}")
    grain = mats[box.sand]
    if sp.deposition_material is not None:  # the grains' own material while they are deposited
        grain = mats[[m.name for m in case.dem.materials].index(sp.deposition_material)]
    settings = GenerationSettings(
        box_length=box.length, box_width=box.width, height=box.height, void_ratio=sp.void_ratio,
        sand=grain, wall=mats[box.side_wall], plate=mats[box.plate],
        friction=sp.deposition_friction, rolling_friction=sp.deposition_rolling_friction,
        rolling_stiffness=sp.deposition_rolling_stiffness, density_scale=sp.density_scale,
        gravity=tuple(case.dem.gravity),
        local_damping=sp.local_damping, safety_factor=case.time.safety_factor,
        contact_law=case.dem.contact_law, unbalanced_force=sp.unbalanced_force, plate_velocity=sp.plate_velocity,
        plate_stress_limit=sp.plate_stress_limit, friction_reduction=sp.friction_reduction,
        hold_friction=sp.hold_friction, layers=sp.layers,
        undercompaction=sp.undercompaction, cloud_solid_fraction=sp.cloud_solid_fraction,
        max_steps_per_layer=sp.max_steps_per_layer,
        seed=case.case.seed)
    t0 = time.perf_counter()
    specimen = generate(sp.method, diameters, settings, log=lambda text: say(f"[{name}] {text}"), comm=comm,
                        shapes=shapes)
    wall_clock = time.perf_counter() - t0
    ok = abs(specimen.void_ratio - sp.void_ratio) <= sp.tolerance
    say(f"[{name}] specimen: e = {specimen.void_ratio:.4f} (target {sp.void_ratio} ± {sp.tolerance}: "
        f"{'OK' if ok else 'MISSED'}), h = {specimen.height * 1e3:.3f} mm, {specimen.steps} steps, {wall_clock:.0f} s")
    targets = [Path(out_dir) / "specimen.npz"] + ([Path(cache)] if cache is not None else [])
    for target in targets if is_root() else []:
        target.parent.mkdir(parents=True, exist_ok=True)
        save_specimen(target, specimen)
    info = {"source": sp.method, "void_ratio_generated": specimen.void_ratio, "void_ratio_target": sp.void_ratio,
            "void_ratio_within_tolerance": bool(ok), "generation_steps": specimen.steps,
            "generation_wall_clock_s": wall_clock, "generation_log": specimen.log}
    return specimen, info


def read_lab_inputs(case, case_path, length, width):
    """What a lab test reads before computing (its ``prepare``): the packing file, whose grains
    must lie in the ``length`` × ``width`` box (overlapping a side by at most 25 % of a radius),
    or the sieve curve (and the clumped grains' shapes). Returns (built dict, the smallest
    grain's radius: a sieve curve's equal-volume one, a file's smallest sphere); bad input is a
    CaseError naming the key."""
    from cosim.case.paths import resolve_path
    from cosim.errors import CaseError
    sp = case.specimen
    if sp.source == "generate":
        try:
            curve = curve_of(sp)
        except ValueError as exc:
            raise CaseError(case_path, "specimen", "sieve curve", str(exc)) from None
        shapes = grain_shapes(case, case_path)
        return {"curve": curve, "shapes": shapes}, 0.5 * float(curve.diameters[0])
    from cosim.apps.dem import warn_overlaps
    try:
        packing = read_specimen(resolve_path(case_path, sp.file))
    except Exception as exc:
        raise CaseError(case_path, "specimen.file", sp.file, f"could not read the packing: {exc}") from None
    pos, radii = packing.positions, packing.radii
    slack = 0.25 * radii[:, None]  # elastic overlap with the side walls of the box it was made in
    if np.any(pos[:, :2] - radii[:, None] < -slack) or np.any(pos[:, :2] + radii[:, None] > (length, width) + slack):
        raise CaseError(case_path, "specimen.file", sp.file, f"the grains must lie inside the {length} m x {width} m "
                        "box (x, y inside it, overlapping a side by at most 25 % of the radius)")
    if packing.clumps is None:  # a clump's members overlap by design
        warn_overlaps(case_path, "specimen.file", sp.file, pos, radii)
    return {"packing": packing}, float(radii.min())


def check_grain_time_step(case, case_path, mats, sand, radius, shapes=None, packing=None):
    """A given ``time.dt`` against the critical step of the smallest grain of ``radius``
    (docs/design.md §2.14); with ``shapes``, of each clumped grain of that equal-volume radius,
    and with a ``packing`` file of clumps, of each of its clumps (their members by their clump's
    critical mass)."""
    if case.time.dt is None:
        return
    from cosim.apps.dem import check_time_step
    from de_domain import Engine, Particles
    if packing is not None and packing.clumps is not None:
        grains, clumps = packing.clumps.bodies(mats, sand)
    elif shapes is None:
        grains, clumps = Particles.from_spheres(np.zeros((1, 3)), [radius], np.full(1, sand, np.int32), mats), None
    else:
        grains, clumps = shapes.at_diameter(2.0 * radius).bodies(mats, sand)
    check_time_step(case_path, case.time, Engine(grains, mats, contact_law=case.dem.contact_law, dt=case.time.dt,
                                                 clumps=clumps))


def lab_specimen(case, built, box: SpecimenBox, out_dir, cache=None, comm=None):
    """A lab test's specimen (direct_shear, triaxial): the packing file read by
    :func:`read_lab_inputs` (unless ``cache`` exists), or generated in ``box``
    (:func:`make_specimen`, of the clumped grains ``built["shapes"]`` if any); returns
    (:class:`~de_domain.deposition.Specimen`, info); collective with ``comm``."""
    sp = case.specimen
    if sp.source == "file" and not (cache is not None and Path(cache).exists()):
        specimen = built["packing"]
        say(f"[{case.case.name}] specimen from {sp.file}: {grains_text(specimen)}, "
            f"h = {specimen.height * 1e3:.3f} mm")
        return specimen, {"source": sp.file, "void_ratio_generated": specimen.void_ratio,
                          "generation_wall_clock_s": 0.0}
    return make_specimen(case, box, built.get("curve"), out_dir, cache, comm, shapes=built.get("shapes"))
