"""The ``cosim`` command line: ``run``, ``check``, ``series``, ``info``, ``schema``.

Exit codes: 0 success, 2 bad input (case file, key, value named), 1 runtime failure.
Under ``mpirun -n N`` every rank runs, only rank 0 prints.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from cosim.errors import EXIT_BAD_INPUT, CaseError

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
                           description="Validate CASE (types, ranges, consistency, referenced files) "
                                       "without running it.")
    check.add_argument("case", metavar="CASE.toml")
    check.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")

    series = sub.add_parser("series", help="direct shear series: cases x normal stresses, Mohr-Coulomb fit",
                            description="Run each direct_shear CASE (one specimen each, e.g. dense and loose) at "
                                        "every normal stress and fit the Mohr-Coulomb envelope (phi, c) of peak "
                                        "and residual strength.")
    series.add_argument("cases", metavar="CASE.toml", nargs="+", help="direct_shear case files")
    series.add_argument("--stresses", type=float, nargs="+", default=[50e3, 100e3, 200e3], metavar="PA",
                        help="normal stresses [Pa] (default 50e3 100e3 200e3)")
    series.add_argument("--out", metavar="DIR", default="runs/out/direct_shear_series", help="output folder")
    series.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override one value in every case; repeatable")

    sub.add_parser("info", help="versions of the stack, MPI size and Numba threads",
                   description="Print versions of DOLFINx, Numba, mpi4py, petsc4py, gmsh, meshio, the MPI size "
                               "and Numba threads.")
    sub.add_parser("schema", help="list every case-file key with its type, unit and default",
                   description="Print the case-file schema: every key with its type, unit, default and allowed "
                               "values.")
    return p


def main(argv=None):
    args = _parser().parse_args(argv)
    from cosim.outputs import say
    try:
        if args.command == "info":
            return _info()
        if args.command == "schema":
            return _schema()
        if args.command == "series":
            from cosim.lab.series import run_series
            for stress in args.stresses:
                if not stress > 0:
                    raise CaseError("<command line>", "--stresses", stress, "normal stresses must be > 0 Pa")
            run_series(args.cases, args.stresses, Path(args.out), args.overrides)
            say(f"outputs: {Path(args.out).resolve()}")
            return 0
        from cosim.case import load_case
        case, resolved = load_case(args.case, args.overrides)
        if args.command == "check":
            say(f"{args.case}: OK (kind '{case.case.kind}', name '{case.case.name}')")
            return 0
        out_dir = Path(args.out) if args.out else DEFAULT_OUT_ROOT / case.case.name
        app = importlib.import_module(f"cosim.apps.{case.case.kind}")
        app.prepare(case, args.case)  # everything that can fail on input, before any computation
        out_dir.mkdir(parents=True, exist_ok=True)
        app.run(case, resolved, args.case, out_dir, resume=args.resume)
        say(f"outputs: {out_dir.resolve()}")
        return 0
    except CaseError as exc:
        say(f"cosim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def _info():
    from cosim.outputs import runtime, say, versions
    for name, version in versions().items():
        say(f"{name:10s} {version}")
    for name, value in runtime().items():
        say(f"{name:10s} {value}")
    return 0


def _schema():
    from cosim.case import Case, _inner_model
    from cosim.outputs import say

    def walk(model, prefix):
        for name, field in model.model_fields.items():
            inner = _inner_model(field.annotation)
            key = f"{prefix}{name}"
            if inner is not None:
                is_list = "list" in str(field.annotation)
                header = f"[[{key}]]" if is_list else f"[{key}]"
                say(header + (f"  {field.description}" if field.description else ""))
                walk(inner, key + ".")
            else:
                default = "required" if field.is_required() else f"default {field.default!r}"
                ann = field.annotation
                ann = ann.__name__ if isinstance(ann, type) else str(ann).replace("typing.", "")
                say(f"  {key:32s} {ann:38s} {default:22s} {field.description or ''}")
    walk(Case, "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
