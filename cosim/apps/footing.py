"""Case kind ``footing``: a rigid strip footing pushed into sand, as a coupled model (grains
only in a zone under the footing, embedded in an FE soil block) or as its all-DEM reference
(the whole block made of grains), both built from one case description (docs/design.md §7).

The geometry is a plane-strain slice: a soil block W × L_y × H (x, y, z from 0) between
frictionless walls (DEM) or rollers (FE) at y = 0 and y = L_y, fixed at its bottom, on
rollers at x = 0 and x = W. ``footing.model`` picks the model:

* ``coupled`` — the FE block (``meshes/trench.geo``) has a trench w × L_y × d at the middle
  of its top, refined towards it with a gmsh size field; the trench's bottom and sides are
  the coupling interface (docs/design.md §5); the grains fill it (generated in a
  w × L_y × d box by ``[specimen]``). The FE soil is linear elastic (``soil.E``, ``soil.nu``,
  e.g. measured on the packing by ``cosim elastic``), as dense as the zone's packing, under
  gravity, with local damping.
* ``dem`` — the grains fill the whole W × L_y × H block (the same ``[specimen]`` generation),
  inside rigid walls: a rough bottom, frictionless sides.

The run, in both models:

1. **Specimen** — generated (or read from ``specimen.file``) and placed in the zone / block;
   the zone's layers as thick as the block's (:func:`layer_count`).
2. **Rest** — the model under gravity runs until the grains' unbalanced force ratio is below
   ``footing.rest_unbalanced_force``. Coupled: the FE far field then carries the zone's
   weight, so the total interface force equals the grains' weight (``rest.csv``; the
   balance is in ``summary.json``).
3. **Loading** — the footing, a rigid two-triangle facet plate B × L_y, starts on the
   highest grain under it (s = 0 at the first contact) and moves down at ``footing.velocity``
   until the settlement s = ``footing.settlement`` × B. ``series.csv``: the footing force
   (the impulse the grains give it over each row's interval / that interval), the bearing
   pressure q = F / (B L_y), s / B, the interface force (coupled; also an impulse over the row's
   interval), the unbalanced force ratio.
4. **Report** — ``summary.json`` (q at s/B = 2, 5, 10 %, the rest balance, wall-clock of
   each phase), ``load_settlement.png``, ``displacement_section.png`` (the grains in the x–z
   section coloured by their displacement during loading, and the FE soil's front face by
   its own, on one scale), ParaView frames (particles, and
   the FE fields in ``fields.xdmf``), ``final_packing.npz``. When both models of the case have run, their
   load–settlement curves are compared in the case's folder (``comparison.csv``, ``.png``).

Outputs go to ``runs/out/<name>/<model>/``.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.case import resolve_path
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
from cosim.soil_model import (
    Model,
    checkpointed_engine,
    come_to_rest,
    restore_fe,
    save_checkpoint,
    unbalanced,
)
from cosim.specimen import SpecimenBox, curve_of, make_specimen, read_specimen

SETTLEMENT_LEVELS = (0.02, 0.05, 0.10)  # s/B at which the bearing pressure is reported
MEAN_RANGE = (0.01, 0.10)  # s/B over which the mean bearing pressure is reported
COLUMNS = ["time", "settlement", "settlement_ratio", "footing_force_z", "bearing_pressure",
           "interface_force_z", "unbalanced_force_ratio", "step"]
FRAMES = 5  # ParaView frames over the loading
STATE = "footing_state.json"  # the loading loop's state at the last checkpoint (with checkpoint.npz)
LOADING_START = "loading_start.npz"  # every grain's position (and FE node's displacement) when the loading began
RELEASE_FRACTION = 0.02  # the generation plate is raised until it carries this x the self-weight stress at the bottom


# --------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class Geometry:
    """Where things are (m): the soil block [0, W] × [0, L_y] × [0, H], the zone (trench)
    x ∈ [x0, x0 + w], z ∈ [H − d, H], the footing centred at x = W / 2."""
    width: float
    thickness: float
    depth: float
    zone_width: float
    zone_depth: float
    footing_width: float

    @classmethod
    def of(cls, case):
        s, z = case.soil, case.zone
        return cls(s.width, s.thickness, s.depth, z.width, z.depth, case.footing.width)

    @property
    def zone_x0(self):
        return 0.5 * (self.width - self.zone_width)

    @property
    def zone_bottom(self):
        return self.depth - self.zone_depth

    def specimen_box(self, model):
        """(length, width, height) of the box the grains are generated in."""
        if model == "coupled":
            return self.zone_width, self.thickness, self.zone_depth
        return self.width, self.thickness, self.depth

    def specimen_origin(self, model):
        """Where the generation box's origin goes in the model."""
        return np.array([self.zone_x0, 0.0, self.zone_bottom]) if model == "coupled" else np.zeros(3)

    def mesh_parameters(self, soil):
        """The DefineConstant values of meshes/trench.geo."""
        return {"W": self.width, "Ly": self.thickness, "H": self.depth, "w": self.zone_width,
                "d": self.zone_depth, "h_near": soil.interface_mesh_size, "h_far": soil.mesh_size,
                "grow": soil.refinement_distance or self.zone_depth}


