"""The interface traction field t_a = f_a / A_a (cosim.interface): lumped nodal areas that
tile the interface, a uniform traction recovered exactly, and the field in the XDMF."""
import numpy as np
import pytest
from mpi4py import MPI

from cosim.interface import Interface, nodal_areas
from fe_domain.build import build_solid
from fe_domain.output import FieldWriter


def test_lumped_nodal_areas_are_a_third_of_each_triangle():
    vertices = np.array([[0.0, 0, 0], [2, 0, 0], [0, 1, 0], [2, 1, 0]])
    triangles = np.array([[0, 1, 2], [1, 3, 2]])
    assert nodal_areas(vertices, triangles) == pytest.approx([1 / 3, 2 / 3, 2 / 3, 1 / 3], rel=1e-15)


@pytest.fixture(scope="module")
def plate():
    solid = build_solid("block.geo", 0.0025, material={"E": 1.0e7, "nu": 0.3, "rho": 2000.0},
                        geometry_parameters={"Lx": 0.01, "Ly": 0.02, "Lz": 0.004}, formulation="mixed")
    return solid, Interface(solid, ["bottom"], material=0)


def test_nodal_areas_tile_the_interface(plate):
    solid, interface = plate
    assert len(interface.nodal_area) == len(interface.owned_nodes)
    assert solid.comm.allreduce(interface.nodal_area.sum()) == pytest.approx(0.01 * 0.02, rel=1e-12)


def test_a_uniform_traction_is_recovered_at_every_node(plate, tmp_path):
    """Vertex impulses of a uniform traction t0 (t0 A_a Δt on node a) give back t0 at every node."""
    solid, interface = plate
    t0 = np.array([1.5e3, -0.5e3, 2.0e4])
    window = 1e-5
    area = nodal_areas(interface.facets.vertices, interface.facets.triangles)
    interface.facets.vertex_impulse[:] = t0 * area[:, None] * window
    interface.receive_forces(window)
    assert interface.traction() == pytest.approx(np.tile(t0, (len(interface.owned_nodes), 1)), rel=1e-12)
    field = interface.traction_field().x.array.reshape(-1, 3)
    off = np.setdiff1d(np.arange(solid.n_owned_nodes), interface.owned_nodes)
    assert np.all(field[off] == 0.0)
    out = MPI.COMM_WORLD.bcast(tmp_path, root=0)
    writer = FieldWriter(solid, out / "fields", extra_fields=[interface.traction_field])
    writer.write()
    writer.close()
    assert 'Name="interface_traction"' in (out / "fields.xdmf").read_text()


def test_smoothing_conserves_the_impulse_and_filters_white_noise_as_a_first_order_low_pass():
    """Windows of white-noise impulses I_n (mean m, variance s²) through the smoothing of time
    constant τ: what the FE gets plus what is held equals what came in, to round-off, every
    step; the mean force is kept; the variance of what the FE gets is s² β/(2 − β),
    β = 1 − exp(−Δt/τ) (the closed form of y_n = β x_n + (1 − β) y_{n−1})."""
    solid = build_solid("block.geo", 0.005, material={"E": 1.0e7, "nu": 0.3, "rho": 2000.0},
                        geometry_parameters={"Lx": 0.01, "Ly": 0.01, "Lz": 0.005}, formulation="mixed",
                        comm=MPI.COMM_SELF)
    window, tau = 1e-5, 1e-4
    interface = Interface(solid, ["bottom"], material=0, smoothing_time=tau)
    rng = np.random.default_rng(7)
    nv = len(interface.facets.vertices)
    mean, sigma, steps = 2.0e-5, 1.0e-5, 20000
    applied, collected = np.zeros(3), np.zeros(3)
    received = np.empty((steps, nv))
    for n in range(steps):
        interface.facets.vertex_impulse[:] = 0.0
        interface.facets.vertex_impulse[:, 2] = rng.normal(mean, sigma, nv)
        collected += interface.facets.vertex_impulse.sum(axis=0)
        interface.receive_forces(window)
        received[n] = interface.released[:, 2]
        assert applied + interface.pending_impulse() == pytest.approx(collected, rel=1e-12, abs=1e-30)
        applied += interface.released.sum(axis=0)
    beta = -np.expm1(-window / tau)
    settled = received[2000:]  # after ~20 τ
    assert settled.mean() == pytest.approx(mean, rel=2e-3)
    assert settled.var() == pytest.approx(sigma**2 * beta / (2 - beta), rel=0.05)


@pytest.mark.slow  # the weight at rest within 1 %: tests/coupling/test_footing.py; the nodal split: the tests above
def test_the_interface_carries_the_grains_weight_at_rest_and_weight_plus_load_when_pressed(tmp_path):
    """studies/interface_traction.py on one coarse mesh and a thin layer: at rest (unbalanced
    force ratio < 1e-3) the total interface force is the grains' weight, pressed by the servo
    wall it is the wall's force plus the weight, both within 1 %."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    study = Path(__file__).parents[2] / "studies" / "interface_traction.py"
    done = subprocess.run([sys.executable, str(study), str(tmp_path), "--sizes", "0.005", "--grains", "60",
                           "--no-noise"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    (row,) = json.loads((tmp_path / "traction_convergence.json").read_text())
    for phase in ("rest", "pressed"):
        assert row[f"{phase}_ufr"] < 1e-3
        assert abs(row[f"{phase}_force"] / row[f"{phase}_expected"] - 1.0) < 1e-2, phase
    assert row["pressed_expected"] > 10 * row["weight"]  # the load, not the weight, dominates when pressed
    assert np.all(np.array(row["pressed_patches"]) > 0.0)  # every quarter of the block carries load
    assert (tmp_path / "traction_convergence.png").exists()
