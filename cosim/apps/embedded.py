"""Case kind ``embedded``: your own soil–structure problem from one gmsh model
(docs/guide/own-geometry.md, docs/design.md §5.1).

The model's physical volumes get roles in the case (``[[embedded.volumes]]``): ``zone``
(grains), ``soil`` (FE in the coupled model, grains in its all-DEM twin) and ``structure``
(FE in both). The coupling interface is every face shared by a grain volume and an FE
volume, found from the cells (:mod:`fe_domain.zone_model`); physical surfaces are FE supports
and DEM walls (``[[embedded.surfaces]]``) or rigid bodies that move during the loading
(``[[embedded.rigid]]``). ``embedded.model`` picks the coupled model or its all-DEM twin.

The run, in both models:

1. **Fill** — the grain volumes are filled to ``specimen.void_ratio`` by radius expansion
   inside their faces (:mod:`de_domain.zone_fill`): the interface, walls and rigid bodies hold
   them, a lid closes each free surface and is lifted and removed at the end;
2. **Rest** — the model (FE volumes under gravity, with local damping) comes to rest; the
   vertical force on every support over the grains' weight is reported (``rest.csv``), and
   the grains' stress by depth with K = σ_h / σ_v (``rest_stress.csv``);
3. **Loading** — each rigid body is held for one row (row 0: the forces at rest), then moves
   with its velocity and rotates about its pivot for ``embedded.loading_time``; ``series.csv``
   has per row and body the displacement, rotation,
   the force the grains exert on it and its moment about the pivot (impulses over the row's
   interval / the interval), and the interface force;
4. **Report** — ``summary.json``, ``load_displacement.png``, ``displacement_section.png`` (the
   grains seen along y, coloured by their displacement during the loading), ParaView frames
   (``particles.pvd``) and the FE fields (``fields.xdmf``); when both models of the case have
   run, ``comparison.csv`` and ``comparison.png`` in the case's folder.

Outputs go to ``runs/out/<name>/<model>/``.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.apps.embedded_model import (
    AXES,
    REST_STRESS_COLUMNS,
    LoadingRamp,
    Roles,
    build_fe,
    grain_materials,
    lining_columns,
    lining_gauges,
    rest_stress,
    roller_axis,
    sections,
    stress_bands,
    write_sections,
)
from cosim.errors import CaseError
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    PvdCollection,
    atomic_write_npz,
    atomic_write_text,
    compilation_seconds,
    is_root,
    mpi_comm,
    say,
    write_run_metadata,
)

FRAMES = 5  # ParaView frames over the loading
STATE = "embedded_state.json"  # the loading loop's state at the last checkpoint (with checkpoint.npz)
LOADING_START = "loading_start.npz"  # every grain's position when the loading began
REST_BAND_GRAINS = 5  # rest_stress.csv: the bands are this many of the largest grains high
RELEASE_FRACTION = 0.02  # the lid is lifted until it carries this x the self-weight stress at the zone's bottom


# --------------------------------------------------------------------------- inputs
def mesh_file(case, case_path):
    """The model's path: relative to the case file, else in meshes/."""
    from cosim.case.paths import resolve_path
    given = resolve_path(case_path, case.embedded.mesh)
    return given if Path(given).exists() else case.embedded.mesh


