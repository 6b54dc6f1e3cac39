"""The step's assembled operators reproduce the integrals of docs/design.md §4.2 (as vector assemblies) to round-off.

The solver applies K_dev, Bᵀ, P, L (and the transposes of Bᵀ and P) assembled once;
here each product is compared with a DOLFINx vector assembly of the integral it
replaces, for random nodal fields, on 1 rank and (``-m mpi``) on all ranks.
"""

import dolfinx
import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fe_domain import forms
from fe_domain.boundary import Material
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

MATERIALS = {"soil": Material(E=5e7, nu=0.3, rho=1800.0), "footing": Material(E=3e9, nu=0.2, rho=2500.0)}


def assembled(solver, integrand, bs):
    vector = dolfinx.la.vector(solver.Q.dofmap.index_map, bs)
    fem.assemble_vector(vector.array, fem.form(integrand))
    vector.scatter_reverse(dolfinx.la.ScatterMode.add)
    return vector.array[:bs * solver.n_owned_nodes]


def product(matrix, x, y, transpose=False):
    (matrix.multTranspose if transpose else matrix.mult)(x.vector, y.vector)
    space = y.function_space
    return y.x.array[:space.dofmap.index_map_bs * space.dofmap.index_map.size_local].copy()


def relative_error(a, b, comm):
    return comm.allreduce(np.abs(a - b).max(), op=MPI.MAX) / comm.allreduce(np.abs(b).max(), op=MPI.MAX)


def check_operators(comm, formulation):
    solver = ExplicitSolid(load_geo("footing", 0.3, comm), MATERIALS, formulation=formulation)
    rng = np.random.default_rng(comm.rank)
    u, v, pi = (fem.Function(solver.V) for _ in range(3))
    p, y_q = fem.Function(solver.Q), fem.Function(solver.Q)
    y_v = fem.Function(solver.V)
    for fn in (u, v, pi, p):
        fn.x.array[:] = rng.standard_normal(fn.x.array.shape)
        fn.x.scatter_forward()
    w, q = ufl.TestFunction(solver.V), ufl.TestFunction(solver.Q)
    operators = solver.operators()
    G, K, tau = solver.G, solver.K, solver.tau
    errors = {}
    if formulation == "displacement":
        stress = forms.deviatoric_stress(u, G) + K * ufl.div(u) * ufl.Identity(3)
        errors["f_int"] = relative_error(product(operators["K"], u, y_v),
                                         assembled(solver, ufl.inner(stress, ufl.grad(w)) * ufl.dx, 3), comm)
        return errors
    stress = forms.deviatoric_stress(u, G) + p * ufl.Identity(3)
    f_int = product(operators["K_dev"], u, y_v) + product(operators["B^T"], p, y_v)
    errors["f_int"] = relative_error(f_int, assembled(solver, ufl.inner(stress, ufl.grad(w)) * ufl.dx, 3), comm)
    errors["projection"] = relative_error(product(operators["P"], p, y_v),
                                          assembled(solver, tau * ufl.inner(w, ufl.grad(p)) * ufl.dx, 3), comm)
    errors["volumetric"] = relative_error(product(operators["B^T"], v, y_q, transpose=True),
                                          assembled(solver, q * ufl.div(v) * ufl.dx, 1), comm)
    stabilisation = product(operators["L"], p, y_q) + product(operators["P"], pi, y_q, transpose=True)
    errors["stabilisation"] = relative_error(
        stabilisation, assembled(solver, tau * ufl.inner(ufl.grad(q), ufl.grad(p) + pi) * ufl.dx, 1), comm)
    return errors


@pytest.mark.parametrize("formulation", ["mixed", "displacement"])
def test_operators_reproduce_the_step_integrals(formulation):
    errors = check_operators(MPI.COMM_SELF, formulation)
    assert max(errors.values()) < 1e-13, errors


@pytest.mark.mpi
@pytest.mark.parametrize("formulation", ["mixed", "displacement"])
def test_operators_reproduce_the_step_integrals_on_all_ranks(formulation):
    errors = check_operators(MPI.COMM_WORLD, formulation)
    assert max(errors.values()) < 1e-13, errors


def test_operator_memory_per_cell_is_bounded():
    """Sparse storage of the step operators: ≈ 0.4 kB per tetrahedron (mixed), see the benchmark."""
    solver = ExplicitSolid(load_geo("block", 0.1, MPI.COMM_SELF), Material(E=1e7, nu=0.3, rho=1000.0))
    n_cells = solver.mesh.topology.index_map(3).size_local
    assert solver.operator_bytes() / n_cells < 600
    # the compiled copy (one rank): the same 16 values per node pair, one index instead of eight
    assert 0 < solver.compiled_operator_bytes() < solver.operator_bytes()
