"""The report of an ``embedded`` run (:mod:`cosim.apps.embedded`; its preset ``footing`` adds
its own): ``summary.json``, the force–displacement plot of the rigid bodies, the displacement
section (grains, FE face, interface, bodies) and, when both models of a case have run, their
comparison. Everything here runs on rank 0, from the run's :class:`~cosim.apps.embedded.Outcome`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cosim.apps.embedded_model import AXES
from cosim.outputs import atomic_write_text, mpi_comm, say


def summary_of(prepared, outcome):
    """The run's summary.json content (rank 0)."""
    em, model, state = prepared.case.embedded, outcome.model, outcome.state
    clock = {**state["clock"], "loading_s": state["loading_before_s"]}
    total = sum(clock.values())
    rigid = rigid_summary(outcome.rigid, outcome.series)
    for body, seating in state["seating"].items():
        rigid[body]["seating"] = seating
    summary = {"model": em.model, "grains": state["grains"], "ranks": mpi_comm().size, "fill": state["fill"],
               "rest": state["rest"], "dem_dt_s": model.engine.dt, "rigid": rigid,
               "wall_clock_s": {**clock, "total_s": total, "compilation_s": outcome.compiling,
                                "total_without_compilation_s": total - outcome.compiling}}
    if model.solid is not None:
        summary.update({"fe_dt_s": model.solid.dt, "fe_dt_critical_s": model.solid.dt_critical,
                        "subcycles": model.subcycles, "fe_cells": state["fe_cells"],
                        "interface_facets": len(model.interface.facets.triangles)})
    return summary


