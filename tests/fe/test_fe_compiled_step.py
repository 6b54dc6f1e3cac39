"""The compiled FE step (fe_domain/compiled.py) against the PETSc step it replaces, on one
rank and on several (owned rows, ghost updates between the calls): the same arithmetic in
another summation order, so the same state to round-off, with every ingredient of a step in
play (loads with a ramp, a body force, a prescribed velocity with a ramp, supports, damping,
the external force a coupling sets — on ghost nodes too, which count for their owners —
energies recorded)."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.mesh import load_geo

STEPS = 300


CASES = [("mixed", None), ("mixed", {"type": "local", "alpha": 0.3}), ("displacement", {"type": "mass", "alpha": 20.0})]


@pytest.mark.parametrize("formulation, damping", CASES)
def test_compiled_step_is_the_petsc_step_to_round_off(formulation, damping):
    compare_with_petsc(MPI.COMM_SELF, formulation, damping)


@pytest.mark.mpi
@pytest.mark.parametrize("formulation, damping", CASES)
def test_compiled_step_on_several_ranks_is_the_petsc_step_to_round_off(formulation, damping):
    compare_with_petsc(MPI.COMM_WORLD, formulation, damping)


def compare_with_petsc(comm, formulation, damping):
    runs = []
    for compiled in (True, False):
        s = make(compiled, formulation, damping, comm)
        assert (s._kernel is not None) is compiled
        s.energy_interval = 50
        rng = np.random.default_rng(3)
        for k in range(STEPS):
            if k % 10 == 0:  # a coupling's interface force, changed now and then
                s.external_force[:] = rng.normal(scale=0.1, size=s.external_force.shape)
            s.step()
        runs.append(s)
    fast, reference = runs

    def largest(array):  # over every rank's nodes, ghosts included
        return comm.allreduce(float(np.abs(array).max()), op=MPI.MAX)

    scale = largest(reference.displacement)
    assert scale > 1e-6  # it moved
    assert largest(fast.displacement - reference.displacement) < 1e-13 * scale
    v_scale = largest(reference.velocity)
    assert largest(fast.velocity - reference.velocity) < 1e-11 * v_scale
    if formulation == "mixed":
        p_scale = largest(reference.pressure)
        assert p_scale > 0
        assert largest(fast.pressure - reference.pressure) < 1e-12 * p_scale
    for row_fast, row_ref in zip(fast.energy_history, reference.energy_history, strict=True):
        for key in ("kinetic", "strain", "external_work", "damping_work", "stabilisation"):
            assert row_fast[key] == pytest.approx(row_ref[key], rel=1e-8, abs=1e-14)
    assert np.allclose(fast.reaction("bottom"), reference.reaction("bottom"), rtol=1e-8, atol=1e-12)


def make(compiled, formulation, damping, comm=MPI.COMM_SELF):
    from fe_domain import build

    tagged = load_geo("block", 0.25, comm)
    records = dict(boundary_conditions=[build._boundary_condition(0, {"type": "fixed", "boundary": "bottom"}),
                                        build._boundary_condition(1, {"type": "velocity", "boundary": "x1",
                                                                      "velocity": [1e-3, 0, 0], "components": [0],
                                                                      "ramp": 0.01})],
                   loads=[build._load(0, {"type": "pressure", "boundary": "top", "pressure": 1e4, "ramp": 0.02}),
                          build._load(1, {"type": "body_force", "acceleration": [0.0, 0.0, -9.81]})],
                   damping=build._damping(damping))
    from fe_domain.explicit import ExplicitSolid
    return ExplicitSolid(tagged, build._material({"E": 1e7, "nu": 0.3, "rho": 1000.0}), formulation=formulation,
                         compiled=compiled, **records)


def test_one_rank_steps_compiled_by_default():
    assert make(None, "mixed", None)._kernel is not None


def test_run_in_compiled_calls_is_step_by_step_bit_for_bit():
    """``run(n)`` steps between energy records in one compiled call: the same bits as n steps."""
    a, b = make(True, "mixed", {"type": "local", "alpha": 0.3}), make(True, "mixed", {"type": "local", "alpha": 0.3})
    for s in (a, b):
        s.energy_interval = 70
    a.run(STEPS)
    for _ in range(STEPS):
        b.step()
    assert a.step_count == b.step_count == STEPS and a.time == b.time
    for name in ("displacement", "velocity", "pressure", "_work"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.energy_history == b.energy_history and len(a.energy_history) == 5


def test_the_compiled_copy_leaves_petscs_matrices_as_they_were():
    """(petsc4py's Mat.convert works in place unless given a matrix to fill.)"""
    solid = make(True, "mixed", None)
    assert solid._stiffness.getType() == "seqbaij"


@pytest.mark.mpi
@pytest.mark.parametrize("compiled", [True, False])
def test_forces_on_ghost_nodes_are_not_read(compiled):
    """On several ranks a force is given by the rank owning its node: the rows of
    ``external_force`` for ghost nodes are ignored, by both step paths."""
    runs = []
    for on_ghosts in (False, True):
        s = make(compiled, "mixed", None, MPI.COMM_WORLD)
        s.external_force[:s.n_owned_nodes] = 0.05
        if on_ghosts:
            s.external_force[s.n_owned_nodes:] = 1e3
        for _ in range(20):
            s.step()
        runs.append(s.displacement.copy())
    if MPI.COMM_WORLD.size > 1:
        assert MPI.COMM_WORLD.allreduce(s.n_nodes - s.n_owned_nodes) > 0  # there are ghost rows
    assert np.array_equal(*runs)
