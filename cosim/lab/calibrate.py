"""``cosim calibrate``: find the sand's micro-parameters so that a lab test (direct shear or
triaxial) gives target results (thesis §1.4: contact stiffness, friction and rolling resistance cannot be
measured; they are fitted so that a simulated lab test matches the real one).

A calibration file (``cosim.case.calibration.CalibrationFile``) names a direct_shear or triaxial case,
targets (a quantity of ``summary.json`` at a stated σ_n or σ₃, with a tolerance; a target may
name its own case, such as a loose specimen's beside the dense one) and up to four parameters
with bounds: of the sand material, or the grains' aspect ratio (a rod of two equal spheres,
:func:`cosim.case.calibration.rod_members`). The search, step by step:

1. **One specimen a case and shape.** Each case's specimen is generated once, as written, and
   reused by every evaluation (as in ``cosim series``): only the test's micro-parameters
   change. An aspect ratio changes the grains: each value makes its own specimen.
2. **An evaluation** is one run per distinct (case, target stress) with one parameter set.
   Its misfit is Σ ((achieved − value) / tolerance)²; the targets are reached when every
   ``|achieved − value| ≤ tolerance``.
3. **Reachability.** The two corners of the bounds (all parameters at their lower, then at
   their upper bound) are evaluated first. φ, dilation and strength rise with μ, β_r and η_r
   and fall with k_n/k_t, so the corners span what the bounds can give. A target outside
   that span by more than its tolerance is reported as unreachable, and the search stops
   before it begins.
4. **Search.** Nelder–Mead (scipy.optimize.minimize; derivative-free, and it tolerates the
   noise of a chaotic simulation) runs on the parameters scaled to [0, 1] within the bounds.
   It starts from a simplex around the centre that spans 30 % of each range. A point the
   simplex puts past a bound is reflected back inside (``s → 1 − abs(1 − (s mod 2))``): clipped to
   the bound, the simplex collapsed onto it and stalled there short of a target just inside.
   A parameter set met again is not run again and is not another evaluation. The search
   stops when the targets are reached, when ``budget`` evaluations (distinct parameter sets)
   are spent, or when the simplex has shrunk to 0.1 % of the ranges.
5. **Resumable.** Every evaluation is a row of ``evaluations.csv``. Rerun, the search
   takes the same steps (Nelder–Mead is deterministic for given values) and reads finished
   evaluations from the CSV instead of running them again.
6. **Confirmation and report.** With ``confirm_case`` (the full-size case), the best
   parameters are run once on it at every target stress. ``calibrated.toml`` is the confirmed
   (or searched) case with the parameters written in. ``report.md``/``report.json`` give
   the target, small-case and full-size values, and ``calibration.png`` the history.
"""
from __future__ import annotations

import csv
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.errors import CaseError
from cosim.outputs import atomic_write_text, say

SIMPLEX_SPAN = 0.3   # the initial simplex spans this fraction of each parameter's range
STALL = 1e-3         # the search has stalled when the simplex is this small (scaled units)


@dataclass
class Evaluation:
    """One parameter set and what the test gave with it (one value per target)."""
    index: int
    parameters: dict
    achieved: list
    misfit: float
    reached: bool
    wall_clock_s: float


@dataclass
class Calibration:
    """The outcome: ``status`` is 'reached', 'unreachable', 'budget' or 'stalled'."""
    status: str
    message: str
    evaluations: list = field(default_factory=list)

    @property
    def best(self):
        return min(self.evaluations, key=lambda e: e.misfit)


def quantity_of(summary, name):
    """A calibration quantity from a run's summary (``CALIBRATION_QUANTITIES``)."""
    if name == "void_ratio_change":
        return summary["void_ratio_end"] - summary["void_ratio_consolidated"]
    return summary[name]


def misfit(achieved, targets):
    """Σ ((achieved − value) / tolerance)² over the targets."""
    return float(sum(((a - t.value) / t.tolerance) ** 2 for a, t in zip(achieved, targets, strict=True)))


