"""Case kind ``dem``: particles, materials and walls from a case file, run for a
duration, with CSV time series, ParaView frames, checkpoints and a progress line.

The DEM runs on MPI rank 0; other ranks wait (the DEM is not domain-decomposed yet).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cosim.case import resolve_path
from cosim.errors import CaseError
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    PvdCollection,
    is_root,
    mpi_comm,
    save_engine_checkpoint,
    say,
    write_run_metadata,
)

CHECKPOINT = "checkpoint.npz"
PROGRESS_CHUNK = 200  # steps between checks of the progress line and checkpoint clock


def prepare(case, case_path):
    """Read/generate the particles and walls; every input failure is a CaseError."""
    dem = case.dem
    names = [m.name for m in dem.materials]
    p = dem.particles
    if p.source == "file":
        from de_domain.packing import load_packing
        try:
            positions, radii = load_packing(resolve_path(case_path, p.file))
        except Exception as exc:
            raise CaseError(case_path, "dem.particles.file", p.file, f"could not read the packing: {exc}") from None
    else:
        from de_domain.packing import random_cloud
        rng = np.random.default_rng(case.case.seed)
        radii = rng.uniform(p.radius[0], p.radius[1], p.count)
        try:
            positions, radii = random_cloud(radii, p.box[0], p.box[1], seed=case.case.seed)
        except ValueError as exc:
            raise CaseError(case_path, "dem.particles.count", p.count, str(exc)) from None
    if len(radii) == 0 or np.any(radii <= 0):
        raise CaseError(case_path, "dem.particles", len(radii), "need at least one sphere, all radii > 0")
    facets = {}
    for i, w in enumerate(dem.walls):
        if w.type == "facets":
            from de_domain import FacetMesh
            try:
                facets[i] = FacetMesh.from_file(resolve_path(case_path, w.file), material=names.index(w.material))
            except Exception as exc:
                raise CaseError(case_path, f"dem.walls[{i}].file", w.file,
                                f"could not read the triangle mesh: {exc}") from None
    return {"positions": positions, "radii": radii, "facets": facets}


def build_engine(case, built, extra_facets=()):
    from de_domain import Engine, Material, Particles, PlaneWall
    dem = case.dem
    names = [m.name for m in dem.materials]
    materials = [Material(**{k: v for k, v in m.model_dump().items() if k != "name"}) for m in dem.materials]
    mat_ids = np.full(len(built["radii"]), names.index(dem.particles.material), np.int32)
    velocities = np.tile(np.asarray(dem.particles.velocity, float), (len(built["radii"]), 1))
    particles = Particles.from_spheres(built["positions"], built["radii"], mat_ids, materials, velocities=velocities)
    walls, facets = [], []
    for i, w in enumerate(dem.walls):
        if w.type == "plane":
            walls.append(PlaneWall(w.point, w.normal, material=names.index(w.material), velocity=w.velocity))
        else:
            mesh = built["facets"][i]
            mesh.velocity = np.asarray(w.velocity, float)
            facets.append(mesh)
    return Engine(particles, materials, walls=walls, facets=facets + list(extra_facets), contact_law=dem.contact_law,
                  gravity=dem.gravity, dt=case.time.dt, safety_factor=case.time.safety_factor,
                  local_damping=dem.local_damping, viscous_damping=dem.viscous_damping)


def run(case, resolved, case_path, out_dir, resume=False):
    out_dir = Path(out_dir)
    if is_root():
        built = prepare(case, case_path)
        _run_root(case, resolved, case_path, out_dir, built, resume)
    mpi_comm().Barrier()


def _run_root(case, resolved, case_path, out_dir, built, resume):
    from de_domain import Engine, diagnostics
    from de_domain.io import write_frame

    checkpoint = out_dir / CHECKPOINT
    if resume:
        if not checkpoint.exists():
            raise CaseError(case_path, "--resume", str(checkpoint),
                            "no checkpoint in the output folder; run without --resume")
        engine = Engine.load_checkpoint(checkpoint)
    else:
        engine = build_engine(case, built)
    write_run_metadata(out_dir, case_path, resolved, case.case.seed)

    total = case.time.steps or int(np.ceil(case.time.duration / engine.dt))
    interval = case.output.interval or total * engine.dt / 20
    every = max(1, int(round(interval / engine.dt)))
    say(f"[{case.case.name}] {engine.particles.n} spheres, dt = {engine.dt:.3e} s "
        f"(critical {engine.critical_timestep():.3e} s), {total} steps, output every {every} steps")

    energy_keys = list(engine.energy())
    series = CsvSeries(out_dir / "series.csv",
                       ["time", "step", "unbalanced_force_ratio", "coordination_number", *energy_keys],
                       resume_time=engine.time if resume else None)
    frames = PvdCollection(out_dir / "particles.pvd", engine.time if resume else None)
    progress = ProgressLine(case.case.name, total, case.output.progress_interval, first_step=engine.step_count)
    last_checkpoint = time.perf_counter()

    def record():
        e = engine.energy()
        series.append([engine.time, engine.step_count, diagnostics.unbalanced_force_ratio(engine),
                       diagnostics.coordination_number(engine), *[e[k] for k in energy_keys]])
        if case.output.vtk:
            frames.add(engine.time, write_frame(out_dir / "frames", engine, engine.step_count))

    if not resume:
        record()
    while engine.step_count < total:
        engine.run(min(every - engine.step_count % every, total - engine.step_count, PROGRESS_CHUNK))
        if engine.step_count % every == 0 or engine.step_count == total:
            record()
        progress.update(engine.step_count, engine.time)
        if time.perf_counter() - last_checkpoint > case.output.checkpoint_interval:
            save_engine_checkpoint(engine, checkpoint)
            last_checkpoint = time.perf_counter()
    progress.update(engine.step_count, engine.time, force=True)
    save_engine_checkpoint(engine, checkpoint)
    series.close()
    from de_domain.packing import save_packing
    p = engine.particles
    save_packing(out_dir / "final_packing.npz", p.pos[:p.n_owned], p.radius[:p.n_owned], time=engine.time)
    from cosim.plots import plot_panels
    plot_panels(out_dir / "series.csv", "time", [
        ("kinetic energy [J]", ["kinetic"], True),
        ("unbalanced force ratio [-]", ["unbalanced_force_ratio"], True),
        ("coordination number [-]", ["coordination_number"], False),
        ("energy [J]", ["dissipated", "work", "residual"], False),
    ], out_dir / "series.png", title=case.case.name)
    e = engine.energy()
    scale = max(abs(e["dissipated"]) + abs(e["work"]), 1e-300)
    say(f"[{case.case.name}] done: t = {engine.time:.4e} s, kinetic energy {e['kinetic']:.3e} J, "
        f"energy balance residual {e['residual']:.3e} J "
        f"({100 * abs(e['residual']) / scale:.2f} % of work + dissipation)")

