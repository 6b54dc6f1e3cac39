"""The tunnel in sand (runs/tunnel.toml), coupled against its all-DEM twin over several packings,
with the FE-only twin beside them, and the settlement trough against Peck (1969) (issue 39
item 3; docs/guide/tunnel.md).

Runs the case with each seed in both models unless a run's summary exists (``--jobs`` runs at
a time, one thread each: ``NUMBA_NUM_THREADS=1``, on ``--ranks`` MPI ranks; two at a time, about
4 minutes a coupled run and 12 an all-DEM one on this 2-core machine), and the FE-only twin once
(it has no packing). Per run: the lining's thrust and moment at the crown, springline and
invert at rest (row 0 of series.csv), at the end of the loading (the mean of the last TAIL of
the rows) and the change between them, each rigid body's vertical force at the end (a
surcharge), and the surface trough's Peck fit
(S_max, i, K = i / z0, the surface volume loss V_s / A; cosim.apps.tunnel_report). Per model
the mean and standard deviation over the seeds, and the coupled model's mean against the
all-DEM one. Writes ``<out>/table.md`` and the pictures of :func:`pictures`.

    python studies/tunnel_seeds.py [--seeds 11 12 13] [--case runs/tunnel.toml] [--out runs/out/tunnel_seeds] [--jobs 2]
                                   [--set embedded.parameters.chimney=0.1 ...] [--ranks 2] [--pictures tunnel]
                                   [--no-fe]

``--pictures NAME``: the pictures are docs/NAME_polar_rest.png, ... (a variant of the case
keeps the shipped case's pictures). ``--no-fe``: without the FE-only twin (a case with rigid
bodies, such as runs/tunnel_surcharge.toml, has none); the pictures then show the grain models.

``--set`` overrides go to every run (a variant of the case); a model's runs that exist are kept,
so a variant of the zone can be compared against another study's all-DEM runs by linking
them into its folder (``<out>/seed<N>/dem``): the all-DEM twin does not depend on the zone.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cosim.apps.tunnel_report import fit_peck, plot_polar, plot_trough, read_sections, read_trough  # noqa: E402
from cosim.lab.shear_report import read_series  # noqa: E402

MODELS = ("coupled", "dem")
WHERE = ("crown", "springline", "invert")
TAIL = 0.2  # the end of the loading: the mean over this last fraction of the rows


#: what OpenMPI needs to start as root and on more ranks than cores (set where not set)
OPENMPI_DEFAULTS = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


def run_all(case, seeds, out, jobs, overrides=(), ranks=1):
    """Every model of every seed whose summary does not exist, ``jobs`` at a time, one thread
    each, on ``ranks`` MPI ranks (the all-DEM runs first: they are the longest)."""
    from concurrent.futures import ThreadPoolExecutor
    todo = [(model, seed) for model in reversed(MODELS) for seed in seeds
            if not (out / f"seed{seed}" / model / "summary.json").exists()]

    def one(model, seed):
        with open(out / f"seed{seed}_{model}.log", "w") as log:
            launcher = ["mpirun", "--oversubscribe", "--bind-to", "none", "-n", str(ranks)] if ranks > 1 else []
            command = [*launcher, sys.executable, "-m", "cosim.cli", "run", str(case),
                       "--out", str(out / f"seed{seed}"), "--set", f"case.seed={seed}",
                       "--set", f'embedded.model="{model}"',
                       *[arg for item in overrides for arg in ("--set", item)]]
            code = subprocess.run(command, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                                  env={**OPENMPI_DEFAULTS, **os.environ, "NUMBA_NUM_THREADS": "1"}).returncode
        if code != 0:
            raise SystemExit(f"the {model} run of seed {seed} failed: see {out}/seed{seed}_{model}.log")

    with ThreadPoolExecutor(jobs) as pool:
        for done in [pool.submit(one, model, seed) for model, seed in todo]:
            done.result()


def run_fe(case, out, overrides=()):
    if not (out / "fe" / "summary.json").exists():
        subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(case), "--out", str(out),
                        "--set", 'embedded.model="fe"', *[arg for item in overrides for arg in ("--set", item)]],
                       cwd=ROOT, check=True)


def measured(folder, volume="lining"):
    """One run's lining forces at rest and at the end, its trough's fit and its wall-clock."""
    summary = json.loads((folder / "summary.json").read_text())
    series = read_series(folder / "series.csv")
    n = max(1, int(round(TAIL * (len(series["time"]) - 1))))
    values = {}
    for q in ("thrust", "moment"):
        for where in WHERE:
            column = series[f"{volume}_{q}_{where}"]
            values[f"{q}_{where}_rest"] = float(column[0])
            values[f"{q}_{where}_end"] = float(np.mean(column[-n:]))
            values[f"{q}_{where}_change"] = values[f"{q}_{where}_end"] - values[f"{q}_{where}_rest"]
    trough = summary["linings"][volume]["trough"]
    values.update({"s_max_mm": 1e3 * trough["s_max_m"], "i_mm": 1e3 * trough["i_m"], "K": trough["K"],
                   "surface_volume_loss_pct": 100.0 * trough["surface_volume_loss"],
                   "wall_clock_s": summary["wall_clock_s"]["total_s"], "grains": summary.get("grains", 0)})
    for name, body in summary.get("rigid", {}).items():  # a surcharge: its force over the last TAIL of the rows
        values[f"{name}_force_z_N"] = body["force_N"][2]
    return values


def table(rows, fe):
    """table.md: per quantity, each model's mean ± std over the seeds, coupled against all-DEM."""
    keys = list(fe.keys()) if fe else list(next(r for m in MODELS for r in rows[m]).keys())
    lines = ["| quantity | coupled (mean ± std) | all-DEM (mean ± std) | coupled − all-DEM | FE-only |",
             "|---|---|---|---|---|"]
    def stats(values):
        if len(values) == 0:
            return float("nan"), "not run"
        spread = f" ± {np.std(values, ddof=1):.2g}" if len(values) > 1 else " (one packing)"
        return float(np.mean(values)), f"{np.mean(values):.4g}{spread}"

    for key in keys:
        (c, c_text), (d, d_text) = (stats([r[key] for r in rows[m]]) for m in MODELS)
        diff = f"{100 * (c - d) / abs(d):+.1f} %" if np.isfinite(c) and np.isfinite(d) and d else "–"
        lines.append(f"| {key} | {c_text} | {d_text} | {diff} | {f'{fe[key]:.4g}' if fe else 'not run'} |")
    return "\n".join(lines) + "\n"