def target_label(t):
    """A target's column in evaluations.csv: quantity@σ, with the case's stem when the target
    names its own case."""
    where = "" if t.case is None else f"{Path(t.case).stem}@"
    return f"{t.quantity}@{where}{t.normal_stress / 1e3:g}kPa"


class EvaluationLog:
    """``evaluations.csv``: one row per evaluation, read back on a rerun (the memo of
    finished evaluations, keyed by the exact parameter values)."""

    def __init__(self, path, names, targets):
        self.path, self.names, self.targets = Path(path), names, targets
        self.columns = ["evaluation", *names, *map(target_label, targets), "misfit", "reached", "wall_clock_s"]
        self.memo = {}
        if self.path.exists():
            with open(self.path, newline="") as f:
                rows = list(csv.DictReader(f))
            if rows and list(rows[0]) != self.columns:
                raise CaseError("<command line>", "--out", str(self.path.parent),
                                f"{self.path.name} there was written for other parameters or targets; "
                                "give another output folder")
            for row in rows:
                values = tuple(float(row[n]) for n in names)
                self.memo[values] = [float(row[target_label(t)]) for t in targets], float(row["wall_clock_s"])
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.path, "w", newline="") as f:
                csv.writer(f).writerow(self.columns)

    def append(self, e):
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerow([e.index, *(repr(e.parameters[n]) for n in self.names),
                                    *(repr(a) for a in e.achieved), repr(e.misfit), int(e.reached),
                                    f"{e.wall_clock_s:.1f}"])


class _Stop(Exception):
    def __init__(self, status, message):
        super().__init__(message)
        self.status, self.message = status, message


def calibrate(spec, evaluate, log_path, progress=say, cases=None):
    """Run the search of the module docstring. ``evaluate(parameters, case, normal_stress,
    label)`` returns a run's summary (a dict with the target quantities); ``case`` is the
    target's entry of ``cases`` (one a target; default None for each), ``label`` names the
    evaluation (its run folder). Returns a :class:`Calibration`."""
    from scipy.optimize import minimize
    names = [p.name for p in spec.parameters]
    lower = np.array([p.lower for p in spec.parameters])
    upper = np.array([p.upper for p in spec.parameters])
    targets = spec.targets
    cases = [None] * len(targets) if cases is None else list(cases)
    tests = list(dict.fromkeys((c, t.normal_stress) for c, t in zip(cases, targets, strict=True)))
    log = EvaluationLog(log_path, names, targets)
    evaluations = []
    t_start = time.perf_counter()

    seen = {}  # parameter set -> its misfit, in this search

    def run(s):
        x = tuple(float(v) for v in lower + reflected(s) * (upper - lower))
        if x in seen:
            return seen[x]
        parameters = dict(zip(names, x, strict=True))
        index = len(evaluations) + 1
        if x in log.memo:
            achieved, clock = log.memo[x]
        else:
            t0 = time.perf_counter()
            summaries = {test: evaluate(parameters, *test, f"{index:03d}") for test in tests}
            achieved = [float(quantity_of(summaries[c, t.normal_stress], t.quantity))
                        for c, t in zip(cases, targets, strict=True)]
            clock = time.perf_counter() - t0
        e = Evaluation(index, parameters, achieved, misfit(achieved, targets),
                       all(abs(a - t.value) <= t.tolerance for a, t in zip(achieved, targets, strict=True)), clock)
        evaluations.append(e)
        seen[x] = e.misfit
        if x not in log.memo:
            log.append(e)
            log.memo[x] = achieved, clock
        _report_progress(progress, e, evaluations, targets, spec.budget, t_start)
        if e.reached:
            raise _Stop("reached", f"every target reached at evaluation {index}")
        if index >= spec.budget:
            raise _Stop("budget", f"the budget of {spec.budget} evaluations is spent before every target was reached")
        return e.misfit

    n = len(names)
    try:
        run(np.zeros(n))  # the corners span what the bounds can give
        run(np.ones(n))
        unreachable = _unreachable(targets, evaluations[0].achieved, evaluations[1].achieved)
        if unreachable:
            raise _Stop("unreachable", "; ".join(unreachable))
        centre = np.full(n, 0.5)
        simplex = np.vstack([centre] + [centre + SIMPLEX_SPAN * np.eye(n)[i] for i in range(n)])
        minimize(run, centre, method="Nelder-Mead",
                 options={"initial_simplex": simplex, "maxfev": 10 * spec.budget, "xatol": STALL,
                          "fatol": 0.0})
        outcome = Calibration("stalled", "the search stalled (its simplex shrank to 0.1 % of the ranges) before "
                                         "every target was reached: the targets may conflict, or the noise of the "
                                         "test is larger than a tolerance", evaluations)
    except _Stop as stop:
        outcome = Calibration(stop.status, stop.message, evaluations)
    return outcome


