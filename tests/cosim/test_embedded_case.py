"""The ``embedded`` kind end to end on a small retaining wall (runs/retaining_wall_small.toml
made smaller): the zone filled inside its faces, the model at rest with every support's
vertical force equal to the grains' weight within 1 %, the wall pushed by the backfill while
it moves away, and the outputs a user opens."""
import json

import numpy as np
import pytest

from cosim.cli import main
from cosim.lab.shear_report import read_series

SMALL = ["embedded.parameters.L=0.09", "embedded.parameters.H=0.04", "embedded.parameters.a=0.03",
         "embedded.loading_time=0.02", "embedded.rows=5", "output.progress_interval=1000.0"]


@pytest.fixture(scope="module")
def coupled(tmp_path_factory):
    out = tmp_path_factory.mktemp("embedded")
    sets = [arg for s in SMALL for arg in ("--set", s)]
    assert main(["run", "runs/retaining_wall_small.toml", *sets, "--out", str(out)]) == 0
    return out / "coupled"


@pytest.fixture(scope="module")
def coupled_k0(tmp_path_factory):
    """The same case with the FE soil given its geostatic stress, K0 = 0.6."""
    out = tmp_path_factory.mktemp("embedded_k0")
    sets = [arg for s in [*SMALL, "embedded.volumes[1].K0=0.6"] for arg in ("--set", s)]
    assert main(["run", "runs/retaining_wall_small.toml", *sets, "--out", str(out)]) == 0
    return out / "coupled"


def test_the_model_rests_on_its_supports_with_the_grains_weight(coupled):
    summary = json.loads((coupled / "summary.json").read_text())
    rest = summary["rest"]
    assert rest["at_rest"]
    assert rest["support_force_over_weight"] == pytest.approx(1.0, abs=0.01)
    fill = summary["fill"]
    assert fill["zone_volume_m3"] == pytest.approx(0.03 * 0.01 * 0.04, rel=1e-12)
    assert fill["void_ratio"] >= 0.74 - 1e-3               # the target, released a little looser
    assert summary["interface_facets"] > 0 and summary["subcycles"] >= 1
    grains = rest["grains"]  # rest_stress.csv summed over the zone (tests/cosim/test_rest_stress.py)
    rows = np.loadtxt(coupled / "rest_stress.csv", delimiter=",", skiprows=1, ndmin=2)
    sigma_zz = np.sum(rows[:, 2] * rows[:, 5]) / np.sum(rows[:, 2])
    assert grains["sigma_zz_Pa"] == pytest.approx(sigma_zz, rel=1e-6) and sigma_zz > 0.0
    assert np.sum(rows[:, 2]) == pytest.approx(fill["zone_volume_m3"], rel=1e-12)
    assert 0.0 < grains["K_x"] < 3.0 and 0.0 < grains["K_y"] < 3.0


def test_the_backfill_pushes_the_wall_away_from_it(coupled):
    series = read_series(coupled / "series.csv")
    assert np.all(series["wall_force_x"] < 0.0)            # the grains push the wall towards -x
    assert np.all(series["interface_force_x"] > 0.0)       # and the FE soil beyond, towards +x
    assert series["wall_displacement"][-1] == pytest.approx(0.00125 * 0.02, rel=0.05)   # v t
    moment_arm = series["wall_moment_y"] / series["wall_force_x"]   # M_y = z F_x about the toe
    assert np.all((moment_arm > 0.0) & (moment_arm < 0.04))  # the thrust acts on the wall, above its toe


def test_the_run_writes_what_a_user_opens(coupled):
    for name in ("load_displacement.png", "displacement_section.png", "particles.pvd", "fields.xdmf",
                 "specimen.npz", "final_packing.npz", "rest.csv", "rest_stress.csv"):
        assert (coupled / name).exists(), name


def test_a_rigid_body_rotates_about_its_pivot_and_translates():
    """place_body: the reference vertices rotated by ω t about the pivot, then moved by v t; their
    velocities v + ω × (x − c(t)), c the pivot moved with the body (closed form: a quarter turn)."""
    from types import SimpleNamespace

    from cosim.apps.embedded import place_body
    from de_domain import FacetMesh
    reference = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    mesh = FacetMesh(reference.copy(), [[0, 1, 2]])
    body = SimpleNamespace(pivot=[0.0, 0.0, 0.0], velocity=[0.5, 0.0, 0.0], angular_velocity=[0.0, np.pi / 2, 0.0])
    place_body(mesh, reference, body, 1.0)   # a quarter turn about +y: (x, z) -> (z, -x)
    assert np.allclose(mesh.vertices, [[0.5, 0, 0], [1.5, 0, 0], [1.5, 0, -1]], atol=1e-12)
    expected = [0.5, 0, 0] + np.cross([0, np.pi / 2, 0], mesh.vertices - [0.5, 0, 0])
    assert np.allclose(mesh.vertex_velocity, expected, atol=1e-12)


