"""P-wave front in a laterally confined bar arrives at L/c_p (docs/design.md §4.6: Δt from h_min, c_p)."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, Material, PrescribedVelocity
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

LENGTH = 1.0
IMPACT_VELOCITY = 1e-3


@pytest.mark.parametrize("formulation", ["mixed", "displacement"])
def test_p_wave_front_reaches_free_end_at_length_over_cp(formulation):
    """Rollers on the sides make the bar 1D (plane P-wave, speed c_p); the left end is
    pushed at v0.  At the free right end the velocity doubles to 2 v0 when the front
    arrives; the arrival time is where the end velocity crosses v0 (half of 2 v0)."""
    material = Material(E=1e7, nu=0.3, rho=1000.0)
    tagged = load_geo("bar", 0.01, MPI.COMM_SELF, parameters={"L": LENGTH, "W": 0.02})
    solver = ExplicitSolid(tagged, material, formulation=formulation, boundary_conditions=[
        Fixed("side_y", (1,)), Fixed("side_z", (2,)),
        PrescribedVelocity("left", (IMPACT_VELOCITY, None, None))])
    end = solver.boundary_nodes("right")
    expected = LENGTH / material.p_wave_speed
    times, end_velocity = [], []
    while solver.time < 1.5 * expected:
        solver.step()
        times.append(solver.time - 0.5 * solver.dt)        # v is at the half step
        end_velocity.append(solver.velocity[end, 0].mean())
    times, end_velocity = np.array(times), np.array(end_velocity)
    i = np.argmax(end_velocity > IMPACT_VELOCITY)
    arrival = np.interp(IMPACT_VELOCITY, end_velocity[i - 1:i + 1], times[i - 1:i + 1])
    assert arrival == pytest.approx(expected, rel=0.02)
    assert end_velocity[-1] == pytest.approx(2 * IMPACT_VELOCITY, rel=0.05)