def reflected(s):
    """A point of the unbounded search folded into [0, 1] by reflection at the bounds."""
    return 1.0 - np.abs(1.0 - np.mod(s, 2.0))


def _unreachable(targets, low, high):
    """The targets outside the span of the two corners' values, each described."""
    out = []
    for t, a, b in zip(targets, low, high, strict=True):
        lo, hi = min(a, b), max(a, b)
        if not lo - t.tolerance <= t.value <= hi + t.tolerance:
            out.append(f"{t.quantity} = {t.value:g} at {t.normal_stress / 1e3:g} kPa cannot be reached within the "
                       f"bounds: their corners give {lo:.4g} ... {hi:.4g}; widen the bounds or add a parameter")
    return out


def _report_progress(progress, e, evaluations, targets, budget, t_start):
    elapsed = time.perf_counter() - t_start
    eta = elapsed / len(evaluations) * (budget - len(evaluations))
    params = ", ".join(f"{k} = {v:.4g}" for k, v in e.parameters.items())
    got = ", ".join(f"{t.quantity} {a:.4g} ({t.value:g} ± {t.tolerance:g})"
                    for t, a in zip(targets, e.achieved, strict=True))
    best = min(x.misfit for x in evaluations)
    progress(f"[calibrate] {e.index}/{budget}: {params} -> {got}; misfit {e.misfit:.3g} (best {best:.3g}); "
             f"{elapsed:.0f} s elapsed, ETA <= {eta:.0f} s")


# --------------------------------------------------------------------------- running the case
class LabEvaluator:
    """Runs direct_shear or triaxial cases with the calibration file's ``fixed`` overrides and
    the parameters set (``--set``, :func:`overrides`) at one stress (σ_n or σ₃), in
    ``out_root/<label>/<case stem>/<σ>kPa``; a case's specimen is generated once for each grain
    shape into ``out_root/specimen_<case stem>[_ar<A>].npz`` and reused. A finished run with
    the same resolved case is read back, not rerun."""

    def __init__(self, out_root, fixed=()):
        self.out_root, self.fixed = Path(out_root), list(fixed)

    def __call__(self, parameters, case_path, normal_stress, label):
        from cosim.apps import Prepared
        from cosim.case import load_case
        from cosim.lab.series import STRESS_KEY, finished, lab_app
        case_path = Path(case_path)
        kind = load_case(case_path)[0].case.kind
        stress = f"{STRESS_KEY[kind]}={float(normal_stress)!r}"
        case, resolved = load_case(case_path, overrides(case_path, parameters, self.fixed) + [stress])
        out_dir = self.out_root / label / case_path.stem / f"{normal_stress / 1e3:g}kPa"
        out_dir.mkdir(parents=True, exist_ok=True)
        shape = f"_ar{parameters['aspect_ratio']!r}" if "aspect_ratio" in parameters else ""
        if not finished(out_dir, resolved):
            built = lab_app(kind).prepare(case, case_path, out_dir, False)
            lab_app(kind).run(Prepared(case, resolved, case_path, out_dir, False, built),
                              specimen_cache=self.out_root / f"specimen_{case_path.stem}{shape}.npz")
        return json.loads((out_dir / "summary.json").read_text())


