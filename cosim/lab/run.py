"""The run the lab tests share (direct shear, triaxial; docs/design.md §3, §3.10).

1. the specimen, generated or read (:mod:`cosim.specimen`), in the test's box;
2. the test built around it (:meth:`LabTest.build`) and consolidated by its servo walls;
3. the loading, one servo update at a time, until the test's measure (the shear displacement
   δ, the axial strain ε₁) reaches its end: a CSV row every ``end / rows`` with the values the
   test samples averaged over the updates since the last row, ParaView frames every
   ``end / 10``, a progress line with ETA, and checkpoints every
   ``output.checkpoint_interval`` of wall-clock (the engine and the loop state: ``--resume``
   goes on bit for bit);
4. the report: the test's summary entries and pictures, the entries every lab test writes
   (grains, steps, void ratios, wall-clock by phase), ``summary.json`` and ``summary.txt``.

Under ``mpirun -n N`` every rank runs the test collectively (the DEM spread over the ranks,
bit-identical to one rank); rank 0 writes the files. A test says what differs through
:class:`LabTest`.
"""
from __future__ import annotations

import json
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.errors import CaseError
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    atomic_write_text,
    is_root,
    load_lab_checkpoint,
    mpi_comm,
    particle_frames,
    save_lab_checkpoint,
    say,
    write_run_metadata,
)

CHECKPOINT = "checkpoint.npz"


@dataclass(frozen=True)
class Loading:
    """The loading phase as a test plans it: its measure ends at ``end`` after about
    ``total_steps`` DEM steps since the start of the run, written in ``rows`` CSV rows;
    ``text`` says so in the log."""
    end: float
    total_steps: int
    rows: int
    text: str


class LabTest(ABC):
    """One lab test as :func:`run_lab_test` drives it. A subclass sets ``engine``, ``radii`` (every
    sphere's, by particle id), ``grain_radii`` (every grain's equal-volume radius), ``d50`` and the
    class constants below."""

    PHASE: str                   # the loading's name in the summary: steps_<PHASE>, wall_clock_<PHASE>_s
    STATE_FILE: str              # the checkpoint's loop and servo state (JSON, beside checkpoint.npz)
    COLUMNS: list[str]           # series.csv
    SAMPLED: int                 # how many values sample() returns (averaged over a row's updates)

    @classmethod
    @abstractmethod
    def specimen(cls, case, built, out_dir, cache=None, comm=None):
        """(:class:`~de_domain.deposition.Specimen`, info) of the specimen in the test's box; collective."""

    @classmethod
    @abstractmethod
    def build(cls, case, specimen, comm=None):
        """The test around a specimen; with ``comm``, the DEM spread over its ranks (collective)."""

    @classmethod
    @abstractmethod
    def restored(cls, case, engine, state):
        """The test around a checkpoint's engine, with its :meth:`saved_state`."""

    @abstractmethod
    def saved_state(self) -> dict:
        """What the test must keep across a checkpoint beyond the loop state (servo state)."""

    @abstractmethod
    def describe(self, height) -> str:
        """The log line of the test as built."""

    @abstractmethod
    def consolidate(self, log) -> int:
        """The consolidation; returns the DEM steps it took."""

    @abstractmethod
    def void_ratio(self) -> float:
        """e of the whole specimen now."""

    @abstractmethod
    def start_state(self) -> dict:
        """The loop state's entries of this test at the end of the consolidation."""

    @abstractmethod
    def plan(self, loop, out_dir, resume) -> Loading:
        """The loading's rate and length (on a new run and on a resume alike)."""

    @abstractmethod
    def measure(self, loop) -> float:
        """The loading's measure now (δ, ε₁)."""

    @abstractmethod
    def advance(self, loop):
        """One servo update of the loading (its velocity ramped by the measure so far)."""

    @abstractmethod
    def sample(self):
        """The ``SAMPLED`` values a row averages, after one update."""

    @abstractmethod
    def row(self, means, loop) -> list:
        """A CSV row (collective when distributed) from the means of the sampled values."""

    @abstractmethod
    def after_update(self, value, loop):
        """Anything the test does after every update, at the measure ``value`` (collective)."""

    @abstractmethod
    def report(self, data, loop, out_dir) -> dict:
        """The test's summary entries from series.csv's ``data``, and its pictures (rank 0)."""

    @abstractmethod
    def summary_text(self, summary) -> str:
        """summary.txt."""

    def grains_text(self) -> str:
        """'N grains', or 'N clumped grains of M spheres'."""
        if self.engine.clumps.count:
            return f"{self.grain_radii.size} clumped grains of {self.radii.size} spheres"
        return f"{self.grain_radii.size} grains"

    def resumed_text(self) -> str:
        """The log line's tail on a resume."""
        return ""


def grain_sizes(engine):
    """(every sphere's radius by particle id, every grain's equal-volume radius, the grains' solid
    volume, their mass-median diameter d50) of a test's engine (collective when distributed)."""
    from cosim.lab.shear_box import mass_median_diameter
    from de_domain.diagnostics import grain_radii
    radii = engine.global_particles().radius
    grains = grain_radii(engine)
    return radii, grains, float(np.sum(4.0 / 3.0 * np.pi * grains**3)), mass_median_diameter(grains)


def check_resume(case_path, out_dir, test_class, what):
    """``--resume`` needs the test's checkpoint: checkpoints start with its loading."""
    out_dir = Path(out_dir)
    if not ((out_dir / CHECKPOINT).exists() and (out_dir / test_class.STATE_FILE).exists()):
        raise CaseError(case_path, "--resume", str(out_dir / CHECKPOINT),
                        f"no {what} checkpoint in the output folder (checkpoints start with the {test_class.PHASE}); "
                        "run without --resume")


