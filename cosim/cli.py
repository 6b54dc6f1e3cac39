"""The ``cosim`` command line: ``run``, ``check``, ``series``, ``elastic``, ``calibrate``, ``info``, ``schema``.

Exit codes: 0 success, 2 bad input (case file, key, value named), 1 runtime failure.
Under ``mpirun -n N`` every rank runs, only rank 0 prints. Validation runs on every
rank and the ranks agree on its outcome (all exit 2, one message); a failure during the
run on any rank ends all ranks (``MPI_Abort``) with the cause printed once.
"""
from __future__ import annotations

import argparse
import importlib
import math
import sys
import traceback
from pathlib import Path

from cosim.errors import EXIT_BAD_INPUT, EXIT_RUN_FAILED, CaseError, RunFailed

DEFAULT_OUT_ROOT = Path("runs/out")


def _parser():
    p = argparse.ArgumentParser(prog="cosim", description="Coupled FE-DE simulator for granular geomechanics.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="run a case file",
                         description="Validate CASE, then run it; outputs go to runs/out/<case.name>/ "
                                     "unless --out is given.")
    run.add_argument("case", metavar="CASE.toml", help="case file")
    run.add_argument("--out", metavar="DIR", help="output folder (default runs/out/<case.name>)")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                     help="override one case value (TOML syntax for VALUE); repeatable")
    run.add_argument("--resume", action="store_true", help="continue from the checkpoint in the output folder")

    check = sub.add_parser("check", help="validate a case file only (exit 0 or 2)",
                           description="Validate CASE exactly as `cosim run` does (types, ranges, "
                                       "consistency, packings, meshes, time steps, the output folder) "
                                       "without running it.")
    check.add_argument("case", metavar="CASE.toml")
    check.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    check.add_argument("--out", metavar="DIR", help="output folder the run would use (checked, not created)")

    series = sub.add_parser("series", help="direct shear or triaxial series: cases x stresses, Mohr-Coulomb fit",
                            description="Run each direct_shear or triaxial CASE (one specimen each, e.g. dense and "
                                        "loose) at every normal stress (direct shear) or cell pressure "
                                        "(triaxial) and fit the Mohr-Coulomb envelope (phi, c) of peak and "
                                        "residual (critical-state) strength.")
    series.add_argument("cases", metavar="CASE.toml", nargs="+", help="direct_shear or triaxial case files")
    series.add_argument("--stresses", type=float, nargs="+", default=[50e3, 100e3, 200e3], metavar="PA",
                        help="normal stresses or cell pressures [Pa] (default 50e3 100e3 200e3)")
    series.add_argument("--out", metavar="DIR",
                        help="output folder (default runs/out/<kind>_series, the kind of the first case)")
    series.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override one value in every case; repeatable")

    elastic = sub.add_parser("elastic", help="small-strain E and nu of a case's packing, for the FE soil",
                             description="Generate a cube of the grains of CASE (a direct_shear or footing case: "
                                         "[dem] materials, [specimen] generation), compress it isotropically to "
                                         "--stress without gravity, apply a small constrained axial strain and "
                                         "report M, lambda, G, K, E and nu (cosim/lab/elastic.py).")
    elastic.add_argument("case", metavar="CASE.toml")
    elastic.add_argument("--stress", type=float, required=True, metavar="PA", help="mean stress p [Pa]")
    elastic.add_argument("--strain", type=float, default=2e-5, help="axial probe strain (default 2e-5)")
    elastic.add_argument("--size", type=float, default=None, metavar="M",
                         help="cube side [m] (default 10 of the largest grains)")
    elastic.add_argument("--out", metavar="DIR", help="output folder (default runs/out/<case.name>/elastic)")
    elastic.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")

    calibrate = sub.add_parser(
        "calibrate", help="fit the sand's micro-parameters to direct shear or triaxial targets",
        description="Search the sand's micro-parameters (friction, rolling_stiffness, rolling_friction, "
                    "stiffness_ratio, within bounds) until a direct_shear or triaxial case gives the target results "
                    "(phi_peak, phi_res, dilation, void ratio change at stated normal stresses), then confirm "
                    "them on a full-size case and write calibrated.toml and a report (cosim/lab/calibrate.py). "
                    "Rerun to continue an interrupted calibration. Exit 0 when every target is reached, 1 when "
                    "not (the report says why), 2 on bad input.")
    calibrate.add_argument("calibration", metavar="CALIBRATION.toml", help="calibration file (targets, parameters)")
    calibrate.add_argument("--out", metavar="DIR", help="output folder (default runs/out/calibrate/<file name>)")
    calibrate.add_argument("--no-confirm", action="store_true", help="skip the run on the confirm_case")

    sub.add_parser("info", help="versions of the stack, MPI size and Numba threads",
                   description="Print versions of DOLFINx, Numba, mpi4py, petsc4py, gmsh, meshio, the MPI size "
                               "and Numba threads.")
    sub.add_parser("schema", help="list every case-file key with its type, unit and default",
                   description="Print the case-file schema: every key with its type, unit, default and allowed "
                               "values.")
    return p


