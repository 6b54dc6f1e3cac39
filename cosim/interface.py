"""The FE–DE interface (docs/design.md §5.1): a tagged FE boundary seen by the DEM as a
triangle facet mesh whose vertices are the FE nodes at X + u, and the particle
impulse on those vertices handed back to the FE nodes as forces.

The DEM is partitioned over all MPI ranks (every rank holds the whole interface facet
mesh, as it holds every wall: de_domain.distributed sums the vertex forces over the
ranks, so every rank has the same impulses), and so may be the FE mesh (the solid's
communicator: all ranks, or this rank alone for an FE replicated on every rank). Each
interface node is owned by exactly one rank of the solid's communicator (DOLFINx's index
map): its position and velocity are gathered from that rank by all, and its force is set
there only, so every impulse the particles give the facets reaches the FE exactly once
(a replicated FE: every rank owns every node, and gathers nothing).

Optional smoothing of the interface force in time (``smoothing_time`` τ > 0): the impulse
I of a window joins an impulse held back H, and the FE receives the part
β (H + I), β = 1 − exp(−Δt_FE/τ), of it — a first-order low-pass filter with time constant
τ; the rest stays held. What is held counts as impulse in transit, so the momentum of
FE + DEM + impulse in transit stays exactly conserved (docs/design.md §5.4); at a steady
load the FE receives, on average, the whole impulse.

The interface traction for ParaView is the nodal force over the node's lumped area,
t_a = f_a / A_a with ``A_a = Σ_{T ∋ a} |T| / 3`` (= ∫ φ_a dA for linear triangles, on the
reference surface).
"""
from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from numba import njit


@njit(cache=True, error_model="numpy")
def _pack_motion(rows, nodes, coordinates, displacement, velocity, dt, after_a_step):
    """Row k = (X + u^n, v^{n+½}) of node ``nodes[k]``; after a step u^n = u^{n+1} − Δt v^{n+½}
    (before the first, u^0)."""
    for k in range(nodes.size):
        a = nodes[k]
        for d in range(3):
            u = displacement[a, d] - dt * velocity[a, d] if after_a_step else displacement[a, d]
            rows[k, d] = coordinates[a, d] + u
            rows[k, 3 + d] = velocity[a, d]


@njit(cache=True, error_model="numpy")
def _unpack_motion(gathered, vertex_of_row, vertices, vertex_velocity):
    """Gathered row r → position and velocity of facet vertex ``vertex_of_row[r]``."""
    for r in range(gathered.shape[0]):
        k = vertex_of_row[r]
        for d in range(3):
            vertices[k, d] = gathered[r, d]
            vertex_velocity[k, d] = gathered[r, 3 + d]


@njit(cache=True, error_model="numpy")
def _set_forces(external_force, nodes, released, vertex_of_node, window):
    """f_a = I_a / Δt_FE on each owned interface node a (its facet vertex's released impulse)."""
    for k in range(nodes.size):
        for d in range(3):
            external_force[nodes[k], d] = released[vertex_of_node[k], d] / window