def footing_plate(geometry, z, material):
    """The rigid footing: a B × L_y rectangle (two triangles) at height z, centred at x = W/2."""
    from de_domain import FacetMesh
    x0, x1 = 0.5 * (geometry.width - geometry.footing_width), 0.5 * (geometry.width + geometry.footing_width)
    ly = geometry.thickness
    vertices = [[x0, 0.0, z], [x1, 0.0, z], [x1, ly, z], [x0, ly, z]]
    return FacetMesh(vertices, [[0, 1, 2], [0, 2, 3]], material=material)


# --------------------------------------------------------------------------- inputs
def _material_ids(case):
    from cosim.apps.dem import materials_of
    ft = case.footing
    roles = {"sand": ft.sand_material, "side_wall": ft.side_wall_material, "footing": ft.material,
             "interface": case.zone.interface_material}
    mats, *ids = materials_of(case.dem, *roles.values())
    return mats, dict(zip(roles, ids, strict=True))


def prepare(case, case_path, out_dir, resume):
    """Every input check before any computation (rank 0 reads, every rank raises the same
    CaseError): the packing against the zone or block, or the sieve curve."""
    from cosim.apps import on_root
    model_dir = Path(out_dir) / case.footing.model
    found = (model_dir / STATE).exists() and (model_dir / "checkpoint.npz").exists()
    if resume and not mpi_comm().allreduce(int(found)):
        raise CaseError(case_path, "--resume", str(model_dir / "checkpoint.npz"),
                        "no footing checkpoint in the output folder (checkpoints start with the loading); "
                        "run without --resume")
    built = mpi_comm().bcast(on_root(mpi_comm(), lambda: _read_inputs(case, case_path)), root=0)
    if case.footing.model == "coupled":
        built["soil_mesh"] = soil_mesh(case, case_path)  # collective: cosim check meshes the block too
    return built


def soil_mesh(case, case_path):
    """The FE soil block's mesh (meshes/trench.geo with the case's sizes), made once, before
    any computation; a block gmsh cannot mesh is a CaseError on every rank."""
    from fe_domain.mesh import MeshError, load_mesh
    try:
        from cosim.apps.coupled import fe_communicator
        return load_mesh("trench.geo", case.soil.mesh_size, fe_communicator(case.soil.fe_partition),
                         Geometry.of(case).mesh_parameters(case.soil))
    except MeshError as exc:
        raise CaseError(case_path, "soil.mesh_size", case.soil.mesh_size,
                        f"gmsh could not mesh the soil block with its trench (meshes/trench.geo): {exc}") from None


def _read_inputs(case, case_path):
    sp = case.specimen
    geometry = Geometry.of(case)
    if sp.source == "generate":
        try:
            return {"curve": curve_of(sp)}
        except ValueError as exc:
            raise CaseError(case_path, "specimen", "sieve curve", str(exc)) from None
    try:
        pos, radii, height, e = read_specimen(resolve_path(case_path, sp.file))
    except Exception as exc:
        raise CaseError(case_path, "specimen.file", sp.file, f"could not read the packing: {exc}") from None
    length, width, depth = geometry.specimen_box(case.footing.model)
    slack = 0.25 * radii[:, None]  # elastic overlap with the walls of the box it was made in
    low, high = pos - radii[:, None], pos + radii[:, None]
    box = np.array([length, width, np.inf])
    swell = float(radii.max())  # a released specimen stands up to a grain radius above its box (§7.3)
    if np.any(low < -slack) or np.any(high > box + slack) or height > depth + swell:
        where = "DEM zone" if case.footing.model == "coupled" else "soil block"
        raise CaseError(case_path, "specimen.file", sp.file,
                        f"the packing does not fit the {where}: its grains must lie in x in [0, {length}], y in "
                        f"[0, {width}] m (overlapping a side by at most 25 % of the radius) and its height "
                        f"({height:.4g} m) must not exceed {depth} m by more than its largest radius")
    from cosim.apps.dem import warn_overlaps
    warn_overlaps(case_path, "specimen.file", sp.file, pos, radii)
    return {"packing": (pos, radii, height, e)}


