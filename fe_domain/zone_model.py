"""One gmsh model split into FE volumes and DEM zones (docs/design.md §5.1).

A user's model (a ``.geo`` with ``DefineConstant`` parameters, or a ``.msh``) holds every
volume of the problem, conforming, with physical names: soil, structures, and the volumes
the grains will fill. :func:`split_model` meshes it once (rank 0) and returns

* the FE mesh of the FE volumes only, distributed (their cells, renumbered nodes, every
  surface group restricted to the faces of FE cells, and the coupling interface as the
  facet group :data:`INTERFACE`): the zone's cells are left out, as if the FE model had a
  hole where the grains are;
* the zone's shape in coordinates, on every rank: its tetrahedra (to place grains in),
  its interface triangles (oriented into the zone) and its free triangles by the surface
  group they lie on (oriented out of it), found from the cells alone by
  :func:`fe_domain.skin.zone_skin` — no hand-tagged interface group;
* every surface group's triangles in coordinates (rigid bodies, walls).

The FE node numbering is that of the source's nodes used by FE cells, in gmsh's order: the
same for any rank count (the interface's facet mesh is ordered by it, docs/design.md §5.2).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import gmsh
import numpy as np
from mpi4py import MPI

from fe_domain.mesh import MeshError, TaggedMesh, _generate, _resolve, built_on_rank, labelled_cells
from fe_domain.skin import zone_skin

#: the facet group of the FE mesh that holds the coupling interface
INTERFACE = "fe_dem_interface"
#: the free faces of a zone that lie on no surface group
UNNAMED = ""


class GroupError(MeshError):
    """A physical group named by the caller is missing from the model or has another dimension."""

    def __init__(self, name, dimension, groups):
        super().__init__(name, dimension, groups)
        self.name, self.dimension, self.groups = name, dimension, groups

    def __str__(self):
        have = ", ".join(f"'{n}' ({'volume' if d == 3 else 'surface' if d == 2 else f'dim {d}'})"
                         for n, d in sorted(self.groups.items()))
        kind = "volume" if self.dimension == 3 else "surface"
        if self.name in self.groups:
            return f"physical group '{self.name}' is not a {kind} (dimension {self.groups[self.name]}); groups: {have}"
        return f"no physical {kind} '{self.name}' in the model; its groups: {have}"


@dataclass(frozen=True)
class ZoneShape:
    """The DEM zone(s) of a model, in coordinates (m): ``tets`` (k, 4, 3); ``interface``
    (m, 3, 3) triangles shared with FE cells, normals (b − a) × (c − a) into the zone;
    ``free`` {surface group name (:data:`UNNAMED` for none): (m, 3, 3)} the zone's faces on
    the model's boundary, normals out of the zone."""
    tets: np.ndarray
    interface: np.ndarray
    free: dict = field(default_factory=dict)

    @property
    def faces(self) -> np.ndarray:
        """Every boundary triangle of the zone (interface and free), (m, 3, 3)."""
        return np.concatenate([self.interface, *self.free.values()]) if self.free else self.interface


@dataclass(frozen=True)
class SplitPayload:
    """What rank 0 sends every rank besides the FE mesh."""
    has_mesh: bool
    zone: ZoneShape
    surfaces: dict       # {surface group: (m, 3, 3) triangles}
    groups: dict         # {physical group name: dimension} of the source model


@dataclass(frozen=True)
class SplitModel:
    """:func:`split_model`'s result: ``fe`` the FE volumes' mesh (None when every volume is a
    zone), ``zone`` the zones' shape, ``surfaces`` every surface group's triangles, ``groups``
    the source's physical groups {name: dimension}."""
    fe: TaggedMesh | None
    zone: ZoneShape
    surfaces: dict
    groups: dict


