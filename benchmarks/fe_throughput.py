"""FE throughput: cell-steps per second of the explicit mixed u–p solid (docs/design.md §4).

    .venv/bin/python benchmarks/fe_throughput.py            # ≈50k and ≈400k tets, 1 and 2 ranks
    .venv/bin/python benchmarks/fe_throughput.py --sizes 0.05 --ranks 1

The driver meshes the unit block (meshes/block.geo) once per size into
benchmarks/out/*.msh, then runs itself as a worker under
``mpirun -n N python benchmarks/fe_throughput.py --worker MSH`` for each rank count.
A worker times ``ExplicitSolid.step()`` (bottom fixed, top traction; the compiled step,
fe_domain/compiled.py — on several ranks its owned rows and DOLFINx's ghost scatters — and
the same mixed solid stepped with PETSc's products beside it, ``compiled=False``) and the floor:
one bare DOLFINx assembly of the internal force ∫ Bᵀ(s(u) + p I) (step 1 alone)
into a preallocated array plus its reverse ghost scatter, on the same mesh.  The
step applies sparse operators assembled once (K_dev, Bᵀ, P, L: six matrix–vector
products for a mixed step, one for the displacement-only P1 step, which is listed
too), so it costs less than the floor's element pass.  Floor, mixed step and
displacement step are timed back to back in one process, REPEATS times; the table
gives the median of each time and of each step/floor ratio, and the operators'
storage per cell (``ExplicitSolid.operator_bytes``, summed over ranks, plus the compiled
copy, ``compiled_operator_bytes``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
import mpi_launch  # noqa: E402

OUT = ROOT / "benchmarks" / "out"
DEFAULT_SIZES = (0.045, 0.0226)      # ≈ 50k and ≈ 400k tetrahedra in the unit cube
MIN_SECONDS = 0.5
REPEATS = 7


def _time_per_call(function, min_seconds=MIN_SECONDS, min_calls=5):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    function()                                   # warm-up
    comm.barrier()
    calls, start = 0, time.perf_counter()
    while True:
        function()
        calls += 1
        elapsed = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        if calls >= min_calls and elapsed >= min_seconds:
            return elapsed / calls


def worker(msh_path: str) -> None:
    import dolfinx
    import numpy as np
    import ufl
    from dolfinx import fem
    from mpi4py import MPI

    from fe_domain import forms
    from fe_domain.boundary import Fixed, Material, Traction
    from fe_domain.explicit import ExplicitSolid
    from fe_domain.mesh import load_msh

    comm = MPI.COMM_WORLD
    tagged = load_msh(msh_path, comm)
    n_cells = tagged.mesh.topology.index_map(3).size_global
    result = {"cells": n_cells, "ranks": comm.size}
    solvers = {}
    for formulation in ("mixed", "displacement"):
        solver = ExplicitSolid(tagged, Material(E=1e7, nu=0.3, rho=1000.0), formulation=formulation,
                               boundary_conditions=[Fixed("bottom")], loads=[Traction("top", (0.0, 0.0, -1e4))])
        solvers[formulation] = solver
        result[f"{formulation}_bytes_per_cell"] = comm.allreduce(solver.operator_bytes()) / n_cells
        result[f"{formulation}_compiled_bytes_per_cell"] = comm.allreduce(solver.compiled_operator_bytes()) / n_cells
    solvers["mixed_petsc"] = ExplicitSolid(tagged, Material(E=1e7, nu=0.3, rho=1000.0), compiled=False,
                                           boundary_conditions=[Fixed("bottom")],
                                           loads=[Traction("top", (0.0, 0.0, -1e4))])
    solver = solvers["mixed"]
    internal_force = fem.form(ufl.inner(forms.deviatoric_stress(solver.u, solver.G)
                                        + solver.p * ufl.Identity(3), ufl.grad(ufl.TestFunction(solver.V))) * ufl.dx)
    vector = dolfinx.la.vector(solver.V.dofmap.index_map, 3)

    def floor():
        vector.array[:] = 0.0
        fem.assemble_vector(vector.array, internal_force)
        vector.scatter_reverse(dolfinx.la.ScatterMode.add)

    samples = {"floor": [], **{name: [] for name in solvers}}
    for _ in range(REPEATS):
        samples["floor"].append(_time_per_call(floor))
        for formulation, solver in solvers.items():
            samples[formulation].append(_time_per_call(solver.step))
    floor_times = np.array(samples["floor"])
    for name, times in samples.items():
        result[name] = float(np.median(times))
        if name != "floor":
            result[f"{name}_ratio"] = float(np.median(np.array(times) / floor_times))
    if comm.rank == 0:
        print("RESULT " + json.dumps(result), flush=True)


def mesh_file(size: float) -> Path:
    from fe_domain.mesh import write_msh
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"block_h{size:g}.msh"
    if not path.exists():
        write_msh("block", path, size)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=float, nargs="+", default=DEFAULT_SIZES, help="mesh sizes (m)")
    parser.add_argument("--ranks", type=int, nargs="+", default=(1, 2), help="MPI rank counts")
    parser.add_argument("--worker", metavar="MSH", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker)
        return
    env = mpi_launch.mpi_env()  # OpenMPI's run-as-root and oversubscribe permissions where unset
    rows = []
    for size in args.sizes:
        path = mesh_file(size)
        for ranks in args.ranks:
            command = ["mpirun", "-n", str(ranks), sys.executable, __file__, "--worker", str(path)]
            # the RESULT line's JSON, escape sequences and trailing text tolerated; a failed
            # worker ends the benchmark with mpirun's exit code and stderr, once
            rows.append(mpi_launch.run_json(command, prefix="RESULT ", env=env, cwd=ROOT))
            print(f"  done: h = {size:g} m, {ranks} rank(s)", file=sys.stderr, flush=True)
    header = (f"{'cells':>8} {'ranks':>5} | {'mixed step':>10} {'cell-steps/s':>13} {'/floor':>6} | "
              f"{'displ. step':>11} {'cell-steps/s':>13} {'/floor':>6} | {'floor':>8} | {'PETSc step':>10} | "
              f"{'B/cell':>20}")
    print(f"Explicit FE step time (ms) and throughput, medians of {REPEATS} back-to-back repeats; "
          "floor = one bare DOLFINx assembly of f_int; PETSc step = the mixed step with PETSc's products; "
          "B/cell = operator storage, mixed / displ. (+ compiled copy)")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['cells']:>8} {r['ranks']:>5} | {1e3 * r['mixed']:>10.2f} {r['cells'] / r['mixed']:>13.3e} "
              f"{r['mixed_ratio']:>6.2f} | {1e3 * r['displacement']:>11.2f} "
              f"{r['cells'] / r['displacement']:>13.3e} {r['displacement_ratio']:>6.2f} | "
              f"{1e3 * r['floor']:>8.2f} | "
              + (f"{1e3 * r['mixed_petsc']:>10.2f}" if "mixed_petsc" in r else f"{'':>10}")
              + f" | {r['mixed_bytes_per_cell']:>6.0f} / {r['displacement_bytes_per_cell']:>4.0f}"
              + (f" (+{r['mixed_compiled_bytes_per_cell']:.0f})" if r['mixed_compiled_bytes_per_cell'] else ""))


if __name__ == "__main__":
    main()
