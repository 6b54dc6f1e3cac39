"""Case kind ``fe``: the explicit mixed u–p solid (docs/design.md §4) on a gmsh mesh,
with boundary conditions and loads by physical-group name, under ``mpirun -n N``.

Outputs: ``fields.xdmf`` (u, v, p, von Mises; ParaView), ``series.csv`` (reaction
forces and the largest displacement), ``energies.csv`` (kinetic, strain, external
work, damping, stabilisation, total), both streamed row by row, their PNG plots,
and per-rank checkpoints (a resume finds its nodes by mesh-input index, so any rank count
and partition may continue them).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cosim.case.paths import mesh_path
from cosim.errors import CaseError, RunFailed
from cosim.outputs import CsvSeries, ProgressLine, is_root, mpi_comm, say, write_run_metadata

PROGRESS_CHUNK = 50  # steps between checks of the progress line and checkpoint clock
#: ``series.csv``: these columns, then ``<group>_x``, ``_y``, ``_z`` for each group of ``fe.reactions``
SERIES_COLUMNS = ("time", "step", "max_displacement")
REACTION_AXES = "xyz"


def reaction_columns(groups):
    """``series.csv``'s reaction columns: ``<group>_x``, ``_y``, ``_z`` for each group (N)."""
    return [f"{n}_{c}" for n in groups for c in REACTION_AXES]


def prepare(case, case_path, out_dir, resume):
    """The solid: the mesh made and distributed, the operators assembled, the time step
    checked against the critical one, and the checkpoint to resume from found; collective."""
    solver = build_solid(case, case_path)
    dt = case.time.dt
    if dt is not None:
        if dt > solver.dt_critical:
            raise CaseError(case_path, "time.dt", dt,
                            f"{dt / solver.dt_critical:.3g} x the critical step {solver.dt_critical:.4g} s of this "
                            f"mesh (h_min / c_p, docs/design.md §4.6); give dt <= {solver.dt_critical:.4g} s or omit "
                            "it for time.safety_factor x critical")
        solver.dt = dt
    from cosim.apps.dem import check_steps
    check_steps(case_path, case.time, solver.dt)
    if resume:
        restore_checkpoint(solver, case_path, out_dir, "checkpoint")
    return solver


def default_alpha_tau(case):
    """The largest α_τ with a safety margin of 2 for the most incompressible material."""
    from fe_domain.explicit import stable_alpha_tau
    return stable_alpha_tau(max(m.nu for m in case.fe.materials))


def build_solid(case, case_path, comm=None):
    """The ExplicitSolid of the case's [fe] section, its mesh partitioned over ``comm`` (default
    all ranks; ``MPI.COMM_SELF``: the whole mesh on this rank); a mesh gmsh cannot make is a
    CaseError."""
    from fe_domain.mesh import MeshError, MeshSizeTooLarge
    try:
        return _solid(case, case_path, comm or mpi_comm())
    except MeshSizeTooLarge as exc:
        raise CaseError(case_path, "fe.mesh_size", case.fe.mesh_size,
                        f"larger than the whole geometry of {Path(case.fe.mesh).name} (its largest extent is "
                        f"{exc.extent:.4g} m); give a mesh size below that, small enough for a few elements "
                        "across the geometry") from None
    except MeshError as exc:
        raise CaseError(case_path, "fe.mesh", case.fe.mesh, f"cannot be meshed: {exc}") from None


def _solid(case, case_path, comm):
    from fe_domain.build import build_solid as build
    fe = case.fe
    if len(fe.materials) == 1 and fe.materials[0].group is None:
        material = {k: getattr(fe.materials[0], k) for k in ("E", "nu", "rho")}
    else:
        material = {m.group: {k: getattr(m, k) for k in ("E", "nu", "rho")} for m in fe.materials}
    drop_none = lambda table: {k: v for k, v in table.model_dump().items() if v is not None}  # noqa: E731
    return build(str(mesh_path(case_path, fe.mesh)), fe.mesh_size, material=material,
                 boundary_conditions=[drop_none(bc) for bc in fe.boundary_conditions],
                 loads=[drop_none(load) for load in fe.loads],
                 damping=fe.damping.model_dump() if fe.damping else None,
                 formulation=fe.formulation, alpha_tau=fe.alpha_tau or default_alpha_tau(case),
                 safety_factor=case.time.safety_factor, geometry_parameters=fe.geometry_parameters or None,
                 comm=comm)


