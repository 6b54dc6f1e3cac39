"""The static solution of an ExplicitSolid's discretisation, K u = f, for checks: the same P1
mesh, materials, supports and loads (at full amplitude) as the explicit run, without its
approach to rest. Only the displacement formulation (``formulation="displacement"``: K is
assembled); one rank; PETSc's direct solve (LU)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


def solve_static(solid, time: float = np.inf) -> None:
    """Set ``solid``'s displacement to the solution of K u = f(time) with its fixed dofs held at
    zero (f: :meth:`ExplicitSolid.load_vector`, default every ramp completed)."""
    if solid.mixed or solid.comm.size > 1:
        raise ValueError("solve_static: a displacement-formulation solid on one rank")
    stiffness = solid.operators()["K"].copy()
    fixed = solid.fixed_dofs.astype(PETSc.IntType)
    rhs = stiffness.createVecRight()
    rhs.array[:] = solid.load_vector(time).ravel()
    rhs.array[fixed] = 0.0
    stiffness.zeroRowsColumns(fixed, 1.0)
    solver = PETSc.KSP().create(MPI.COMM_SELF)
    solver.setOperators(stiffness)
    solver.setType("preonly")
    solver.getPC().setType("lu")
    solution = rhs.duplicate()
    solver.solve(rhs, solution)
    solid.displacement[:] = solution.array.reshape(-1, 3)