def overrides(case_path, parameters, fixed=()):
    """The ``--set`` overrides that give the case at ``case_path`` the calibration file's
    ``fixed`` ones, then the ``parameters``: the sand material's micro-parameters; the aspect
    ratio as its one [[dem.clumps]] template, a rod of two equal spheres."""
    from cosim.case import load_case
    from cosim.case.calibration import rod_members
    case, _ = load_case(case_path, list(fixed))
    names = [m.name for m in case.dem.materials]
    sand = names.index(getattr(case, case.case.kind).sand_material)
    return list(fixed) + [f"dem.clumps[0].members={rod_members(v)!r}" if k == "aspect_ratio" else
                          f"dem.materials[{sand}].{k}={v!r}" for k, v in parameters.items()]


def confirm(setup, parameters, out_root):
    """The best parameters on each target's confirmation case (``setup.confirm_cases``) at its
    stress: the achieved value per target, None for a target without one."""
    evaluate = LabEvaluator(out_root, setup.spec.set)
    return [None if c is None else float(quantity_of(evaluate(parameters, c, t.normal_stress, "best"), t.quantity))
            for c, t in zip(setup.confirm_cases, setup.spec.targets, strict=True)]


def calibrated_case_text(case_path, overrides, note):
    """The case file with the calibrated values written in (TOML; comments are not kept),
    a packing file path made absolute so the new file works from anywhere."""
    import tomllib

    import tomli_w

    from cosim.case.loading import apply_overrides
    from cosim.case.paths import resolve_path
    raw = apply_overrides(case_path, tomllib.loads(Path(case_path).read_text()), overrides)
    specimen = raw.get("specimen", {})
    if "file" in specimen:
        specimen["file"] = str(resolve_path(case_path, specimen["file"]))
    return "".join(f"# {line}\n" for line in note.splitlines()) + tomli_w.dumps(raw)


# --------------------------------------------------------------------------- report
def write_report(out_root, setup, outcome, confirmed=None, calibrated=()):
    """``report.json``, ``report.md`` and ``calibration.png`` in ``out_root``: per target its
    case, the searched case's value and the confirmation's (``confirmed``: one a target, None
    where none ran); ``calibrated``: the case files written."""
    spec, best = setup.spec, outcome.best
    rows = []
    for i, t in enumerate(spec.targets):
        rows.append({"quantity": t.quantity, "normal_stress": t.normal_stress, "target": t.value,
                     "tolerance": t.tolerance, "case": Path(setup.cases[i]).stem, "searched_case": best.achieved[i],
                     "confirm_case": None if confirmed is None else confirmed[i]})
    report = {"status": outcome.status, "message": outcome.message, "evaluations": len(outcome.evaluations),
              "best_evaluation": best.index, "parameters": best.parameters, "misfit": best.misfit,
              "bounds": {p.name: [p.lower, p.upper] for p in spec.parameters}, "targets": rows,
              "wall_clock_s": sum(e.wall_clock_s for e in outcome.evaluations),
              "calibrated_cases": list(calibrated)}
    atomic_write_text(out_root / "report.json", json.dumps(report, indent=2))
    lines = [f"# Calibration: {outcome.status}", "", outcome.message, "",
             f"Best of {len(outcome.evaluations)} evaluations (no. {best.index}): "
             + ", ".join(f"{k} = {v:.4g}" for k, v in best.parameters.items()), "",
             "| quantity | case | σ [kPa] | target | searched case | confirm case |", "|---|---|---|---|---|---|"]
    for r in rows:
        c = "-" if r["confirm_case"] is None else f"{r['confirm_case']:.4g}"
        lines.append(f"| {r['quantity']} | {r['case']} | {r['normal_stress'] / 1e3:g} | {r['target']:g} ± "
                     f"{r['tolerance']:g} | {r['searched_case']:.4g} | {c} |")
    atomic_write_text(out_root / "report.md", "\n".join(lines) + "\n")
    plot_history(out_root / "calibration.png", spec, outcome)
    return report


