"""Every class of bad case input gives one clear error naming file, key, value and
what is allowed — before any computation — and ``cosim`` exits with code 2."""
import copy
import tomllib
from pathlib import Path

import pytest
import tomli_w

from cosim.case import load_case
from cosim.cli import main
from cosim.errors import EXIT_BAD_INPUT, CaseError

DEMO = Path(__file__).parents[2] / "runs" / "demo_dem_settling.toml"


@pytest.fixture
def base():
    return tomllib.loads(DEMO.read_text())


def write(tmp_path, data, name="case.toml"):
    path = tmp_path / name
    path.write_text(tomli_w.dumps(data))
    return path


def expect_error(tmp_path, data, key, value_text, allowed_text, overrides=()):
    path = write(tmp_path, data)
    with pytest.raises(CaseError) as info:
        load_case(path, overrides)
    msg = str(info.value)
    assert str(path) in msg
    assert f"'{key}'" in msg, msg
    assert value_text in msg, msg
    assert allowed_text in msg, msg
    # the CLI turns it into exit code 2 with the same message
    assert main(["check", str(path), *sum((["--set", o] for o in overrides), [])]) == EXIT_BAD_INPUT
    return msg


def test_demo_case_is_valid():
    case, resolved = load_case(DEMO)
    assert case.case.kind == "dem"
    assert resolved["dem"]["materials"][0]["stiffness_ratio"] == 4.0
    assert main(["check", str(DEMO)]) == 0


def test_unknown_top_level_key(tmp_path, base):
    base["solver"] = {"x": 1}
    expect_error(tmp_path, base, "solver", "{'x': 1}", "unknown key; allowed keys here: case, time, output, dem")


def test_unknown_nested_key_names_allowed_keys(tmp_path, base):
    base["dem"]["materials"][0]["frction"] = 0.3
    expect_error(tmp_path, base, "dem.materials[0].frction", "0.3", "allowed keys here: name, density, young")


def test_wrong_type(tmp_path, base):
    base["dem"]["materials"][0]["young"] = "stiff"
    expect_error(tmp_path, base, "dem.materials[0].young", "'stiff'", "valid number")


def test_out_of_range_value_names_bound_and_unit(tmp_path, base):
    base["dem"]["materials"][0]["restitution"] = 1.5
    expect_error(tmp_path, base, "dem.materials[0].restitution", "1.5", "less than or equal to 1")
    base["dem"]["materials"][0]["restitution"] = 0.5
    base["dem"]["materials"][0]["density"] = -2650.0
    msg = expect_error(tmp_path, base, "dem.materials[0].density", "-2650.0", "greater than 0")
    assert "kg/m^3" in msg


def test_wrong_choice_lists_allowed(tmp_path, base):
    base["dem"]["contact_law"] = "jkr"
    expect_error(tmp_path, base, "dem.contact_law", "'jkr'", "'linear' or 'hertz'")


def test_missing_required_key(tmp_path, base):
    del base["dem"]["materials"][0]["young"]
    expect_error(tmp_path, base, "dem.materials[0].young", "None", "required key is missing")


def test_inconsistent_duration_and_steps(tmp_path, base):
    base["time"]["steps"] = 100
    expect_error(tmp_path, base, "time.duration / time.steps", "(0.12, 100)", "exactly one of duration")


def test_inconsistent_box(tmp_path, base):
    base["dem"]["particles"]["box"] = [[0.0, 0.0, 0.0], [0.03, -0.03, 0.06]]
    expect_error(tmp_path, base, "dem.particles.box", "-0.03", "max corner coordinate must exceed")


def test_undefined_material_reference(tmp_path, base):
    base["dem"]["walls"][2]["material"] = "steel"
    expect_error(tmp_path, base, "dem.walls[2].material", "'steel'", "must be one of the materials: ['sand']")


def test_output_interval_longer_than_run(tmp_path, base):
    base["output"]["interval"] = 1.0
    expect_error(tmp_path, base, "output.interval", "1.0", "must not exceed time.duration")


def test_missing_packing_file(tmp_path, base):
    base["dem"]["particles"] = {"source": "file", "file": "nowhere.npz", "material": "sand"}
    expect_error(tmp_path, base, "dem.particles.file", "'nowhere.npz'", "file not found")


def test_missing_facet_mesh_file(tmp_path, base):
    base["dem"]["walls"].append({"type": "facets", "file": "lid.stl", "material": "sand"})
    expect_error(tmp_path, base, "dem.walls[5].file", "'lid.stl'", "file not found")