def prepare(case, case_path, out_dir, resume):
    """Mesh and split the model and check it against the case (collective; every rank raises
    the same CaseError): groups exist with the right dimension, the zone has an interface with
    the FE, rollers are planes normal to an axis, the grain volumes are at least
    GRAINS_ACROSS of the largest grains thick."""
    from cosim.apps import on_root
    from cosim.case.validation import GRAINS_ACROSS
    from cosim.specimen import curve_of, grain_shapes
    from de_domain.zone_fill import thickness
    from fe_domain.mesh import MeshError
    from fe_domain.zone_model import GroupError, split_model
    em = case.embedded
    model_dir = Path(out_dir) / em.model
    found = (model_dir / STATE).exists() and (model_dir / "checkpoint.npz").exists()
    if resume and not mpi_comm().allreduce(int(found)):
        raise CaseError(case_path, "--resume", str(model_dir / "checkpoint.npz"),
                        "no checkpoint of the loading in the output folder (checkpoints start with the loading); "
                        "run without --resume")
    roles = Roles.of(em)
    from cosim.apps.coupled import fe_communicator
    try:
        split = split_model(mesh_file(case, case_path), em.mesh_size, em.parameters, roles.grains, list(roles.fe),
                            fe_communicator(em.fe_partition))
    except GroupError as exc:
        raise CaseError(case_path, _key_of_group(em, exc.name), exc.name, str(exc)) from None
    except (MeshError, FileNotFoundError, ValueError) as exc:
        raise CaseError(case_path, "embedded.mesh", em.mesh,
                        f"the model could not be meshed and split: {exc}") from None
    for key, group in ([(f"embedded.surfaces[{i}].group", s.group) for i, s in enumerate(em.surfaces)]
                       + [(f"embedded.rigid[{i}].surface", r.surface) for i, r in enumerate(em.rigid)]
                       + ([("embedded.ground", em.ground)] if em.ground else [])):
        if split.groups.get(group) != 2:
            raise CaseError(case_path, key, group, str(GroupError(group, 2, split.groups)))
    for i, s in enumerate(em.surfaces):
        if s.fe == "roller" and split.fe is not None and s.group in split.fe.groups:
            axis = roller_axis(split.surfaces[s.group])
            if axis is None:
                raise CaseError(case_path, f"embedded.surfaces[{i}].fe", "roller",
                                f"surface '{s.group}' is not a plane normal to x, y or z; use 'fixed'")
    built = {"split": split}
    if em.model == "fe":
        return built
    if case.specimen.source == "file":
        built["packing"] = mpi_comm().bcast(on_root(mpi_comm(), lambda: read_packing(case, case_path, split)), root=0)
        d_max = 2.0 * float(np.max(built["packing"].enclosing_radii()))
        what = "largest grains"
    else:
        built["curve"] = curve_of(case.specimen)
        built["shapes"] = grain_shapes(case, case_path)
        d_max = float(built["curve"].diameters[-1])
        if built["shapes"] is not None:  # a clump's length: its enclosing sphere's diameter
            d_max *= float(np.max(built["shapes"].reach_ratios()))
        what = "largest grains" if built["shapes"] is None else "largest clumped grains' lengths"
    spacing = 0.1 * d_max  # the estimate's resolution
    across = thickness(split.zone.tets, split.zone.faces, spacing, np.random.default_rng(0),
                       at_least=GRAINS_ACROSS * d_max)
    if across + spacing < GRAINS_ACROSS * d_max:
        raise CaseError(case_path, "embedded.volumes", roles.grains,
                        f"the grain volumes are {across * 1e3:.2f} mm thick at most: at least {GRAINS_ACROSS} of the "
                        f"{what} ({GRAINS_ACROSS * d_max * 1e3:.2f} mm) are needed")
    return built


def read_packing(case, case_path, split):
    """The grains of ``specimen.file`` (:class:`~de_domain.deposition.SpherePacking`, or the
    :class:`~de_domain.clumps.ClumpPacking` of a clumped specimen.npz), at rest in the model's
    coordinates; every sphere's centre must lie in a grain volume, or within its radius of a
    free surface (a CaseError names the first that does not)."""
    from cosim.apps.dem import warn_overlaps
    from cosim.case.paths import resolve_path
    from cosim.specimen import read_specimen
    from de_domain.deposition import SpherePacking
    from de_domain.zone_fill import inside_tets
    sp = case.specimen
    try:
        specimen = read_specimen(resolve_path(case_path, sp.file))
        pos, radii = specimen.positions, specimen.radii
    except Exception as exc:
        raise CaseError(case_path, "specimen.file", sp.file, f"could not read the packing: {exc}") from None
    outside = ~inside_tets(pos, split.zone.tets)
    roles = Roles.of(case.embedded)
    free = [t for g, t in split.zone.free.items() if is_free_surface(roles, g)]
    if free and outside.any():  # a grain may stand above a free surface by less than its radius
        from scipy.spatial import cKDTree

        from de_domain.zone_fill import sample_triangles
        distance, _ = cKDTree(sample_triangles(np.concatenate(free), 0.1 * float(radii.min()))).query(pos[outside])
        outside[outside] = distance > radii[outside]
    outside = np.flatnonzero(outside)
    if len(outside):
        i = int(outside[0])
        raise CaseError(case_path, "specimen.file", sp.file,
                        f"{len(outside)} of its {len(radii)} grains lie outside the grain volumes "
                        f"({', '.join(Roles.of(case.embedded).grains)}), the first at "
                        f"{np.round(pos[i], 6).tolist()} m: "
                        "a packing is given in the model's coordinates (as the specimen.npz a run writes)")
    if specimen.clumps is None:
        warn_overlaps(case_path, "specimen.file", sp.file, pos, radii)
        return SpherePacking(pos, radii)
    return specimen.clumps


