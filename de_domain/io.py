"""ParaView output: particles and facet meshes as plain-XML VTU (ASCII), a small
numpy-only writer."""
from __future__ import annotations

from pathlib import Path

import numpy as np

_VTK_VERTEX = 1
_VTK_TRIANGLE = 5


def _data_array(name, values):
    values = np.asarray(values)
    comps = 1 if values.ndim == 1 else values.shape[1]
    kind = "Int32" if values.dtype.kind in "iub" else "Float64"
    body = " ".join(str(int(v)) if kind == "Int32" else repr(float(v)) for v in values.ravel())
    return f'<DataArray type="{kind}" Name="{name}" NumberOfComponents="{comps}" format="ascii">{body}</DataArray>\n'


def _write_vtu(path, points, connectivity, cell_size, cell_type, point_data):
    n_cells = connectivity.size // cell_size if cell_size else 0
    offsets = np.arange(1, n_cells + 1) * cell_size
    parts = ['<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">\n',
             f'<UnstructuredGrid><Piece NumberOfPoints="{len(points)}" NumberOfCells="{n_cells}">\n',
             "<PointData>\n", *[_data_array(k, v) for k, v in point_data.items()], "</PointData>\n",
             "<Points>\n", _data_array("Points", np.asarray(points, float).reshape(-1, 3)), "</Points>\n",
             "<Cells>\n", _data_array("connectivity", connectivity.astype(np.int64)),
             _data_array("offsets", offsets), _data_array("types", np.full(n_cells, cell_type)), "</Cells>\n",
             "</Piece></UnstructuredGrid>\n</VTKFile>\n"]
    Path(path).write_text("".join(parts))
    return Path(path)


def write_particles_vtu(path, particles):
    """Spheres as VTK vertices with radius, velocity, angular velocity, force, material, group
    (the owned particles only: ghost copies are left out)."""
    mine = particles.owned
    n = int(np.count_nonzero(mine))
    return _write_vtu(path, particles.pos[mine], np.arange(n), 1, _VTK_VERTEX, {
        "radius": particles.radius[mine], "velocity": particles.vel[mine],
        "angular_velocity": particles.angvel[mine], "force": particles.force[mine],
        "material": particles.material[mine], "group": particles.group[mine]})


def write_facets_vtu(path, mesh):
    """A FacetMesh as triangles with vertex velocity, force and impulse."""
    return _write_vtu(path, mesh.vertices, mesh.triangles.ravel(), 3, _VTK_TRIANGLE, {
        "velocity": mesh.vertex_velocity, "force": mesh.vertex_force, "impulse": mesh.vertex_impulse})


def write_frame(directory, engine, step):
    """Particles (and every facet mesh) of one output frame; returns the written paths.

    A distributed engine (``engine.domain`` set; collective): every rank's owned
    particles are gathered in global-id order and rank 0 writes the files, once; every
    rank returns the same paths."""
    directory = Path(directory)
    particle_path = directory / f"particles_{step:08d}.vtu"
    facet_paths = [directory / f"facets{k}_{step:08d}.vtu" for k in range(len(engine.facets))]
    domain = getattr(engine, "domain", None)
    if domain is None:
        directory.mkdir(parents=True, exist_ok=True)
        paths = [write_particles_vtu(particle_path, engine.particles)]
        for path, mesh in zip(facet_paths, engine.facets, strict=True):
            paths.append(write_facets_vtu(path, mesh))
        return paths
    particles = engine.global_particles()  # collective
    if domain.comm.rank == 0:  # the facet meshes are global: identical on every rank
        directory.mkdir(parents=True, exist_ok=True)
        write_particles_vtu(particle_path, particles)
        for path, mesh in zip(facet_paths, engine.facets, strict=True):
            write_facets_vtu(path, mesh)
    domain.comm.Barrier()  # the files exist when any rank returns
    return [particle_path, *facet_paths]
