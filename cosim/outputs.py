"""Run outputs: provenance (resolved case, versions, MPI, threads, seed), CSV
time series written row by row, and the progress line.

Everything is written so that a crash mid-run leaves the files written so far
intact: CSV rows are flushed as they are produced, metadata and checkpoints are
written to a temporary name and renamed (atomic on POSIX).
"""
from __future__ import annotations

import csv
import json
import os
import platform
import re
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import tomli_w


def mpi_comm():
    from mpi4py import MPI
    return MPI.COMM_WORLD


def is_root():
    return mpi_comm().rank == 0


def say(*args, **kwargs):
    """print() on MPI rank 0 only."""
    if is_root():
        print(*args, **kwargs, flush=True)


def versions():
    """Versions of the stack a run depends on (``cosim info``).

    Collective under MPI: importing petsc4py/dolfinx initialises PETSc, which is a
    collective call, so every rank must call this (see :func:`write_run_metadata`)."""
    out = {"python": platform.python_version()}
    for module in ("cosim", "numpy", "numba", "mpi4py", "petsc4py", "dolfinx", "basix", "ffcx", "ufl", "gmsh",
                   "meshio", "pydantic"):
        try:
            mod = __import__(module)
            out[module] = getattr(mod, "__version__", None) or _dist_version(module)
        except Exception as exc:  # a missing optional piece is reported, not fatal
            out[module] = f"unavailable ({type(exc).__name__})"
    return out


def _dist_version(name):
    from importlib.metadata import version
    return version(name)


def runtime():
    """MPI size, Numba threads and the libgomp wait policy chosen for this process."""
    import numba

    from de_domain import threading
    return {"mpi_size": mpi_comm().size, "numba_threads": numba.get_num_threads(),
            "numba_threading_layer": numba.config.THREADING_LAYER, "thread_waiting": threading.CHOICE,
            "host": platform.node()}


def compilation_seconds():
    """Seconds this process has spent compiling so far: Numba kernels and DOLFINx's FFCx forms,
    cache misses only (a later run loads both from their on-disk caches)."""
    from fe_domain import jit
    from numba_support import compile_clock
    return compile_clock.seconds() + jit.compile_seconds()