# --------------------------------------------------------------------------- models
def build_model(case, grains, height, mesh=None):
    """The model ``footing.model`` of the case with the specimen ``grains`` = (positions,
    radii) of height ``height`` (generation-box coordinates), and for the coupled model the
    soil ``mesh`` (:func:`soil_mesh`; made here if None); collective."""
    from de_domain import Engine, Particles, PlaneWall
    geometry = Geometry.of(case)
    model = case.footing.model
    mats, ids = _material_ids(case)
    pos = grains[0] + geometry.specimen_origin(model)
    radii = grains[1]
    surface = float(geometry.specimen_origin(model)[2] + height)
    particles = Particles.from_spheres(pos, radii, np.full(len(radii), ids["sand"], np.int32), mats)
    ly, W = geometry.thickness, geometry.width
    walls = [PlaneWall((0, 0, 0), (0, 1, 0), ids["side_wall"]), PlaneWall((0, ly, 0), (0, -1, 0), ids["side_wall"])]
    if model == "dem":
        walls += [PlaneWall((0, 0, 0), (0, 0, 1), ids["interface"]),
                  PlaneWall((0, 0, 0), (1, 0, 0), ids["side_wall"]), PlaneWall((W, 0, 0), (-1, 0, 0), ids["side_wall"])]
    footing = footing_plate(geometry, surface, ids["footing"])
    comm = mpi_comm() if mpi_comm().size > 1 else None
    dem = case.dem
    engine_args = dict(contact_law=dem.contact_law, gravity=dem.gravity, safety_factor=case.time.safety_factor,
                       local_damping=dem.local_damping, viscous_damping=dem.viscous_damping, comm=comm)
    if model == "dem":
        engine = Engine(particles, mats, walls=walls, facets=[footing], **engine_args)
        return Model(model, engine, footing, surface)
    density = soil_density(case, radii, geometry.zone_width * geometry.thickness * height)
    solid, interface = build_soil(case, geometry, ids["interface"], density, mesh)
    engine = Engine(particles, mats, walls=walls, facets=[footing, interface.facets], **engine_args)
    from cosim.apps.coupled import time_steps
    fe_dt, dem_dt, n_sub = time_steps(engine.dt, case.time.safety_factor * solid.dt_critical, case.zone.subcycles)
    solid.dt, engine.dt = fe_dt, dem_dt
    return Model(model, engine, footing, surface, solid, interface, n_sub, density)


def soil_density(case, radii, volume):
    """The FE soil's density: ``soil.rho``, or the bulk density of the packing, ρ_s V_s / V, of
    grains ``radii`` filling ``volume`` (the zone up to the specimen's height)."""
    if case.soil.rho is not None:
        return case.soil.rho
    sand = [m for m in case.dem.materials if m.name == case.footing.sand_material][0]
    return sand.density * float(np.sum(4.0 / 3.0 * np.pi * radii**3)) / volume


def build_soil(case, geometry, interface_material, density, mesh=None):
    """The FE soil block with its trench (``mesh``, or meshes/trench.geo meshed here), of
    ``density`` (kg/m³), and the interface on the trench's faces; collective."""
    from cosim.apps.coupled import check_replicas, fe_communicator
    from cosim.interface import Interface
    from fe_domain.build import build_solid
    from fe_domain.explicit import stable_alpha_tau
    soil = case.soil
    rollers = [{"type": "fixed", "boundary": "bottom"},
               {"type": "fixed", "boundary": "sides_x", "components": [0]},
               {"type": "fixed", "boundary": "sides_y", "components": [1]}]
    solid = build_solid(mesh if mesh is not None else "trench.geo", soil.mesh_size,
                        material={"E": soil.E, "nu": soil.nu, "rho": density},
                        boundary_conditions=rollers,
                        loads=[{"type": "body_force", "acceleration": list(case.dem.gravity)}],
                        damping={"type": "local", "alpha": soil.damping} if soil.damping > 0 else None,
                        formulation="mixed", alpha_tau=stable_alpha_tau(soil.nu),
                        safety_factor=case.time.safety_factor,
                        geometry_parameters=geometry.mesh_parameters(soil),
                        comm=fe_communicator(soil.fe_partition))
    check_replicas(solid)
    return solid, Interface(solid, ["zone"], interface_material)


