"""What the FE–DE coupling uses: interface triangles, node positions/velocities, external forces."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Material
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

MATERIALS = {"soil": Material(E=5e7, nu=0.3, rho=1800.0), "footing": Material(E=3e9, nu=0.2, rho=2500.0)}


def interface_area(solver, name):
    x = solver.node_coordinates + solver.displacement
    tri = solver.facet_triangles(name)
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    return solver.comm.allreduce(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def test_interface_triangles_tile_the_footing_underside():
    solver = ExplicitSolid(load_geo("footing", 0.2, MPI.COMM_SELF), MATERIALS)
    triangles = solver.facet_triangles("interface")
    assert triangles.shape[1] == 3
    assert interface_area(solver, "interface") == pytest.approx(0.5 * 0.5, rel=1e-12)
    assert np.allclose(solver.node_coordinates[triangles][..., 2], 0.0)


def test_external_force_impulse_becomes_momentum_of_a_free_body():
    """No supports: internal forces cancel, so Σ M v = Σ F Δt per step (docs/design.md §5.4)."""
    solver = ExplicitSolid(load_geo("footing", 0.3, MPI.COMM_SELF), MATERIALS)
    nodes = solver.boundary_nodes("interface")
    force = np.array([10.0, -20.0, 300.0])
    solver.external_force[nodes] = force / len(nodes)
    solver.run(50)
    momentum = (solver.mass.reshape(-1, 3) * solver.velocity).sum(axis=0)
    assert momentum == pytest.approx(force * solver.dt * 50, rel=1e-12)


def test_mixed_materials_by_cell_group_set_the_time_step():
    solver = ExplicitSolid(load_geo("footing", 0.3, MPI.COMM_SELF), MATERIALS)
    footing = MATERIALS["footing"]
    h_footing = solver.h_cells[solver.tagged_mesh.cells("footing")].min()
    assert solver.dt_critical <= h_footing / footing.p_wave_speed
    assert solver.dt == pytest.approx(0.5 * solver.dt_critical)
    with pytest.raises(ValueError, match="'footing'"):
        ExplicitSolid(solver.tagged_mesh, {"soil": MATERIALS["soil"]})


@pytest.mark.parametrize("group, area", [("interface", 0.25), ("footing_top", 0.25), ("soil_top", 3.75),
                                         ("soil_bottom", 4.0), ("soil_sides", 8.0)])
def test_footing_facet_groups_cover_their_surfaces_exactly_once(group, area):
    assert interface_area(ExplicitSolid(load_geo("footing", 0.3, MPI.COMM_SELF), MATERIALS), group) == \
        pytest.approx(area, rel=1e-12)
