"""The static solution of an ExplicitSolid's discretisation, K u = f, for checks and for the
FE-only twin of an embedded case: the same P1 mesh, materials, supports and loads as the
explicit run, without its approach to rest. Only the displacement formulation
(``formulation="displacement"``: K is assembled); one rank (a replicated copy under mpirun);
PETSc's direct solve (LU), factorised once."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class StaticSolver:
    """K u = f(time) of ``solid`` with its fixed dofs held at zero; K is factorised on the first
    solve and kept (the loads change with time, the stiffness does not)."""

    def __init__(self, solid):
        if solid.mixed or solid.comm.size > 1:
            raise ValueError("a static solve needs a displacement-formulation solid on one rank")
        self.solid = solid
        self.fixed = solid.fixed_dofs.astype(PETSc.IntType)
        stiffness = solid.operators()["K"].copy()
        stiffness.zeroRowsColumns(self.fixed, 1.0)
        self.solver = PETSc.KSP().create(MPI.COMM_SELF)
        self.solver.setOperators(stiffness)
        self.solver.setType("preonly")
        self.solver.getPC().setType("lu")
        self.rhs = stiffness.createVecRight()
        self.solution = self.rhs.duplicate()

    def solve(self, time: float = np.inf) -> None:
        """Set the solid's displacement to the solution under the loads at ``time`` (default every
        ramp completed; :meth:`ExplicitSolid.load_vector`) and its clock to ``time`` when finite."""
        self.rhs.array[:] = self.solid.load_vector(time).ravel()
        self.rhs.array[self.fixed] = 0.0
        self.solver.solve(self.rhs, self.solution)
        self.solid.displacement[:] = self.solution.array.reshape(-1, 3)
        if np.isfinite(time):
            self.solid.time = time


def solve_static(solid, time: float = np.inf) -> None:
    """One static solve of ``solid`` (:class:`StaticSolver`)."""
    StaticSolver(solid).solve(time)