class Interface:
    """Gather/scatter between the ``ExplicitSolid`` boundary groups ``names`` and a DEM ``FacetMesh``.

    ``facets`` (every rank) is the DEM facet mesh; its vertex k is the FE node with
    mesh-input index ``input_nodes[k]``. Collective construction.
    """

    def __init__(self, solid, names, material=0, smoothing_time=0.0):
        from de_domain import FacetMesh

        names = [names] if isinstance(names, str) else list(names)
        name = "+".join(names)
        self.solid, self.comm = solid, solid.comm
        nodes = np.unique(np.concatenate([solid.boundary_nodes(n) for n in names]))
        self.owned_nodes = nodes[nodes < solid.n_owned_nodes]           # this rank's interface nodes
        # vertices ordered by the node's index in the mesh input (gmsh), not by DOLFINx's global
        # index, which depends on the partition: the facet mesh, and a DEM checkpoint of it, are
        # then the same for every rank count and partition
        owned_input = solid.input_node_index[self.owned_nodes]
        triangles = solid.input_node_index[np.concatenate([solid.facet_triangles(n) for n in names])]
        all_owned = self.comm.allgather(owned_input)
        all_triangles = self.comm.allgather(triangles)
        counts = [len(a) for a in all_owned]
        self._rows = slice(sum(counts[:self.comm.rank]), sum(counts[:self.comm.rank + 1]))  # this rank's rows
        self._gathered = np.empty((sum(counts), 6))             # (X + u, v) of every rank's rows, rank order
        self._gather_counts = [6 * c for c in counts]
        gathered = np.concatenate(all_owned)
        order = np.argsort(gathered)
        self.input_nodes = gathered[order]
        if len(np.unique(self.input_nodes)) != len(self.input_nodes):
            raise RuntimeError(f"interface '{name}': a node is owned by two ranks")
        self._from_gathered = order                     # gathered row -> vertex: vertex k = row order[k]
        self._vertex_of_row = np.argsort(order)         # vertex of each gathered row
        tri = np.searchsorted(self.input_nodes, np.concatenate(all_triangles).reshape(-1, 3))
        if len(tri) == 0:
            raise ValueError(f"interface '{name}' has no facets")
        state = self._gather_motion()[self._from_gathered]
        positions = state[:, :3]
        self.facets = FacetMesh(positions, tri, material=material, source_nodes=self.input_nodes)
        self.facets.set_vertex_state(positions, state[:, 3:])
        self._traction_field = None
        self.smoothing_time = float(smoothing_time)
        self.held = np.zeros_like(positions)         # impulse held back by the smoothing (every vertex)
        self.held_before = self.held.copy()          # ... before the last receive_forces (for checkpoints)
        self.released = np.zeros_like(positions)     # impulse handed to the FE's next step (every vertex)
        self.owned_vertices = self._vertex_of_row[self._rows]  # facet vertex of each owned node
        self.nodal_area = nodal_areas(positions, tri)[self.owned_vertices]  # of this rank's owned nodes

    def _gather_motion(self):
        """The rows (X + u^n, v^{n+½}) of every rank's owned interface nodes, in rank order, on
        every rank (this rank's packed in place, then gathered into the same kept buffer)."""
        s = self.solid
        _pack_motion(self._gathered[self._rows], self.owned_nodes, s.node_coordinates, s.displacement, s.velocity,
                     s.dt, s.step_count > 0)
        if self.comm.size > 1:
            self.comm.Allgatherv(MPI.IN_PLACE, [self._gathered, self._gather_counts])
        return self._gathered

    def send_motion(self):
        """docs/design.md §5.3 step 2: after the FE step n → n+1 the vertices start at X + u^n and move
        with v^{n+½} over the window (the DEM advances them linearly, x += v Δt)."""
        _unpack_motion(self._gather_motion(), self._vertex_of_row, self.facets.vertices, self.facets.vertex_velocity)
        self.facets.reset_impulse()

    def receive_forces(self, window):
        """docs/design.md §5.3 step 4: interface force for the next FE step = impulse / Δt_FE, set on
        this rank's owned nodes only, so it is applied once. With smoothing, the impulse released
        from the window's and the held one (module docstring)."""
        impulse = self.facets.vertex_impulse
        if self.smoothing_time > 0.0:
            self.held_before[:] = self.held
            total = self.held + impulse
            np.multiply(self.release_fraction(window), total, out=self.released)
            np.subtract(total, self.released, out=self.held)
        else:
            self.released[:] = impulse
        _set_forces(self.solid.external_force, self.owned_nodes, self.released, self.owned_vertices, window)

    def release_fraction(self, window):
        """β = 1 − exp(−Δt_FE/τ) of the smoothing (module docstring); 1 without."""
        return -math.expm1(-window / self.smoothing_time) if self.smoothing_time > 0.0 else 1.0

    def pending_impulse(self):
        """Σ impulse collected by the DEM and not yet applied to the FE: released for the next FE
        step, and held back by the smoothing (the same on every rank)."""
        return self.released.sum(axis=0) + self.held.sum(axis=0)

    def traction(self):
        """Traction t_a = f_a / A_a (Pa) that the particles exert on this rank's owned
        interface nodes, from the interface force the FE applies in its next step."""
        return self.solid.external_force[self.owned_nodes] / self.nodal_area[:, None]

    def traction_field(self):
        """The traction as a P1 vector field ``interface_traction`` (zero off the interface),
        for :class:`fe_domain.output.FieldWriter`; refreshed at each call; collective."""
        if self._traction_field is None:
            from dolfinx import fem
            self._traction_field = fem.Function(self.solid.V, name="interface_traction")
        values = self._traction_field.x.array.reshape(-1, 3)
        values[:] = 0.0
        values[self.owned_nodes] = self.traction()
        self._traction_field.x.scatter_forward()
        return self._traction_field


def nodal_areas(vertices, triangles):
    """Lumped area of each vertex, ``A_a = Σ_{T ∋ a} |T| / 3`` (m²)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    third = np.linalg.norm(np.cross(b - a, c - a), axis=1) / 6.0
    area = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(area, triangles[:, k], third)
    return area
