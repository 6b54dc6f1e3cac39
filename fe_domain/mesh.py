"""gmsh → DOLFINx meshes with cell and facet tags addressed by physical-group name.

A geometry is a gmsh ``.geo`` source in ``meshes/`` (or an already meshed ``.msh``
file).  Rank 0 of the communicator builds or reads the gmsh model, generates the
3D tetrahedral mesh with the requested size, and ``dolfinx.io.gmshio.model_to_mesh``
distributes it (docs/design.md §1.2: ``meshes/*.geo`` → gmsh → dolfinx mesh + facet tags),
cut into parts by :func:`reproducible_partitioner`: DOLFINx's default (PT-SCOTCH) cut the
same tiny footing mesh two different ways over 12 runs on 2 ranks (2026-12-03), and a
different cut changes the order of the FE sums, i.e. the bits of a run and of its resume;
it also ghosts the cells around every owned node (by shared vertex, not facet).
Physical-group names are broadcast with the mesh so that case files can say
``facets("interface")`` and never use raw tag numbers.
"""

from __future__ import annotations

import functools
import math
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import gmsh
import meshio
import numpy as np
from dolfinx import cpp
from dolfinx.io import gmshio
from dolfinx.mesh import GhostMode, Mesh, MeshTagsMetaClass
from mpi4py import MPI
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import reverse_cuthill_mckee

MESH_DIR = Path(__file__).resolve().parent.parent / "meshes"


@dataclass
class TaggedMesh:
    """A distributed tetrahedral mesh with its named physical groups.

    ``cell_tags`` and ``facet_tags`` hold the gmsh physical tag numbers of the local
    (owned and ghost) entities; ``groups`` maps each physical-group name to
    ``(dim, tag)``.
    """

    mesh: Mesh
    cell_tags: MeshTagsMetaClass
    facet_tags: MeshTagsMetaClass
    groups: dict[str, tuple[int, int]]

    def tag(self, name: str, dim: int) -> int:
        """gmsh physical tag number of group ``name`` (dimension checked)."""
        if name not in self.groups:
            raise KeyError(f"physical group {name!r} not in mesh; available: {sorted(self.groups)}")
        group_dim, tag = self.groups[name]
        if group_dim != dim:
            raise KeyError(f"physical group {name!r} has dimension {group_dim}, expected {dim}")
        return tag

    def facets(self, name: str) -> np.ndarray:
        """Local indices of the facets in the 2D physical group ``name``."""
        tag = self.tag(name, self.mesh.topology.dim - 1)
        return self.facet_tags.indices[self.facet_tags.values == tag]

    def cells(self, name: str) -> np.ndarray:
        """Local indices of the cells in the 3D physical group ``name``."""
        tag = self.tag(name, self.mesh.topology.dim)
        return self.cell_tags.indices[self.cell_tags.values == tag]

    def names(self, dim: int) -> list[str]:
        """Names of the physical groups of dimension ``dim``."""
        return sorted(n for n, (d, _) in self.groups.items() if d == dim)


class MeshError(ValueError):
    """gmsh could not make a usable tetrahedral mesh of a source (raised on every rank)."""


class MeshSizeTooLarge(MeshError):
    """The mesh size exceeds the largest extent of the whole geometry (found before meshing)."""

    def __init__(self, mesh_size, extent):
        super().__init__(mesh_size, extent)
        self.mesh_size, self.extent = mesh_size, extent

    def __str__(self):
        return (f"mesh size {self.mesh_size:g} m is larger than the whole geometry (its largest extent is "
                f"{self.extent:.6g} m)")


def _distributed(comm: MPI.Comm, rank: int, build) -> TaggedMesh:
    """Build a gmsh model with ``build()`` on ``rank`` and distribute it into a TaggedMesh."""
    return built_on_rank(comm, rank, build)[0]


