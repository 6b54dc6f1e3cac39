"""Diagnostics against closed forms; VTU output and mesh loaders round-trip."""
import math

import meshio
import numpy as np
import pytest

from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall
from de_domain import diagnostics as dg
from de_domain.io import write_facets_vtu, write_frame, write_particles_vtu

R = 1e-3
MAT = [Material(young=5e7, friction=0.5, restitution=0.5)]


def engine_of(positions, walls=(), **kw):
    p = Particles.from_spheres(positions, R, materials=MAT)
    return Engine(p, MAT, walls=list(walls), gravity=(0, 0, 0), **kw)


@pytest.mark.parametrize("lo, fraction", [((0.0, -1, -1), 0.5), ((0.0, 0.0, -1), 0.25), ((0.0, 0.0, 0.0), 0.125),
                                          ((-1, -1, -1), 1.0)])
def test_solid_volume_of_sphere_cut_by_box(lo, fraction):
    engine = engine_of([[0.0, 0.0, 0.0]])
    region = dg.BoxRegion(lo, (1.0, 1.0, 1.0))
    assert dg.solid_volume(engine, region) == pytest.approx(fraction * 4 / 3 * math.pi * R**3, rel=1e-4)


def test_solid_volume_sphere_region_lens_and_void_ratio():
    engine = engine_of([[0.0, 0.0, 0.0], [5 * R, 0.0, 0.0]])
    region = dg.SphereRegion((0.0, 0.0, 0.0), 5 * R)  # holds sphere 0, half of sphere 1 (almost)
    d, r, big = 5 * R, R, 5 * R
    lens = (math.pi * (big + r - d) ** 2 * (d * d + 2 * d * r - 3 * r * r + 2 * d * big + 6 * r * big - 3 * big**2)
            / (12 * d))
    solid = 4 / 3 * math.pi * R**3 + lens
    assert dg.solid_volume(engine, region) == pytest.approx(solid, rel=1e-12)
    assert dg.void_ratio(engine, region) == pytest.approx((region.volume - solid) / solid, rel=1e-12)
    assert dg.porosity(engine, region) == pytest.approx(1 - solid / region.volume, rel=1e-12)


def test_love_weber_stress_of_a_compressed_column():
    """Two spheres squeezed between walls x = 0 and x = 4r − 2δ: σ_xx V = F × 4r (minus overlaps)."""
    delta = 1e-6
    walls = [PlaneWall((0, 0, 0), (1, 0, 0)), PlaneWall((4 * R - 3 * delta, 0, 0), (-1, 0, 0))]
    engine = engine_of([[R - delta, 0, 0], [3 * R - 2 * delta, 0, 0]], walls=walls, dt=1e-12)
    engine.step()
    c = engine.contacts()
    assert len(c["i"]) == 1 and len(c["wall_particle"]) == 2
    force = 2 * 5e7 * R * delta  # k_n δ, equal at the three contacts
    region = dg.BoxRegion((-R, -2 * R, -2 * R), (5 * R, 2 * R, 2 * R))
    sigma = dg.love_weber_stress(engine, region)
    lever = 2 * (R - delta / 2) + (2 * R - delta)  # wall arms + branch length
    assert sigma[0, 0] == pytest.approx(force * lever / region.volume, rel=1e-6)
    assert np.abs(sigma).sum() == pytest.approx(abs(sigma[0, 0]), rel=1e-9)
    assert dg.coordination_number(engine) == pytest.approx(1.0)
    assert dg.coordination_number(engine, include_walls=True) == pytest.approx(2.0)
    assert dg.unbalanced_force_ratio(engine) == pytest.approx(0.0, abs=1e-9)
    assert dg.kinetic_energy(engine) == pytest.approx(0.0, abs=1e-20)