def run(prepared):
    from fe_domain.output import ENERGY_COLUMNS, FieldWriter

    comm = mpi_comm()
    case, out_dir, solver, resume = prepared.case, prepared.out_dir, prepared.built, prepared.resume
    checkpoint = out_dir / f"checkpoint.rank{comm.rank}of{comm.size}.npz"
    write_run_metadata(out_dir, prepared.case_path, prepared.resolved, case.case.seed)

    total = case.time.steps or int(np.ceil(case.time.duration / solver.dt))
    interval = case.output.interval or total * solver.dt / 20
    every = max(1, int(round(interval / solver.dt)))
    solver.energy_interval = every
    n_cells = comm.allreduce(solver.mesh.topology.index_map(3).size_local)
    say(f"[{case.case.name}] {n_cells} tetrahedra on {comm.size} rank(s), dt = {solver.dt:.3e} s "
        f"(critical {solver.dt_critical:.3e} s), {total} steps, output every {every} steps")

    reactions = case.fe.reactions
    resume_time = solver.time if resume else None
    # on resume, the rows of the checkpoint's instant are the files' if it is an output step (a
    # final row off the output grid is dropped, as an uninterrupted run has none there)
    output_instant = solver.step_count % every == 0
    series = energies = None
    if is_root():
        series = CsvSeries(out_dir / "series.csv", [*SERIES_COLUMNS, *reaction_columns(reactions)], resume_time,
                           keep_resume_instant=output_instant)
        energies = CsvSeries(out_dir / "energies.csv", ENERGY_COLUMNS, resume_time, keep_resume_instant=output_instant)
    fields = FieldWriter(solver, out_dir / ("fields_from_step%d" % solver.step_count if resume else "fields"))
    progress = ProgressLine(case.case.name, total, case.output.progress_interval, first_step=solver.step_count)
    last_checkpoint = time.perf_counter()
    written = 0

    while solver.step_count < total:
        solver.run(min(every - solver.step_count % every, total - solver.step_count, PROGRESS_CHUNK))
        if solver.step_count % every == 0 or solver.step_count == total:
            check_finite(solver)
            row = [solver.time, solver.step_count, _max_displacement(solver)]
            for name in reactions:
                row.extend(solver.reaction(name))
            if series is not None:
                series.append(row)
                for entry in solver.energy_history[written:]:
                    energies.append([entry[c] for c in ENERGY_COLUMNS])
            written = len(solver.energy_history)
            fields.write()
        progress.update(solver.step_count, solver.time)
        if comm.allreduce(time.perf_counter() - last_checkpoint > case.output.checkpoint_interval, op=_mpi_lor()):
            write_checkpoint(solver, checkpoint)
            last_checkpoint = time.perf_counter()
    progress.update(solver.step_count, solver.time, force=True)
    write_checkpoint(solver, checkpoint)
    fields.close()
    if is_root():
        series.close()
        energies.close()
        _plots(case, out_dir, reactions)
    say(f"[{case.case.name}] done: t = {solver.time:.4e} s, largest displacement {_max_displacement(solver):.4e} m")


def check_finite(solver):
    """Collective: raise RunFailed on every rank if any rank's displacement or velocity
    stopped being finite (the explicit step diverged, or a load overflowed)."""
    local = bool(np.isfinite(solver.displacement).all() and np.isfinite(solver.velocity).all())
    if not mpi_comm().allreduce(local, op=_mpi_land()):
        raise RunFailed(f"the FE state is not finite at step {solver.step_count} (t = {solver.time:.4e} s): the run "
                        "diverged; the rows and fields written so far are kept")


