"""XDMF fields, energy and reaction CSV files."""

import csv

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import Fixed, LocalNonViscousDamping, Material, Traction
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo
from fe_domain.output import ENERGY_COLUMNS, Recorder


def test_recorder_writes_fields_energies_and_reactions(tmp_path):
    solver = ExplicitSolid(load_geo("block", 0.5, MPI.COMM_SELF), Material(E=1e7, nu=0.3, rho=1000.0),
                           damping=LocalNonViscousDamping(0.7), boundary_conditions=[Fixed("bottom")],
                           loads=[Traction("top", (0.0, 0.0, -1e4))])
    recorder = Recorder(solver, tmp_path, field_interval=50, energy_interval=10,
                        reaction_boundaries=("bottom",), reaction_interval=10)
    solver.run(200, callback=recorder)
    recorder.close()
    assert (tmp_path / "fields.xdmf").exists() and (tmp_path / "fields.h5").exists()
    xdmf = (tmp_path / "fields.xdmf").read_text()
    for name in ("u", "v", "p", "von_mises"):
        assert f'Name="{name}"' in xdmf
    assert xdmf.count('<Time Value=') == 4 * 5                # 4 fields at t = 0 and 4 intervals
    energies = list(csv.DictReader(open(tmp_path / "energies.csv")))
    assert tuple(energies[0]) == ENERGY_COLUMNS and len(energies) == 20
    reactions = np.loadtxt(tmp_path / "reactions.csv", delimiter=",", skiprows=1)
    assert reactions.shape == (20, 4)
    assert reactions[-1, 3] == pytest.approx(1e4, rel=0.05)   # supports carry the load
    assert float(energies[-1]["damping_work"]) > 0.0
