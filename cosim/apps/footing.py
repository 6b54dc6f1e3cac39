"""Case kind ``footing``: a rigid strip footing pushed into sand, as a coupled model (grains
only in a zone under the footing, embedded in an FE soil block) or as its all-DEM reference
(the whole block made of grains), both built from one case description (docs/guide/footing.md).

The kind is a preset of the ``embedded`` kind (:mod:`cosim.apps.embedded`, docs/guide/own-geometry.md):
its [footing], [soil] and [zone] sections make the model ``meshes/strip_footing.geo`` and its
roles (:func:`as_embedded`), which runs as any embedded case; this module adds the bearing
capacity's report. The geometry is a plane-strain slice: a soil block W × L_y × H (x, y, z
from 0) between frictionless walls (DEM) or rollers (FE) at y = 0 and y = L_y, fixed at its
bottom, on rollers at x = 0 and x = W; the DEM zone w × L_y × d at the middle of its top;
the footing B × L_y on the zone's top. ``footing.model`` picks the model:

* ``coupled`` — grains in the zone, the rest of the block FE soil (linear elastic, ``soil.E``,
  ``soil.nu``, e.g. measured on the packing by ``cosim elastic``, as dense as the packing,
  under gravity, with local damping); the zone's bottom and sides are the coupling interface;
* ``dem`` — the grains fill the whole block, inside rigid walls: a rough bottom, frictionless sides.

The run, in both models (as every embedded run):

1. **Fill** — the grain volume is filled to ``specimen.void_ratio`` by radius expansion inside
   its faces, a lid over its top (or the grains of ``specimen.file``, in model coordinates);
2. **Rest** — under gravity until the grains' unbalanced force ratio is below
   ``footing.rest_unbalanced_force``; coupled, the FE soil then carries the zone's weight
   (``rest.csv``; the balance in ``summary.json``);
3. **Seating** — the footing moves down to the highest grain under it and on until it carries
   ``footing.seating_pressure``; the settlement counts from there;
4. **Loading** — it is held for one row (row 0), then moves down at ``footing.velocity`` to
   the settlement ``footing.settlement`` × B. ``series.csv`` (the embedded kind's columns, body
   ``footing``) and ``load_settlement.csv``: the settlement s, s / B, the bearing pressure
   q = F_z / (B L_y) (F_z the impulse the grains give the footing over each row's interval / that
   interval), the interface force, the unbalanced force ratio;
5. **Report** — ``summary.json`` (q at s/B = 2, 5, 10 %, the mean over 1–10 %, the seating, the
   rest balance, the wall-clock of each phase), ``load_settlement.png``, ``displacement_section.png``
   (the grains coloured by their displacement during loading, and the FE soil's front face by
   its own, on one scale), ParaView frames (particles, and the FE fields in ``fields.xdmf``),
   ``final_packing.npz``. When both models of the case have run, their load–settlement curves
   are compared in the case's folder (``comparison.csv``, ``.png``).

Outputs go to ``runs/out/<name>/<model>/``.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.errors import CaseError
from cosim.outputs import atomic_write_text, say

SETTLEMENT_LEVELS = (0.02, 0.05, 0.10)  # s/B at which the bearing pressure is reported
MEAN_RANGE = (0.01, 0.10)  # s/B over which the mean bearing pressure is reported
COLUMNS = ["time", "settlement", "settlement_ratio", "bearing_pressure", "footing_force_z", "interface_force_z",
           "unbalanced_force_ratio", "step"]  # load_settlement.csv
MESH = "strip_footing.geo"
BODY = "footing"  # the rigid body's name in the embedded model


# --------------------------------------------------------------------------- the preset
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

    def mesh_parameters(self, soil):
        """The DefineConstant values of meshes/strip_footing.geo."""
        return {"W": self.width, "Ly": self.thickness, "H": self.depth, "w": self.zone_width,
                "d": self.zone_depth, "B": self.footing_width, "h_near": soil.interface_mesh_size,
                "h_far": soil.mesh_size, "grow": soil.refinement_distance or self.zone_depth}


def as_embedded(case):
    """The case with the [embedded] section its [footing], [soil] and [zone] make: the model
    meshes/strip_footing.geo, volume ``zone`` grains and ``soil`` FE (grains in the all-DEM
    twin), the bottom fixed and rough, the sides on rollers and frictionless, the footing a rigid
    body seated on the grains and pushed down."""
    from cosim.case.schema import EmbeddedSection, EmbeddedSurface, EmbeddedVolume, RigidBody
    ft, soil, zone = case.footing, case.soil, case.zone
    geometry = Geometry.of(case)
    section = EmbeddedSection(
        model=ft.model, mesh=MESH, mesh_size=soil.mesh_size, parameters=geometry.mesh_parameters(soil),
        volumes=[EmbeddedVolume(group="zone", role="zone"),
                 EmbeddedVolume(group="soil", role="soil", E=soil.E, nu=soil.nu, rho=soil.rho, K0=soil.K0)],
        surfaces=[EmbeddedSurface(group="bottom", fe="fixed", dem="wall", material=zone.interface_material),
                  EmbeddedSurface(group="sides_x", fe="roller", dem="wall", material=ft.side_wall_material),
                  EmbeddedSurface(group="sides_y", fe="roller", dem="wall", material=ft.side_wall_material)],
        rigid=[RigidBody(name=BODY, surface="footing", material=ft.material, velocity=[0.0, 0.0, -ft.velocity],
                         pivot=[0.5 * geometry.width, 0.0, geometry.depth], seating_pressure=ft.seating_pressure)],
        loading_time=ft.settlement * ft.width / ft.velocity, rows=ft.rows, sand_material=ft.sand_material,
        interface_material=zone.interface_material, lid_material=zone.interface_material,
        rest_unbalanced_force=ft.rest_unbalanced_force, max_rest_time=ft.max_rest_time, damping=soil.damping,
        subcycles=zone.subcycles, fe_partition=soil.fe_partition)
    return case.model_copy(update={"embedded": section})


#: where an embedded check's key is in a footing case
FOOTING_KEYS = {"embedded.mesh": "soil.mesh_size", "embedded.volumes": "zone.width / zone.depth / soil.thickness"}


def prepare(case, case_path, out_dir, resume):
    """The embedded kind's checks on the preset's model (meshed here, collective), with their
    keys named as the footing case names them."""
    from cosim.apps import embedded
    try:
        return embedded.prepare(as_embedded(case), case_path, out_dir, resume)
    except CaseError as exc:
        key = FOOTING_KEYS.get(exc.key, exc.key)
        value = case.soil.mesh_size if exc.key == "embedded.mesh" else exc.value
        raise CaseError(exc.file, key, value, exc.allowed) from None


def run(prepared):
    """The embedded run of the preset, then the bearing capacity's report (rank 0)."""
    from cosim.apps import embedded, embedded_report
    prepared = dataclasses.replace(prepared, case=as_embedded(prepared.case))
    outcome = embedded.simulate(prepared)
    if outcome is None:
        return
    case = prepared.case
    summary = embedded_report.summary_of(prepared, outcome)
    curve = load_settlement(outcome.series, case)
    write_load_settlement(outcome.out_dir / "load_settlement.csv", curve)
    summary.update({"seating": summary["rigid"][BODY].get("seating"), "bearing_pressure_at": bearing_pressure_at(curve),
                    "mean_bearing_pressure": mean_bearing_pressure(curve)})
    atomic_write_text(outcome.out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    plot_load_settlement({case.footing.model: curve}, outcome.out_dir / "load_settlement.png", case.case.name)
    embedded_report.plot_section(outcome, prepared.built["split"], outcome.out_dir / "displacement_section.png",
                          f"{case.case.name} ({case.footing.model}): settlement "
                          f"{100 * case.footing.settlement:.0f} % of B")
    compare_models(prepared.out_dir, case.case.name)
    clock = summary["wall_clock_s"]
    say(f"[{case.case.name}/{case.footing.model}] q at s/B = "
        + ", ".join(f"{100 * k:.0f} %: {q / 1e3:.2f} kPa" for k, q in summary["bearing_pressure_at"].items())
        + f"; wall-clock {clock['total_s']:.0f} s, of which {clock['compilation_s']:.0f} s compiling (first run only)")


# --------------------------------------------------------------------------- report
def load_settlement(series, case):
    """The footing's curve from an embedded series: settlement s (from the seating), s / B,
    q = F_z / (B L_y), with the rows' time, interface force, unbalanced force ratio and step."""
    B, ly = case.footing.width, case.soil.thickness
    s = series[f"{BODY}_displacement"]
    return {"time": series["time"], "settlement": s, "settlement_ratio": s / B,
            "bearing_pressure": series[f"{BODY}_force_z"] / (B * ly), "footing_force_z": series[f"{BODY}_force_z"],
            "interface_force_z": series["interface_force_z"],
            "unbalanced_force_ratio": series["unbalanced_force_ratio"], "step": series["step"]}


def write_load_settlement(path, curve):
    """load_settlement.csv: the COLUMNS of ``curve``."""
    rows = np.column_stack([curve[c] for c in COLUMNS])
    atomic_write_text(path, ",".join(COLUMNS) + "\n" + "".join(",".join(f"{v:.9g}" for v in row) + "\n"
                                                              for row in rows))


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


def plot_load_settlement(curves, path, title):
    """q against s/B for each model in ``curves`` ({label: series})."""
    from cosim.plots import plt
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


def compare_models(case_dir, title):
    """When both models' curves (load_settlement.csv) exist in ``case_dir``: ``comparison.csv`` (q of each at the
    SETTLEMENT_LEVELS and its mean over MEAN_RANGE, their difference; the wall-clocks without
    compilation in a comment line) and ``comparison.png``; prints the same as a table."""
    case_dir = Path(case_dir)
    paths = {m: case_dir / m / "load_settlement.csv" for m in ("coupled", "dem")}
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
