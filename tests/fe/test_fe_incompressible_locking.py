"""Nearly incompressible block (ν = 0.4999): the stabilised mixed u–p P1 element of
docs/design.md §4 matches a converged reference, the pure-displacement P1 element locks."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import LinearProblem
from mpi4py import MPI

from fe_domain.boundary import Fixed, MassProportionalDamping, Material, Traction
from fe_domain.explicit import ExplicitSolid, stable_alpha_tau
from fe_domain.mesh import load_geo

E, NU, STRESS = 1e7, 0.4999, 1e4
MATERIAL = Material(E=E, nu=NU, rho=1000.0)


def mean_top_settlement(tagged, u):
    """Area-weighted mean of −u_z over the top face, in units of σ/E."""
    ds = ufl.Measure("ds", domain=tagged.mesh, subdomain_data=tagged.facet_tags)(tagged.groups["top"][1])
    area = fem.assemble_scalar(fem.form(fem.Constant(tagged.mesh, 1.0) * ds))
    return -fem.assemble_scalar(fem.form(u[2] * ds)) / area / (STRESS / E)


def taylor_hood_reference(mesh_size):
    """Static P2–P1 (inf-sup stable) solution: bottom clamped, top pressed by σ.
    Converged to 0.2 %: mesh sizes 0.25 / 0.125 / 0.083 give 0.8988 / 0.9031 / 0.9044."""
    tagged = load_geo("block", mesh_size, MPI.COMM_SELF)
    mesh = tagged.mesh
    element = ufl.MixedElement([ufl.VectorElement("CG", mesh.ufl_cell(), 2),
                                ufl.FiniteElement("CG", mesh.ufl_cell(), 1)])
    W = fem.FunctionSpace(mesh, element)
    (u, p), (w, q) = ufl.TrialFunctions(W), ufl.TestFunctions(W)
    G, K = MATERIAL.shear_modulus, MATERIAL.bulk_modulus
    eps = lambda a: ufl.sym(ufl.grad(a))  # noqa: E731
    a = (2 * G * ufl.inner(ufl.dev(eps(u)), eps(w)) + p * ufl.div(w) + q * ufl.div(u) - p * q / K) * ufl.dx
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)(tagged.groups["top"][1])
    L = ufl.inner(fem.Constant(mesh, np.array([0.0, 0.0, -STRESS])), w) * ds
    W0, _ = W.sub(0).collapse()
    dofs = fem.locate_dofs_topological((W.sub(0), W0), 2, tagged.facets("bottom"))
    bc = fem.dirichletbc(fem.Function(W0), dofs, W.sub(0))
    solution = LinearProblem(a, L, bcs=[bc], petsc_options={
        "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}).solve()
    return mean_top_settlement(tagged, solution.sub(0).collapse())


def explicit_static_settlement(formulation):
    """Damped explicit run until the settlement changes < 0.2 % per 4000 steps.

    The mixed run creeps slowly at the end (step 3's τ-term smooths p by a fixed
    fraction per step, independent of Δt): ≈ 0.88 after 30k steps, ≈ 0.89 in the limit.
    """
    tagged = load_geo("block", 0.25, MPI.COMM_SELF)
    shear_wave_speed = np.sqrt(MATERIAL.shear_modulus / MATERIAL.rho)
    solver = ExplicitSolid(tagged, MATERIAL, formulation=formulation, alpha_tau=stable_alpha_tau(NU),
                           damping=MassProportionalDamping(np.pi * shear_wave_speed),
                           boundary_conditions=[Fixed("bottom")],
                           loads=[Traction("top", (0.0, 0.0, -STRESS))])
    previous = np.inf
    for _ in range(15):
        solver.run(4000)
        settlement = mean_top_settlement(tagged, solver.u)
        if abs(settlement - previous) < 2e-3 * abs(settlement):
            return settlement
        previous = settlement
    raise AssertionError(f"{formulation}: no static state after {solver.step_count} steps")


def test_mixed_formulation_matches_reference_while_displacement_p1_locks():
    reference = taylor_hood_reference(0.125)
    mixed = explicit_static_settlement("mixed")
    displacement = explicit_static_settlement("displacement")
    assert mixed == pytest.approx(reference, rel=0.05)
    assert displacement < 0.5 * reference      # locked: far too stiff
