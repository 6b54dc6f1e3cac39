"""gmsh pipeline: .geo sources → DOLFINx meshes whose tags are addressed by name."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.mesh import load_geo, load_mesh, load_msh, msh_to_vtu, write_msh

EXPECTED_GROUPS = {
    "bar": {"solid"}, "block": {"solid"}, "footing": {"soil", "footing"}, "cavity": {"rock"},
}
EXPECTED_FACETS = {
    "bar": {"left", "right", "side_y", "side_z"},
    "block": {"x0", "x1", "y0", "y1", "bottom", "top"},
    "footing": {"interface", "footing_top", "soil_top", "soil_bottom", "soil_sides"},
    "cavity": {"cavity", "bottom", "top", "sides_x", "ends_y"},
}
SIZES = {"bar": 0.05, "block": 0.25, "footing": 0.3, "cavity": 0.5}


def _volume(tagged):
    x = tagged.mesh.geometry.x
    cells = tagged.mesh.geometry.dofmap.array.reshape(-1, 4)
    cells = cells[:tagged.mesh.topology.index_map(3).size_local]
    e = x[cells[:, 1:]] - x[cells[:, :1]]
    local = np.abs(np.einsum("ij,ij->i", e[:, 0], np.cross(e[:, 1], e[:, 2]))).sum() / 6.0
    return tagged.mesh.comm.allreduce(local)


@pytest.mark.parametrize("name", sorted(EXPECTED_GROUPS))
def test_every_geo_source_gives_named_cell_and_facet_groups(name):
    tagged = load_geo(name, SIZES[name], MPI.COMM_SELF)
    assert set(tagged.names(3)) == EXPECTED_GROUPS[name]
    assert set(tagged.names(2)) == EXPECTED_FACETS[name]
    for facet_group in EXPECTED_FACETS[name]:
        assert len(tagged.facets(facet_group)) > 0, facet_group
    cells = np.concatenate([tagged.cells(g) for g in EXPECTED_GROUPS[name]])
    assert len(np.unique(cells)) == tagged.mesh.topology.index_map(3).size_local


def test_cavity_volume_is_block_minus_cylinder():
    tagged = load_geo("cavity", 0.25, MPI.COMM_SELF)
    assert _volume(tagged) == pytest.approx(4.0 * 4.0 * 1.0 - np.pi * 0.5 ** 2, rel=1e-2)


def test_mesh_size_and_geometry_parameters_are_honoured():
    coarse = load_geo("block", 0.5, MPI.COMM_SELF, parameters={"Lz": 2.0})
    fine = load_geo("block", 0.25, MPI.COMM_SELF, parameters={"Lz": 2.0})
    assert _volume(coarse) == pytest.approx(2.0, rel=1e-12)
    assert fine.mesh.topology.index_map(3).size_local > 4 * coarse.mesh.topology.index_map(3).size_local


def test_unknown_group_name_is_a_clear_error():
    tagged = load_geo("block", 0.5, MPI.COMM_SELF)
    with pytest.raises(KeyError, match="'lid' not in mesh"):
        tagged.facets("lid")
    with pytest.raises(KeyError, match="dimension"):
        tagged.facets("solid")


def test_msh_file_round_trip_keeps_names_and_converts_with_meshio(tmp_path):
    msh = write_msh("footing", tmp_path / "footing.msh", 0.4)
    from_geo = load_geo("footing", 0.4, MPI.COMM_SELF)
    from_msh = load_mesh(msh, comm=MPI.COMM_SELF)
    assert from_msh.groups == from_geo.groups
    assert len(from_msh.facets("interface")) == len(from_geo.facets("interface"))
    assert load_msh(msh, MPI.COMM_SELF).mesh.topology.index_map(3).size_local == \
        from_geo.mesh.topology.index_map(3).size_local
    import meshio
    vtu = meshio.read(msh_to_vtu(msh, tmp_path / "footing.vtu"))
    assert len(vtu.cells_dict["tetra"]) == from_geo.mesh.topology.index_map(3).size_local


def test_geo_without_mesh_size_is_rejected():
    with pytest.raises(ValueError, match="mesh_size"):
        load_mesh("block.geo")