# --------------------------------------------------------------------------- run
def run(prepared):
    from cosim.apps import coupled as coupled_app
    case = prepared.case
    out_dir = Path(prepared.out_dir) / case.footing.model
    if is_root():
        out_dir.mkdir(parents=True, exist_ok=True)
    mpi_comm().Barrier()
    write_run_metadata(out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    name = f"{case.case.name}/{case.footing.model}"
    clock = {}
    compiling_before = compilation_seconds()

    if prepared.resume:
        state = json.loads((out_dir / STATE).read_text())
        model = resumed_model(case, prepared.case_path, out_dir, prepared.built, state)
        say(f"[{name}] resumed the loading at row {state['row']} (t = {model.time:.4e} s)")
    else:
        t0 = time.perf_counter()
        grains, height, specimen_info = _specimen(case, prepared.built, out_dir, name)
        clock["specimen_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        model = build_model(case, grains, height, prepared.built.get("soil_mesh"))
        clock["build_s"] = time.perf_counter() - t0
        n_cells = _cells(model.solid) if model.solid is not None else 0  # collective
        say(f"[{name}] {len(grains[1])} grains, DEM dt = {model.engine.dt:.3e} s"
            + (f", FE dt = {model.solid.dt:.3e} s ({model.subcycles} DEM steps per FE step), "
               f"{n_cells} tetrahedra, {len(model.interface.facets.triangles)} interface facets"
               + coupled_app.fe_layout(model.solid) if model.solid is not None else
               (f", on {mpi_comm().size} MPI ranks" if mpi_comm().size > 1 else "")))
        t0 = time.perf_counter()
        rest = come_to_rest(model, out_dir, name, case.footing.rest_unbalanced_force, case.footing.max_rest_time)
        clock["rest_s"] = time.perf_counter() - t0
        state = {"specimen_info": specimen_info, "rest": rest, "clock": clock, "grains": len(grains[1]),
                 "cells": n_cells, "surface": model.surface, "soil_density": model.soil_density, "row": 0,
                 "loading_before_s": 0.0, "compilation_before_s": 0.0}

    state["compilation_before_s"] = state.get("compilation_before_s", 0.0) + compilation_seconds() - compiling_before
    compiling_before = compilation_seconds()
    t0 = time.perf_counter()
    series = load(case, model, out_dir, name, state, prepared.resume)
    clock = {**state["clock"], "loading_s": state["loading_before_s"] + time.perf_counter() - t0}
    compiling = state["compilation_before_s"] + compilation_seconds() - compiling_before
    specimen_info, rest, n_grains, n_cells = (state[k] for k in ("specimen_info", "rest", "grains", "cells"))

    if is_root():
        summary = _summary(case, model, n_grains, n_cells, specimen_info, rest, series, clock, compiling,
                           state.get("seating"))
        atomic_write_text(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
        plot_load_settlement({case.footing.model: series}, out_dir / "load_settlement.png", case.case.name)
        compare_models(Path(prepared.out_dir), case.case.name)
        say(f"[{name}] q at s/B = " + ", ".join(f"{100 * k:.0f} %: {q / 1e3:.2f} kPa"
                                                for k, q in summary["bearing_pressure_at"].items())
            + f"; wall-clock {sum(clock.values()):.0f} s, of which {compiling:.0f} s compiling (first run only)")


def _cells(solid):
    return solid.comm.allreduce(solid.mesh.topology.index_map(3).size_local)


def _specimen(case, built, out_dir, name):
    """((positions, radii), height, info) in generation-box coordinates; collective."""
    if "packing" in built:
        pos, radii, height, e = built["packing"]
        say(f"[{name}] specimen from {case.specimen.file}: {len(radii)} grains")
        return (pos, radii), height, {"source": case.specimen.file, "void_ratio_generated": e,
                                      "generation_wall_clock_s": 0.0}
    geometry = Geometry.of(case)
    mats, ids = _material_ids(case)
    length, width, depth = geometry.specimen_box(case.footing.model)
    box = SpecimenBox(length, width, depth, mats, ids["sand"], ids["side_wall"], ids["interface"])
    comm = mpi_comm() if mpi_comm().size > 1 else None
    pos, radii, height, info = make_specimen(case, box, built["curve"], out_dir, comm=comm, label=name,
                                             release_stress=RELEASE_FRACTION * self_weight_stress(case, depth),
                                             layers=layer_count(case, built["curve"]),
                                             bulk_margin=float(built["curve"].diameters[-1]))
    return (pos, radii), height, info


def layer_count(case, curve):
    """Layers of the under-compaction in this model: the all-DEM block's count
    (``specimen.layers`` or the default for its depth), and in the coupled zone as many as keep
    the block's layer thickness. The compaction a layer needs, and the stress it locks in,
    depend on its thickness, so the two models' grains are generated alike."""
    from de_domain.deposition import layer_count as default_count
    sp, geometry = case.specimen, Geometry.of(case)
    block = sp.layers or default_count(sp.void_ratio, sp.cloud_solid_fraction, geometry.depth,
                                       float(curve.diameters[-1]))
    if case.footing.model == "dem":
        return block
    return max(1, round(block * geometry.zone_depth / geometry.depth))


def bulk_density(case):
    """ρ_s / (1 + e_target): the packing's bulk density (kg/m³)."""
    sand = [m for m in case.dem.materials if m.name == case.footing.sand_material][0]
    return sand.density / (1.0 + case.specimen.void_ratio)


def self_weight_stress(case, depth):
    """ρ_s g H / (1 + e): the vertical stress at depth H of the specimen at its target void ratio (Pa)."""
    return bulk_density(case) * float(np.linalg.norm(case.dem.gravity)) * depth


def load(case, model, out_dir, name, state, resume=False):
    """Push the footing down at footing.velocity to the final settlement; series.csv rows;
    a checkpoint every output.checkpoint_interval (after a row), from which ``resume``
    continues; returns the series as a dict of arrays (rank 0) or None."""
    from cosim.apps import coupled as coupled_app
    from cosim.lab.shear_report import read_series
    from de_domain.io import write_frame
    from fe_domain.output import FieldWriter
    ft = case.footing
    B, ly = ft.width, case.soil.thickness
    final = ft.settlement * B
    row_time = final / ft.rows / ft.velocity
    footing = model.footing
    start_path = out_dir / LOADING_START
    fe_start = None
    if resume:
        z0, first_row = state["z0"], state["row"] + 1
        start_grains = fe_start = None
        if is_root():
            with np.load(start_path) as start:
                start_grains = start["position"]
                if "fe_displacement" in start:
                    fe_start = start["fe_displacement"]
    else:
        footing.vertices[:, 2] = surface_under(footing, model.engine.global_particles())  # collective
        footing.velocity = np.array([0.0, 0.0, -ft.velocity])
        state["seating"] = seat_footing(model, B * ly, ft.seating_pressure, row_time / 4, final, name)
        z0, first_row = float(footing.vertices[:, 2].mean()), 1
        footing.reset_impulse()
        model.take_interface_impulse()  # the rest phase's is not the loading's
        grains = model.engine.global_particles()  # collective
        start_grains = grains.pos.copy()
        fe_start = fe_nodes(model.solid)[1] if model.solid is not None else None  # collective
        if is_root():
            atomic_write_npz(start_path, position=start_grains,
                             **({} if fe_start is None else {"fe_displacement": fe_start}))
    resume_time = model.time if resume else None
    rows = CsvSeries(out_dir / "series.csv", COLUMNS, resume_time) if is_root() else None
    frames = PvdCollection(out_dir / "particles.pvd", resume_time) if is_root() and case.output.vtk else None
    fields = None
    if model.solid is not None and coupled_app.writes_fe_files(model.solid):
        stem = f"fields_from_step{model.solid.step_count}" if resume else "fields"
        fields = FieldWriter(model.solid, out_dir / stem, extra_fields=[model.interface.traction_field])
    progress = ProgressLine(name, ft.rows, case.output.progress_interval, first_step=first_row - 1)
    frame_every = max(1, ft.rows // FRAMES)
    t_last = model.time
    t_entry = last_checkpoint = time.perf_counter()
    for k in range(first_row, ft.rows + 1):
        model.advance(row_time)
        elapsed = model.time - t_last
        t_last = model.time
        force = footing.vertex_impulse.sum(axis=0) / elapsed
        footing.reset_impulse()
        interface_force = model.take_interface_impulse() / elapsed  # over the same interval as the footing's
        settlement = z0 - float(footing.vertices[:, 2].mean())
        row = [model.time, settlement, settlement / B, force[2], force[2] / (B * ly), interface_force[2],
               unbalanced(model), model.engine.step_count]
        if rows is not None:
            rows.append(row)
        if k % frame_every == 0 or k == ft.rows:
            paths = write_frame(out_dir / "frames", model.engine, model.engine.step_count) if case.output.vtk else None
            if frames is not None:
                frames.add(model.time, paths)
            if fields is not None:
                fields.write()
        progress.update(k, model.time)
        due = time.perf_counter() - last_checkpoint > case.output.checkpoint_interval
        if k < ft.rows and mpi_comm().bcast(due, root=0):  # rank 0's clock decides for all
            now = time.perf_counter()
            save_checkpoint(out_dir, model, {**state, "row": k, "z0": z0,
                                              "loading_before_s": state["loading_before_s"] + now - t_entry}, STATE)
            last_checkpoint = now
    progress.update(ft.rows, model.time, force=True)
    footing.velocity = np.zeros(3)
    grains = model.engine.global_particles()  # collective
    soil = None
    if model.solid is not None:
        coordinates, displacement = fe_nodes(model.solid)  # collective
        soil = None if fe_start is None else (coordinates, displacement - fe_start)
    if is_root():
        from de_domain.packing import save_packing
        save_packing(out_dir / "final_packing.npz", grains.pos, grains.radius)
    if fields is not None:
        fields.close()
    if rows is None:
        return None
    rows.close()
    plot_displacement_section(case, model, start_grains, grains, out_dir / "displacement_section.png", soil)
    return read_series(out_dir / "series.csv")


def seat_footing(model, area, pressure, interval, limit, name):
    """Move the footing (already on the highest grain under it, moving down) until its bearing
    pressure, averaged over ``interval`` seconds, reaches ``pressure``: the seating load, after
    which the settlement is counted. A loose grain on top of the surface carries almost nothing
    while it is pushed into the surface below it; the seating load skips that travel in both
    models alike. Returns {"pressure_Pa", "travel_m"}; collective. ``pressure`` = 0: no travel."""
    footing = model.footing
    z_contact = float(footing.vertices[:, 2].mean())
    q = 0.0
    while q < pressure:
        footing.reset_impulse()
        start = model.time
        model.advance(interval)
        q = footing.vertex_impulse.sum(axis=0)[2] / (model.time - start) / area
        if z_contact - float(footing.vertices[:, 2].mean()) > limit:
            raise RuntimeError(f"[{name}] the footing did not reach its seating pressure {pressure:.4g} Pa within "
                               f"the whole settlement {limit:.4g} m (it carries {q:.4g} Pa): lower "
                               "footing.seating_pressure")
    travel = z_contact - float(footing.vertices[:, 2].mean())
    if pressure > 0:
        say(f"[{name}] footing seated: q = {q / 1e3:.3f} kPa after {travel * 1e3:.3f} mm from the first contact "
            f"(seating pressure {pressure / 1e3:.3g} kPa); the settlement counts from here")
    return {"pressure_Pa": float(q), "travel_m": travel}


def resumed_model(case, case_path, out_dir, built, state):
    """The model at the last checkpoint of the loading: the DEM engine (grains, walls, footing,
    interface facets with their impulse) and, coupled, the FE soil on the prepared mesh with its
    state and the interface force in transit; collective."""
    engine = checkpointed_engine(case_path, out_dir, state, STATE)
    if case.footing.model == "dem":
        return Model("dem", engine, engine.facets[0], state["surface"])
    _, ids = _material_ids(case)
    solid, interface = build_soil(case, Geometry.of(case), ids["interface"], state["soil_density"],
                                  built["soil_mesh"])
    restore_fe(solid, interface, engine, case_path, out_dir)
    return Model("coupled", engine, engine.facets[0], state["surface"], solid, interface,
                 int(round(solid.dt / engine.dt)), state["soil_density"])


def fe_nodes(solid):
    """(coordinates, displacement) of every FE node, in mesh-input order, on rank 0 (None on
    the others); collective over the FE's ranks."""
    owned = slice(0, solid.n_owned_nodes)
    rows = np.hstack([solid.input_node_index[owned, None].astype(np.float64), solid.node_coordinates[owned],
                      solid.displacement[owned]])
    parts = solid.comm.gather(rows, root=0)
    if not is_root():
        return None, None
    rows = np.concatenate(parts)
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    return rows[:, 1:4], rows[:, 4:7]


def surface_under(footing, grains):
    """Top of the highest grain under the footing (its x range widened by each grain's radius), m."""
    x0, x1 = footing.vertices[:, 0].min(), footing.vertices[:, 0].max()
    under = (grains.pos[:, 0] + grains.radius > x0) & (grains.pos[:, 0] - grains.radius < x1)
    return float(np.max(grains.pos[under, 2] + grains.radius[under]))


# --------------------------------------------------------------------------- report
def bearing_pressure_at(series, levels=SETTLEMENT_LEVELS):
    """{s/B: q} interpolated in the series at each level it reaches."""
    s, q = series["settlement_ratio"], series["bearing_pressure"]
    reach = s[-1] + 0.5 * (s[-1] - s[-2]) if s.size > 1 else -1.0  # the last row, within half a row
    return {k: float(np.interp(k, s, q)) for k in levels if reach >= k}


def mean_bearing_pressure(series, span=None):
    """The mean of q over the rows with s/B in ``span`` (default MEAN_RANGE), or None when none is."""
    lo, hi = span or MEAN_RANGE
    s = series["settlement_ratio"]
    inside = (s >= lo) & (s <= hi + 1e-9)
    return float(np.mean(series["bearing_pressure"][inside])) if inside.any() else None


def _summary(case, model, n_grains, n_cells, specimen_info, rest, series, clock, compiling, seating):
    """The run's summary (rank 0; no collective in here). ``compiling``: seconds of one-time
    Numba/FFCx compilation inside the phases' wall-clock (none when the caches were warm)."""
    total = sum(clock.values())
    out = {"model": case.footing.model, "grains": n_grains, "ranks": mpi_comm().size,
           "dem_dt_s": model.engine.dt, "specimen": {k: v for k, v in specimen_info.items() if k != "generation_log"},
           "rest": rest, "seating": seating, "bearing_pressure_at": bearing_pressure_at(series),
           "mean_bearing_pressure": mean_bearing_pressure(series),
           "wall_clock_s": {**clock, "total_s": total, "compilation_s": compiling,
                            "total_without_compilation_s": total - compiling}}
    if model.solid is not None:
        out.update({"fe_dt_s": model.solid.dt, "subcycles": model.subcycles, "fe_cells": n_cells,
                    "interface_facets": len(model.interface.facets.triangles)})
    return out


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _plot_fe_face(ax, geometry, coordinates, displacement, top):
    """``|Δu|`` of the FE soil's front face (y = its smallest y), mm, filled contours over the
    face's nodes with the zone's trench left empty, on the colour scale 0 … ``top``."""
    from matplotlib.tri import Triangulation
    face = np.isclose(coordinates[:, 1], coordinates[:, 1].min(), rtol=0.0, atol=1e-9 * geometry.width)
    x, z = coordinates[face, 0], coordinates[face, 2]
    mesh = Triangulation(x, z)
    cx, cz = x[mesh.triangles].mean(axis=1), z[mesh.triangles].mean(axis=1)
    inside = (cx > geometry.zone_x0) & (cx < geometry.zone_x0 + geometry.zone_width) & (cz > geometry.zone_bottom)
    mesh.set_mask(inside)
    levels = np.linspace(0.0, top, 21)
    ax.tricontourf(mesh, np.clip(1e3 * np.linalg.norm(displacement[face], axis=1), 0.0, top), levels=levels,
                   cmap="viridis")


def plot_load_settlement(curves, path, title):
    """q against s/B for each model in ``curves`` ({label: series})."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, series in curves.items():
        ax.plot(100 * series["settlement_ratio"], series["bearing_pressure"] / 1e3, label=label)
    for level in SETTLEMENT_LEVELS:
        ax.axvline(100 * level, color="0.85", lw=0.8, zorder=0)
    ax.set_xlabel("settlement s / B [%]")
    ax.set_ylabel("bearing pressure q [kPa]")
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_displacement_section(case, model, before, after, path, soil=None):
    """The grains of the slice seen along y (an x–z section), coloured by ``|Δx|`` during the
    loading, and (coupled, ``soil`` = FE node coordinates and Δu) the FE soil's front face
    coloured by ``|Δu|`` on the same scale; the zone's outline and the footing drawn on top."""
    plt = _plt()
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle, Rectangle
    geometry = Geometry.of(case)
    disp = np.linalg.norm(after.pos - before, axis=1)
    top = 1e3 * float(np.percentile(disp, 99.5)) or 1.0
    order = np.argsort(after.pos[:, 1])  # front grains (small y) drawn last
    fig, ax = plt.subplots(figsize=(8.0, 8.0 * geometry.depth / geometry.width + 1.2))
    if soil is not None:
        _plot_fe_face(ax, geometry, *soil, top)
    circles = PatchCollection([Circle((after.pos[i, 0], after.pos[i, 2]), after.radius[i]) for i in order[::-1]],
                              cmap="viridis", linewidths=0)
    circles.set_array(1e3 * disp[order[::-1]])
    circles.set_clim(0.0, top)
    ax.add_collection(circles)
    label = "displacement during loading [mm]" if soil is not None else "grain displacement during loading [mm]"
    fig.colorbar(circles, ax=ax, label=label, shrink=0.8)
    ax.add_patch(Rectangle((0, 0), geometry.width, geometry.depth, fill=False, lw=1.0, color="0.3"))
    if model.kind == "coupled":
        ax.add_patch(Rectangle((geometry.zone_x0, geometry.zone_bottom), geometry.zone_width, geometry.zone_depth,
                               fill=False, lw=1.2, ls="--", color="tab:red", label="FE-DE interface"))
        ax.legend(loc="lower right")
    z = float(model.footing.vertices[:, 2].mean())
    ax.add_patch(Rectangle((0.5 * (geometry.width - geometry.footing_width), z), geometry.footing_width,
                           0.04 * geometry.depth, color="0.2"))
    ax.set_xlim(0, geometry.width)
    ax.set_ylim(0, geometry.depth * 1.08)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(f"{case.case.name} ({model.kind}): settlement {100 * case.footing.settlement:.0f} % of B")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def compare_models(case_dir, title):
    """When both models' series exist in ``case_dir``: ``comparison.csv`` (q of each at the
    SETTLEMENT_LEVELS and its mean over MEAN_RANGE, their difference; the wall-clocks without
    compilation in a comment line) and ``comparison.png``; prints the same as a table."""
    paths = {m: case_dir / m / "series.csv" for m in ("coupled", "dem")}
    summaries = {m: case_dir / m / "summary.json" for m in paths}
    if not all(p.exists() for p in [*paths.values(), *summaries.values()]):
        return None
    from cosim.lab.shear_report import read_series  # CSV -> dict of arrays
    curves = {m: read_series(p) for m, p in paths.items()}
    info = {m: json.loads(p.read_text()) for m, p in summaries.items()}
    q = {m: bearing_pressure_at(c) for m, c in curves.items()}
    rows = [(f"{level:g}", f"{100 * level:g} %", q["coupled"][level], q["dem"][level]) for level in SETTLEMENT_LEVELS
            if level in q["coupled"] and level in q["dem"]]
    means = {m: mean_bearing_pressure(c) for m, c in curves.items()}
    if means["coupled"] is not None and means["dem"] is not None:
        lo, hi = MEAN_RANGE
        rows.append((f"mean_{lo:g}-{hi:g}", f"mean {100 * lo:g}-{100 * hi:g} %", means["coupled"], means["dem"]))
    wall = {m: info[m]["wall_clock_s"] for m in info}
    warm = {m: w.get("total_without_compilation_s", w["total_s"]) for m, w in wall.items()}
    lines = ["settlement_ratio,q_coupled_Pa,q_dem_Pa,difference"]
    lines += [f"{key},{qc:.6g},{qd:.6g},{(qc - qd) / qd:.4f}" for key, _, qc, qd in rows]
    lines.append(f"# wall-clock without compilation, s: coupled {warm['coupled']:.1f}, dem {warm['dem']:.1f}, "
                 f"ratio {warm['dem'] / warm['coupled']:.2f}; grains: coupled {info['coupled']['grains']}, "
                 f"dem {info['dem']['grains']}")
    atomic_write_text(case_dir / "comparison.csv", "\n".join(lines) + "\n")
    plot_load_settlement({f"coupled ({info['coupled']['grains']} grains + FE)": curves["coupled"],
                          f"all-DEM ({info['dem']['grains']} grains)": curves["dem"]},
                         case_dir / "comparison.png", f"{title}: coupled against all-DEM")
    compiling = {m: w.get("compilation_s", 0.0) for m, w in wall.items()}
    say(comparison_table(title, [row[1:] for row in rows], info, warm, compiling, case_dir))
    return lines


def comparison_table(title, rows, info, warm, compiling, case_dir):
    """The coupled-against-all-DEM comparison as the aligned text a person reads at the end of a run."""
    out = [f"[{title}] coupled ({info['coupled']['grains']:,} grains + {info['coupled'].get('fe_cells', 0):,} FE "
           f"cells) against all-DEM ({info['dem']['grains']:,} grains): {case_dir / 'comparison.png'}",
           f"  {'s/B':>12}  {'q coupled [kPa]':>15}  {'q all-DEM [kPa]':>15}  {'difference':>10}"]
    out += [f"  {label:>12}  {qc / 1e3:>15.2f}  {qd / 1e3:>15.2f}  {100 * (qc - qd) / qd:>+9.1f} %"
            for label, qc, qd in rows]
    out.append(f"  wall-clock without compilation: coupled {warm['coupled']:.0f} s, all-DEM {warm['dem']:.0f} s "
               f"({warm['dem'] / warm['coupled']:.1f}x less for the coupled model)")
    out.append(f"  one-time compilation (Numba, FFCx; cached for later runs): {compiling['coupled']:.0f} s in the "
               f"coupled run, {compiling['dem']:.0f} s in the all-DEM run")
    return "\n".join(out)
