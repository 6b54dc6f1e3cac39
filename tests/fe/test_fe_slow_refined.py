"""Refined-mesh versions of the verification cases (``make test-slow``)."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, Material, PrescribedVelocity
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

pytestmark = pytest.mark.slow


def test_total_energy_conserved_over_10000_steps_on_a_fine_mesh():
    tagged = load_geo("bar", 0.025, MPI.COMM_SELF, parameters={"W": 0.1})
    solver = ExplicitSolid(tagged, Material(E=1e7, nu=0.45, rho=1000.0), boundary_conditions=[Fixed("left")])
    solver.velocity[:, 1] = 0.01 * np.sin(0.5 * np.pi * solver.node_coordinates[:, 0])
    solver.energy_interval = 100
    solver.run(10_000)
    total = np.array([row["total"] for row in solver.energy_history])
    assert np.abs(total / total[0] - 1.0).max() < 0.005


def test_p_wave_arrival_error_shrinks_under_refinement():
    """The front is smeared over a few elements: its arrival error is O(h)."""
    material = Material(E=1e7, nu=0.3, rho=1000.0)
    errors = []
    for size in (0.02, 0.005):
        tagged = load_geo("bar", size, MPI.COMM_SELF, parameters={"L": 1.0, "W": 0.02})
        solver = ExplicitSolid(tagged, material, boundary_conditions=[
            Fixed("side_y", (1,)), Fixed("side_z", (2,)), PrescribedVelocity("left", (1e-3, None, None))])
        end = solver.boundary_nodes("right")
        expected = 1.0 / material.p_wave_speed
        while solver.velocity[end, 0].mean() < 1e-3:       # half of the doubled end velocity
            solver.step()
        errors.append(abs(solver.time - 0.5 * solver.dt - expected) / expected)
    assert errors[1] < 0.6 * errors[0] and errors[1] < 0.01