def split_model(path, mesh_size, parameters, zones, volumes, comm=MPI.COMM_WORLD, rank=0) -> SplitModel:
    """Mesh the model ``path`` (a ``.geo`` with ``mesh_size`` and DefineConstant
    ``parameters``, or a ``.msh``) and split it: the physical volumes ``zones`` become the
    DEM zone, the physical volumes ``volumes`` the FE mesh (a volume in neither is dropped);
    collective. A group missing or of another dimension is a :class:`GroupError`, a zone that
    touches no FE volume while there are some a :class:`MeshError`, on every rank."""
    path = str(path)
    zones, volumes = list(zones), list(volumes)

    def build():
        if path.endswith(".msh"):
            gmsh.merge(str(_resolve(path, ".msh")))
        else:
            _generate(_resolve(path, ".geo"), mesh_size, parameters)
        groups = {gmsh.model.getPhysicalName(d, t): d for d, t in gmsh.model.getPhysicalGroups()}
        for name in zones + volumes:
            if groups.get(name) != 3:
                raise GroupError(name, 3, groups)
        if INTERFACE in groups:
            raise MeshError(f"the model has a physical group named '{INTERFACE}', a name kept for the interface "
                            "found from the zone's cells; rename it")
        source = labelled_cells()
        surfaces = _surface_triangles(source.points)
        zone_cells = np.isin(source.volume, zones)
        skin = zone_skin(source.points, source.cells, source.volume, set(zones), set(volumes))
        if volumes and zones and len(skin.interface) == 0:
            raise MeshError(f"the DEM zone ({', '.join(zones)}) shares no face with an FE volume "
                            f"({', '.join(volumes)}): no coupling interface")
        zone = ZoneShape(source.points[source.cells[zone_cells]], source.points[skin.interface],
                         _free_by_group(source.points, skin.free, surfaces))
        payload = SplitPayload(bool(volumes), zone, {n: source.points[t] for n, t in surfaces.items()}, groups)
        if volumes:
            _make_fe_model(source, volumes, surfaces, skin.interface)
        return payload

    mesh, payload = built_on_rank(comm, rank, build)
    return SplitModel(mesh, payload.zone, payload.surfaces, payload.groups)


def _surface_triangles(points) -> dict:
    """{surface group name: (m, 3) node indices} of the current gmsh model (3-node triangles)."""
    tags, _, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    out = {}
    for dim, group in gmsh.model.getPhysicalGroups(2):
        name = gmsh.model.getPhysicalName(dim, group)
        blocks = [np.zeros((0, 3), np.int64)]
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, group):
            types, _, nodes = gmsh.model.mesh.getElements(dim, entity)
            blocks += [index[np.asarray(n, np.int64)].reshape(-1, 3) for t, n in zip(types, nodes, strict=True)
                       if t == 2]
        out[name] = np.vstack(blocks)
    return out


def _keys(triangles) -> np.ndarray:
    """A row per triangle, its sorted node triple viewed as one void scalar (for set membership)."""
    s = np.ascontiguousarray(np.sort(np.asarray(triangles, np.int64), axis=1))
    return s.view(np.dtype((np.void, s.dtype.itemsize * 3))).ravel()


def _free_by_group(points, free, surfaces) -> dict:
    """The zone's free triangles (node indices) split by the surface group each lies on
    (the first by name when several), as coordinates; the rest under :data:`UNNAMED`."""
    keys = _keys(free)
    left = np.ones(len(free), bool)
    out = {}
    for name in sorted(surfaces):
        on = left & np.isin(keys, _keys(surfaces[name]))
        if on.any():
            out[name] = points[free[on]]
            left &= ~on
    if left.any():
        out[UNNAMED] = points[free[left]]
    return out


def _make_fe_model(source, volumes, surfaces, interface) -> None:
    """Replace the current gmsh model by the FE volumes alone: their nodes renumbered from 1
    in the source's order, a discrete volume per FE group, every surface group restricted to
    faces of FE cells, and the interface as the surface group :data:`INTERFACE`."""
    fe = np.isin(source.volume, volumes)
    used = np.unique(source.cells[fe])
    number = np.zeros(len(source.points), np.int64)
    number[used] = np.arange(1, len(used) + 1)
    fe_faces = _keys(source.cells[fe][:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3))
    gmsh.model.add("fe_volumes")
    gmsh.model.setCurrent("fe_volumes")
    first = None
    for name in volumes:
        entity = gmsh.model.addDiscreteEntity(3)
        if first is None:
            first = entity
            gmsh.model.mesh.addNodes(3, entity, np.arange(1, len(used) + 1), source.points[used].ravel())
        cells = source.cells[source.volume == name]
        gmsh.model.mesh.addElementsByType(entity, 4, [], number[cells].ravel())
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [entity]), name)
    for name, triangles in [*sorted(surfaces.items()), (INTERFACE, interface)]:
        triangles = triangles[np.isin(_keys(triangles), fe_faces)]
        if len(triangles):
            entity = gmsh.model.addDiscreteEntity(2)
            gmsh.model.mesh.addElementsByType(entity, 2, [], number[triangles].ravel())
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [entity]), name)
