"""Case kind ``coupled``: an FE solid and DEM particles that touch through a tagged
FE boundary (docs/design.md §5), under ``mpirun -n N``: the DEM distributed over all ranks
(bit-identical to a serial one for the same interface motion); the FE either replicated,
every rank stepping the whole mesh (``coupling.fe_partition = "replicated"``, the default: no
FE messages, and the whole run bit-identical to one rank's), or partitioned over the ranks
(``"distributed"``, for FE meshes whose step costs more than a rank's share of the DEM step).

Per FE step (the coupling schedule, docs/design.md §5.3):

  1. the FE advances v^{n+½}, u^{n+1} with the interface force of the last window;
  2. the interface vertices start at X + u^n and move with v^{n+½};
  3. the DEM runs ``subcycles`` steps against them, accumulating the impulse per FE node;
  4. interface force for the next FE step = impulse / Δt_FE.

Δt_FE = subcycles × Δt_DE, both within their stability limits.

Outputs: ``series.csv`` (interface force, mean interface displacement, linear momentum
of FE, DEM and the impulse in transit — conserved when no external force acts — and the
DEM diagnostics), its PNG, ``fields.xdmf`` (FE, with the interface traction f_a / A_a),
``particles.pvd`` (particles and the interface facets).
"""
from __future__ import annotations

import hashlib
import math
import time
from pathlib import Path

import numpy as np

from cosim.apps import dem as dem_app
from cosim.apps import fe as fe_app
from cosim.apps import on_root
from cosim.compiled_coupling import CoupledStepper
from cosim.interface import Interface
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    PvdCollection,
    commit_checkpoint,
    is_root,
    mpi_comm,
    resume_row_missing,
    save_engine_checkpoint,
    say,
    staged,
    write_run_metadata,
)
from de_domain.comm import sum_in_rank_order
from de_domain.diagnostics import linear_momentum

PROGRESS_CHUNK = 50  # FE steps between checks of the progress line (on one rank: in one compiled call)

COLUMNS = ["time", "fe_step", "interface_force_x", "interface_force_y", "interface_force_z",
           "interface_displacement_z", "momentum_fe_x", "momentum_fe_y", "momentum_fe_z",
           "momentum_dem_x", "momentum_dem_y", "momentum_dem_z", "impulse_in_transit_x",
           "impulse_in_transit_y", "impulse_in_transit_z", "momentum_total_x", "momentum_total_y",
           "momentum_total_z", "unbalanced_force_ratio", "coordination_number"]


FE_CHECKPOINT_STEM = "checkpoint.fe"


def dem_checkpoint_path(out_dir):
    """The DEM checkpoint: one file for all ranks."""
    return Path(out_dir) / "checkpoint.npz"


def fe_checkpoint_path(out_dir, solid):
    """This rank's part of the FE checkpoint, named by the FE's communicator (a replicated FE is
    one part, ``rank0of1``, as on one rank)."""
    return Path(out_dir) / f"{FE_CHECKPOINT_STEM}.rank{solid.comm.rank}of{solid.comm.size}.npz"


def writes_fe_files(solid):
    """Whether this rank writes the FE's files (its checkpoint part, the XDMF fields): every rank
    when the FE is partitioned over all, rank 0 alone when every rank holds the whole FE."""
    return solid.comm.size == mpi_comm().size or is_root()


def fe_communicator(fe_partition):
    """The FE's communicator: all ranks (``fe_partition = "distributed"``), or this rank alone
    (``"replicated"``: every rank builds and steps the whole mesh)."""
    from mpi4py import MPI
    return mpi_comm() if fe_partition == "distributed" else MPI.COMM_SELF


def fe_layout(solid):
    """How the FE lies on the ranks, for the run's first line ("" on one rank)."""
    ranks = mpi_comm().size
    if ranks == 1:
        return ""
    return f", DEM on {ranks} MPI ranks, FE " + ("partitioned over them" if solid.comm.size == ranks
                                                 else "on each (replicated)")