def test_fe_soil_given_k0_starts_at_rest(coupled, coupled_k0):
    """Given its geostatic stress, the FE soil does not settle under its weight: at rest its
    largest displacement is a small part of the same soil's settlement from zero stress (only the
    grains' push at the interface moves it), and the supports still carry the whole weight."""
    summary = json.loads((coupled_k0 / "summary.json").read_text())
    assert summary["rest"]["at_rest"]
    assert summary["rest"]["support_force_over_weight"] == pytest.approx(1.0, abs=0.01)
    settled, given = (np.load(out / "loading_start.npz")["fe_displacement"] for out in (coupled, coupled_k0))
    assert np.abs(given[:, 2]).max() < 0.2 * np.abs(settled[:, 2]).max()


def test_a_lining_contracts_from_the_loadings_start():
    """The linings' contraction amplitude (embedded_model.LoadingRamp): 0 until the loading starts, then
    linear to 1 over the loading, and held."""
    from cosim.apps.embedded_model import LoadingRamp
    ramp = LoadingRamp(0.5)
    assert ramp(10.0) == 0.0                       # the loading has not started
    ramp.start = 2.0
    assert [ramp(t) for t in (1.0, 2.0, 2.25, 2.5, 9.0)] == [0.0, 0.0, 0.5, 1.0, 1.0]


def test_a_tunnel_lining_reports_its_section_forces_and_contracts(tmp_path):
    """runs/tunnel_small.toml (a closed ring of 1,329 grains around the lining, FE soil with
    K0 = 0.5), 0.03 s of loading: the supports carry the grains' weight within 1 %, the lining
    carries the ground (thrust > 0 all round at rest), its section forces are written every 5°
    from the crown, its contraction (V_L = 1 %) unloads it (less thrust at the end at every
    cut), and the ground surface's settlement is written across the model. With
    time.fe_safety_factor the FE's exact limit lets the grains step at their own step (one
    DEM step per FE step, the FE's step the DEM's, below 0.8 of the limit)."""
    sets = ["embedded.rows=6", "embedded.loading_time=0.03", "output.progress_interval=1000.0"]
    args = [a for s in sets for a in ("--set", s)]
    assert main(["run", "runs/tunnel_small.toml", *args, "--out", str(tmp_path)]) == 0
    sections = np.genfromtxt(tmp_path / "coupled" / "lining_sections.csv", delimiter=",", names=True)
    assert np.allclose(np.diff(sections["angle_deg"]), 5.0) and sections["angle_deg"][0] == 2.5
    assert np.all(sections["thrust_at_rest"] > 0.0)
    assert np.all(sections["thrust_end"] < sections["thrust_at_rest"])
    summary = json.loads((tmp_path / "coupled" / "summary.json").read_text())
    rest = summary["rest"]
    assert rest["at_rest"] and rest["support_force_over_weight"] == pytest.approx(1.0, abs=0.01)
    assert summary["subcycles"] == 1 and summary["fe_dt_s"] == summary["dem_dt_s"] < 0.8 * summary["fe_dt_critical_s"]
    series = read_series(tmp_path / "coupled" / "series.csv")
    for where in ("crown", "springline", "invert"):
        assert f"lining_thrust_{where}" in series and f"lining_moment_{where}" in series
    vertical, horizontal = series["lining_diameter_change_vertical"], series["lining_diameter_change_horizontal"]
    assert vertical[-1] < vertical[0] and horizontal[-1] < horizontal[0]     # the contracting lining shrinks
    linings = json.loads((tmp_path / "coupled" / "summary.json").read_text())["linings"]
    assert linings["lining"]["outer_radius_m"] == pytest.approx(0.03, rel=1e-6)
    assert (tmp_path / "coupled" / "lining_polar.png").stat().st_size > 0
    trough = np.genfromtxt(tmp_path / "coupled" / "settlement_trough.csv", delimiter=",", names=True, dtype=None,
                           encoding=None)   # the ground's FE nodes (the ring is buried: no grains under it)
    assert set(trough["source"]) == {"fe"} and np.all(np.isfinite(trough["settlement"]))
    assert trough["x"].min() == pytest.approx(0.0, abs=1e-12) and trough["x"].max() == pytest.approx(0.15, rel=1e-9)


