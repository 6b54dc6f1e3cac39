"""One gmsh model split into FE volumes and a DEM zone (fe_domain/zone_model.py), on the
retaining-wall backfill (meshes/retaining_wall.geo: a zone x < a, the FE soil beyond, a
plane slice): the zone's volume and faces against their closed-form sizes, the FE mesh made
of the FE volume alone with the interface as a facet group, the all-DEM split, and the
errors a user's model can raise."""
import numpy as np
import pytest
from mpi4py import MPI

from de_domain.zone_fill import tets_volume
from fe_domain.mesh import MeshError
from fe_domain.skin import triangle_areas
from fe_domain.zone_model import INTERFACE, GroupError, split_model

L, LY, H, A = 0.14, 0.01, 0.06, 0.05
PARAMETERS = {"L": L, "Ly": LY, "H": H, "a": A, "h": 0.01}


def area(triangles):
    corners = triangles.reshape(-1, 3)
    index = np.arange(len(corners)).reshape(-1, 3)
    return float(triangle_areas(corners, index).sum())


@pytest.fixture(scope="module")
def coupled():
    return split_model("retaining_wall.geo", 0.01, PARAMETERS, ["zone"], ["soil"], MPI.COMM_SELF)


def test_the_zone_has_its_volume_and_an_interface_facing_the_grains(coupled):
    zone = coupled.zone
    assert tets_volume(zone.tets) == pytest.approx(A * LY * H, rel=1e-12)
    assert area(zone.interface) == pytest.approx(LY * H, rel=1e-12)
    t = zone.interface
    normals = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.allclose(t[:, :, 0], A) and np.all(normals[:, 0] < 0)   # the plane x = a, normal into x < a
    free = {name: area(tris) for name, tris in zone.free.items()}
    assert free == pytest.approx({"wall": LY * H, "base": A * LY, "top": A * LY, "sides": 2 * A * H}, rel=1e-12)


def test_the_fe_mesh_is_the_soil_alone_with_the_interface_as_a_facet_group(coupled):
    fe = coupled.fe
    assert fe.names(3) == ["soil"]
    assert INTERFACE in fe.names(2) and "wall" not in fe.names(2)   # the wall bounds the zone only
    x = fe.mesh.geometry.x
    assert x[:, 0].min() == pytest.approx(A) and x[:, 0].max() == pytest.approx(L)
    cells = fe.mesh.topology.index_map(3).size_local
    assert cells > 0 and len(fe.facets(INTERFACE)) == len(coupled.zone.interface)


def test_the_all_dem_split_has_no_fe_and_the_whole_backfill_as_zone():
    split = split_model("retaining_wall.geo", 0.01, PARAMETERS, ["zone", "soil"], [], MPI.COMM_SELF)
    assert split.fe is None and len(split.zone.interface) == 0
    assert tets_volume(split.zone.tets) == pytest.approx(L * LY * H, rel=1e-12)
    assert area(split.zone.free["far"]) == pytest.approx(LY * H, rel=1e-12)


def test_a_missing_or_wrong_group_is_named():
    with pytest.raises(GroupError, match="no physical volume 'backfill'.*'soil' \\(volume\\)"):
        split_model("retaining_wall.geo", 0.01, PARAMETERS, ["backfill"], ["soil"], MPI.COMM_SELF)
    with pytest.raises(GroupError, match="'wall' is not a volume"):
        split_model("retaining_wall.geo", 0.01, PARAMETERS, ["wall"], ["soil"], MPI.COMM_SELF)


def test_a_zone_that_touches_no_fe_volume_is_refused(tmp_path):
    geo = tmp_path / "apart.geo"
    geo.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\nBox(2) = {2, 0, 0, 1, 1, 1};\n'
                   'Physical Volume("zone") = {1};\nPhysical Volume("soil") = {2};\n')
    with pytest.raises(MeshError, match="shares no face with an FE volume"):
        split_model(str(geo), 0.5, {}, ["zone"], ["soil"], MPI.COMM_SELF)


@pytest.mark.parametrize("cover", [0.1, 0.03], ids=["buried", "reaching-the-surface"])
def test_a_ring_zone_around_a_tunnel_lining(cover):
    """meshes/tunnel.geo (half model): a DEM zone ring of thickness a around a lining of outer
    diameter D, FE soil beyond. The interface is the two half circles, the lining's extrados and
    the ring's outside (where it is under ground), found from the cells; the zone's volume is
    the half annulus (less what lies above the ground when a > C). The circles are faceted:
    within 1 % (chords of h / R ≈ 0.1 rad)."""
    D, a, Ly, h = 0.1, 0.05, 0.01, 0.005
    parameters = {"D": D, "C": cover, "a": a, "Ly": Ly, "h": h, "h_far": 0.02}
    split = split_model("tunnel.geo", 0.02, parameters, ["zone"], ["lining", "soil"], MPI.COMM_SELF)
    ro, rz = D / 2, D / 2 + a
    if cover >= a:
        assert tets_volume(split.zone.tets) == pytest.approx(0.5 * np.pi * (rz**2 - ro**2) * Ly, rel=0.01)
        assert area(split.zone.interface) == pytest.approx(np.pi * (ro + rz) * Ly, rel=0.01)
        assert "ground" not in split.zone.free
    else:   # the ring cut by the ground surface: its top is a free surface of the zone
        assert area(split.zone.free["ground"]) > 0.0
        assert area(split.zone.interface) < np.pi * (ro + rz) * Ly
    assert sorted(split.fe.names(3)) == ["lining", "soil"]
    assert area(split.zone.free["axis"]) == pytest.approx(2 * a * Ly if cover >= a else (a + cover) * Ly, rel=1e-9)


def test_a_strip_on_the_ground_over_a_tunnel():
    """meshes/tunnel.geo with B > 0: the ground surface over 0 <= x <= B/2 (half model) is the
    surface "strip" (a surcharge's footing), the rest stays "ground"; with the ring cut by the
    ground surface both are free faces of the zone, the strip B/2 × Ly exactly, and the zone's
    ground and strip together are its top without the strip (B = 0)."""
    D, a, Ly, h, B = 0.1, 0.05, 0.01, 0.005, 0.04
    parameters = {"D": D, "C": 0.03, "a": a, "Ly": Ly, "h": h, "h_far": 0.02}
    plain = split_model("tunnel.geo", 0.02, parameters, ["zone"], ["lining", "soil"], MPI.COMM_SELF)
    strip = split_model("tunnel.geo", 0.02, {**parameters, "B": B}, ["zone"], ["lining", "soil"], MPI.COMM_SELF)
    assert strip.groups["strip"] == 2 and "strip" not in plain.groups
    assert area(strip.zone.free["strip"]) == pytest.approx(0.5 * B * Ly, rel=1e-9)
    assert np.allclose(strip.zone.free["strip"][:, :, 2], D + 0.2 + 0.03)  # on the ground surface: below + D + C
    assert area(strip.zone.free["ground"]) + area(strip.zone.free["strip"]) == \
        pytest.approx(area(plain.zone.free["ground"]), rel=1e-9)