def built_on_rank(comm: MPI.Comm, rank: int, build) -> tuple[TaggedMesh | None, object]:
    """Run ``build()`` on ``rank`` in a gmsh session and distribute the gmsh model it leaves
    current; returns (TaggedMesh, payload) on every rank, where ``build`` returns a payload
    (broadcast) or None. A payload with ``has_mesh`` False distributes no mesh (None).

    A failure on ``rank`` (a syntax error, a file that is not a mesh, no tetrahedra, no
    volume group) is broadcast and raised as :class:`MeshError` on every rank, so no rank
    is left waiting for a mesh that will not come."""
    failure, groups, payload = None, None, None
    if comm.rank == rank:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        try:
            payload = build()
            groups = {gmsh.model.getPhysicalName(dim, tag): (dim, tag)
                      for dim, tag in gmsh.model.getPhysicalGroups()}
            if getattr(payload, "has_mesh", True):
                failure = _unusable(groups)
        except MeshError as exc:  # ours, raised as it is on every rank
            failure = exc
        except Exception as exc:  # gmsh reports every error as a bare Exception
            failure = f"gmsh: {exc}"
    failure, groups, payload = comm.bcast((failure, groups, payload), root=rank)
    try:
        if isinstance(failure, MeshError):
            raise failure
        if failure:
            raise MeshError(failure)
        if not getattr(payload, "has_mesh", True):
            return None, payload
        with _cells_partitioned_by(reproducible_partitioner):
            mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, rank, gdim=3)
        return TaggedMesh(mesh, cell_tags, facet_tags, groups), payload
    finally:
        if comm.rank == rank:
            gmsh.finalize()


def reproducible_partitioner(comm, n_parts, tdim, cells, ghost_mode):
    """A DOLFINx cell partitioner (``create_mesh(..., partitioner=...)``) that cuts the mesh the
    same way on every run and ghosts by shared vertex. The cells (tetrahedra), gathered on
    rank 0, are ordered by reverse Cuthill–McKee of their dual graph (an edge per shared
    facet; scipy: breadth-first level sets from a peripheral cell, so they sweep across the
    mesh) and the order is cut into ``n_parts`` runs of equal cell count. Returns, per local
    cell, its owner followed (unless ``ghost_mode`` is none) by the other parts of every cell
    that shares a vertex with it, where it is a ghost: every cell around an owned node is then
    on the rank, so the owned rows of an assembled operator read local nodes only (the
    compiled step on several ranks, :mod:`fe_domain.compiled`). DOLFINx 0.5.2 disables its own
    vertex ghosting. Collective."""
    offsets = np.asarray(cells.offsets)
    width = int(offsets[1] - offsets[0]) if offsets.size > 1 else tdim + 1
    local = np.asarray(cells.array, np.int64).reshape(-1, width)[:, :tdim + 1]  # the vertices come first
    gathered = comm.gather(local, root=0)
    pieces = None
    if comm.rank == 0:
        counts = [len(c) for c in gathered]
        every = np.concatenate(gathered)
        n = len(every)
        part = np.empty(n, np.int32)
        part[_cuthill_mckee_order(every)] = (np.arange(n) * n_parts) // max(n, 1)
        extra = _vertex_neighbour_parts(every, part) if ghost_mode != GhostMode.none else np.zeros((0, 2), np.int64)
        n_extra = np.bincount(extra[:, 0], minlength=n)
        offsets = np.concatenate([[0], np.cumsum(1 + n_extra)])
        data = np.empty(offsets[-1], np.int32)
        data[offsets[:-1]] = part
        first_extra = np.concatenate([[0], np.cumsum(n_extra)])[:-1]
        data[offsets[extra[:, 0]] + 1 + np.arange(len(extra)) - first_extra[extra[:, 0]]] = extra[:, 1]
        starts = np.cumsum([0] + counts)
        pieces = [(data[offsets[starts[r]]:offsets[starts[r + 1]]], offsets[starts[r]:starts[r + 1] + 1]
                   - offsets[starts[r]]) for r in range(comm.size)]
    data, offsets = comm.scatter(pieces, root=0)
    return cpp.graph.AdjacencyList_int32(np.ascontiguousarray(data, np.int32), np.ascontiguousarray(offsets, np.int32))


def _cuthill_mckee_order(cells):
    """Reverse Cuthill–McKee order of the tetrahedra ``cells`` (n, 4) by their dual graph."""
    n = len(cells)
    faces = np.sort(cells[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3), axis=1)
    cell_of = np.repeat(np.arange(n), 4)
    order = np.lexsort(faces.T[::-1])
    faces, cell_of = faces[order], cell_of[order]
    shared = np.all(faces[1:] == faces[:-1], axis=1)
    a, b = cell_of[:-1][shared], cell_of[1:][shared]
    graph = csr_matrix((np.ones(2 * a.size, np.int8), (np.concatenate([a, b]), np.concatenate([b, a]))),
                       shape=(n, n))
    graph.sort_indices()
    return reverse_cuthill_mckee(graph, symmetric_mode=True)