def test_the_fe_only_tunnel_agrees_with_einstein_and_schwartz(tmp_path):
    """runs/tunnel_small.toml as its FE-only twin (the zone FE soil, K0 = 0.5), made deep (cover
    3 D, ground 0.4 m wide and 0.2 m below) with a lining 50 x stiffer than the soil's
    flexibility ratio allows in the coupled run (F* = 23, C* = 0.021, as a concrete lining in
    sand) and without weight, 4 cells through it: the part of N(θ) and M(θ) symmetric about the
    springline (the overburden's gradient and the free surface load the crown and invert
    unequally; the closed form has neither) against the no-slip solution of Einstein & Schwartz
    (1979) with σ_v at the axis: thrust within 6 % (the ground presses on R + t/2: +5 % at the
    springline), moment within 10 % of its largest. Contracting the tied lining pulls it into
    tension (the FE ground cannot let go of it)."""
    from fe_domain.lining import LinedTunnel, einstein_schwartz
    D, C, t, below, z_axis = 0.06, 0.18, 0.003, 0.2, 0.23
    parameters = f"{{ D = {D}, C = {C}, t = {t}, a = 0.015, W = 0.4, below = {below}, Ly = 0.01, h = 0.00075, " \
                 "h_far = 0.03, grow = 0.1, h_y = 0.005 }"
    sets = ['embedded.model="fe"', f"embedded.parameters={parameters}",
            f"embedded.linings[0].centre=[0.0, 0.0, {z_axis}]", "embedded.volumes[2].E=1.0e9",
            "embedded.volumes[2].rho=1.0"]
    args = [a for s in sets for a in ("--set", s)]
    assert main(["run", "runs/tunnel_small.toml", *args, "--out", str(tmp_path)]) == 0
    out = tmp_path / "fe"
    sections = np.genfromtxt(out / "lining_sections.csv", delimiter=",", names=True)
    density = json.loads((out / "summary.json").read_text())["soil_density"]
    assert density == pytest.approx(2650.0 / 1.74)
    angles = sections["angle_deg"]
    assert np.allclose(angles + angles[::-1], 180.0)       # cuts symmetric about the springline
    thrust = 0.5 * (sections["thrust_at_rest"] + sections["thrust_at_rest"][::-1])
    moment = 0.5 * (sections["moment_at_rest"] + sections["moment_at_rest"][::-1])
    tunnel = LinedTunnel(radius=D / 2 - t / 2, thickness=t, ground_E=2.0e6, ground_nu=0.38, lining_E=1.0e9,
                         lining_nu=0.2, pressure=density * 9.81 * (C + D / 2), K=0.5)
    thrust_es, moment_es, c_star, f_star = einstein_schwartz(tunnel, angles)
    assert f_star == pytest.approx(23.1, abs=0.1) and c_star == pytest.approx(0.0213, abs=1e-4)
    assert np.max(np.abs(thrust / thrust_es - 1.0)) < 0.06
    assert np.max(np.abs(moment - moment_es)) < 0.10 * np.max(np.abs(moment_es))
    assert np.all(sections["thrust_end"] < 0.0)


def test_the_models_are_compared_only_when_both_have_finished(tmp_path):
    """compare_models (the last step of an embedded run): with the other model still running —
    its series.csv only a header, or no summary.json yet — nothing is compared and nothing
    fails; with both finished, comparison.csv has each rigid body's mean force and moment."""
    from types import SimpleNamespace

    from cosim.apps.embedded_report import compare_models
    columns = ["time", "wall_displacement", "wall_rotation"] + [f"wall_{q}_{a}" for q in ("force", "moment")
                                                                for a in "xyz"]
    wall = [SimpleNamespace(name="wall", velocity=[1.0, 0.0, 0.0])]

    def write(model, rows, finished=True):
        folder = tmp_path / model
        folder.mkdir(exist_ok=True)
        text = ",".join(columns) + "\n"
        text += "".join(",".join(str(v * (1 + k)) for k in range(len(columns))) + "\n" for v in rows)
        (folder / "series.csv").write_text(text)
        if finished:
            (folder / "summary.json").write_text("{}")

    write("coupled", [1.0, 2.0])
    write("dem", [], finished=False)
    assert compare_models(tmp_path, wall, "t") is None                   # the twin has not finished
    write("dem", [])
    assert compare_models(tmp_path, wall, "t") is None                   # its series has no rows yet
    assert not (tmp_path / "comparison.csv").exists()
    write("dem", [2.0, 4.0])
    lines = compare_models(tmp_path, wall, "t")
    assert lines[0] == "quantity,coupled,dem,difference"
    assert (tmp_path / "comparison.csv").read_text().startswith("quantity,coupled,dem,difference\nwall_force_x,")
