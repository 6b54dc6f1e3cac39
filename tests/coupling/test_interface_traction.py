"""The interface traction field t_a = f_a / A_a (cosim.interface): lumped nodal areas that
tile the interface, a uniform traction recovered exactly, and the field in the XDMF."""
import numpy as np
import pytest
from mpi4py import MPI

from cosim.interface import Interface, nodal_areas
from fe_domain.build import build_solid
from fe_domain.output import FieldWriter


def test_lumped_nodal_areas_are_a_third_of_each_triangle():
    vertices = np.array([[0.0, 0, 0], [2, 0, 0], [0, 1, 0], [2, 1, 0]])
    triangles = np.array([[0, 1, 2], [1, 3, 2]])
    assert nodal_areas(vertices, triangles) == pytest.approx([1 / 3, 2 / 3, 2 / 3, 1 / 3], rel=1e-15)


@pytest.fixture(scope="module")
def plate():
    solid = build_solid("block.geo", 0.0025, material={"E": 1.0e7, "nu": 0.3, "rho": 2000.0},
                        geometry_parameters={"Lx": 0.01, "Ly": 0.02, "Lz": 0.004}, formulation="mixed")
    return solid, Interface(solid, ["bottom"], material=0)


def test_nodal_areas_tile_the_interface(plate):
    solid, interface = plate
    assert len(interface.nodal_area) == len(interface.owned_nodes)
    assert solid.comm.allreduce(interface.nodal_area.sum()) == pytest.approx(0.01 * 0.02, rel=1e-12)


def test_a_uniform_traction_is_recovered_at_every_node(plate, tmp_path):
    """Vertex impulses of a uniform traction t0 (t0 A_a Δt on node a) give back t0 at every node."""
    solid, interface = plate
    t0 = np.array([1.5e3, -0.5e3, 2.0e4])
    window = 1e-5
    area = nodal_areas(interface.facets.vertices, interface.facets.triangles)
    interface.facets.vertex_impulse[:] = t0 * area[:, None] * window
    interface.receive_forces(window)
    assert interface.traction() == pytest.approx(np.tile(t0, (len(interface.owned_nodes), 1)), rel=1e-12)
    field = interface.traction_field().x.array.reshape(-1, 3)
    off = np.setdiff1d(np.arange(solid.n_owned_nodes), interface.owned_nodes)
    assert np.all(field[off] == 0.0)
    out = MPI.COMM_WORLD.bcast(tmp_path, root=0)
    writer = FieldWriter(solid, out / "fields", extra_fields=[interface.traction_field])
    writer.write()
    writer.close()
    assert 'Name="interface_traction"' in (out / "fields.xdmf").read_text()