def _key_of_group(em, name):
    """The case key that names physical group ``name``."""
    for i, v in enumerate(em.volumes):
        if v.group == name:
            return f"embedded.volumes[{i}].group"
    return "embedded.volumes"




# --------------------------------------------------------------------------- fill
def container(case, split, mats, ids):
    """The walls that hold the grains while they are filled in (:class:`ContainerWall`): the
    interface, and every free face of the zone by its surface's role — a rigid body's or a DEM
    wall's material, else a lid of ``embedded.lid_material`` (:func:`is_free_surface`)."""
    from de_domain.zone_fill import ContainerWall
    em, roles = case.embedded, Roles.of(case.embedded)
    rigid = {r.surface: r for r in roles.rigid}
    walls = [ContainerWall(split.zone.interface, mats[ids[em.interface_material]])] if len(split.zone.interface) else []
    for group, triangles in split.zone.free.items():
        if is_free_surface(roles, group):
            walls.append(ContainerWall(triangles, mats[ids[em.lid_material]], lid=True))
        elif group in rigid:
            walls.append(ContainerWall(triangles, mats[ids[rigid[group].material]]))
        else:
            walls.append(ContainerWall(triangles, mats[ids[roles.surfaces[group].material]]))
    return walls


def is_free_surface(roles, group):
    """Whether the zone's faces on surface ``group`` are a free surface once the grains are in:
    neither a DEM wall nor a rigid body that holds the grains (one placed on them later, with a
    ``seating_pressure``, is a free surface until then)."""
    held = {r.surface for r in roles.rigid if r.seating_pressure is None}
    wall = group in roles.surfaces and roles.surfaces[group].dem == "wall"
    return group not in held and not wall


def fill(case, built, out_dir, name):
    """Fill the grain volumes (collective); returns (the grains: a
    :class:`~de_domain.deposition.SpherePacking` or :class:`~de_domain.clumps.ClumpPacking`,
    info) and writes ``specimen.npz``."""
    from cosim.specimen import save_specimen
    from de_domain.deposition import (
        GenerationSettings,
        Specimen,
        SpherePacking,
        diameters_for_solid_volume,
        solid_volume_for,
    )
    from de_domain.zone_fill import fill_zone, tets_volume
    sp, split = case.specimen, built["split"]
    mats, ids = grain_materials(case)
    volume = tets_volume(split.zone.tets)
    if "packing" in built:
        grains = built["packing"]
        solids = grains.volumes()
        e = (volume - float(np.sum(solids))) / float(np.sum(solids))
        say(f"[{name}] grains from {sp.file}: {len(solids)}, e = {e:.4f} over the grain volumes")
        spheres = {} if isinstance(grains, SpherePacking) else {"spheres": len(grains.members()[1])}
        return grains, {"source": sp.file, "grains": len(solids), **spheres, "void_ratio": e,
                        "zone_volume_m3": volume, "wall_clock_s": 0.0}
    rng = np.random.default_rng(case.case.seed)
    diameters = diameters_for_solid_volume(built["curve"], solid_volume_for(sp.void_ratio, volume), rng)
    sand = mats[ids[sp.deposition_material or case.embedded.sand_material]]  # the grains' material while filled
    height = float(np.ptp(split.zone.tets[:, :, 2]))
    weight_stress = sand.density / (1.0 + sp.void_ratio) * float(np.linalg.norm(case.dem.gravity)) * height
    settings = GenerationSettings(
        box_length=1.0, height=height, void_ratio=sp.void_ratio, sand=sand, wall=sand, plate=sand,
        friction=sp.deposition_friction, rolling_friction=sp.deposition_rolling_friction,
        rolling_stiffness=sp.deposition_rolling_stiffness, density_scale=sp.density_scale,
        gravity=tuple(case.dem.gravity), local_damping=sp.local_damping, safety_factor=case.time.safety_factor,
        contact_law=case.dem.contact_law, unbalanced_force=sp.unbalanced_force, plate_velocity=sp.plate_velocity,
        cloud_solid_fraction=sp.cloud_solid_fraction, max_steps_per_layer=sp.max_steps_per_layer,
        release_stress=RELEASE_FRACTION * weight_stress, seed=case.case.seed)
    say(f"[{name}] filling {volume * 1e6:.1f} cm³ of grain volume ({', '.join(Roles.of(case.embedded).grains)}): "
        f"{len(diameters)} grains, d = {diameters.min() * 1e3:.2f}-{diameters.max() * 1e3:.2f} mm, "
        f"target e = {sp.void_ratio}")
    t0 = time.perf_counter()
    comm = mpi_comm() if mpi_comm().size > 1 else None
    try:
        filled = fill_zone(split.zone.tets, container(case, split, mats, ids), diameters, settings,
                           log=lambda text: say(f"[{name}] {text}"), comm=comm, shapes=built.get("shapes"),
                           settle=sp.zone_stress == "weight")
    except ValueError as exc:
        raise RuntimeError(f"[{name}] {exc}") from None
    ok = abs(filled.void_ratio - sp.void_ratio) <= sp.tolerance
    bulk = "" if filled.bulk_void_ratio is None else \
        f"; {filled.bulk_void_ratio:.4f} in its bulk, one d_max from its faces (spheres pack looser at a face)"
    say(f"[{name}] grains: e = {filled.void_ratio:.4f} over the grain volume (target {sp.void_ratio} ± {sp.tolerance}: "
        f"{'OK' if ok else 'MISSED'}){bulk}")
    top = float(np.max(filled.positions[:, 2] + filled.radii))
    if is_root():
        save_specimen(out_dir / "specimen.npz", Specimen(filled.positions, filled.radii, top, filled.void_ratio,
                                                         "zone_fill", filled.steps, clumps=filled.clumps))
    grains = SpherePacking(filled.positions, filled.radii) if filled.clumps is None else filled.clumps
    info = {"grains": len(filled.radii) if filled.clumps is None else filled.clumps.count,
            **({} if filled.clumps is None else {"spheres": len(filled.radii)}),
            "void_ratio": filled.void_ratio, "void_ratio_bulk": filled.bulk_void_ratio,
            "void_ratio_target": sp.void_ratio, "void_ratio_within_tolerance": bool(ok), "zone_volume_m3": volume,
            "steps": filled.steps,
            "wall_clock_s": time.perf_counter() - t0}
    return grains, info


