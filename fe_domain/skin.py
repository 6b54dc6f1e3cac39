"""The faces between the volumes of a tetrahedral mesh, found from the cells alone.

A general embedded DEM zone (a zone of any shape gmsh can mesh, in one model with the FE
volumes around it) needs the coupling interface without a hand-tagged surface: it is every
triangle shared by a tetrahedron of a zone volume and a tetrahedron of an FE volume (skin
detection, as Kratos finds the skin of a model part). The zone's other boundary triangles,
shared with no cell at all, are its free faces (a free surface, or the slice walls of a
plane model).

A triangle is keyed by its sorted node triple; each cell contributes its four faces. A face
seen from a zone cell and from an FE cell is on the interface. Its orientation: the normal
(x_b − x_a) × (x_c − x_a) of the returned triangle (a, b, c) points out of the FE cell, into
the zone (towards the grains). A free face's normal points out of the zone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the faces of a tetrahedron (n0, n1, n2, n3), each with the node opposite to it
TET_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
TET_OPPOSITE = np.array([0, 1, 2, 3])


@dataclass(frozen=True)
class Skin:
    """The interface and free faces of the zone, as node-index triangles (m, 3) of the mesh."""
    interface: np.ndarray    # shared by a zone cell and an FE cell; normal into the zone
    free: np.ndarray         # of a zone cell, shared with no cell; normal out of the zone


def zone_skin(points, cells, cell_volume, zone, structure) -> Skin:
    """The skin of the zone volumes in a tetrahedral mesh.

    ``points`` (n, 3) node coordinates; ``cells`` (c, 4) node indices; ``cell_volume`` (c,)
    the volume (physical group) label of each cell; ``zone`` and ``structure`` the labels of
    the DEM-zone volumes and of the FE volumes. Cells of other labels (neither) border the
    zone through faces that are neither interface nor free: a face of the zone shared with
    such a cell is left out of both."""
    cells = np.asarray(cells, np.int64)
    label = np.asarray(cell_volume)
    in_zone, in_fe = np.isin(label, list(zone)), np.isin(label, list(structure))
    faces = cells[:, TET_FACES].reshape(-1, 3)               # 4 faces per cell, cell-major
    opposite = cells[:, TET_OPPOSITE].reshape(-1)
    owner = np.repeat(np.arange(len(cells)), 4)
    keys = np.sort(faces, axis=1)
    _, face_id, count = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    face_id = face_id.reshape(-1)
    if np.any(count > 2):
        raise ValueError("a triangle is shared by more than two tetrahedra: the mesh is not conforming")
    seen_by_zone = np.zeros(len(count), bool)
    seen_by_zone[face_id[in_zone[owner]]] = True
    seen_by_fe = np.zeros(len(count), bool)
    seen_by_fe[face_id[in_fe[owner]]] = True
    interface_rows = in_fe[owner] & seen_by_zone[face_id]    # the FE cell's copy of each interface face
    free_rows = in_zone[owner] & (count[face_id] == 1)       # zone faces on the mesh's boundary
    points = np.asarray(points, float)
    return Skin(interface=_outward(points, faces[interface_rows], opposite[interface_rows]),
                free=_outward(points, faces[free_rows], opposite[free_rows]))


def _outward(points, triangles, opposite):
    """``triangles`` reordered so that their normals point out of the cell they were taken
    from: away from the node opposite to them."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), points[opposite] - a) > 0
    out = triangles.copy()
    out[flip, 1], out[flip, 2] = triangles[flip, 2], triangles[flip, 1]
    return out


def triangle_areas(points, triangles):
    """Area of each triangle (m,)."""
    a, b, c = (np.asarray(points, float)[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def triangle_normals(points, triangles):
    """Unit normals of the triangles (m, 3): (x_b − x_a) × (x_c − x_a), normalised."""
    a, b, c = (np.asarray(points, float)[triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    return n / np.linalg.norm(n, axis=1)[:, None]