def plot_history(path, spec, outcome):
    """Misfit, scaled parameters and scaled target errors against the evaluation number."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    evals = outcome.evaluations
    k = [e.index for e in evals]
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 8.0), sharex=True)
    misfits = np.array([e.misfit for e in evals])
    axes[0].semilogy(k, np.maximum(misfits, 1e-6), "o-", ms=3, label="misfit")
    axes[0].semilogy(k, np.maximum(np.minimum.accumulate(misfits), 1e-6), color="tab:red", label="best so far")
    axes[0].axhline(len(spec.targets), color="0.6", ls=":", label="every error = its tolerance")
    axes[0].set_ylabel("Σ (error / tolerance)²")
    axes[0].legend(fontsize=8)
    for p in spec.parameters:
        axes[1].plot(k, [(e.parameters[p.name] - p.lower) / (p.upper - p.lower) for e in evals], "o-", ms=3,
                     label=f"{p.name} ({p.lower:g} ... {p.upper:g})")
    axes[1].set_ylabel("parameter within its bounds")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].legend(fontsize=8)
    for i, t in enumerate(spec.targets):
        axes[2].plot(k, [(e.achieved[i] - t.value) / t.tolerance for e in evals], "o-", ms=3, label=target_label(t))
    axes[2].axhspan(-1, 1, color="tab:green", alpha=0.15, label="within tolerance")
    axes[2].set_ylabel("(achieved − target) / tolerance")
    axes[2].set_xlabel("evaluation")
    axes[2].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(f"cosim calibrate: {outcome.status}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_calibration(calibration_path, out_root, confirm_runs=True):
    """``cosim calibrate``: validate, search, confirm, report; returns the Calibration."""
    from cosim.case.calibration import load_calibration
    setup = load_calibration(calibration_path)
    out_root = Path(out_root)
    outcome = calibrate(setup.spec, LabEvaluator(out_root / "search", setup.spec.set), out_root / "evaluations.csv",
                        cases=setup.cases)
    say(f"[calibrate] {outcome.status}: {outcome.message}")
    best = outcome.best
    confirmed = None
    if outcome.status == "reached" and confirm_runs and any(c is not None for c in setup.confirm_cases):
        say(f"[calibrate] confirming {best.parameters} on "
            f"{', '.join(sorted({str(c) for c in setup.confirm_cases if c is not None}))}")
        confirmed = confirm(setup, best.parameters, out_root / "confirm")
    written = []
    if outcome.status == "reached":  # each case the result was last run on, with the parameters written in
        finals = [c if confirmed is None or k is None else k
                  for c, k in zip(setup.cases, setup.confirm_cases, strict=True)]
        for n, case_path in enumerate(dict.fromkeys(finals)):
            note = (f"Calibrated by `cosim calibrate {calibration_path}` (see report.md next to this file):\n"
                    + "\n".join(f"  {k} = {v!r}" for k, v in best.parameters.items())
                    + f"\nfrom {Path(case_path).resolve()}")
            written.append(out_root / ("calibrated.toml" if n == 0 else f"calibrated_{Path(case_path).stem}.toml"))
            atomic_write_text(written[-1], calibrated_case_text(
                case_path, overrides(case_path, best.parameters, setup.spec.set), note))
    report = write_report(out_root, setup, outcome, confirmed, [str(w) for w in written])
    say((out_root / "report.md").read_text())
    say(f"[calibrate] outputs: {out_root} (best misfit {report['misfit']:.3g})")
    return outcome
