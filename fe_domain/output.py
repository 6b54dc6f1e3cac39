"""Outputs of the FE solid: XDMF fields for ParaView, energy and reaction CSV files.

Fields written: displacement u, velocity v, the mixed formulation's mean stress p (P1, at
nodes; zero in the displacement formulation) and the von Mises stress √(3/2 s:s) of
s = 2G dev ε(u) (DG0, one value per cell), plus any fields the caller adds (e.g. the
coupling's interface traction). A solid with an initial (geostatic) stress σ0: u and p are
measured from it and the von Mises stress is of the whole deviator, s + dev σ0. With σ0 or
in the displacement formulation, ``mean_stress`` (DG0) is the whole mean stress,
p + tr σ0 / 3 (p = K div u in the displacement formulation).
"""

from __future__ import annotations

import csv
from pathlib import Path

import ufl
from dolfinx import fem
from dolfinx.io import XDMFFile

from fe_domain import forms, jit

jit.install()   # fem.Expression below is JIT-compiled too (see fe_domain/jit.py)

ENERGY_COLUMNS = ("time", "step", "kinetic", "strain", "external_work", "damping_work",
                  "stabilisation", "total")


class FieldWriter:
    """u, v, p, von Mises stress and ``extra_fields`` to one XDMF time series
    (``path``.xdmf + .h5). ``extra_fields``: callables, each returning a function on the
    solver's mesh brought up to date (called collectively at every write)."""

    def __init__(self, solver, path: str | Path, extra_fields=()):
        self.solver = solver
        self.extra_fields = tuple(extra_fields)
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.file = XDMFFile(solver.comm, str(Path(path).with_suffix(".xdmf")), "w")
        self.file.write_mesh(solver.mesh)
        points = solver.D0.element.interpolation_points()
        self.cell_fields = [(fem.Function(solver.D0, name="von_mises"),
                              fem.Expression(forms.von_mises(solver.u, solver.G, solver.initial_stress), points))]
        if solver.initial_stress is not None or not solver.mixed:
            mean = solver.pressure_form
            if solver.initial_stress is not None:
                mean = mean + ufl.tr(solver.initial_stress) / 3.0
            self.cell_fields.append((fem.Function(solver.D0, name="mean_stress"), fem.Expression(mean, points)))

    def write(self) -> None:
        """Append the current state at t = solver.time."""
        if self.solver.initial_stress is not None:
            self.solver.update_initial_stress()
        for field, expression in self.cell_fields:
            field.interpolate(expression)
        t = self.solver.time
        extra = [field() for field in self.extra_fields]
        cell_fields = [field for field, _ in self.cell_fields]
        for field in (self.solver.u, self.solver.v, self.solver.p, *cell_fields, *extra):
            self.file.write_function(field, t)

    def close(self) -> None:
        self.file.close()


def write_energies_csv(solver, path: str | Path) -> None:
    """``solver.energy_history`` (recorded every ``energy_interval`` steps) as CSV (rank 0)."""
    if solver.comm.rank != 0:
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=ENERGY_COLUMNS)
        writer.writeheader()
        writer.writerows(solver.energy_history)


class ReactionLog:
    """Reaction force (N) of each named support group per call of ``record()``, to CSV."""

    def __init__(self, solver, boundaries: list[str]):
        self.solver = solver
        self.boundaries = list(boundaries)
        self.rows: list[list[float]] = []

    def record(self) -> None:
        row = [self.solver.time]
        for name in self.boundaries:
            row.extend(self.solver.reaction(name))
        self.rows.append(row)

    def write_csv(self, path: str | Path) -> None:
        if self.solver.comm.rank != 0:
            return
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        header = ["time"] + [f"{name}_{c}" for name in self.boundaries for c in "xyz"]
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            writer.writerows(self.rows)


class Recorder:
    """Step callback: fields every ``field_interval`` steps, reactions every
    ``reaction_interval``; energies are recorded by the solver every ``energy_interval``.
    ``close()`` writes ``energies.csv`` and ``reactions.csv`` into ``out_dir``."""

    def __init__(self, solver, out_dir: str | Path, field_interval: int = 0,
                 energy_interval: int = 0, reaction_boundaries: tuple[str, ...] = (),
                 reaction_interval: int = 1):
        self.solver = solver
        self.out_dir = Path(out_dir)
        self.field_interval = field_interval
        self.reaction_interval = reaction_interval
        solver.energy_interval = energy_interval
        self.fields = FieldWriter(solver, self.out_dir / "fields") if field_interval > 0 else None
        self.reactions = ReactionLog(solver, list(reaction_boundaries)) if reaction_boundaries else None
        if self.fields is not None:
            self.fields.write()

    def __call__(self, solver) -> None:
        n = solver.step_count
        if self.fields is not None and n % self.field_interval == 0:
            self.fields.write()
        if self.reactions is not None and n % self.reaction_interval == 0:
            self.reactions.record()

    def close(self) -> None:
        if self.fields is not None:
            self.fields.close()
        write_energies_csv(self.solver, self.out_dir / "energies.csv")
        if self.reactions is not None:
            self.reactions.write_csv(self.out_dir / "reactions.csv")
        self.solver.comm.Barrier()