def pictures(folders, fe_folder, case_name, axis_x, z0, name="tunnel"):
    """docs/<name>_polar_rest.png (N and M at rest: each model's mean over the seeds, and the
    FE-only twin's), docs/<name>_polar_end.png (at the end of the loading, coupled and all-DEM:
    the FE-only lining, tied to its ground, is pulled into tension by the contraction),
    docs/<name>_trough.png (every run's settlements and fitted trough) and the first seed's
    displacement sections; ``fe_folder`` None: without the FE-only twin."""
    mean = {}
    for model in MODELS:
        runs = [read_sections(folder / "lining_sections.csv") for label, folder in folders if label.startswith(model)]
        if runs:
            mean[model] = {k: np.mean([r[k] for r in runs], axis=0) for k in runs[0]}
    fe = read_sections(fe_folder / "lining_sections.csv") if fe_folder is not None else None
    counts = {m: sum(label.startswith(m) for label, _ in folders) for m in mean}
    names = {m: f"{'coupled' if m == 'coupled' else 'all-DEM'} (mean of {counts[m]})" for m in mean}
    for when, with_fe in (("rest", True), ("end", False)):
        column = "at_rest" if when == "rest" else "end"
        curves = {names[m]: (mean[m]["angle_deg"], mean[m][f"thrust_{column}"], mean[m][f"moment_{column}"])
                  for m in mean}
        if with_fe and fe is not None:
            curves["FE-only"] = (fe["angle_deg"], fe["thrust_at_rest"], fe["moment_at_rest"])
        plot_polar(curves, ROOT / "docs" / f"{name}_polar_{when}.png",
                   f"{case_name}: the lining {'at rest' if when == 'rest' else 'at the end of the loading'}")
    troughs = {}
    for label, folder in [*folders, *([("FE-only", fe_folder)] if fe_folder is not None else [])]:
        x, settlement = read_trough(folder / "settlement_trough.csv", axis_x)
        troughs[label] = (x, settlement, fit_peck(x, settlement, z0))
    plot_trough(troughs, ROOT / "docs" / f"{name}_trough.png", f"{case_name}: surface settlement against Peck (1969)")
    for model in mean:
        first = next(folder for label, folder in folders if label.startswith(model))
        shutil.copy(first / "displacement_section.png", ROOT / "docs" / f"{name}_displacement_{model}.png")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    parser.add_argument("--case", type=Path, default=ROOT / "runs" / "tunnel.toml")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "out" / "tunnel_seeds")
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time, one thread each")
    parser.add_argument("--ranks", type=int, default=1, help="MPI ranks a run (mpirun -n RANKS), one thread each")
    parser.add_argument("--no-run", action="store_true", help="report the runs that exist, start none")
    parser.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE",
                        help="a case override for every run, as cosim run --set")
    parser.add_argument("--no-pictures", action="store_true", help="write table.md only (not the docs' pictures)")
    parser.add_argument("--pictures", default="tunnel", metavar="NAME", help="the pictures' names: docs/NAME_*.png")
    parser.add_argument("--no-fe", action="store_true", help="without the FE-only twin")
    args = parser.parse_args()
    import tomllib
    case = tomllib.loads(args.case.read_text())
    lining = case["embedded"]["linings"][0]
    p = case["embedded"]["parameters"]
    z0 = p["C"] + p["D"] / 2.0
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.no_fe:
        run_fe(args.case, args.out / "fe_only", args.overrides)
    if not args.no_run:
        run_all(args.case, args.seeds, args.out, args.jobs, args.overrides, args.ranks)
    folders, rows = [], {m: [] for m in MODELS}
    for seed in args.seeds:
        out = args.out / f"seed{seed}"
        for model in MODELS:
            if (out / model / "summary.json").exists():
                rows[model].append(measured(out / model))
                folders.append((f"{model} {seed}", out / model))
    fe = None if args.no_fe else measured(args.out / "fe_only" / "fe")
    text = table(rows, fe)
    (args.out / "table.md").write_text(text)
    print(text)
    if not args.no_pictures:
        pictures(folders, None if args.no_fe else args.out / "fe_only" / "fe", case["case"]["name"],
                 lining["centre"][0], z0, args.pictures)


if __name__ == "__main__":
    main()
