"""Case kind ``dem``: particles, materials and walls from a case file, run for a
duration, with CSV time series, ParaView frames, checkpoints and a progress line.

Under ``mpirun -n N`` (N > 1) the DEM is distributed over the ranks (``Engine(comm=...)``,
bit-identical to a serial run); rank 0 writes every output (CSV series, ParaView frames,
final packing, plots, checkpoints) from the gathered/global state. A given time step
is checked against the critical step before the run, and a packing
file for NaN/inf values, lengths and initial overlaps.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from cosim.case.messages import warn
from cosim.case.paths import resolve_path
from cosim.errors import CaseError, RunFailed
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    PvdCollection,
    mpi_comm,
    resume_row_missing,
    save_engine_checkpoint,
    say,
    write_run_metadata,
)

CHECKPOINT = "checkpoint.npz"
PROGRESS_CHUNK = 200  # steps between checks of the progress line and checkpoint clock


MAX_STEPS = 10**9  # a longer run is a typo (a duration in ms written in s), not a plan
OVERLAP_WARNING = 0.05  # initial overlaps above this fraction of the smaller radius are reported
ENERGY_WARNING = 0.05  # an energy balance residual above this fraction of work + dissipation is reported
#: ``series.csv``: these columns, then every term of ``Engine.energy()`` in its order (J; docs/reference/outputs.md)
SERIES_COLUMNS = ("time", "step", "unbalanced_force_ratio", "coordination_number")


def prepare(case, case_path, out_dir, resume):
    """The engine, built from the case (or loaded from the checkpoint to resume), with its
    time step checked. Serial (one rank): as ever. Under ``mpirun -n N`` (N > 1),
    collective: rank 0 reads the inputs and sends them to every rank, and every rank
    builds its share of the distributed engine (``comm``)."""
    comm = mpi_comm()
    distributed = comm if comm.size > 1 else None
    if resume:
        return load_checkpoint(case_path, Path(out_dir) / CHECKPOINT, comm=distributed)
    if distributed is None:
        built = read_inputs(case, case_path)
    else:
        from cosim.apps import on_root
        built = comm.bcast(on_root(comm, lambda: read_inputs(case, case_path)), root=0)
    engine = build_engine(case_path, case, built, comm=distributed)
    check_time_step(case_path, case.time, engine)  # collective when distributed (critical step)
    return engine


def load_checkpoint(case_path, checkpoint, comm=None):
    """The engine saved in ``checkpoint`` (serial or distributed, with ``comm``: over its
    ranks, from a checkpoint of any rank count)."""
    from de_domain import Engine
    if not checkpoint.exists():
        raise CaseError(case_path, "--resume", str(checkpoint),
                        "no checkpoint in the output folder; run without --resume")
    try:
        return Engine.load_checkpoint(checkpoint, comm=comm)
    except Exception as exc:
        raise CaseError(checkpoint, "<checkpoint>", checkpoint.name, f"cannot be read ({exc}); run without --resume") \
            from None


def read_inputs(case, case_path):
    """Read/generate the spheres and read the facet meshes; every input failure is a CaseError."""
    dem = case.dem
    names = [m.name for m in dem.materials]
    p = dem.particles
    clumps = None
    if p.grains == "clumps":
        clumps = place_clumps(case, case_path)
        positions, radii = clumps.centres, clumps.scale
    elif p.source == "file":
        positions, radii = read_packing(case_path, "dem.particles.file", p.file)
    else:
        from de_domain.packing import random_cloud
        rng = np.random.default_rng(case.case.seed)
        radii = rng.uniform(p.radius[0], p.radius[1], p.count)
        try:
            positions, radii = random_cloud(radii, p.box[0], p.box[1], seed=case.case.seed)
        except ValueError as exc:
            raise CaseError(case_path, "dem.particles.count", p.count, str(exc)) from None
    facets = {}
    for i, w in enumerate(dem.walls):
        if w.type == "facets":
            from de_domain import FacetMesh
            try:
                facets[i] = FacetMesh.from_file(resolve_path(case_path, w.file), material=names.index(w.material))
            except Exception as exc:
                raise CaseError(case_path, f"dem.walls[{i}].file", w.file,
                                f"could not read the triangle mesh: {exc}") from None
    return {"positions": positions, "radii": radii, "facets": facets, "clumps": clumps}


def place_clumps(case, case_path):
    """``count`` grains of the [[dem.clumps]] shapes (drawn by share), each scaled to an equal-volume
    radius drawn uniformly from ``radius``, at random non-overlapping places in ``box`` (their
    enclosing spheres do not overlap) in random orientations (``de_domain.clumps.clump_cloud``)."""
    from cosim.case.validation import clump_templates
    from de_domain.clumps import clump_cloud
    p = case.dem.particles
    rng = np.random.default_rng(case.case.seed)
    templates = clump_templates(case_path, case.dem)
    share = np.array([t.share for t in case.dem.clumps])
    template_of = rng.choice(len(templates), size=p.count, p=share / share.sum())
    size = rng.uniform(p.radius[0], p.radius[1], p.count)
    try:
        return clump_cloud(templates, template_of, 2.0 * size, p.box[0], p.box[1], case.case.seed, rng)
    except ValueError as exc:
        raise CaseError(case_path, "dem.particles.count", p.count, f"{exc} (each grain's enclosing sphere)") from None


def read_packing(case_path, key, name):
    """(positions, radii) of the packing file ``name`` named by ``key``; its initial
    overlaps above OVERLAP_WARNING of the smaller radius are reported once."""
    from de_domain.packing import load_packing
    try:
        positions, radii = load_packing(resolve_path(case_path, name))
    except Exception as exc:
        raise CaseError(case_path, key, name, f"could not read the packing: {exc}") from None
    warn_overlaps(case_path, key, name, positions, radii)
    return positions, radii


def warn_overlaps(case_path, key, name, positions, radii):
    from scipy.spatial import cKDTree
    pairs = cKDTree(positions).query_pairs(2.0 * float(radii.max()), output_type="ndarray")
    if len(pairs) == 0:
        return
    i, j = pairs[:, 0], pairs[:, 1]
    overlap = (radii[i] + radii[j] - np.linalg.norm(positions[i] - positions[j], axis=1)) / np.minimum(radii[i],
                                                                                                      radii[j])
    large = overlap > OVERLAP_WARNING
    if np.any(large):
        warn(case_path, key, name, f"{int(large.sum())} sphere pair(s) overlap by more than "
                                   f"{100 * OVERLAP_WARNING:.0f} % of the smaller radius (largest "
                                   f"{100 * overlap.max():.0f} %): they push apart at the start")


def check_time_step(case_path, time_section, engine):
    """A given Δt must not exceed the critical step (docs/design.md §2.14); above half of
    it a warning; and the run must have a sensible number of steps."""
    critical = engine.critical_timestep()
    dt = time_section.dt
    if dt is not None and dt > critical:
        raise CaseError(case_path, "time.dt", dt,
                        f"{dt / critical:.3g} x the critical step {critical:.4g} s of these spheres "
                        f"(docs/design.md §2.14); the explicit step would diverge. Give dt <= "
                        f"{0.5 * critical:.4g} s, or omit it for time.safety_factor x critical")
    if dt is not None and dt > 0.5 * critical:
        warn(case_path, "time.dt", dt, f"{dt / critical:.2f} x the critical step {critical:.4g} s: close to the "
                                       "stability limit with many contacts per sphere")
    check_steps(case_path, time_section, engine.dt)


def check_steps(case_path, time_section, dt):
    """The run length in steps of ``dt`` is at most MAX_STEPS."""
    if time_section.duration is not None and time_section.duration / dt > MAX_STEPS:
        raise CaseError(case_path, "time.duration", time_section.duration,
                        f"{time_section.duration / dt:.3g} steps of dt = {dt:.4g} s; at most {MAX_STEPS:.0e} "
                        "steps per run")


def build_engine(case_path, case, built, extra_facets=(), comm=None):
    """The Engine of the case's [dem] section and the ``built`` inputs (read_inputs);
    with ``comm``, distributed over its ranks (collective; the same ``built`` on every rank).
    Fewer particles than ranks cannot be decomposed: a CaseError on every rank alike."""
    n = len(built["radii"])
    if comm is not None and n < comm.size:
        source = "file" if case.dem.particles.file else "count"
        raise CaseError(case_path, f"dem.particles.{source}", n,
                        f"{n} particle(s) cannot be spread over {comm.size} MPI ranks (each rank owns a slab of "
                        f"particles); run with at most {n} ranks (mpirun -n {max(n, 1)}) or without mpirun")
    try:
        return _engine(case, built, extra_facets, comm)
    except ValueError as exc:  # the de_domain constructors check their own inputs
        raise CaseError(case_path, "dem", "[dem]", str(exc)) from None


def materials_of(dem, *names):
    """The de_domain Materials of [[dem.materials]] in their order (a material's id is its
    index), followed by the ids of the given material ``names``."""
    from de_domain import Material
    materials = [Material(**{k: v for k, v in m.model_dump().items() if k != "name"}) for m in dem.materials]
    order = [m.name for m in dem.materials]
    return (materials, *(order.index(n) for n in names))


def _engine(case, built, extra_facets, comm=None):
    from de_domain import Engine, Particles, PlaneWall
    from de_domain.clumps import Clumps
    dem = case.dem
    names = [m.name for m in dem.materials]
    materials = materials_of(dem)[0]
    mat_ids = np.full(len(built["radii"]), names.index(dem.particles.material), np.int32)
    velocities = np.tile(np.asarray(dem.particles.velocity, float), (len(built["radii"]), 1))
    clumps = None
    if built.get("clumps") is not None:
        c = built["clumps"]
        particles, clumps = Clumps.place(c.templates, c.template_of, c.centres, c.orientations, materials,
                                         material_of=mat_ids, velocities=velocities, scales=c.scale)
    else:
        particles = Particles.from_spheres(built["positions"], built["radii"], mat_ids, materials,
                                           velocities=velocities)
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
                  local_damping=dem.local_damping, viscous_damping=dem.viscous_damping, comm=comm, clumps=clumps)


def run(prepared):
    """The DEM: on every rank when distributed (``mpirun -n N``, N > 1), alone otherwise;
    rank 0 writes the outputs."""
    case = prepared.case
    write_run_metadata(prepared.out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    if prepared.built is not None:
        _run_engine(case, prepared.built, prepared.out_dir, prepared.resume)
    mpi_comm().Barrier()


def advance(engine, nsteps):
    """``engine.run(nsteps)``. A distributed engine checks for a diverged state
    collectively (de_domain.distributed.check_finite) and raises the same
    FloatingPointError on every rank: a RunFailed, which rank 0 reports once."""
    try:
        engine.run(nsteps)
    except FloatingPointError as exc:
        if engine.domain is None:
            raise
        raise RunFailed(str(exc)) from None


def _run_engine(case, engine, out_dir, resume):
    """The run loop; collective when the engine is distributed (every rank calls it), with
    the files written on rank 0 only."""
    from de_domain import diagnostics
    from de_domain.io import write_frame

    comm = engine.domain.comm if engine.domain is not None else None
    root = comm is None or comm.rank == 0
    n_particles = engine.domain.n_global if comm is not None else engine.particles.n
    checkpoint = out_dir / CHECKPOINT
    total = case.time.steps or int(np.ceil(case.time.duration / engine.dt))
    interval = case.output.interval or total * engine.dt / 20
    every = max(1, int(round(interval / engine.dt)))
    critical = engine.critical_timestep()  # collective when distributed
    ranks = f" on {comm.size} MPI ranks" if comm is not None else ""
    clumps = engine.clumps.count
    grains = f"{clumps} clumps of {n_particles} spheres" if clumps else f"{n_particles} spheres"
    say(f"[{case.case.name}] {grains}{ranks}, dt = {engine.dt:.3e} s "
        f"(critical {critical:.3e} s), {total} steps, output every {every} steps")

    energy_keys = list(engine.energy())
    series = frames = None
    # on resume, the row of the checkpoint's instant is the file's if it is an output step (a final
    # row off the output grid is dropped): not computed again from the loaded state, whose last-step
    # contacts are unknown after a resume over another rank count (cosim.outputs.CsvSeries)
    output_instant = engine.step_count % every == 0
    if root:
        series = CsvSeries(out_dir / "series.csv",
                           [*SERIES_COLUMNS, *energy_keys],
                           resume_time=engine.time if resume else None, keep_resume_instant=output_instant)
        frames = PvdCollection(out_dir / "particles.pvd", engine.time if resume else None,
                               keep_resume_instant=output_instant)
    progress = ProgressLine(case.case.name, total, case.output.progress_interval, first_step=engine.step_count)
    last_checkpoint = time.perf_counter()

    def record():
        e = engine.energy()  # the diagnostics and frames are collective when distributed
        row = [engine.time, engine.step_count, diagnostics.unbalanced_force_ratio(engine),
               diagnostics.coordination_number(engine), *[e[k] for k in energy_keys]]
        paths = write_frame(out_dir / "frames", engine, engine.step_count) if case.output.vtk else None
        if root:
            series.append(row)
            if paths is not None:
                frames.add(engine.time, paths)

    def checkpoint_due():  # rank 0's clock decides for every rank
        due = time.perf_counter() - last_checkpoint > case.output.checkpoint_interval
        return comm.bcast(due, root=0) if comm is not None else due

    if not resume or resume_row_missing(series, output_instant, comm):
        record()
    while engine.step_count < total:
        advance(engine, min(every - engine.step_count % every, total - engine.step_count, PROGRESS_CHUNK))
        if engine.step_count % every == 0 or engine.step_count == total:
            record()
        progress.update(engine.step_count, engine.time)
        if checkpoint_due():
            save_engine_checkpoint(engine, checkpoint)
            last_checkpoint = time.perf_counter()
    progress.update(engine.step_count, engine.time, force=True)
    save_engine_checkpoint(engine, checkpoint)
    particles = engine.global_particles()  # collective when distributed; all, in global-id order
    e = engine.energy()
    if not root:
        return
    series.close()
    from de_domain.packing import save_packing
    mine = particles.owned
    save_packing(out_dir / "final_packing.npz", particles.pos[mine], particles.radius[mine], time=engine.time)
    if engine.clumps.count:  # the grains the spheres make up: which clump each is in, the clumps' state
        np.savez(out_dir / "final_clumps.npz", **engine.clumps.arrays())
    from cosim.plots import plot_panels
    plot_panels(out_dir / "series.csv", "time", [
        ("kinetic energy [J]", ["kinetic"], True),
        ("unbalanced force ratio [-]", ["unbalanced_force_ratio"], True),
        ("coordination number [-]", ["coordination_number"], False),
        ("energy [J]", ["dissipated", "work", "residual"], False),
    ], out_dir / "series.png", title=case.case.name)
    scale = max(abs(e["dissipated"]) + abs(e["work"]), 1e-300)
    say(f"[{case.case.name}] done: t = {engine.time:.4e} s, kinetic energy {e['kinetic']:.3e} J, "
        f"energy balance residual {e['residual']:.3e} J "
        f"({100 * abs(e['residual']) / scale:.2f} % of work + dissipation)")
    if abs(e["residual"]) > ENERGY_WARNING * scale:
        say(f"cosim: warning: [{case.case.name}] the energy balance is off by {100 * abs(e['residual']) / scale:.0f} % "
            "of work + dissipation (docs/design.md §2.15): the time step is likely too large for these contacts; "
            "try a smaller time.dt or time.safety_factor", file=sys.stderr)