def test_zero_wall_normal(tmp_path, base):
    base["dem"]["walls"][0]["normal"] = [0.0, 0.0, 0.0]
    expect_error(tmp_path, base, "dem.walls[0].normal", "[0.0, 0.0, 0.0]", "non-zero vector")


def test_toml_syntax_error(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[case]\nname = \n")
    with pytest.raises(CaseError, match=r"broken.toml: key '<syntax>'.*valid TOML"):
        load_case(path)
    assert main(["check", str(path)]) == EXIT_BAD_INPUT


def test_missing_case_file(tmp_path):
    assert main(["check", str(tmp_path / "absent.toml")]) == EXIT_BAD_INPUT


def test_set_override_is_validated(tmp_path, base):
    expect_error(tmp_path, base, "dem.local_damping", "1.5", "less than 1", overrides=["dem.local_damping=1.5"])


def test_set_override_applies(tmp_path, base):
    path = write(tmp_path, base)
    case, resolved = load_case(path, ["dem.particles.count=500", "case.name=short", "dem.gravity=[0, 0, -1.62]"])
    assert case.dem.particles.count == 500 and case.case.name == "short"
    assert resolved["dem"]["gravity"] == [0.0, 0.0, -1.62]


def test_set_override_malformed(tmp_path, base):
    path = write(tmp_path, base)
    with pytest.raises(CaseError, match="section.key=value"):
        load_case(path, ["dem.local_damping"])


def test_run_rejects_bad_input_before_creating_outputs(tmp_path, base):
    bad = copy.deepcopy(base)
    bad["dem"]["particles"]["count"] = -3
    path = write(tmp_path, bad)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == EXIT_BAD_INPUT
    assert not out.exists()


FE = Path(__file__).parents[2] / "runs" / "fe_footing.toml"


@pytest.fixture
def fe_base():
    return tomllib.loads(FE.read_text())


def test_fe_demo_case_is_valid():
    assert main(["check", str(FE)]) == 0


def test_fe_unknown_boundary_name_lists_the_mesh_groups(tmp_path, fe_base):
    fe_base["fe"]["boundary_conditions"][0]["boundary"] = "soil_botom"
    expect_error(tmp_path, fe_base, "fe.boundary_conditions[0].boundary", "'soil_botom'",
                 "not a surface physical group of footing.geo; available: ['footing_top', 'interface', 'soil_bottom'")


def test_fe_unknown_material_group(tmp_path, fe_base):
    fe_base["fe"]["materials"][1]["group"] = "plate"
    expect_error(tmp_path, fe_base, "fe.materials[1].group", "'plate'", "available: ['footing', 'soil']")


def test_fe_missing_mesh(tmp_path, fe_base):
    fe_base["fe"]["mesh"] = "dam.geo"
    expect_error(tmp_path, fe_base, "fe.mesh", "'dam.geo'", "mesh not found")


def test_fe_geo_needs_mesh_size(tmp_path, fe_base):
    del fe_base["fe"]["mesh_size"]
    expect_error(tmp_path, fe_base, "fe.mesh_size", "None", "needs a mesh size")


def test_fe_velocity_condition_needs_velocity(tmp_path, fe_base):
    fe_base["fe"]["boundary_conditions"][0]["type"] = "velocity"
    expect_error(tmp_path, fe_base, "fe.boundary_conditions[0].velocity", "None", "needs velocity")


def test_fe_poisson_ratio_range(tmp_path, fe_base):
    fe_base["fe"]["materials"][0]["nu"] = 0.5
    expect_error(tmp_path, fe_base, "fe.materials[0].nu", "0.5", "less than 0.5")


def test_fe_alpha_tau_above_the_stability_bound(tmp_path, fe_base):
    fe_base["fe"]["alpha_tau"] = 1.0
    expect_error(tmp_path, fe_base, "fe.alpha_tau", "1.0", "step 3 is unstable above alpha_tau = 0.277 for nu = 0.3")


COUPLED = Path(__file__).parents[2] / "runs" / "coupled_footing_on_sand.toml"


def test_coupled_flagship_case_is_valid():
    case, _ = load_case(COUPLED)
    assert case.coupling.interface == ["bottom", "x0", "x1", "y0", "y1"]


def test_coupled_unknown_interface_group(tmp_path):
    data = tomllib.loads(COUPLED.read_text())
    data["dem"]["particles"]["file"] = str(COUPLED.parent / data["dem"]["particles"]["file"])
    data["coupling"]["interface"] = ["bottom", "sides"]
    expect_error(tmp_path, data, "coupling.interface[1]", "'sides'", "not a surface physical group of block.geo")
