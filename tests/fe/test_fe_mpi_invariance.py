"""Results do not depend on the number of ranks (docs/design.md §4.8 ghost updates, §5.5 MPI).

Collective: run under ``mpirun -n 2 python -m pytest -m mpi``.  Every rank also runs
the same case on COMM_SELF and compares node by node (gmsh node numbers).
"""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import (
    BodyForce,
    Fixed,
    MassProportionalDamping,
    Material,
    NormalPressure,
    PrescribedVelocity,
    Traction,
    ramp,
)
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

MATERIALS = {"soil": Material(E=5e7, nu=0.3, rho=1800.0), "footing": Material(E=3e9, nu=0.2, rho=2500.0)}
N_STEPS, RECORD_EVERY = 60, 15


def footing_history(comm):
    """Footing on soil: gravity, a ramped pressure on the plate, a tangential traction,
    a moving side, and an 'interface' force written into external_force (owned nodes)."""
    tagged = load_geo("footing", 0.3, comm)
    solver = ExplicitSolid(tagged, MATERIALS, damping=MassProportionalDamping(50.0),
                           boundary_conditions=[Fixed("soil_bottom"),
                                                PrescribedVelocity("soil_sides", (1e-3, None, None))],
                           loads=[BodyForce((0.0, 0.0, -9.81)),
                                  NormalPressure("footing_top", 2e5, ramp(1e-3)),
                                  Traction("soil_top", (1e3, 0.0, 0.0))])
    interface = solver.boundary_nodes("interface")
    owned = interface[interface < solver.n_owned_nodes]
    solver.energy_interval = RECORD_EVERY
    history = []
    for _ in range(N_STEPS):
        x = solver.node_coordinates[owned]
        solver.external_force[owned] = np.column_stack([x[:, 0], x[:, 1], -1.0 - x[:, 0]]) * 50.0
        solver.step()
        if solver.step_count % RECORD_EVERY == 0:
            n = solver.n_owned_nodes
            keys = comm.allgather(solver.input_node_index[:n])
            u = comm.allgather(solver.displacement[:n])
            p = comm.allgather(solver.pressure[:n])
            order = np.argsort(np.concatenate(keys))
            history.append((np.concatenate(u)[order], np.concatenate(p)[order],
                            solver.reaction("soil_bottom")))
    return history, solver.energy_history


@pytest.mark.mpi
def test_displacement_history_is_the_same_on_all_ranks_and_on_one():
    parallel, parallel_energy = footing_history(MPI.COMM_WORLD)
    serial, serial_energy = footing_history(MPI.COMM_SELF)
    for (u_n, p_n, r_n), (u_1, p_1, r_1) in zip(parallel, serial, strict=True):
        assert np.abs(u_n - u_1).max() <= 1e-10 * np.abs(u_1).max()
        assert np.abs(p_n - p_1).max() <= 1e-10 * np.abs(p_1).max()
        assert np.abs(r_n - r_1).max() <= 1e-10 * np.abs(r_1).max()
    for e_n, e_1 in zip(parallel_energy, serial_energy, strict=True):
        assert e_n["total"] == pytest.approx(e_1["total"], rel=1e-10)
    assert np.abs(parallel[-1][0]).max() > 0


@pytest.mark.mpi
def test_interface_facets_are_reported_once_across_ranks():
    solver = ExplicitSolid(load_geo("footing", 0.2, MPI.COMM_WORLD), MATERIALS)
    x = solver.node_coordinates
    tri = solver.facet_triangles("interface")
    area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    assert solver.comm.allreduce(area.sum()) == pytest.approx(0.25, rel=1e-12)
    assert solver.comm.allreduce(len(tri)) == len(load_geo("footing", 0.2, MPI.COMM_SELF).facets("interface"))


@pytest.mark.mpi
def test_the_mesh_is_cut_the_same_way_every_time_in_equal_parts():
    """fe_domain.mesh.reproducible_partitioner (DOLFINx's PT-SCOTCH default cut one mesh two
    ways over 12 runs): the same owned cells when the mesh is made again, and cell counts
    per rank that differ by at most one."""
    comm = MPI.COMM_WORLD

    def owned_cells():
        mesh = load_geo("footing", 0.3, comm).mesh
        n = mesh.topology.index_map(3).size_local
        return np.sort(np.asarray(mesh.topology.original_cell_index)[:n])

    first, second = owned_cells(), owned_cells()
    assert np.array_equal(first, second)
    counts = comm.allgather(first.size)
    assert max(counts) - min(counts) <= 1 and sum(counts) == len(np.unique(np.concatenate(comm.allgather(first))))