def atomic_write_text(path, text):
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_write_npz(path, **arrays):
    """``np.savez`` to a temporary file renamed over ``path``: never a half-written file."""
    import numpy as np
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def save_engine_checkpoint(engine, path):
    """``engine.save_checkpoint`` to a temporary file, then rename: a crash never leaves
    a broken checkpoint. A distributed engine's: collective, rank 0 writes and renames."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.npz")
    engine.save_checkpoint(tmp)  # a distributed engine's ends with a barrier: the file is complete
    if engine.runner.is_root:
        os.replace(tmp, path)
    engine.runner.barrier()


CHECKPOINT_COMMIT = "checkpoint.commit.json"  # the files of a checkpoint being made current


def staged(path):
    """Where a file of a checkpoint of several files is written before the set is committed."""
    path = Path(path)
    return path.with_name(f"{path.stem}.staged{path.suffix}")


def commit_checkpoint(out_dir, finals, comm=None):
    """Make the staged files (:func:`staged`, written and complete) of one checkpoint the current
    ones, all or none; ``finals``: this rank's files, by their final names; collective. Rank 0
    writes a commit record naming every rank's files, renames each staged file onto its name
    and removes the record. A kill among the renames leaves the record, and
    :func:`finish_commit` completes them on ``--resume``: the files never mix two instants."""
    comm = comm or mpi_comm()
    comm.Barrier()  # every rank's staged files are complete
    names = comm.gather([Path(f).name for f in finals], root=0)
    if comm.rank == 0:
        atomic_write_text(Path(out_dir) / CHECKPOINT_COMMIT, json.dumps(sorted({n for part in names for n in part})))
        finish_commit(out_dir)
    comm.Barrier()


def finish_commit(out_dir):
    """The renames of an interrupted :func:`commit_checkpoint` (rank 0; nothing if none)."""
    record = Path(out_dir) / CHECKPOINT_COMMIT
    if not record.exists():
        return
    for name in json.loads(record.read_text()):
        source = staged(Path(out_dir) / name)
        if source.exists():
            os.replace(source, Path(out_dir) / name)
    record.unlink()


def save_lab_checkpoint(out_dir, engine, state_name, state):
    """A lab test's checkpoint: the engine (``checkpoint.npz``, collective) and its loop and
    servo ``state`` (JSON ``state_name``, rank 0), naming the step it belongs to; committed
    together (:func:`commit_checkpoint`)."""
    out_dir = Path(out_dir)
    save_engine_checkpoint(engine, staged(out_dir / "checkpoint.npz"))
    finals = []
    if is_root():
        state = {**state, "step": engine.step_count}
        atomic_write_text(staged(out_dir / state_name), json.dumps(state, default=lambda x: x.item()))
        finals = [out_dir / "checkpoint.npz", out_dir / state_name]
    commit_checkpoint(out_dir, finals)


def load_lab_checkpoint(out_dir, state_name, comm=None):
    """(engine, state) of :func:`save_lab_checkpoint`; a state of another step is a CaseError."""
    from cosim.errors import CaseError
    from de_domain import Engine
    engine = Engine.load_checkpoint(Path(out_dir) / "checkpoint.npz", comm=comm)
    state = json.loads((Path(out_dir) / state_name).read_text())
    if state["step"] != engine.step_count:
        raise CaseError(Path(out_dir) / state_name, "step", state["step"],
                        f"does not match the checkpoint (step {engine.step_count}); run without --resume")
    return engine, state


def write_run_metadata(out_dir, case_path, resolved, seed):
    """Write ``case.resolved.toml`` (re-runnable) and ``run_info.json`` next to the outputs.

    Collective: call it on every rank (the version listing initialises PETSc); rank 0 writes."""
    info = {"case_file": str(Path(case_path).resolve()), "command": sys.argv,
            "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "seed": seed, "versions": versions(), **runtime()}
    if not is_root():
        return
    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "case.resolved.toml", tomli_w.dumps(_drop_none(resolved)))
    atomic_write_text(out_dir / "run_info.json", json.dumps(info, indent=2))


def check_output_folder(path):
    """Refuse an output folder that cannot be created or written, before any computation:
    an existing file, a path under a file, or a folder without write permission."""
    from cosim.errors import CaseError
    path = Path(path)
    existing = path
    while not existing.exists():
        if existing.is_symlink():  # a dangling link
            raise CaseError("<command line>", "--out", str(path), f"{existing} is a broken symbolic link")
        existing = existing.parent
    if not existing.is_dir():
        what = "is a file" if existing == path else f"lies under {existing}, which is a file"
        raise CaseError("<command line>", "--out", str(path), f"the output folder {what}; give a folder")
    try:  # os.access says yes to root even on a read-only file system: try it
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise CaseError("<command line>", "--out", str(path),
                        f"cannot write in {existing} ({exc.strerror}); give a folder you may write to") from None


def _drop_none(obj):
    if isinstance(obj, dict):
        return {k: _drop_none(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, list):
        return [_drop_none(v) for v in obj]
    return obj


RESUME_TOLERANCE = 1e-8  # relative: times in the files have 10 significant digits (CSV, PVD)


def kept_on_resume(t, resume_time, keep_resume_instant):
    """Whether a row or frame of time ``t`` (as read back from a file, so rounded) stays when a
    run resumes at ``resume_time``: every earlier one, and the one of the resume instant itself
    when ``keep_resume_instant`` (a kind that writes it before its checkpoint); not a later one."""
    margin = RESUME_TOLERANCE * abs(resume_time)
    return t < resume_time - margin or (keep_resume_instant and t <= resume_time + margin)


def at_resume_instant(t, resume_time):
    """Whether a time ``t`` read back from a file is the resume instant itself."""
    return abs(t - resume_time) <= RESUME_TOLERANCE * abs(resume_time)


class CsvSeries:
    """A CSV time series, one flushed row at a time; on resume keeps the rows before
    ``resume_time`` (and the one at it, with ``keep_resume_instant``).

    The row of the resume instant is never to be computed again after a checkpoint is loaded:
    what a row reads of the last step (contact forces, hence the unbalanced force ratio and the
    coordination number) is not in a checkpoint resumed over another rank count, so it would read
    "no contacts". A kind that writes a row before its checkpoint keeps the one the file has
    (``keep_resume_instant`` when the instant is an output instant of the resumed run, so a
    final row off the output grid is dropped); ``resume_row_kept`` says whether it had one."""

    def __init__(self, path, columns, resume_time=None, keep_resume_instant=True):
        self.path, self.columns = Path(path), list(columns)
        kept = []
        if resume_time is not None and self.path.exists():
            with open(self.path) as f:
                kept = [r for r in csv.DictReader(f)
                        if kept_on_resume(float(r[self.columns[0]]), resume_time, keep_resume_instant)]
        self.resume_row_kept = bool(kept) and resume_time is not None and keep_resume_instant and \
            at_resume_instant(float(kept[-1][self.columns[0]]), resume_time)
        self._file = open(self.path, "w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(self.columns)
        for r in kept:
            self._writer.writerow([r[c] for c in self.columns])
        self._file.flush()

    def append(self, row):
        self._writer.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in row])
        self._file.flush()

    def close(self):
        self._file.close()


def resume_row_missing(series, output_instant, comm=None):
    """Whether a resumed run must write the row of its resume instant itself: an output
    instant (``output_instant``) whose row the file did not have (``output.interval`` changed on
    ``--resume``). With ``comm``, rank 0's ``series`` (:class:`CsvSeries`) decides for every
    rank (collective); without, the caller is the one process that writes."""
    missing = bool(output_instant) and not (series is not None and series.resume_row_kept)
    return comm.bcast(missing, root=0) if comm is not None else missing


class ProgressLine:
    """``step 1200/5000 (24%)  t=1.20e-03 s  3.4e+03 steps/s  ETA 0:01:10`` every few seconds (rank 0);
    ``unit`` names what is counted (an embedded loading counts its CSV rows)."""

    def __init__(self, label, total_steps, interval_s=2.0, first_step=0, unit="step"):
        self.label, self.total, self.interval = label, total_steps, interval_s
        self.t0 = self.last = time.perf_counter()
        self.first = first_step
        self.unit = unit

    def update(self, step, sim_time, force=False):
        now = time.perf_counter()
        if not force and now - self.last < self.interval:
            return
        self.last = now
        done = step - self.first
        rate = done / max(now - self.t0, 1e-9)
        self.total = max(self.total, step)  # an estimated total may be passed
        eta = (self.total - step) / rate if rate > 0 else float("inf")
        eta_s = time.strftime("%H:%M:%S", time.gmtime(eta)) if eta != float("inf") else "--:--:--"
        say(f"[{self.label}] {self.unit} {step}/{self.total} ({100.0 * step / self.total:5.1f}%)  "
            f"t={sim_time:.4e} s  {rate:.3e} {self.unit}s/s  ETA {eta_s}")


class PvdCollection:
    """A ParaView ``.pvd`` collection of VTU frames, rewritten atomically after each frame.

    Files written together at one time are parts 0, 1, ... of that timestep (e.g.
    particles and facet meshes). On resume the existing entries before ``resume_time`` are
    kept (and those at it, with ``keep_resume_instant``).
    """

    _ENTRY = re.compile(r'<DataSet timestep="([^"]+)" group="" part="(\d+)" file="([^"]+)"/>')

    def __init__(self, path, resume_time=None, keep_resume_instant=True):
        self.path = Path(path)
        self.entries = []
        if resume_time is not None and self.path.exists():
            self.entries = [(t, int(part), f) for t, part, f in self._ENTRY.findall(self.path.read_text())
                            if kept_on_resume(float(t), resume_time, keep_resume_instant)]

    def add(self, t, files):
        for part, f in enumerate(files):
            self.entries.append((f"{t:.9e}", part, str(Path(f).relative_to(self.path.parent))))
        body = "\n".join(f'    <DataSet timestep="{t}" group="" part="{part}" file="{f}"/>'
                         for t, part, f in self.entries)
        atomic_write_text(self.path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                                     f"  <Collection>\n{body}\n  </Collection>\n</VTKFile>\n")


def particle_frames(enabled, out_dir, loop, spacing, resume_time=None):
    """ParaView frames of the particles and walls (``frames/`` + ``particles.pvd``) every
    ``spacing`` of a loading measure (a lab test's shear displacement or axial strain); the
    next frame's value is kept in ``loop["next_frame"]`` (checkpointed). Returns
    ``write(engine, value)``, collective when the engine is distributed."""
    if not enabled:
        return lambda engine, value: None
    from de_domain.io import write_frame
    index = None
    if is_root():
        (Path(out_dir) / "frames").mkdir(parents=True, exist_ok=True)
        index = PvdCollection(Path(out_dir) / "particles.pvd", resume_time)

    def write(engine, value):
        if value >= loop["next_frame"] - 1e-12:
            paths = write_frame(Path(out_dir) / "frames", engine, engine.step_count)
            if index is not None:
                index.add(engine.time, paths)
            loop["next_frame"] += spacing
    return write