# --------------------------------------------------------------------------- model
def build_model(case, built, grains, ramp):
    """The DEM engine (``grains``, a :class:`~de_domain.deposition.SpherePacking` or
    :class:`~de_domain.clumps.ClumpPacking`; facets: rigid bodies first, then the DEM walls that
    are no plane, the interface last; plane walls for the DEM walls that are
    (:func:`planar_walls`)) and the FE volumes with the interface; collective. Returns
    (soil_model.Model, rigid FacetMeshes)."""
    from cosim.apps.coupled import check_replicas, fe_stable_step, time_steps
    from cosim.interface import Interface
    from cosim.soil_model import Model
    from de_domain import Engine
    from de_domain.zone_fill import facet_mesh, planar_walls, tets_volume
    em, split = case.embedded, built["split"]
    roles = Roles.of(em)
    mats, ids = grain_materials(case)
    particles, clumps = grains.bodies(mats, ids[em.sand_material])
    positions, radii = grains.members()
    bodies = rigid_bodies(case, split, ids)
    for mesh, body in zip(bodies, em.rigid, strict=True):
        if body.seating_pressure is not None:  # clear of the grains, by a grain, until it is seated (seat)
            d = direction(body)
            mesh.vertices += (gap_to_grains(mesh.vertices, d, positions, radii) - 2.0 * float(radii.max())) * d
    planes, walls = [], []  # the DEM walls: planes where they can be, else facets
    for group, s in roles.surfaces.items():
        if s.dem == "wall" and group in split.zone.free:
            these, rest = planar_walls(split.zone.free[group], split.zone.tets, ids[s.material])
            planes += these
            walls += [facet_mesh(rest, ids[s.material])] if len(rest) else []
    comm = mpi_comm() if mpi_comm().size > 1 else None
    dem = case.dem
    engine_args = dict(contact_law=dem.contact_law, gravity=dem.gravity, safety_factor=case.time.safety_factor,
                       local_damping=dem.local_damping, viscous_damping=dem.viscous_damping, comm=comm, clumps=clumps)
    if split.fe is None:
        engine = Engine(particles, mats, walls=planes, facets=bodies + walls, **engine_args)
        return Model(engine), bodies
    sand = mats[ids[em.sand_material]]
    bulk = sand.density * float(np.sum(grains.volumes())) / tets_volume(split.zone.tets)
    solid = build_fe(case, split, roles, bulk, ramp)
    check_replicas(solid)
    interface = Interface(solid, ["fe_dem_interface"], ids[em.interface_material])
    engine = Engine(particles, mats, walls=planes, facets=bodies + walls + [interface.facets], **engine_args)
    fe_dt, dem_dt, n_sub = time_steps(engine.dt, fe_stable_step(case.time, solid), em.subcycles)
    solid.dt, engine.dt = fe_dt, dem_dt
    return Model(engine, solid, interface, n_sub, bulk), bodies