def check_replicas(solid):
    """A replicated FE: every rank must have meshed the same nodes and cells (gmsh and DOLFINx
    are deterministic; this guards the DEM, which sees the interface facets of each rank's
    mesh); collective."""
    comm = mpi_comm()
    if solid.comm.size == comm.size:
        return
    digest = hashlib.sha256(solid.node_coordinates.tobytes())
    digest.update(solid.input_node_index.tobytes())
    digest.update(solid.mesh.geometry.dofmap.array.tobytes())
    if len(set(comm.allgather(digest.hexdigest()))) > 1:
        raise RuntimeError("the replicated FE mesh differs between the ranks; set fe_partition = 'distributed' "
                           "(coupling.fe_partition, or soil.fe_partition of a footing case)")


def prepare(case, case_path, out_dir, resume):
    """The FE solid (replicated or partitioned, ``fe_communicator``), the interface, the DEM
    engine (distributed when there are several ranks) and the two time steps, each within its
    stability limit; or, to resume, the FE and DEM states from the checkpoints; collective."""
    from cosim.errors import CaseError
    comm = mpi_comm()
    dem_checkpoint = dem_checkpoint_path(out_dir)
    if resume and comm.allgather(dem_checkpoint.exists()).count(False):
        raise CaseError(case_path, "--resume", str(dem_checkpoint),
                        "no coupled checkpoint in the output folder; run without --resume")
    solid = fe_app.build_solid(case, case_path, fe_communicator(case.coupling.fe_partition))
    check_replicas(solid)
    material = [m.name for m in case.dem.materials].index(case.coupling.material)
    interface = Interface(solid, case.coupling.interface, material, case.coupling.smoothing_time)
    fe_step = fe_stable_step(case.time, solid)
    distributed = comm if comm.size > 1 else None
    if resume:
        state = fe_app.restore_checkpoint(solid, case_path, out_dir, FE_CHECKPOINT_STEM)
        if "interface_held" in state:  # (before the last window's impulse joined it; absent: none)
            interface.held[:] = state["interface_held"]
        engine = dem_app.load_checkpoint(case_path, dem_checkpoint, comm=distributed)
        if abs(engine.time - solid.time) > 0.5 * engine.dt:  # files of two runs mixed by hand
            raise CaseError(case_path, "--resume", str(dem_checkpoint),
                            f"the DEM checkpoint (t = {engine.time:.6e} s) and the FE checkpoint (t = "
                            f"{solid.time:.6e} s) are of different instants; run without --resume")
        interface.facets = engine.facets[-1]  # the interface is the last facet mesh (build_engine)
        n_sub = int(round(solid.dt / engine.dt))
        engine.keep_sorted = True  # one DEM window per FE step: the sorted copies stay between windows
        engine.wall_forces_each_run = False  # nothing reads them between windows (checkpoints update them)
        return {"solid": solid, "interface": interface, "engine": engine, "subcycles": n_sub}
    built = comm.bcast(on_root(comm, lambda: dem_app.read_inputs(case, case_path)), root=0)
    engine = dem_app.build_engine(case_path, case, built, extra_facets=[interface.facets], comm=distributed)
    fe_dt, dem_dt, n_sub = time_steps(engine.dt, fe_step, case.coupling.subcycles)
    solid.dt = fe_dt
    engine.dt = dem_dt
    dem_app.check_steps(case_path, case.time, fe_dt)
    engine.keep_sorted = True
    engine.wall_forces_each_run = False
    return {"solid": solid, "interface": interface, "engine": engine, "subcycles": n_sub}


def save_checkpoint(out_dir, solid, engine, interface):
    """The DEM (one file, collective) and the FE state (``fe_checkpoint_path``), committed together
    (:func:`cosim.outputs.commit_checkpoint`); collective."""
    commit_checkpoint(out_dir, stage_checkpoint(out_dir, solid, engine, interface))


