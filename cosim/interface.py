"""The FE–DE interface (docs/design.md §5.1): a tagged FE boundary seen by the DEM as a
triangle facet mesh whose vertices are the FE nodes at X + u, and the particle
impulse on those vertices handed back to the FE nodes as forces.

The FE mesh is partitioned over all MPI ranks; the DEM runs on rank 0. Each
interface node is owned by exactly one rank (DOLFINx's index map), which sends its
position and velocity to rank 0 and receives its force back: every impulse the
particles give the facets reaches the FE exactly once.
"""
from __future__ import annotations

import numpy as np


class Interface:
    """Gather/scatter between the ``ExplicitSolid`` boundary groups ``names`` and a DEM ``FacetMesh``.

    ``facets`` (rank 0 only) is the DEM facet mesh; its vertex k is the FE node with
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
        all_owned = self.comm.gather(owned_global, root=0)
        all_triangles = self.comm.gather(triangles, root=0)
        self.facets = None
        if self.comm.rank == 0:
            self._counts = [len(a) for a in all_owned]
            gathered = np.concatenate(all_owned)
            order = np.argsort(gathered)
            self.global_nodes = gathered[order]
            if len(np.unique(self.global_nodes)) != len(self.global_nodes):
                raise RuntimeError(f"interface '{name}': a node is owned by two ranks")
            self._from_gathered = order                     # gathered row -> vertex: vertex k = row order[k]
            tri = np.searchsorted(self.global_nodes, np.concatenate(all_triangles).reshape(-1, 3))
            if len(tri) == 0:
                raise ValueError(f"interface '{name}' has no facets")
            positions, velocities = self._gathered_state()
            self.facets = FacetMesh(positions, tri, material=material, source_nodes=self.global_nodes)
            self.facets.set_vertex_state(positions, velocities)
        else:
            self._gathered_state()

    def _gathered_state(self):
        """(positions X + u^n, velocities v^{n+½}) of the interface vertices, on rank 0."""
        s = self.solid
        nodes = self.owned_nodes
        u_now = s.displacement[nodes] - s.dt * s.velocity[nodes] if s.step_count else s.displacement[nodes]
        local = np.hstack([s.node_coordinates[nodes] + u_now, s.velocity[nodes]])
        rows = self.comm.gather(local, root=0)
        if self.comm.rank != 0:
            return None, None
        state = np.concatenate(rows)[self._from_gathered]
        return state[:, :3], state[:, 3:]

    def send_motion(self):
        """docs/design.md §5.3 step 2: after the FE step n → n+1 the vertices start at X + u^n and move
        with v^{n+½} over the window (the DEM advances them linearly, x += v Δt)."""
        positions, velocities = self._gathered_state()
        if self.facets is not None:
            self.facets.set_vertex_state(positions, velocities)
            self.facets.reset_impulse()

    def receive_forces(self, window):
        """docs/design.md §5.3 step 4: interface force for the next FE step = impulse / Δt_FE, scattered
        to the owning ranks; it is set on owned nodes only, so it is applied once."""
        chunks = None
        if self.comm.rank == 0:
            force = np.empty_like(self.facets.vertex_impulse)
            force[self._from_gathered] = self.facets.vertex_impulse / window   # back to gathered-row order
            chunks = np.split(force, np.cumsum(self._counts)[:-1])
        mine = self.comm.scatter(chunks, root=0)
        self.solid.external_force[self.owned_nodes] = mine

    def pending_impulse(self):
        """Σ impulse of the last DEM window not yet applied to the FE (rank 0; zeros elsewhere)."""
        return self.facets.vertex_impulse.sum(axis=0) if self.facets is not None else np.zeros(3)