def _vertex_neighbour_parts(cells, part):
    """(cell, part) rows, sorted and unique: the parts other than the cell's own that own a
    cell sharing a vertex with it."""
    vertex = cells.ravel()
    cell_of = np.repeat(np.arange(len(cells)), cells.shape[1])
    vertex_parts = np.unique(np.stack([vertex, part[cell_of]], axis=1), axis=0)  # sorted by vertex
    start = np.searchsorted(vertex_parts[:, 0], vertex, "left")
    count = np.searchsorted(vertex_parts[:, 0], vertex, "right") - start
    rows = np.repeat(start - np.concatenate([[0], np.cumsum(count)[:-1]]), count) + np.arange(count.sum())
    pairs = np.unique(np.stack([np.repeat(cell_of, count), vertex_parts[rows, 1]], axis=1), axis=0)
    return pairs[pairs[:, 1] != part[pairs[:, 0]]]


@contextmanager
def _cells_partitioned_by(cell_partitioner):
    """``gmshio.model_to_mesh`` (DOLFINx 0.5.2 takes no partitioner argument) creating its mesh
    with ``cell_partitioner``: its module's ``create_mesh`` replaced for the call."""
    original = gmshio.create_mesh
    gmshio.create_mesh = functools.partial(original, partitioner=cell_partitioner)
    try:
        yield
    finally:
        gmshio.create_mesh = original


def _unusable(groups: dict[str, tuple[int, int]]) -> str | None:
    """Why the current gmsh model cannot be distributed, or None."""
    if not any(dim == 3 for dim, _ in groups.values()):
        return ("the gmsh model has no 3D physical group: cells outside physical groups are dropped, "
                "so tag the volume(s)")
    tets = gmsh.model.mesh.getElementsByType(4)[0]
    if len(tets) == 0:
        return "gmsh made no tetrahedra (an empty or degenerate geometry? check the .geo parameters and size)"
    return None


def load_geo(path: str | Path, mesh_size: float, comm: MPI.Comm = MPI.COMM_WORLD,
             parameters: dict[str, float] | None = None, rank: int = 0) -> TaggedMesh:
    """Mesh a gmsh ``.geo`` source with tetrahedra of size ``mesh_size`` (m).

    ``parameters`` override the ``DefineConstant`` values of the source (gmsh ONELAB
    names ``"Parameters/<name>"``), e.g. ``{"L": 2.0}``.  A bare name is looked up
    in ``meshes/``.
    """
    path = _resolve(path, ".geo")
    return _distributed(comm, rank, lambda: _generate(path, mesh_size, parameters))


def load_msh(path: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, rank: int = 0) -> TaggedMesh:
    """Read a gmsh ``.msh`` file (with physical groups) and distribute it."""
    path = _resolve(path, ".msh")
    return _distributed(comm, rank, lambda: gmsh.merge(str(path)))


def load_mesh(path: str | Path, mesh_size: float | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
              parameters: dict[str, float] | None = None) -> TaggedMesh:
    """Load ``.geo`` (meshed with ``mesh_size``, required) or ``.msh`` by suffix."""
    suffix = Path(path).suffix or ".geo"
    if suffix == ".msh":
        return load_msh(path, comm)
    if suffix == ".geo":
        if mesh_size is None or mesh_size <= 0:
            raise ValueError(f"mesh_size = {mesh_size!r}: a .geo source needs a mesh size > 0 (m)")
        return load_geo(path, mesh_size, comm, parameters)
    raise ValueError(f"mesh file {str(path)!r}: suffix {suffix!r} not one of '.geo', '.msh'")


@dataclass(frozen=True)
class VolumeCells:
    """Every tetrahedron of a gmsh model with the physical volume it belongs to (serial arrays,
    gmsh's node order): ``points`` (n, 3), ``cells`` (c, 4) node indices, ``volume`` (c,) the
    physical-group name of each cell's volume."""
    points: np.ndarray
    cells: np.ndarray
    volume: np.ndarray


