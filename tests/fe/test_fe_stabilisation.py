"""The measured stability bound of step 3's explicit τ-term (see fe_domain.explicit)."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, Material
from fe_domain.explicit import DEFAULT_ALPHA_TAU, STABILITY_CONSTANT, ExplicitSolid, stable_alpha_tau
from fe_domain.mesh import load_geo


def max_energy_ratio(nu, alpha_tau, n_steps=600, mesh_size=0.25):
    """Undamped block, bottom fixed, random initial velocities: max E(t)/E(0)."""
    material = Material(E=1e7, nu=nu, rho=1000.0)
    solver = ExplicitSolid(load_geo("block", mesh_size, MPI.COMM_SELF), material,
                           alpha_tau=alpha_tau, boundary_conditions=[Fixed("bottom")])
    solver.velocity[:] = 1e-3 * np.random.default_rng(0).standard_normal(solver.velocity.shape)
    solver.energy_interval = 20
    with np.errstate(all="ignore"):
        solver.run(n_steps)
    total = np.array([row["total"] for row in solver.energy_history])
    return np.nanmax(np.where(np.isfinite(total), total, np.inf)) / total[0]


@pytest.mark.parametrize("nu", [0.3, 0.45, 0.499])
def test_default_alpha_tau_is_stable_up_to_nu_0499(nu):
    assert max_energy_ratio(nu, DEFAULT_ALPHA_TAU) < 1.01


def test_stable_alpha_tau_is_stable_for_nu_04999():
    assert max_energy_ratio(0.4999, stable_alpha_tau(0.4999)) < 1.01


@pytest.mark.parametrize("nu", [0.3, 0.499])
def test_alpha_tau_above_the_measured_bound_blows_up(nu):
    g_over_k = 3.0 * (1.0 - 2.0 * nu) / (2.0 * (1.0 + nu))
    assert max_energy_ratio(nu, 2.0 * STABILITY_CONSTANT * g_over_k) > 1e3