def stage_checkpoint(out_dir, solid, engine, interface):
    """Write the DEM checkpoint (collective) and this rank's part of the FE state (if it writes one,
    ``writes_fe_files``) to their staged files; returns this rank's files by their final names,
    for the commit. The impulse in transit is
    the interface facets' vertex impulse in the DEM file, and the impulse held back by the
    smoothing (before that window's joined it) in the FE files; the FE's interface force is made
    again from the two on resume."""
    dem_checkpoint = dem_checkpoint_path(out_dir)
    save_engine_checkpoint(engine, staged(dem_checkpoint))
    finals = [dem_checkpoint] if is_root() else []
    if writes_fe_files(solid):
        fe_checkpoint = fe_checkpoint_path(out_dir, solid)
        fe_app.write_checkpoint(solid, staged(fe_checkpoint), extra={"interface_held": interface.held_before})
        finals.append(fe_checkpoint)
    return finals


def fe_stable_step(time, solid):
    """The FE's largest step (s): ``time.fe_safety_factor`` × its exact limit 2/ω_max where the
    case gives that factor (:meth:`fe_domain.explicit.ExplicitSolid.refine_critical_step`, which
    also makes the solid accept steps up to that limit: call it before restoring a checkpoint),
    else ``time.safety_factor`` × the cell estimate min h/c_p (docs/design.md §4.6). Collective."""
    if time.fe_safety_factor is None:
        return time.safety_factor * solid.dt_critical
    return time.fe_safety_factor * solid.refine_critical_step()


def time_steps(dem_dt, fe_dt_stable, subcycles=None):
    """(Δt_FE, Δt_DE, n): Δt_FE = n Δt_DE with Δt_DE ≤ its stable step and Δt_FE ≤ the FE's."""
    n = subcycles or max(1, math.floor(fe_dt_stable / dem_dt))
    fe_dt = min(fe_dt_stable, n * dem_dt)
    return fe_dt, fe_dt / n, n


