"""The FE-only twin of an ``embedded`` case (``embedded.model = "fe"``; docs/guide/tunnel.md):
every volume of the model linear elastic, the zones as the first 'soil' volume (its E, ν, K0
and density), solved statically (:class:`fe_domain.static.StaticSolver`, the displacement
formulation) at rest — gravity and the soils' geostatic stress, the linings carrying what
the ground's in-situ stress does not find in the opening (the "wished in place" excavation
loading of the closed forms) — and at each row of the loading (the linings' contraction
ramped over embedded.loading_time). Each rank solves its own replicated copy; rank 0 writes.

Outputs, as the other models' where they apply: ``series.csv`` (per row the linings' thrust
and moment at the crown, springline and invert), ``<volume>_sections.csv``,
``settlement_trough.csv`` (the ground's FE nodes), ``fields.xdmf`` (at rest and each row;
displacement measured from the start, not from rest) and ``summary.json``."""
from __future__ import annotations

import json
import time
from pathlib import Path

from cosim.apps.embedded_model import (
    LoadingRamp,
    Roles,
    build_fe,
    grain_materials,
    lining_columns,
    lining_gauges,
    sections,
    write_sections,
)
from cosim.outputs import CsvSeries, atomic_write_text, is_root, say, write_run_metadata


def bulk_density(case):
    """The FE-only soil's density (kg/m³): the first 'soil' volume's rho, else the grains'
    density over 1 + the specimen's target void ratio."""
    em = case.embedded
    soil = next(v for v in em.volumes if v.role == "soil")
    if soil.rho is not None:
        return soil.rho
    mats, ids = grain_materials(case)
    return float(mats[ids[em.sand_material]].density) / (1.0 + case.specimen.void_ratio)


def run(prepared):
    """Solve at rest and over the loading; write the outputs (rank 0)."""
    from cosim.apps.embedded_report import write_trough
    from cosim.apps.tunnel_report import ground_height, report_linings
    from cosim.soil_model import fe_nodes
    from fe_domain.output import FieldWriter
    from fe_domain.static import StaticSolver
    case, em = prepared.case, prepared.case.embedded
    out_dir = Path(prepared.out_dir) / "fe"
    if is_root():
        out_dir.mkdir(parents=True, exist_ok=True)
    write_run_metadata(out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    name = f"{case.case.name}/fe"
    t0 = time.perf_counter()
    split = prepared.built["split"]
    ramp = LoadingRamp(em.loading_time)
    density = bulk_density(case)
    solid = build_fe(case, split, Roles.of(em), density, ramp)
    static = StaticSolver(solid)
    gauges = lining_gauges(case, solid)
    static.solve(0.0)                                    # at rest: the ramp has not started
    at_rest = [sections(gauge) for gauge in gauges]
    rest_displacement = fe_nodes(solid)[1]              # rank 0: the FE nodes in mesh-input order
    fields = FieldWriter(solid, out_dir / "fields") if is_root() else None
    rows = CsvSeries(out_dir / "series.csv", ["time", *lining_columns(em.linings), "row"]) if is_root() else None
    ramp.start = 0.0
    for k in range(em.rows + 1):
        static.solve(k * em.loading_time / em.rows)
        row = [solid.time]
        for gauge in gauges:
            row += gauge.row()
        if rows is not None:
            rows.append([*row, k])
            fields.write()
    coordinates, end_displacement = fe_nodes(solid)
    if not is_root():
        return
    rows.close()
    fields.close()
    for lining, gauge, rest in zip(em.linings, gauges, at_rest, strict=True):
        write_sections(out_dir / f"{lining.volume}_sections.csv", rest, sections(gauge))
    if em.ground:
        write_trough(split.surfaces[em.ground], case.dem.gravity, out_dir / "settlement_trough.csv",
                     (coordinates, end_displacement - rest_displacement))
    cells = solid.mesh.topology.index_map(3).size_local
    radii = {lining.volume: gauge.ring.outer_radius for lining, gauge in zip(em.linings, gauges, strict=True)}
    ground = ground_height(split.surfaces[em.ground], case.dem.gravity) if em.ground else None
    linings = report_linings(case, out_dir, "fe", radii, ground)
    wall_clock = time.perf_counter() - t0
    summary = {"model": "fe", "fe_cells": cells, "soil_density": density, "solve": "static (LU)", "linings": linings,
               "wall_clock_s": {"total_s": wall_clock}}
    atomic_write_text(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    say(f"[{name}] {cells} cells, soil density {density:.0f} kg/m³, solved at rest and {em.rows} rows in "
        f"{wall_clock:.1f} s")