def report(prepared, outcome):
    """summary.json, load_displacement.png (with rigid bodies), displacement_section.png and, when
    both models of the case have run, their comparison (rank 0)."""
    from cosim.apps.tunnel_report import ground_height, report_linings
    case, em, split = prepared.case, prepared.case.embedded, prepared.built["split"]
    summary = summary_of(prepared, outcome)
    if em.ground:
        write_trough(split.surfaces[em.ground], case.dem.gravity, outcome.out_dir / "settlement_trough.csv",
                     outcome.fe_motion, (outcome.start, outcome.grains))
    if em.linings:
        ground = ground_height(split.surfaces[em.ground], case.dem.gravity) if em.ground else None
        summary["linings"] = report_linings(case, outcome.out_dir, em.model, outcome.state["lining_outer_radii"],
                                            ground)
    atomic_write_text(outcome.out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    if outcome.rigid:
        plot_rigid_forces({em.model: outcome.series}, outcome.rigid, outcome.out_dir / "load_displacement.png",
                          case.case.name)
    plot_section(outcome, split, outcome.out_dir / "displacement_section.png", f"{case.case.name} ({em.model})")
    compare_models(Path(prepared.out_dir), outcome.rigid, case.case.name)
    total = summary["wall_clock_s"]["total_s"]
    say(f"[{case.case.name}/{case.embedded.model}] done: wall-clock {total:.0f} s, of which {outcome.compiling:.0f} s "
        "compiling (first run only)")


def write_trough(triangles, gravity, path, fe_motion=None, grains=None):
    """settlement_trough.csv: the settlement (m, down +, along g) during the loading of the FE
    nodes that are vertices of the ground surface's ``triangles`` (``fe_motion``: the nodes'
    coordinates and displacement; source "fe"), and of the grains of the top layer under it,
    their centre within a largest grain's diameter of the surface's highest point at the
    loading's start, or, where the grains alone make the ground (no FE node on the surface: the
    all-DEM twin, whose FE may be a lining) and settled below that band (a fill under its weight
    at full size), of the highest grain's centre (``grains``: their positions then and the
    particles at the end; source "dem"), by their position x, y (rank 0)."""
    down = np.asarray(gravity, float) / np.linalg.norm(gravity)
    rows = []
    if fe_motion is not None:
        coordinates, displacement = fe_motion
        vertices = {tuple(v) for v in np.round(triangles.reshape(-1, 3), 12)}
        on = np.array([tuple(c) in vertices for c in np.round(coordinates, 12)], bool)
        rows += [(x, y, d @ down, "fe") for (x, y, _), d in zip(coordinates[on], displacement[on], strict=True)]
    if grains is not None:
        start, end = grains
        height, band = -start @ down, 2.0 * float(end.radius.max())
        top = float((-triangles.reshape(-1, 3) @ down).max())
        if not rows and not np.any(height > top - band):  # grains alone, settled below the band
            top = float(height.max())
        layer = height > top - band
        moved = (end.pos - start)[layer] @ down
        rows += [(x, y, d, "dem") for (x, y, _), d in zip(start[layer], moved, strict=True)]
    rows.sort(key=lambda row: (row[3], row[0], row[1]))
    text = "x,y,settlement,source\n" + "".join(f"{x:.9g},{y:.9g},{d:.9g},{src}\n" for x, y, d, src in rows)
    atomic_write_text(path, text)


def rigid_summary(rigid, series, tail=0.2):
    """Per rigid body: its final displacement and rotation, and the force and moment (mean over
    the last ``tail`` of the rows), with the lever arm ``|M × F| / |F|²`` about the pivot."""
    out = {}
    n = max(1, int(round(tail * len(series["time"]))))
    for body in rigid:
        force = np.array([np.mean(series[f"{body.name}_force_{a}"][-n:]) for a in AXES])
        moment = np.array([np.mean(series[f"{body.name}_moment_{a}"][-n:]) for a in AXES])
        norm2 = float(force @ force)
        out[body.name] = {"displacement_m": float(series[f"{body.name}_displacement"][-1]),
                          "rotation_rad": float(series[f"{body.name}_rotation"][-1]),
                          "force_N": force.tolist(), "moment_Nm": moment.tolist(),
                          "lever_arm_m": float(np.linalg.norm(np.cross(force, moment)) / norm2) if norm2 else None}
    return out


def plot_rigid_forces(curves, rigid, path, title):
    """``|F|`` of each rigid body against its displacement (or rotation), one line per model."""
    from cosim.plots import plt
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, series in curves.items():
        for body in rigid:
            moves = np.any(body.velocity)
            x = series[f"{body.name}_displacement"] * 1e3 if moves else np.degrees(series[f"{body.name}_rotation"])
            f = np.linalg.norm([series[f"{body.name}_force_{a}"] for a in AXES], axis=0)
            ax.plot(x, f, label=f"{body.name} ({label})")
    ax.set_xlabel("displacement [mm]" if any(np.any(b.velocity) for b in rigid) else "rotation [deg]")
    ax.set_ylabel("force of the grains on the body |F| [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_section(outcome, split, path, title):
    """The model seen along y (an x–z section): the grains coloured by ``|Δx|`` during the
    loading; (coupled) the FE volumes' front face (their smallest y) coloured by ``|Δu|`` on the
    same scale, left empty where the grains are, with the interface dashed; the rigid bodies
    where the loading left them."""
    from matplotlib.collections import PatchCollection, PolyCollection
    from matplotlib.patches import Circle

    from cosim.plots import plt
    after = outcome.grains
    disp = np.linalg.norm(after.pos - outcome.start, axis=1)
    top = 1e3 * float(np.percentile(disp, 99.5)) or 1.0
    order = np.argsort(after.pos[:, 1])[::-1]  # front grains (small y) drawn last
    fig, ax = plt.subplots(figsize=(8.0, 5.0))
    if outcome.fe_motion is not None:
        _plot_fe_face(ax, *outcome.fe_motion, split.zone.tets, top)
    circles = PatchCollection([Circle((after.pos[i, 0], after.pos[i, 2]), after.radius[i]) for i in order],
                              cmap="viridis", linewidths=0)
    circles.set_array(1e3 * disp[order])
    circles.set_clim(0.0, top)
    ax.add_collection(circles)
    label = "displacement during loading [mm]" if outcome.fe_motion is not None else \
        "grain displacement during loading [mm]"
    fig.colorbar(circles, ax=ax, label=label, shrink=0.8)
    for mesh in outcome.model.engine.facets[:len(outcome.rigid)]:  # rigid bodies first (build_model)
        ax.add_collection(PolyCollection(mesh.vertices[mesh.triangles][:, :, [0, 2]], facecolors="0.2",
                                         edgecolors="0.2", linewidths=1.5))
    if outcome.fe_motion is not None and len(split.zone.interface):
        ax.add_collection(PolyCollection(split.zone.interface[:, :, [0, 2]], facecolors="none", edgecolors="tab:red",
                                         linewidths=1.2, linestyles="--", label="FE-DE interface"))
        ax.legend(loc="lower right")
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _plot_fe_face(ax, coordinates, displacement, grain_tets, top):
    """``|Δu|`` (mm) of the FE nodes on the model's front face (its smallest y), filled contours
    on the scale 0 … ``top``, masked where a triangle's centre lies in the grain volumes."""
    from matplotlib.tri import Triangulation

    from de_domain.zone_fill import inside_tets
    y0 = float(coordinates[:, 1].min())
    scale = float(np.ptp(coordinates, axis=0).max())
    face = np.abs(coordinates[:, 1] - y0) < 1e-9 * scale
    x, z = coordinates[face, 0], coordinates[face, 2]
    mesh = Triangulation(x, z)
    centres = np.column_stack([x[mesh.triangles].mean(axis=1), np.full(len(mesh.triangles), y0 + 1e-6 * scale),
                               z[mesh.triangles].mean(axis=1)])
    mesh.set_mask(inside_tets(centres, grain_tets))
    ax.tricontourf(mesh, np.clip(1e3 * np.linalg.norm(displacement[face], axis=1), 0.0, top),
                   levels=np.linspace(0.0, top, 21), cmap="viridis")


def compare_models(case_dir, rigid, title):
    """When both models have run to their end (each folder's ``summary.json``, written last) and
    their series have the rigid bodies' columns: ``comparison.csv`` (per rigid body the mean
    force and moment over the loading in each model and their difference) and
    ``comparison.png``. A twin still running (its series partial) or of another case is left
    out with a line saying so."""
    models = ("coupled", "dem")
    if not rigid or not all((case_dir / m / "summary.json").exists() for m in models):
        return None
    from cosim.lab.shear_report import read_series
    curves = {m: read_series(case_dir / m / "series.csv") for m in models}
    wanted = [f"{body.name}_{q}_{a}" for body in rigid for q in ("force", "moment") for a in AXES]
    if any(name not in curves[m] or len(curves[m][name]) == 0 for m in models for name in wanted):
        say(f"[{title}] not compared with the other model: its series.csv has no rows of these rigid bodies "
            "(still running, or of another case)")
        return None
    lines = ["quantity,coupled,dem,difference"]
    for body in rigid:
        for q in [f"force_{a}" for a in AXES] + [f"moment_{a}" for a in AXES]:
            c, d = (float(np.mean(curves[m][f"{body.name}_{q}"])) for m in ("coupled", "dem"))
            lines.append(f"{body.name}_{q},{c:.6g},{d:.6g},{(c - d) / d if d else float('nan'):.4f}")
    atomic_write_text(case_dir / "comparison.csv", "\n".join(lines) + "\n")
    if rigid:
        plot_rigid_forces({"coupled": curves["coupled"], "all-DEM": curves["dem"]}, rigid, case_dir / "comparison.png",
                          f"{title}: coupled against all-DEM")
    say(f"[{title}] coupled against all-DEM (mean over the loading): {case_dir / 'comparison.csv'}\n  "
        + "\n  ".join(lines[1:]))
    return lines