def rigid_bodies(case, split, ids):
    """The rigid bodies' facet meshes where the model puts them."""
    from de_domain.zone_fill import facet_mesh
    return [facet_mesh(split.surfaces[r.surface], ids[r.material]) for r in case.embedded.rigid]


def direction(body):
    """The unit vector of a rigid body's velocity."""
    v = np.asarray(body.velocity, float)
    return v / np.linalg.norm(v)


def gap_to_grains(vertices, direction, positions, radii):
    """How far (m) a rigid body (its ``vertices``) moves along the unit ``direction`` before it
    touches a grain: the least, over the grains whose projection on the plane normal to the
    direction overlaps the body's bounding rectangle there (widened by their radius), of the
    distance from the grain's surface to the body's leading plane ``max(x · direction)``;
    negative when a grain already reaches past that plane. Exact for a flat body normal to its
    motion (a footing, a plate), the first contact of its leading plane otherwise."""
    lateral = np.linalg.svd(np.asarray(direction, float)[None, :])[2][1:]  # two unit vectors normal to it
    body, grains = vertices @ lateral.T, positions @ lateral.T
    under = np.all((grains + radii[:, None] > body.min(axis=0)) & (grains - radii[:, None] < body.max(axis=0)), axis=1)
    if not under.any():
        raise RuntimeError("no grain lies in the path of a rigid body placed on the grains (seating_pressure)")
    return float(np.min(positions[under] @ direction - radii[under]) - np.max(vertices @ direction))


