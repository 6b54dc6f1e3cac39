"""The explicit FE's exact stability limit (ExplicitSolid.refine_critical_step, docs/design.md
§4.6): 2/ω_max of the lumped-mass central-difference step, against a dense eigensolution, and
shown to be the limit by stepping just below and just above it."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, Material
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

STEEL = Material(E=2.0e7, nu=0.2, rho=2500.0)


def block(formulation="displacement"):
    """The unit cube (meshes/block.geo), its base fixed, undamped."""
    return ExplicitSolid(load_geo("block", 0.25, MPI.COMM_SELF), STEEL, boundary_conditions=[Fixed("bottom")],
                         formulation=formulation)


def test_the_limit_is_two_over_the_highest_frequency_of_the_lumped_system():
    """ω_max² = the largest eigenvalue of M^-½ K M^-½ (dense, numpy) to 1e-8, and the cell
    estimate min h/c_p differs from it (it is no bound)."""
    solid = block()
    estimate = solid.dt_critical
    stiffness = solid.operators()["K"]
    n = 3 * solid.n_owned_nodes
    dense = np.zeros((n, n))
    rows, cols, values = stiffness.getValuesCSR() if stiffness.getType() == "aij" else \
        stiffness.convert("aij").getValuesCSR()
    for i in range(n):
        dense[i, cols[rows[i]:rows[i + 1]]] = values[rows[i]:rows[i + 1]]
    root = 1.0 / np.sqrt(solid.mass[:n])
    omega_max = np.sqrt(np.linalg.eigvalsh(root[:, None] * dense * root[None, :])[-1])
    limit = solid.refine_critical_step()
    assert limit == pytest.approx(2.0 / omega_max, rel=1e-8)
    assert solid.dt_critical == limit
    assert abs(limit / estimate - 1.0) > 0.05


def max_energy_ratio(solid, fraction, steps=400):
    """Step at ``fraction`` of the exact limit from random velocities: max E(t)/E(0)."""
    limit = solid.refine_critical_step()
    solid.dt_critical = 2.0 * limit  # let the test step past the limit
    solid.dt = fraction * limit
    solid.velocity[:] = 1e-3 * np.random.default_rng(0).standard_normal(solid.velocity.shape)
    solid.energy_interval = 10
    with np.errstate(all="ignore"):
        solid.run(steps)
    total = np.array([row["total"] for row in solid.energy_history])
    return np.nanmax(np.where(np.isfinite(total), total, np.inf)) / total[0]


def test_stepping_just_below_the_limit_is_stable_and_just_above_blows_up():
    """Below: bounded, the staggered step's energy (u at n, v at n + ½) of a mode of frequency ω
    swinging by at most 1/(1 − (ω Δt/2)²) about its conserved value (25 at 0.98 of the limit);
    above: the highest mode grows by ≈ 1 + 2√(2·0.02) a step."""
    assert max_energy_ratio(block(), 0.98) < 1.0 / (1.0 - 0.98 ** 2)
    assert max_energy_ratio(block(), 1.02) > 1e3


def test_the_mixed_form_keeps_its_cell_estimate():
    with pytest.raises(ValueError, match="displacement formulation"):
        block("mixed").refine_critical_step()