def test_vtu_files_read_back(tmp_path):
    engine = engine_of([[0.0, 0.0, 0.0], [3 * R, 0.0, 0.0]])
    engine.particles.vel[1] = (1.0, 2.0, 3.0)
    path = write_particles_vtu(tmp_path / "p.vtu", engine.particles)
    mesh = meshio.read(path)
    assert np.allclose(mesh.points, engine.particles.pos)
    assert np.allclose(mesh.point_data["radius"], R)
    assert np.allclose(mesh.point_data["velocity"][1], (1.0, 2.0, 3.0))
    facets = FacetMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    back = meshio.read(write_facets_vtu(tmp_path / "f.vtu", facets))
    assert back.cells[0].type == "triangle" and back.cells[0].data.tolist() == [[0, 1, 2]]
    engine.facets.append(facets)
    assert len(write_frame(tmp_path / "frames", engine, 7)) == 2


def test_stl_and_gmsh_loaders_merge_vertices(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    tris = np.array([[0, 1, 3], [0, 3, 2]])
    soup = meshio.Mesh(points[tris.ravel()], [("triangle", np.arange(6).reshape(2, 3))])
    soup.write(tmp_path / "s.stl")
    mesh = FacetMesh.from_file(tmp_path / "s.stl")
    assert mesh.vertices.shape == (4, 3) and mesh.triangles.shape == (2, 3)
    assert mesh.n_edges == 5
    tagged = meshio.Mesh(np.vstack([points, [[5, 5, 5]]]), [("triangle", tris), ("triangle", np.array([[0, 1, 4]]))],
                         cell_data={"gmsh:physical": [np.array([7, 7]), np.array([8])],
                                    "gmsh:geometrical": [np.array([1, 1]), np.array([2])]})
    tagged.write(tmp_path / "m.msh", file_format="gmsh22", binary=False)
    mesh = FacetMesh.from_gmsh(tmp_path / "m.msh", physical=7)
    assert mesh.triangles.shape == (2, 3) and sorted(mesh.source_nodes.tolist()) == [0, 1, 2, 3]


def test_a_frame_in_pieces_opens_in_vtk_as_one_dataset(tmp_path):
    """Two pieces and the ``.pvtu`` naming them (what each rank and the root write under MPI):
    read by :func:`de_domain.io.read_frame` in global-id order, and by VTK's own parallel reader
    (ParaView's; where ``python3-vtk9`` is installed) as one grid with every field."""
    from de_domain.io import particle_fields, read_frame, write_pvtu

    engine = engine_of([[0.0, 0.0, 0.0], [3 * R, 0.0, 0.0], [6 * R, 0.0, 0.0]])
    p = engine.particles
    p.vel[:] = np.arange(9.0).reshape(3, 3)
    ids = np.array([2, 0, 1])  # the rows' global ids
    halves = [p.take(np.array([0])), p.take(np.array([1, 2]))]
    pieces = []
    for k, (half, half_ids) in enumerate(zip(halves, (ids[:1], ids[1:]), strict=True)):
        points, fields = particle_fields(half, half_ids, clump=np.full(half.n, -1))
        pieces.append(f"piece_{k}.vtu")
        meshio.Mesh(points, [("vertex", np.arange(len(points)).reshape(-1, 1))], point_data=fields).write(
            tmp_path / pieces[-1], file_format="vtu", binary=True, compression=None)
    path = write_pvtu(tmp_path / "frame.pvtu", pieces, fields)
    points, back = read_frame(path)
    np.testing.assert_array_equal(back["id"], [0, 1, 2])
    np.testing.assert_array_equal(points, p.pos[[1, 2, 0]])
    np.testing.assert_array_equal(back["velocity"], p.vel[[1, 2, 0]])
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy
    reader = vtk.vtkXMLPUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    assert grid.GetNumberOfPoints() == 3
    data = grid.GetPointData()
    assert sorted(data.GetArrayName(k) for k in range(data.GetNumberOfArrays())) == sorted(fields)
    np.testing.assert_array_equal(vtk_to_numpy(data.GetArray("id")), [2, 0, 1])
    np.testing.assert_array_equal(vtk_to_numpy(data.GetArray("velocity")), p.vel)