def run_lab_test(prepared, test_class, specimen_cache=None):
    """The test of a prepared case (:class:`cosim.apps.Prepared`); under ``mpirun -n N``
    (N > 1) collectively on all ranks."""
    case = prepared.case
    write_run_metadata(prepared.out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    comm = mpi_comm()
    if comm.size > 1 or is_root():
        _run(test_class, case, Path(prepared.out_dir), prepared.built, specimen_cache, prepared.resume,
             comm if comm.size > 1 else None)
    comm.Barrier()


def _started(test_class, case, out_dir, built, specimen_cache, comm, log):
    """Steps 1 and 2 of the module docstring: (test, loop state) at the end of the consolidation."""
    if comm is not None:
        built = comm.bcast(built, root=0)  # prepare() read the inputs on rank 0
    specimen, specimen_info = test_class.specimen(case, built, out_dir, specimen_cache, comm)
    test = test_class.build(case, specimen, comm)
    ranks = f", DEM on {comm.size} MPI ranks" if comm is not None else ""
    log(test.describe(specimen.height) + ranks)
    t_consolidation = time.perf_counter()
    consolidation_steps = test.consolidate(log)
    loop = {"specimen_info": specimen_info, "consolidation_steps": consolidation_steps,
            "e_consolidated": test.void_ratio(), **test.start_state(), "next_row": 0.0,
            "sums": [0.0] * test.SAMPLED, "n": 0, "next_frame": 0.0,
            "wall_clock_consolidation_s": time.perf_counter() - t_consolidation,
            f"wall_clock_{test.PHASE}_s": 0.0, "wall_clock_before_s": 0.0}
    return test, loop


def _run(test_class, case, out_dir, built, specimen_cache, resume, comm):
    name = case.case.name
    log = lambda text: say(f"[{name}] {text}")  # noqa: E731
    t_start = time.perf_counter()
    if resume:
        engine, loop = load_lab_checkpoint(out_dir, test_class.STATE_FILE, comm)
        test = test_class.restored(case, engine, loop)
        log(f"resumed at step {engine.step_count}{test.resumed_text()}")
    else:
        test, loop = _started(test_class, case, out_dir, built, specimen_cache, comm, log)
    engine, wall_clock = test.engine, f"wall_clock_{test.PHASE}_s"

    # 3. the loading
    loading = test.plan(loop, out_dir, resume)
    log(loading.text)
    series = CsvSeries(out_dir / "series.csv", test.COLUMNS, resume_time=engine.time if resume else None) \
        if is_root() else None
    frames = particle_frames(case.output.vtk, out_dir, loop, loading.end / 10, engine.time if resume else None)
    if not resume:
        frames(engine, 0.0)
    progress = ProgressLine(name, loading.total_steps, case.output.progress_interval, first_step=engine.step_count)
    spacing = loading.end / loading.rows
    sums = np.zeros(test.SAMPLED)
    sums[:len(loop["sums"])] = loop["sums"]  # (a checkpoint of an older version kept fewer)
    n = loop["n"]
    t0 = last_checkpoint = time.perf_counter()
    while True:
        test.advance(loop)
        sums += test.sample()
        n += 1
        value = test.measure(loop)
        done = value >= loading.end
        if value >= loop["next_row"] or done:
            row = test.row(sums / n, loop)  # collective when distributed
            if series is not None:
                series.append(row)
            sums, n = np.zeros(test.SAMPLED), 0
            loop["next_row"] += spacing
            frames(engine, value)
        test.after_update(value, loop)
        progress.update(engine.step_count, engine.time)
        if done:
            break
        due = time.perf_counter() - last_checkpoint > case.output.checkpoint_interval
        if due if comm is None else comm.bcast(due, root=0):  # rank 0's clock decides for all
            now = time.perf_counter()
            loop.update({"sums": sums.tolist(), "n": n, wall_clock: loop[wall_clock] + now - t0,
                         "wall_clock_before_s": loop["wall_clock_before_s"] + now - t_start})
            t0 = t_start = last_checkpoint = now
            save_lab_checkpoint(out_dir, engine, test.STATE_FILE, {**loop, **test.saved_state()})  # collective
    progress.update(engine.step_count, engine.time, force=True)
    if not is_root():
        return None
    series.close()

    # 4. the report
    from cosim.lab.shear_report import read_series
    data = read_series(out_dir / "series.csv")
    summary = test.report(data, loop, out_dir)
    summary.update({
        "case": name, "grains": int(test.grain_radii.size), "d50": test.d50, "dt": engine.dt,
        **({"clumps": engine.clumps.count, "spheres": int(test.radii.size)} if engine.clumps.count else {}),
        "steps_consolidation": loop["consolidation_steps"],
        f"steps_{test.PHASE}": int(engine.step_count - loop["consolidation_steps"]),
        "void_ratio_consolidated": loop["e_consolidated"], "void_ratio_end": float(data["void_ratio"][-1]),
        "wall_clock_consolidation_s": loop["wall_clock_consolidation_s"],
        wall_clock: loop[wall_clock] + time.perf_counter() - t0,
        "wall_clock_total_s": loop["wall_clock_before_s"] + time.perf_counter() - t_start,
        **{k: v for k, v in loop["specimen_info"].items() if k != "generation_log"},
    })
    atomic_write_text(out_dir / "summary.json", json.dumps(summary, indent=2))
    text = test.summary_text(summary)
    atomic_write_text(out_dir / "summary.txt", text)
    for line in text.splitlines():
        log(line)
    return summary
