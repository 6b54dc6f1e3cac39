"""The FE soil's state at rest under gravity (docs/design.md §4.7): a geostatic initial stress
with a given K0 starts in equilibrium; without one, a column loaded by its weight between
rollers settles to K0 = ν / (1 − ν)."""

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fe_domain.boundary import BodyForce, Fixed, GeostaticStress, LocalNonViscousDamping, Material
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo
from fe_domain.output import FieldWriter

E, NU, RHO, G = 1e6, 0.3, 1600.0, 9.81
GRAVITY = (0.0, 0.0, -G)
ROLLERS = [Fixed("x0", (0,)), Fixed("x1", (0,)), Fixed("y0", (1,)), Fixed("y1", (1,)), Fixed("bottom", (2,))]


def column(loads, damping=None):
    """The unit cube (meshes/block.geo, z from 0 to 1) between rollers on its sides and base."""
    return ExplicitSolid(load_geo("block", 0.25, MPI.COMM_SELF), Material(E=E, nu=NU, rho=RHO),
                         boundary_conditions=ROLLERS, loads=loads, damping=damping)


def cell_midpoint_values(solid, expression):
    """A UFL expression at the cell midpoints (DG0 interpolation) and the midpoints' z."""
    field = fem.Function(solid.D0)
    field.interpolate(fem.Expression(expression, solid.D0.element.interpolation_points()))
    midpoints = solid.node_coordinates[solid.Q.dofmap.list.array.reshape(-1, 4)].mean(axis=1)
    return field.x.array[solid.D0.dofmap.list.array], midpoints[:, 2]


@pytest.mark.parametrize("k0", [0.4, 1.0, 1.6])
def test_geostatic_stress_with_given_k0_starts_in_equilibrium(k0):
    """div σ0 + ρg = 0 holds exactly for the P1 element (σ0 linear, ∇w constant): the column
    given its weight and σ0 does not move, undamped, over 500 steps; the base carries the
    weight; σ0 is −ρ g d vertically and K0 times that horizontally."""
    solid = column([BodyForce(GRAVITY), GeostaticStress(GRAVITY, (0.0, 0.0, 1.0), k0, ("solid",))])
    weight = RHO * G * 1.0
    solid.run(500)
    settlement = RHO * G / E  # the order of the column's settlement from zero stress (H = 1 m)
    assert np.abs(solid.displacement).max() < 1e-9 * settlement
    assert np.abs(solid.pressure).max() < 1e-9 * weight
    assert solid.reaction("bottom")[2] == pytest.approx(weight, rel=1e-12)  # x, y: the side rollers at its edges
    sigma0 = solid.initial_stress
    vertical, z = cell_midpoint_values(solid, sigma0[2, 2])
    horizontal, _ = cell_midpoint_values(solid, sigma0[0, 0])
    shear, _ = cell_midpoint_values(solid, sigma0[0, 2])
    assert vertical == pytest.approx(-RHO * G * (1.0 - z), rel=1e-12)
    assert horizontal == pytest.approx(k0 * vertical, rel=1e-12)
    assert np.abs(shear).max() == 0.0


def test_column_under_its_weight_settles_to_k0_of_poisson_ratio():
    """Without an initial stress the column, loaded by its weight, comes to rest (local damping)
    with σ_h = ν / (1 − ν) σ_v: its mean stress p = σ_v (1 + 2 K0) / 3 at mid-height (σ_v = −ρ g d)."""
    solid = column([BodyForce(GRAVITY)], damping=LocalNonViscousDamping(0.7))
    solid.run(3000)
    k0 = NU / (1.0 - NU)
    z = solid.node_coordinates[:, 2]
    middle = np.isclose(z, 0.5)
    expected = -RHO * G * 0.5 * (1.0 + 2.0 * k0) / 3.0
    assert solid.pressure[middle].mean() == pytest.approx(expected, rel=0.01)
    assert solid.reaction("bottom")[2] == pytest.approx(RHO * G, rel=0.01)


def test_fields_with_initial_stress_give_the_whole_mean_stress(tmp_path):
    """The XDMF's mean_stress is p + tr σ0 / 3 (the state is the initial one: p = 0) and its
    von Mises stress that of σ0's deviator, |σ_v| (1 − K0)."""
    k0 = 0.5
    solid = column([BodyForce(GRAVITY), GeostaticStress(GRAVITY, (0.0, 0.0, 1.0), k0, ("solid",))])
    writer = FieldWriter(solid, tmp_path / "fields")
    writer.write()
    writer.close()
    fields = {name: function for function, _ in writer.cell_fields for name in [function.name]}
    z = solid.node_coordinates[solid.Q.dofmap.list.array.reshape(-1, 4)].mean(axis=1)[:, 2]
    sigma_v = -RHO * G * (1.0 - z)
    cells = solid.D0.dofmap.list.array
    assert fields["mean_stress"].x.array[cells] == pytest.approx(sigma_v * (1.0 + 2.0 * k0) / 3.0, rel=1e-12)
    assert fields["von_mises"].x.array[cells] == pytest.approx(np.abs(sigma_v) * (1.0 - k0), rel=1e-12)
    assert (tmp_path / "fields.xdmf").exists()
