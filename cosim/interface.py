"""The FE–DE interface (docs/design.md §5.1): a tagged FE boundary seen by the DEM as a
triangle facet mesh whose vertices are the FE nodes at X + u, and the particle
impulse on those vertices handed back to the FE nodes as forces.

The FE mesh is partitioned over all MPI ranks, and so is the DEM (every rank holds
the whole interface facet mesh, as it holds every wall: de_domain.distributed sums
the vertex forces over the ranks, so every rank has the same impulses). Each
interface node is owned by exactly one rank (DOLFINx's index map): its position and
velocity are gathered from that rank by all, and its force is set there only, so
every impulse the particles give the facets reaches the FE exactly once.
"""
from __future__ import annotations

import numpy as np


class Interface:
    """Gather/scatter between the ``ExplicitSolid`` boundary groups ``names`` and a DEM ``FacetMesh``.

    ``facets`` (every rank) is the DEM facet mesh; its vertex k is the FE node with
    global index ``global_nodes[k]``. Collective construction.
    """

    def __init__(self, solid, names, material=0):
        from de_domain import FacetMesh

        names = [names] if isinstance(names, str) else list(names)
        name = "+".join(names)
        self.solid, self.comm = solid, solid.comm
        nodes = np.unique(np.concatenate([solid.boundary_nodes(n) for n in names]))
        self.owned_nodes = nodes[nodes < solid.n_owned_nodes]           # this rank's interface nodes
        owned_global = solid.global_node_index[self.owned_nodes]
        triangles = solid.global_node_index[np.concatenate([solid.facet_triangles(n) for n in names])]
        all_owned = self.comm.allgather(owned_global)
        all_triangles = self.comm.allgather(triangles)
        counts = [len(a) for a in all_owned]
        self._rows = slice(sum(counts[:self.comm.rank]), sum(counts[:self.comm.rank + 1]))  # this rank's rows
        gathered = np.concatenate(all_owned)
        order = np.argsort(gathered)
        self.global_nodes = gathered[order]
        if len(np.unique(self.global_nodes)) != len(self.global_nodes):
            raise RuntimeError(f"interface '{name}': a node is owned by two ranks")
        self._from_gathered = order                     # gathered row -> vertex: vertex k = row order[k]
        self._vertex_of_row = np.argsort(order)         # vertex of each gathered row
        tri = np.searchsorted(self.global_nodes, np.concatenate(all_triangles).reshape(-1, 3))
        if len(tri) == 0:
            raise ValueError(f"interface '{name}' has no facets")
        positions, velocities = self._gathered_state()
        self.facets = FacetMesh(positions, tri, material=material, source_nodes=self.global_nodes)
        self.facets.set_vertex_state(positions, velocities)

    def _gathered_state(self):
        """(positions X + u^n, velocities v^{n+½}) of the interface vertices, on every rank."""
        s = self.solid
        nodes = self.owned_nodes
        u_now = s.displacement[nodes] - s.dt * s.velocity[nodes] if s.step_count else s.displacement[nodes]
        local = np.hstack([s.node_coordinates[nodes] + u_now, s.velocity[nodes]])
        state = np.concatenate(self.comm.allgather(local))[self._from_gathered]
        return state[:, :3], state[:, 3:]

    def send_motion(self):
        """docs/design.md §5.3 step 2: after the FE step n → n+1 the vertices start at X + u^n and move
        with v^{n+½} over the window (the DEM advances them linearly, x += v Δt)."""
        positions, velocities = self._gathered_state()
        self.facets.set_vertex_state(positions, velocities)
        self.facets.reset_impulse()

    def receive_forces(self, window):
        """docs/design.md §5.3 step 4: interface force for the next FE step = impulse / Δt_FE, set on
        this rank's owned nodes only, so it is applied once."""
        vertices = self._vertex_of_row[self._rows]
        self.solid.external_force[self.owned_nodes] = self.facets.vertex_impulse[vertices] / window

    def pending_impulse(self):
        """Σ impulse of the last DEM window not yet applied to the FE (the same on every rank)."""
        return self.facets.vertex_impulse.sum(axis=0)
