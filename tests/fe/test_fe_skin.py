"""The zone's skin from the cells alone (fe_domain/skin.py): the interface is every triangle
shared by a zone tetrahedron and an FE tetrahedron, oriented into the zone; the free faces
are the zone's triangles on the mesh boundary, oriented out of it. Checked against the
closed-form areas and normals of a trench-shaped zone in a block meshed by gmsh."""
import gmsh
import numpy as np
import pytest

from fe_domain.skin import triangle_areas, triangle_normals, zone_skin


def test_two_tetrahedra_share_one_face_oriented_into_the_zone():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], float)
    cells = np.array([[0, 1, 2, 3], [0, 2, 1, 4]])   # the zone above z = 0, the FE below
    skin = zone_skin(points, cells, np.array([1, 2]), zone={1}, structure={2})
    assert sorted(skin.interface[0]) == [0, 1, 2]
    assert np.allclose(triangle_normals(points, skin.interface), [[0, 0, 1]])
    assert len(skin.free) == 3
    centre = points[[0, 1, 2, 3]].mean(axis=0)
    for triangle, normal in zip(skin.free, triangle_normals(points, skin.free), strict=True):
        assert normal @ (points[triangle].mean(axis=0) - centre) > 0   # out of the zone


@pytest.fixture(scope="module")
def trench():
    """The unit block with a zone x ∈ [0.25, 0.75], z ∈ [0.5, 1] through its whole y (a
    plane slice with a trench), two conforming volumes: (points, tets, volume label)."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        block = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        zone = gmsh.model.occ.addBox(0.25, 0, 0.5, 0.5, 1, 0.5)
        gmsh.model.occ.fragment([(3, block)], [(3, zone)])
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.2)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.zeros(int(tags.max()) + 1, np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        cells, labels = [], []
        for _, volume in gmsh.model.getEntities(3):
            lo = np.array(gmsh.model.getBoundingBox(3, volume)[:3])
            _, _, nodes = gmsh.model.mesh.getElements(3, volume)
            tets = index[np.asarray(nodes[0], np.int64)].reshape(-1, 4)
            cells.append(tets)
            labels.append(np.full(len(tets), "zone" if np.isclose(lo[2], 0.5) else "soil"))
    finally:
        gmsh.finalize()
    return coords.reshape(-1, 3), np.vstack(cells), np.concatenate(labels)


def test_the_trench_interface_is_its_bottom_and_sides_facing_the_grains(trench):
    points, cells, labels = trench
    skin = zone_skin(points, cells, labels, zone={"zone"}, structure={"soil"})
    area = triangle_areas(points, skin.interface)
    assert area.sum() == pytest.approx(0.5 * 1.0 + 2 * 0.5 * 1.0, rel=1e-12)   # bottom + two sides
    centres = points[skin.interface].mean(axis=1)
    normals = triangle_normals(points, skin.interface)
    bottom, left, right = (np.isclose(centres[:, 2], 0.5), np.isclose(centres[:, 0], 0.25),
                           np.isclose(centres[:, 0], 0.75))
    assert np.all(bottom | left | right)
    assert np.allclose(normals[bottom], [0, 0, 1]) and np.allclose(normals[left], [1, 0, 0])
    assert np.allclose(normals[right], [-1, 0, 0])


def test_the_trench_free_faces_are_its_top_and_the_slice_faces(trench):
    points, cells, labels = trench
    skin = zone_skin(points, cells, labels, zone={"zone"}, structure={"soil"})
    area = triangle_areas(points, skin.free)
    assert area.sum() == pytest.approx(0.5 * 1.0 + 2 * 0.5 * 0.5, rel=1e-12)   # top + the two y faces
    centres = points[skin.free].mean(axis=1)
    normals = triangle_normals(points, skin.free)
    top, front, back = np.isclose(centres[:, 2], 1.0), np.isclose(centres[:, 1], 0.0), np.isclose(centres[:, 1], 1.0)
    assert np.all(top | front | back)
    assert np.allclose(normals[top], [0, 0, 1]) and np.allclose(normals[front], [0, -1, 0])
    assert np.allclose(normals[back], [0, 1, 0])


def test_a_non_conforming_mesh_is_refused():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 1]], float)
    cells = np.array([[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]])
    with pytest.raises(ValueError, match="not conforming"):
        zone_skin(points, cells, np.array([1, 2, 2]), zone={1}, structure={2})


ZONE_IN_BLOCK = """// a unit block with a zone of width w through its whole y, from its top down to z = 0.5
SetFactory("OpenCASCADE");
DefineConstant[ w = {0.5, Min 0.05, Max 0.9, Name "Parameters/w"} ];
Box(1) = {0, 0, 0, 1, 1, 1};
Box(2) = {0.5 - w / 2, 0, 0.5, w, 1, 0.5};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
e = 1e-6;
zone() = Volume In BoundingBox{0.5 - w / 2 - e, -e, 0.5 - e, 0.5 + w / 2 + e, 1 + e, 1 + e};
soil() = Volume{:};
soil() -= zone();
Physical Volume("zone") = {zone()};
Physical Volume("soil") = {soil()};
"""


@pytest.mark.parametrize("width", [0.5, 0.3])
def test_a_gmsh_model_with_named_volumes_gives_the_interface_of_its_zone(tmp_path, width):
    """From a .geo with a DefineConstant overridden by the caller, as a case file would: the
    interface of the zone named "zone" against the volume named "soil" is its bottom and sides."""
    from fe_domain.mesh import volume_cells
    source = tmp_path / "zone_in_block.geo"
    source.write_text(ZONE_IN_BLOCK)
    model = volume_cells(source, mesh_size=0.2, parameters={"w": width})
    assert set(model.volume) == {"zone", "soil"}
    skin = zone_skin(model.points, model.cells, model.volume, zone={"zone"}, structure={"soil"})
    assert triangle_areas(model.points, skin.interface).sum() == pytest.approx(width + 2 * 0.5, rel=1e-12)
    assert triangle_areas(model.points, skin.free).sum() == pytest.approx(width + 2 * 0.5 * width, rel=1e-12)