def main(argv=None):
    args = _parser().parse_args(argv)
    from cosim.outputs import mpi_comm, say
    comm = mpi_comm()
    try:
        if args.command == "info":
            return _info()
        if args.command == "schema":
            return _schema()
        if args.command == "series":
            jobs, out_root = _guarded(comm, lambda: _agreed(comm, lambda: _series_jobs(args)), passes=CaseError)
            return _guarded(comm, lambda: _series(jobs, out_root))
        if args.command == "elastic":
            return _elastic(args)
        if args.command == "calibrate":
            return _calibrate(args)
        if args.command == "check" and _is_calibration_file(args.case):
            from cosim.case.calibration import load_calibration
            load_calibration(args.case)
            say(f"{args.case}: OK (a calibration file: run it with `cosim calibrate {args.case}`)")
            return 0
        app, prepared = _guarded(comm, lambda: _agreed(comm, lambda: _prepare(args)), passes=CaseError)
        if args.command == "check":
            say(f"{args.case}: OK (kind '{prepared.case.case.kind}', name '{prepared.case.case.name}'; "
                f"outputs would go to {prepared.out_dir})")
            return 0
        return _guarded(comm, lambda: _run(app, prepared))
    except CaseError as exc:
        say(f"cosim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (RunFailed, FloatingPointError) as exc:  # a diverged state (every rank alike, or one process)
        say(f"cosim: run failed: {exc}", file=sys.stderr)
        return EXIT_RUN_FAILED


def _finish_interrupted_commit(out_dir):
    """A run killed while making its last checkpoint current left a commit record: finish it
    (rank 0), so that --resume reads the files of one instant (cosim.outputs.commit_checkpoint).
    The record is in the output folder, or in its model folder (footing, embedded: <out>/<model>/)."""
    from cosim.outputs import finish_commit, is_root, mpi_comm
    if is_root():
        for folder in [Path(out_dir), *(p for p in sorted(Path(out_dir).glob("*")) if p.is_dir())]:
            finish_commit(folder)
    mpi_comm().Barrier()


def _prepare(args):
    """The whole validation ``cosim run`` does before computing: the case file, the output
    folder, then the kind's own inputs (packings, meshes, time steps, checkpoint)."""
    from cosim.apps import Prepared
    from cosim.case import load_case
    from cosim.outputs import check_output_folder
    case, resolved = load_case(args.case, args.overrides)
    out_dir = Path(args.out) if args.out else DEFAULT_OUT_ROOT / case.case.name
    check_output_folder(out_dir)
    app = importlib.import_module(f"cosim.apps.{case.case.kind}")
    resume = getattr(args, "resume", False)
    if resume:
        _finish_interrupted_commit(out_dir)
    built = app.prepare(case, args.case, out_dir, resume)
    return app, Prepared(case, resolved, Path(args.case), out_dir, resume, built)


def _run(app, prepared):
    from cosim.outputs import is_root, mpi_comm, say
    if is_root():
        prepared.out_dir.mkdir(parents=True, exist_ok=True)
    mpi_comm().Barrier()
    app.run(prepared)
    say(f"outputs: {prepared.out_dir.resolve()}")
    return 0


def _series_jobs(args):
    """(the validated jobs of the series, its output folder); collective through ``_agreed``."""
    from cosim.case import load_case
    from cosim.lab.series import validate_series
    for stress in args.stresses:
        if not (math.isfinite(stress) and stress > 0):
            raise CaseError("<command line>", "--stresses", stress, "normal stresses must be finite and > 0 Pa")
    if args.out:
        out_root = Path(args.out)
    else:  # runs/out/direct_shear_series or runs/out/triaxial_series
        out_root = DEFAULT_OUT_ROOT / f"{load_case(args.cases[0], list(args.overrides))[0].case.kind}_series"
    return validate_series(args.cases, args.stresses, out_root, args.overrides), out_root


def _series(jobs, out_root):
    from cosim.lab.series import run_series
    from cosim.outputs import say
    run_series(jobs, out_root)
    say(f"outputs: {out_root.resolve()}")
    return 0


def _agreed(comm, validate):
    """Run ``validate`` on every rank; if it raises CaseError on any rank, raise the first
    failing rank's error on all of them, so every rank exits 2 with one message."""
    try:
        result, error = validate(), None
    except CaseError as exc:
        result, error = None, exc
    if comm.size > 1:
        errors = comm.allgather(None if error is None else (error.file, error.key, error.value, error.allowed))
        first = next((e for e in errors if e is not None), None)
        if first is not None:
            raise CaseError(*first)
    elif error is not None:
        raise error
    return result


def _guarded(comm, work, passes=RunFailed):
    """Run ``work``; under ``mpirun -n N`` (N > 1) an exception on one rank that the others
    do not share (anything but ``passes``, which every rank raises alike) is printed by
    that rank, then MPI_Abort ends every rank: none is left waiting in a collective the
    failed rank will never reach."""
    try:
        return work()
    except passes:
        raise
    except Exception as exc:
        if comm.size == 1:
            raise
        if isinstance(exc, CaseError):
            sys.stderr.write(f"cosim: error (rank {comm.rank}): {exc}\n")
            code = EXIT_BAD_INPUT
        elif isinstance(exc, FloatingPointError):  # a diverged state, found on this rank
            sys.stderr.write(f"cosim: run failed on rank {comm.rank} of {comm.size}: {exc}\n")
            code = EXIT_RUN_FAILED
        else:
            sys.stderr.write(f"cosim: rank {comm.rank} of {comm.size} failed:\n{traceback.format_exc()}")
            code = EXIT_RUN_FAILED
        sys.stderr.write(f"cosim: ending all {comm.size} ranks (MPI_Abort)\n")
        sys.stderr.flush()
        comm.Abort(code)


def _elastic(args):
    """``cosim elastic``: one process (the cube is small); the arguments checked first."""
    from cosim.case import load_case
    from cosim.lab.elastic import measure, roles
    from cosim.outputs import check_output_folder, mpi_comm
    if mpi_comm().size > 1:
        raise CaseError("<command line>", "mpirun", mpi_comm().size, "cosim elastic runs on one process")
    case, _ = load_case(args.case, args.overrides)
    roles(case, args.case)
    for key, value, ok in (("--stress", args.stress, math.isfinite(args.stress) and args.stress > 0),
                           ("--strain", args.strain, math.isfinite(args.strain) and 0 < args.strain <= 1e-3),
                           ("--size", args.size, args.size is None or (math.isfinite(args.size) and args.size > 0))):
        if not ok:
            allowed = {"--stress": "a mean stress > 0 Pa", "--strain": "a small strain in (0, 1e-3]",
                       "--size": "a cube side > 0 m"}[key]
            raise CaseError("<command line>", key, value, allowed)
    out_dir = Path(args.out) if args.out else DEFAULT_OUT_ROOT / case.case.name / "elastic"
    check_output_folder(out_dir)
    measure(case, args.case, args.stress, args.strain, out_dir, args.size)
    return 0


def _is_calibration_file(path):
    """A calibration file names its case (``case = "x.toml"``); a case file has a [case] table."""
    import tomllib
    try:
        return isinstance(tomllib.loads(Path(path).read_text(encoding="utf-8")).get("case"), str)
    except (OSError, ValueError):
        return False  # load_case reports it


def _calibrate(args):
    """``cosim calibrate``: one process; the calibration file and its cases checked first."""
    from cosim.case.calibration import load_calibration
    from cosim.lab.calibrate import run_calibration
    from cosim.outputs import check_output_folder, mpi_comm
    if mpi_comm().size > 1:
        raise CaseError("<command line>", "mpirun", mpi_comm().size, "cosim calibrate runs on one process")
    load_calibration(args.calibration)
    out_dir = Path(args.out) if args.out else DEFAULT_OUT_ROOT / "calibrate" / Path(args.calibration).stem
    check_output_folder(out_dir)
    outcome = run_calibration(args.calibration, out_dir, confirm_runs=not args.no_confirm)
    return 0 if outcome.status == "reached" else EXIT_RUN_FAILED


def _info():
    from cosim.outputs import runtime, say, versions
    for name, version in versions().items():
        say(f"{name:10s} {version}")
    for name, value in runtime().items():
        say(f"{name:10s} {value}")
    return 0


def _schema():
    from cosim.outputs import say
    from cosim.schema_doc import default_value, walk

    for entry in walk():
        field = entry.field
        if entry.model is not None:
            header = f"[[{entry.key}]]" if entry.is_list else f"[{entry.key}]"
            say(header + (f"  {field.description}" if field.description else ""))
        else:
            default = default_value(field)
            default = "required" if default is ... else f"default {default!r}"
            ann = field.annotation
            ann = ann.__name__ if isinstance(ann, type) else str(ann).replace("typing.", "")
            say(f"  {entry.key:32s} {ann:38s} {default:22s} {field.description or ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
