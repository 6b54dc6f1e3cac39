"""Damped explicit runs converge to the static solution (docs/design.md §4.7 damping)."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, LocalNonViscousDamping, MassProportionalDamping, Material, Traction
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

E, NU, STRESS = 1e7, 0.3, 1e4
MATERIAL = Material(E=E, nu=NU, rho=1000.0)


@pytest.mark.parametrize("damping", [
    LocalNonViscousDamping(0.7),
    MassProportionalDamping(2 * np.pi * MATERIAL.p_wave_speed / 4.0),
], ids=["local", "mass-proportional"])
def test_uniaxial_compression_converges_to_analytic_displacement(damping):
    """Unit cube on three symmetry rollers, top pressed by σ: u_z(top) = −σH/E,
    u_x(x=1) = νσ/E, and the bottom supports push back with σA."""
    tagged = load_geo("block", 0.25, MPI.COMM_SELF)
    solver = ExplicitSolid(tagged, MATERIAL, damping=damping,
                           boundary_conditions=[Fixed("x0", (0,)), Fixed("y0", (1,)), Fixed("bottom", (2,))],
                           loads=[Traction("top", (0.0, 0.0, -STRESS))])
    solver.run(1500)
    top, side = solver.boundary_nodes("top"), solver.boundary_nodes("x1")
    assert solver.displacement[top, 2].mean() == pytest.approx(-STRESS / E, rel=0.01)
    assert solver.displacement[side, 0].mean() == pytest.approx(NU * STRESS / E, rel=0.01)
    assert solver.reaction("bottom") == pytest.approx([0.0, 0.0, STRESS * 1.0], abs=0.01 * STRESS)