def area(mesh):
    """The total area of a facet mesh's triangles (m²)."""
    t = mesh.vertices[mesh.triangles]
    return 0.5 * float(np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


def seat(model, bodies, rigid, interval, loading_time, name):
    """Place each body with a ``seating_pressure`` on the grains: move it along its velocity to
    the first grain (:func:`gap_to_grains`), then on at its velocity until its force against the
    motion over its area, averaged over ``interval`` s, reaches the seating pressure (within
    the travel of its whole loading, ``|v|`` × ``loading_time``); it then
    stops, and the loading counts from there. A loose grain on the surface carries almost
    nothing while it is pushed into the grains below it; the seating load skips that travel in
    both models alike. Returns {name: {"pressure_Pa", "travel_m"}}; collective."""
    grains = model.engine.global_particles()  # collective
    out = {}
    for mesh, body in zip(bodies, rigid, strict=True):
        if body.seating_pressure is None:
            continue
        d, v = direction(body), np.asarray(body.velocity, float)
        limit = float(np.linalg.norm(v)) * loading_time
        gap = gap_to_grains(mesh.vertices, d, grains.pos, grains.radius)
        mesh.set_vertex_state(mesh.vertices + gap * d, np.tile(v, (len(mesh.vertices), 1)))
        contact, surface, pressure = mesh.vertices.copy(), area(mesh), 0.0
        while pressure < body.seating_pressure:
            mesh.reset_impulse()
            start = model.time
            model.advance(interval)
            pressure = float(-(mesh.vertex_impulse.sum(axis=0) @ d)) / (model.time - start) / surface
            if float((mesh.vertices - contact)[0] @ d) > limit:
                raise RuntimeError(f"[{name}] {body.name} did not reach its seating pressure "
                                   f"{body.seating_pressure:.4g} Pa within its whole loading travel {limit:.4g} m "
                                   f"(it carries {pressure:.4g} Pa): lower its seating_pressure")
        mesh.velocity = np.zeros(3)
        travel = float((mesh.vertices - contact)[0] @ d)
        if body.seating_pressure > 0:
            say(f"[{name}] {body.name} seated: {pressure / 1e3:.3f} kPa after {travel * 1e3:.3f} mm from the first "
                f"contact (seating pressure {body.seating_pressure / 1e3:.3g} kPa); its displacement counts from here")
        out[body.name] = {"pressure_Pa": pressure, "travel_m": travel}
    return out


def report_rest_stress(engine, tets, d_max, out_dir, name):
    """``rest_stress.csv``: the grains' stress at rest in horizontal bands REST_BAND_GRAINS
    ``d_max`` high (:func:`~cosim.apps.embedded_model.rest_stress`); returns its summary, the
    earth pressure coefficients over the grain volume. Collective."""
    rows, overall = rest_stress(engine, stress_bands(tets, REST_BAND_GRAINS * d_max))
    if is_root():
        lines = [",".join(REST_STRESS_COLUMNS)] + [",".join(f"{v:.9g}" for v in row) for row in rows]
        atomic_write_text(out_dir / "rest_stress.csv", "\n".join(lines) + "\n")
    say(f"[{name}] the grains at rest: K = sigma_h / sigma_v = {overall['K_x']:.3f} (x), {overall['K_y']:.3f} (y) "
        f"over their volume, sigma_v = {overall['sigma_zz_Pa']:.4g} Pa (rest_stress.csv: by depth)")
    return overall


def resumed_model(case, case_path, out_dir, built, state, ramp):
    """The model at the last checkpoint of the loading (DEM engine with its rigid bodies, walls
    and interface facets; the FE volumes on the prepared mesh with their state); collective.
    Returns (soil_model.Model, rigid FacetMeshes)."""
    from cosim.apps.coupled import fe_stable_step
    from cosim.interface import Interface
    from cosim.soil_model import Model, checkpointed_engine, restore_fe
    em, split = case.embedded, built["split"]
    engine = checkpointed_engine(case_path, out_dir, state, STATE)
    bodies = engine.facets[:len(em.rigid)]  # rigid bodies first (build_model)
    if split.fe is None:
        return Model(engine), bodies
    _, ids = grain_materials(case)
    solid = build_fe(case, split, Roles.of(em), state["soil_density"], ramp)
    interface = Interface(solid, ["fe_dem_interface"], ids[em.interface_material])
    fe_stable_step(case.time, solid)  # the solid's limit as the run had it, before its step is restored
    restore_fe(solid, interface, engine, case_path, out_dir)
    return Model(engine, solid, interface, int(round(solid.dt / engine.dt)),
                 state["soil_density"]), bodies




# --------------------------------------------------------------------------- loading
def columns(rigid, linings=()):
    """series.csv columns: per rigid body its motion, force and moment; per lining its thrust and
    moment at the crown, springline and invert (:data:`cosim.apps.embedded_model.LINING_GAUGES`); the interface
    force."""
    per_body = [f"{r.name}_{q}" for r in rigid for q in
                ("displacement", "rotation", *(f"force_{a}" for a in AXES), *(f"moment_{a}" for a in AXES))]
    return ["time", *per_body, *lining_columns(linings), *(f"interface_force_{a}" for a in AXES),
            "unbalanced_force_ratio", "step"]


def rotation_matrix(axis_angle):
    """R of a rotation by ``|θ|`` about ``θ / |θ|`` (Rodrigues' formula)."""
    theta = float(np.linalg.norm(axis_angle))
    if theta == 0.0:
        return np.eye(3)
    k = np.asarray(axis_angle) / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def place_body(mesh, reference, body, elapsed):
    """The body's vertices at ``elapsed`` s of loading — reference rotated by ω t about the
    pivot, then translated by v t — and their velocities v + ω × (x − c(t))."""
    pivot = np.asarray(body.pivot, float)
    omega, velocity = np.asarray(body.angular_velocity, float), np.asarray(body.velocity, float)
    centre = pivot + velocity * elapsed
    positions = (reference - pivot) @ rotation_matrix(omega * elapsed).T + centre
    mesh.set_vertex_state(positions, velocity + np.cross(omega, positions - centre))


def load(case, model, bodies, rigid, references, out_dir, name, state, ramp, resume=False):
    """Hold the rigid bodies for one row (row 0: the forces at rest), then move them (from their
    ``references`` vertices) and contract the linings (``ramp`` starts) for
    embedded.loading_time; series.csv, and each lining's section forces at rest and at the end
    (<volume>_sections.csv); a checkpoint every output.checkpoint_interval (after a row), from
    which ``resume`` continues; returns the series (rank 0)."""
    from cosim.apps import coupled as coupled_app
    from cosim.lab.shear_report import read_series
    from cosim.soil_model import save_checkpoint, unbalanced
    from de_domain.io import write_frame
    from fe_domain.output import FieldWriter
    em = case.embedded
    row_time = em.loading_time / em.rows
    gauges = lining_gauges(case, model.solid) if em.linings else []
    state["lining_outer_radii"] = {lining.volume: gauge.ring.outer_radius
                                   for lining, gauge in zip(em.linings, gauges, strict=True)}
    if resume:
        first_row, start = state["row"] + 1, state["loading_start_time"]
        ramp.start = start
    else:
        first_row, start = 0, None  # row 0: the bodies held, the thrust at rest; they move from its end
        for mesh in bodies:
            mesh.reset_impulse()
        model.take_interface_impulse()  # the rest phase's is not the loading's
    resume_time = model.time if resume else None
    rows = CsvSeries(out_dir / "series.csv", columns(rigid, em.linings), resume_time) if is_root() else None
    frames = PvdCollection(out_dir / "particles.pvd", resume_time) if is_root() and case.output.vtk else None
    fields = None
    if model.solid is not None and coupled_app.writes_fe_files(model.solid):
        stem = f"fields_from_step{model.solid.step_count}" if resume else "fields"
        fields = FieldWriter(model.solid, out_dir / stem, extra_fields=[model.interface.traction_field])
    progress = ProgressLine(name, em.rows, case.output.progress_interval, first_step=first_row - 1,
                            unit="row")
    frame_every = max(1, em.rows // FRAMES)
    t_last = model.time
    t_entry = last_checkpoint = time.perf_counter()
    for k in range(first_row, em.rows + 1):
        for mesh, reference, body in zip(bodies, references, rigid, strict=True):
            place_body(mesh, reference, body, 0.0 if k == 0 else model.time - start)
            if k == 0:
                mesh.velocity = np.zeros(3)
        model.advance(row_time)
        elapsed, t_last = model.time - t_last, model.time
        if k == 0:
            start = ramp.start = state["loading_start_time"] = model.time
            state["sections_at_rest"] = [sections(gauge) for gauge in gauges]
        row = [model.time]
        for mesh, body in zip(bodies, rigid, strict=True):
            t = model.time - start
            arm = mesh.vertices - (np.asarray(body.pivot) + np.asarray(body.velocity) * t)
            force = mesh.vertex_impulse.sum(axis=0) / elapsed
            moment = np.cross(arm, mesh.vertex_impulse).sum(axis=0) / elapsed
            mesh.reset_impulse()
            row += [float(np.linalg.norm(body.velocity)) * t, float(np.linalg.norm(body.angular_velocity)) * t,
                    *force, *moment]
        for gauge in gauges:
            row += gauge.row()
        row += [*(model.take_interface_impulse() / elapsed), unbalanced(model), model.engine.step_count]
        if rows is not None:
            rows.append(row)
        if k % frame_every == 0 or k == em.rows:
            paths = write_frame(out_dir / "frames", model.engine, model.engine.step_count) if case.output.vtk else None
            if frames is not None:
                frames.add(model.time, paths)
            if fields is not None:
                fields.write()
        progress.update(k, model.time)
        due = time.perf_counter() - last_checkpoint > case.output.checkpoint_interval
        if k < em.rows and mpi_comm().bcast(due, root=0):  # rank 0's clock decides for all
            now = time.perf_counter()
            save_checkpoint(out_dir, model, {**state, "row": k,
                                             "loading_before_s": state["loading_before_s"] + now - t_entry}, STATE)
            last_checkpoint = now
    progress.update(em.rows, model.time, force=True)
    for lining, gauge, at_rest in zip(em.linings, gauges, state.get("sections_at_rest", []), strict=True):
        write_sections(out_dir / f"{lining.volume}_sections.csv", at_rest, sections(gauge))
    state["loading_before_s"] += time.perf_counter() - t_entry
    for mesh in bodies:
        mesh.velocity = np.zeros(3)
    if fields is not None:
        fields.close()
    if rows is None:
        return None
    rows.close()
    return read_series(out_dir / "series.csv")




# --------------------------------------------------------------------------- run
@dataclass
class Outcome:
    """What a run leaves for its report (rank 0): the output folder, the loop's state, the
    series, the rigid bodies as they moved (pivots with their seating offset), the model, the
    grains at the loading's start (positions) and end, the FE nodes' coordinates and their
    displacement during the loading (coupled; else None), the compilation seconds."""
    out_dir: Path
    state: dict
    series: dict
    rigid: list
    model: object
    start: np.ndarray
    grains: object
    fe_motion: tuple
    compiling: float


def run(prepared):
    """Fill, rest, seat, load (:func:`simulate`), then the report
    (:func:`cosim.apps.embedded_report.report`)."""
    from cosim.apps.embedded_report import report
    if prepared.case.embedded.model == "fe":
        from cosim.apps.embedded_fe import run as run_fe
        run_fe(prepared)
        return
    outcome = simulate(prepared)
    if outcome is not None:
        report(prepared, outcome)


def placed(rigid, offsets):
    """The rigid bodies with their pivots moved by the seating ``offsets`` (m, one per body)."""
    return [body.model_copy(update={"pivot": list(np.add(body.pivot, offset))})
            for body, offset in zip(rigid, offsets, strict=True)]


def simulate(prepared):
    """The run up to its outputs of record (series.csv, rest.csv, frames, fields, packings,
    checkpoints); collective. Returns the :class:`Outcome` on rank 0, None on the others."""
    from cosim.soil_model import come_to_rest, fe_nodes
    case, em = prepared.case, prepared.case.embedded
    out_dir = Path(prepared.out_dir) / em.model
    if is_root():
        out_dir.mkdir(parents=True, exist_ok=True)
    mpi_comm().Barrier()
    write_run_metadata(out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    name = f"{case.case.name}/{em.model}"
    compiling_before = compilation_seconds()
    _, ids = grain_materials(case)
    unmoved = [b.vertices.copy() for b in rigid_bodies(case, prepared.built["split"], ids)]
    ramp = LoadingRamp(em.loading_time)  # the linings' contraction: from the loading's start
    if prepared.resume:
        state = json.loads((out_dir / STATE).read_text())
        model, bodies = resumed_model(case, prepared.case_path, out_dir, prepared.built, state, ramp)
        say(f"[{name}] resumed the loading at row {state['row']} (t = {model.time:.4e} s)")
    else:
        clock = {}
        t0 = time.perf_counter()
        grains, fill_info = fill(case, prepared.built, out_dir, name)
        clock["fill_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        model, bodies = build_model(case, prepared.built, grains, ramp)
        clock["build_s"] = time.perf_counter() - t0
        say(f"[{name}] {fill_info['grains']} grains, DEM dt = {model.engine.dt:.3e} s"
            + (f", FE dt = {model.solid.dt:.3e} s ({model.subcycles} DEM steps per FE step; the FE's limit "
               f"{model.solid.dt_critical:.3e} s), "
               f"{len(model.interface.facets.triangles)} interface facets" if model.solid is not None else ""))
        t0 = time.perf_counter()
        rest = come_to_rest(model, out_dir, name, em.rest_unbalanced_force, em.max_rest_time)
        rest["grains"] = report_rest_stress(model.engine, prepared.built["split"].zone.tets,
                                            2.0 * float(np.max(grains.enclosing_radii())), out_dir, name)
        seating = seat(model, bodies, em.rigid, em.loading_time / em.rows / 4, em.loading_time, name)
        clock["rest_s"] = time.perf_counter() - t0
        cells = model.solid.comm.allreduce(model.solid.mesh.topology.index_map(3).size_local) \
            if model.solid is not None else 0  # collective
        state = {"fill": fill_info, "rest": rest, "seating": seating, "clock": clock, "grains": fill_info["grains"],
                 "fe_cells": cells,
                 "soil_density": model.soil_density, "row": 0, "loading_before_s": 0.0,
                 "compilation_before_s": 0.0,
                 "offsets": [(mesh.vertices[0] - reference[0]).tolist()
                             for mesh, reference in zip(bodies, unmoved, strict=True)]}
        start = model.engine.global_particles().pos  # collective
        fe_start = fe_nodes(model.solid)[1] if model.solid is not None else None  # collective
        if is_root():
            atomic_write_npz(out_dir / LOADING_START, position=start,
                             **({} if fe_start is None else {"fe_displacement": fe_start}))
    rigid = placed(em.rigid, state["offsets"])
    references = [reference + np.asarray(offset) for reference, offset in zip(unmoved, state["offsets"], strict=True)]
    state["compilation_before_s"] += compilation_seconds() - compiling_before
    compiling_before = compilation_seconds()
    series = load(case, model, bodies, rigid, references, out_dir, name, state, ramp, prepared.resume)
    grains = model.engine.global_particles()  # collective
    fe_end = fe_nodes(model.solid) if model.solid is not None else None  # collective
    compiling = state["compilation_before_s"] + compilation_seconds() - compiling_before
    if not is_root():
        return None
    from de_domain.packing import save_packing
    save_packing(out_dir / "final_packing.npz", grains.pos, grains.radius)
    if model.engine.clumps.count:  # every clump on every rank: which clump each sphere is in, the clumps' state
        np.savez(out_dir / "final_clumps.npz", **model.engine.clumps.arrays())
    with np.load(out_dir / LOADING_START) as loaded:
        start = loaded["position"]
        fe_motion = None if fe_end is None else (fe_end[0], fe_end[1] - loaded["fe_displacement"])
    return Outcome(out_dir, state, series, rigid, model, start, grains, fe_motion, compiling)