def _max_displacement(solver):
    local = np.max(np.linalg.norm(solver.displacement[:solver.n_owned_nodes], axis=1), initial=0.0)
    return mpi_comm().allreduce(float(local), op=_mpi_max())


def restore_checkpoint(solver, case_path, out_dir, stem):
    """Restore ``solver`` from the newest complete set of FE checkpoint files
    ``<stem>.rank<r>of<n>.npz`` in ``out_dir`` and return the state it used (with any extra
    arrays); collective. This rank's own file when the newest set is of this rank count and
    every rank's file fits its partition (bit-identical continuation); otherwise each node's
    values from the rank of that set that owned it, found by its mesh-input index (another
    rank count, or DOLFINx partitioned the same mesh otherwise). The newest set, not this
    rank count's: an output folder may hold an older set of this count, from before a run
    with another rank count or FE layout."""
    import re
    comm = solver.comm
    own = Path(out_dir) / f"{stem}.rank{comm.rank}of{comm.size}.npz"
    chosen = None
    if comm.rank == 0:
        found = {}
        for path in Path(out_dir).glob(f"{stem}.rank*of*.npz"):
            match = re.fullmatch(re.escape(stem) + r"\.rank(\d+)of(\d+)\.npz", path.name)
            if match:
                found.setdefault(int(match.group(2)), {})[int(match.group(1))] = path
        complete = {n: files for n, files in found.items() if sorted(files) == list(range(n))}
        if complete:  # the newest; on a tie this rank count's
            chosen = max(complete, key=lambda n: (max(f.stat().st_mtime for f in complete[n].values()),
                                                  n == comm.size))
    chosen = comm.bcast(chosen, root=0)
    if chosen is None:
        raise CaseError(case_path, "--resume", str(own), "no complete set of FE checkpoint files in the output "
                                                          "folder; run without --resume")
    if chosen == comm.size:
        state = _read(own)
        if comm.allreduce(solver.fits(state), op=_mpi_land()):
            solver.restore_state(state)
            return state
    states = [_read(Path(out_dir) / f"{stem}.rank{r}of{chosen}.npz") for r in range(chosen)]
    failure = None
    try:
        solver.restore_from_ranks(states)
    except (KeyError, ValueError) as exc:
        failure = str(exc)
    failure = next((f for f in comm.allgather(failure) if f is not None), None)  # every rank alike
    if failure is not None:
        raise CaseError(case_path, "--resume", str(own), f"the FE checkpoint does not fit this mesh ({failure}); "
                                                          "run without --resume")
    return states[0]


def _read(path):
    with np.load(path) as data:
        return {key: data[key] for key in data.files}


def write_checkpoint(solver, path, extra=None):
    """This rank's FE state (and the arrays of ``extra``) to ``path`` (a temporary file, then renamed)."""
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez(tmp, **solver.checkpoint_state(), **(extra or {}))
    tmp.replace(path)


def _plots(case, out_dir, reactions):
    from cosim.plots import plot_panels
    panels = [("largest |u| [m]", ["max_displacement"], False)]
    if reactions:
        panels.append(("reaction [N]", [f"{n}_{c}" for n in reactions for c in "xyz"], False))
    plot_panels(out_dir / "series.csv", "time", panels, out_dir / "series.png", title=case.case.name)
    plot_panels(out_dir / "energies.csv", "time", [
        ("energy [J]", ["kinetic", "strain", "external_work", "damping_work", "stabilisation"], False),
        ("total (conserved) [J]", ["total"], False)], out_dir / "energies.png", title=case.case.name)


def _mpi_land():
    from mpi4py import MPI
    return MPI.LAND


def _mpi_lor():
    from mpi4py import MPI
    return MPI.LOR


def _mpi_max():
    from mpi4py import MPI
    return MPI.MAX
