"""Solver construction from plain (TOML-like) parameters."""

import pytest
from mpi4py import MPI

from fe_domain.boundary import LocalNonViscousDamping, NormalPressure, PrescribedVelocity
from fe_domain.build import build_solid

FOOTING = dict(
    material={"soil": {"E": 5e7, "nu": 0.3, "rho": 1800.0}, "footing": {"E": 3e9, "nu": 0.2, "rho": 2500.0}},
    boundary_conditions=[{"type": "fixed", "boundary": "soil_bottom"},
                         {"type": "velocity", "boundary": "soil_sides", "velocity": [0.0, 0.0, 0.0],
                          "components": [0, 1]}],
    loads=[{"type": "pressure", "boundary": "footing_top", "pressure": 1e5, "ramp": 0.01},
           {"type": "body_force", "acceleration": [0.0, 0.0, -9.81]}],
    damping={"type": "local", "alpha": 0.7},
)


def test_footing_case_from_plain_tables_runs():
    solver = build_solid("footing.geo", 0.4, comm=MPI.COMM_SELF, **FOOTING)
    assert isinstance(solver.damping, LocalNonViscousDamping)
    solver.run(20)
    assert solver.displacement[:, 2].min() < 0.0
    assert solver.reaction("soil_bottom")[2] > 0.0


def test_plain_tables_map_to_records():
    from fe_domain.build import _boundary_condition, _load
    bc = _boundary_condition(0, FOOTING["boundary_conditions"][1])
    assert isinstance(bc, PrescribedVelocity) and list(bc.velocity) == [0.0, 0.0, None]
    load = _load(0, FOOTING["loads"][0])
    assert isinstance(load, NormalPressure) and load.amplitude(0.005) == pytest.approx(0.5)


@pytest.mark.parametrize("key, table, message", [
    ("boundary_conditions", [{"type": "clamped", "boundary": "soil_bottom"}], r"boundary_conditions\[0\].type"),
    ("loads", [{"type": "point", "boundary": "footing_top"}], r"loads\[0\].type"),
    ("damping", {"type": "rayleigh", "alpha": 1.0}, "damping.type"),
])
def test_bad_tables_name_the_key(key, table, message):
    with pytest.raises(ValueError, match=message):
        build_solid("footing.geo", 0.5, comm=MPI.COMM_SELF, **{**FOOTING, key: table})