def volume_cells(path: str | Path, mesh_size: float | None = None,
                 parameters: dict[str, float] | None = None) -> VolumeCells:
    """The tetrahedra of a ``.geo`` source (meshed with ``mesh_size`` and ``parameters``, as
    :func:`load_geo`) or a ``.msh`` file, labelled by physical volume (serial, one process).
    A cell in no physical volume is dropped, as DOLFINx drops it."""
    path = Path(path)
    if path.suffix != ".msh" and not (mesh_size and mesh_size > 0):
        raise ValueError(f"mesh_size = {mesh_size!r}: a .geo source needs a mesh size > 0 (m)")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        if path.suffix == ".msh":
            gmsh.merge(str(_resolve(path, ".msh")))
        else:
            _generate(_resolve(path, ".geo"), mesh_size, parameters)
        labelled = labelled_cells()
    finally:
        gmsh.finalize()
    if len(labelled.cells) == 0:
        raise MeshError(f"{path}: no tetrahedra in a physical volume")
    return labelled


def labelled_cells() -> VolumeCells:
    """The tetrahedra of the current (meshed) gmsh model labelled by physical volume, with every
    node of the model (gmsh's order)."""
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1 if len(tags) else 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    cells, names = [np.zeros((0, 4), np.int64)], [np.zeros(0, object)]
    for dim, group in gmsh.model.getPhysicalGroups(3):
        name = gmsh.model.getPhysicalName(dim, group)
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, group):
            types, _, nodes = gmsh.model.mesh.getElements(dim, entity)
            for kind, element_nodes in zip(types, nodes, strict=True):
                if kind == 4:  # 4-node tetrahedron
                    tets = index[np.asarray(element_nodes, np.int64)].reshape(-1, 4)
                    cells.append(tets)
                    names.append(np.full(len(tets), name, dtype=object))
    return VolumeCells(coordinates.reshape(-1, 3), np.vstack(cells), np.concatenate(names))


def write_msh(geo_path: str | Path, msh_path: str | Path, mesh_size: float,
              parameters: dict[str, float] | None = None) -> Path:
    """Mesh a ``.geo`` source and save it as ``.msh`` (serial; for reuse or inspection)."""
    gmsh.initialize()
    try:
        _generate(_resolve(geo_path, ".geo"), mesh_size, parameters)
        gmsh.write(str(msh_path))
    finally:
        gmsh.finalize()
    return Path(msh_path)


def msh_to_vtu(msh_path: str | Path, out_path: str | Path) -> Path:
    """Convert a ``.msh`` to a VTU (tetrahedra + ``gmsh:physical`` cell data) with meshio."""
    src = meshio.read(msh_path)
    tets = [(i, block) for i, block in enumerate(src.cells) if block.type == "tetra"]
    physical = src.cell_data.get("gmsh:physical")
    cell_data = {"gmsh:physical": [physical[i] for i, _ in tets]} if physical else {}
    meshio.write(out_path, meshio.Mesh(src.points, [b for _, b in tets], cell_data=cell_data))
    return Path(out_path)


def _generate(path: Path, mesh_size: float, parameters: dict[str, float] | None) -> None:
    """Open ``path`` in the (initialised) gmsh session and mesh it in 3D: elements of at most
    ``mesh_size`` and at least half of it, unless the source sets ``Mesh.MeshSizeMin`` itself
    (a source with a size field that refines below ``mesh_size``, e.g. meshes/strip_footing.geo)."""
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.onelab.clear()  # ONELAB values outlive gmsh.finalize(): drop the last file's
    for name, value in (parameters or {}).items():
        gmsh.onelab.setNumber(f"Parameters/{name}", [float(value)])
    gmsh.open(str(path))
    _check_size_fits(mesh_size)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
    if gmsh.option.getNumber("Mesh.MeshSizeMin") == 0.0:  # a source refining with a size field sets its own
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * mesh_size)
    gmsh.model.mesh.generate(3)


def _check_size_fits(mesh_size: float) -> None:
    """Raise :class:`MeshSizeTooLarge` when ``mesh_size`` exceeds the largest extent of the
    opened geometry's bounding box (gmsh would mesh it with degenerate elements, or fail
    obscurely); a model without entities is left to the checks after meshing."""
    if not gmsh.model.getEntities():
        return
    lo_hi = gmsh.model.getBoundingBox(-1, -1)
    extent = max(hi - lo for lo, hi in zip(lo_hi[:3], lo_hi[3:], strict=True))
    if math.isfinite(extent) and 0.0 < extent < mesh_size:
        raise MeshSizeTooLarge(float(mesh_size), float(extent))


def _resolve(path: str | Path, suffix: str) -> Path:
    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(suffix)
    if not path.exists() and (MESH_DIR / path).exists():
        path = MESH_DIR / path
    if not path.exists():
        raise FileNotFoundError(f"mesh source {str(path)!r} not found (also looked in {MESH_DIR})")
    return path