def run(prepared):
    case, out_dir, resume = prepared.case, prepared.out_dir, prepared.resume
    solid, interface, engine = (prepared.built[k] for k in ("solid", "interface", "engine"))
    fe_dt, n_sub = solid.dt, prepared.built["subcycles"]
    dem_dt = engine.dt
    write_run_metadata(out_dir, prepared.case_path, prepared.resolved, case.case.seed)

    total = case.time.steps or int(math.ceil(case.time.duration / fe_dt))
    interval = case.output.interval or total * fe_dt / 20
    every = max(1, int(round(interval / fe_dt)))
    say(f"[{case.case.name}] FE dt = {fe_dt:.3e} s, DEM dt = {dem_dt:.3e} s ({n_sub} DEM steps per FE step), "
        f"{total} FE steps, output every {every}{fe_layout(solid)}")

    # on resume, the row of the checkpoint's instant is the file's if it is an output step (as in
    # an uninterrupted run; a final row off the output grid is dropped): not computed again from
    # the loaded state, whose last-step contacts are unknown after a resume over another rank count
    resume_time = solid.time if resume else None
    output_instant = solid.step_count % every == 0
    series = CsvSeries(out_dir / "series.csv", COLUMNS, resume_time, keep_resume_instant=output_instant) \
        if is_root() else None
    frames = PvdCollection(out_dir / "particles.pvd", resume_time, keep_resume_instant=output_instant) \
        if is_root() and case.output.vtk else None
    from fe_domain.output import FieldWriter
    fields = FieldWriter(solid, out_dir / ("fields_from_step%d" % solid.step_count if resume else "fields"),
                         extra_fields=[interface.traction_field]) if writes_fe_files(solid) else None
    progress = ProgressLine(case.case.name, total, case.output.progress_interval, first_step=solid.step_count)
    if resume:
        interface.receive_forces(solid.dt)  # the interface force in transit, from the saved impulse
        say(f"[{case.case.name}] resumed at FE step {solid.step_count} (t = {solid.time:.4e} s)")
    if not resume or resume_row_missing(series, output_instant, mpi_comm()):
        record(solid, engine, interface, series, frames, out_dir, case.output.vtk)
    last_checkpoint = time.perf_counter()
    stepper = CoupledStepper(solid, engine, interface, n_sub)
    while solid.step_count < total:
        stepper.run(min(PROGRESS_CHUNK, every - solid.step_count % every, total - solid.step_count), coupled_step)
        if solid.step_count % every == 0 or solid.step_count == total:
            record(solid, engine, interface, series, frames, out_dir, case.output.vtk)
            if fields is not None:
                fields.write()
        progress.update(solid.step_count, solid.time)
        if mpi_comm().bcast(time.perf_counter() - last_checkpoint > case.output.checkpoint_interval, root=0):
            save_checkpoint(out_dir, solid, engine, interface)
            last_checkpoint = time.perf_counter()
    progress.update(solid.step_count, solid.time, force=True)
    save_checkpoint(out_dir, solid, engine, interface)
    if fields is not None:
        fields.close()
    if series is not None:
        series.close()
        from cosim.plots import plot_panels
        plot_panels(out_dir / "series.csv", "time", [
            ("interface force z [N]", ["interface_force_z"], False),
            ("mean interface u_z [m]", ["interface_displacement_z"], False),
            ("FE + DEM + transit momentum [N s]\n(constant without gravity/walls)",
             ["momentum_total_x", "momentum_total_y", "momentum_total_z"], False),
            ("unbalanced force ratio [-]", ["unbalanced_force_ratio"], True)],
            out_dir / "series.png", title=case.case.name)
        plot_panels(out_dir / "series.csv", "interface_displacement_z", [
            ("interface force z [N]", ["interface_force_z"], False)], out_dir / "load_settlement.png",
            title=f"{case.case.name}: load against mean interface displacement [m]")
    say(f"[{case.case.name}] done: t = {solid.time:.4e} s")


def coupled_step(solid, engine, interface, subcycles):
    """One FE step and its DEM window, docs/design.md §5.3, steps 1–4, from Python (several
    ranks; :class:`cosim.compiled_coupling.CoupledStepper` runs many in one compiled call on one)."""
    solid.step()
    interface.send_motion()
    dem_app.advance(engine, subcycles)
    interface.receive_forces(solid.dt)


def momentum(solid, engine, interface):
    """Linear momentum (N s) of the FE nodes, of the grains (spheres and clumps,
    :func:`de_domain.diagnostics.linear_momentum`) and of the impulse in transit (each summed over
    the ranks that hold a part of it)."""
    owned = slice(0, solid.n_owned_nodes)
    fe = sum_in_rank_order(solid.comm, np.sum(solid.mass.reshape(-1, 3)[owned] * solid.velocity[owned], axis=0))
    return fe, linear_momentum(engine), interface.pending_impulse()


def record(solid, engine, interface, series, frames, out_dir, vtk):
    fe_app.check_finite(solid)
    fe, de, transit = momentum(solid, engine, interface)
    nodes = interface.owned_nodes
    uz = solid.comm.allreduce(float(np.sum(solid.displacement[nodes, 2])))
    count = solid.comm.allreduce(len(nodes))
    from de_domain import diagnostics
    from de_domain.io import write_frame
    force = interface.facets.vertex_impulse.sum(axis=0) / solid.dt
    row = [solid.time, solid.step_count, *force, uz / count, *fe, *de, *transit, *(fe + de + transit),
           diagnostics.unbalanced_force_ratio(engine), diagnostics.coordination_number(engine)]  # collective
    paths = write_frame(out_dir / "frames", engine, solid.step_count) if vtk else None
    if series is not None:
        series.append(row)
    if frames is not None:
        frames.add(engine.time, paths)
