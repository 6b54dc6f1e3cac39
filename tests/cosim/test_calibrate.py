"""``cosim calibrate`` (cosim/lab/calibrate.py): the search on closed-form surrogates of the
direct shear test, where the answer is known; its resume, budget and reachability report;
bad calibration files; and one real calibration of a miniature shear box end to end."""
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cosim.case.calibration import CalibrationFile
from cosim.cli import main
from cosim.lab.calibrate import calibrate

RUNS = Path(__file__).resolve().parents[2] / "runs"


def surrogate(calls=None):
    """φ_peak = 20° + 20° μ + 20° η_r and φ_res = 18° + 18° μ + 4° η_r at any σ_n."""
    def evaluate(parameters, case, normal_stress, label):
        if calls is not None:
            calls.append((dict(parameters), normal_stress))
        mu, eta = parameters["friction"], parameters.get("rolling_friction", 0.0)
        return {"peak_friction_angle_deg": 20 + 20 * mu + 20 * eta,
                "residual_friction_angle_deg": 18 + 18 * mu + 4 * eta}
    return evaluate


def spec(targets, parameters, budget=40):
    return CalibrationFile.model_validate({
        "case": "unused.toml", "budget": budget,
        "targets": [{"quantity": q, "value": v, "tolerance": tol, "normal_stress": 100e3} for q, v, tol in targets],
        "parameters": [{"name": n, "lower": lo, "upper": hi} for n, lo, hi in parameters]})


THESIS = [("peak_friction_angle_deg", 42.0, 0.3), ("residual_friction_angle_deg", 33.0, 0.3)]
MU_ETA = [("friction", 0.2, 1.2), ("rolling_friction", 0.0, 0.5)]


def test_search_finds_the_known_parameters_of_a_surrogate(tmp_path):
    """20 μ + 20 η = 22 and 18 μ + 4 η = 15: μ = 10.6/14, η = 1.1 − μ."""
    outcome = calibrate(spec(THESIS, MU_ETA), surrogate(), tmp_path / "evaluations.csv", progress=lambda s: None)
    assert outcome.status == "reached"
    best = outcome.best
    assert best.reached and best is outcome.evaluations[-1]
    mu = 10.6 / 14
    # tolerance 0.3° on both angles: μ and η to within about 0.02
    assert best.parameters["friction"] == pytest.approx(mu, abs=0.02)
    assert best.parameters["rolling_friction"] == pytest.approx(1.1 - mu, abs=0.03)
    assert len(outcome.evaluations) < 40


def test_a_rerun_reads_every_evaluation_back_and_ends_the_same(tmp_path):
    first = calibrate(spec(THESIS, MU_ETA), surrogate(), tmp_path / "e.csv", progress=lambda s: None)
    calls = []
    again = calibrate(spec(THESIS, MU_ETA), surrogate(calls), tmp_path / "e.csv", progress=lambda s: None)
    assert calls == []
    assert [e.parameters for e in again.evaluations] == [e.parameters for e in first.evaluations]
    assert again.best.achieved == first.best.achieved


def test_an_interrupted_search_continues_where_it_stopped(tmp_path):
    calls = []

    def dies_after_five(parameters, case, normal_stress, label):
        if len(calls) == 5:
            raise KeyboardInterrupt
        return surrogate(calls)(parameters, case, normal_stress, label)

    with pytest.raises(KeyboardInterrupt):
        calibrate(spec(THESIS, MU_ETA), dies_after_five, tmp_path / "e.csv", progress=lambda s: None)
    rest = []
    outcome = calibrate(spec(THESIS, MU_ETA), surrogate(rest), tmp_path / "e.csv", progress=lambda s: None)
    reference = calibrate(spec(THESIS, MU_ETA), surrogate(), tmp_path / "fresh.csv", progress=lambda s: None)
    assert len(rest) == len(reference.evaluations) - 5
    assert outcome.best.parameters == reference.best.parameters


def test_a_target_beyond_the_bounds_is_reported_after_the_two_corners(tmp_path):
    """μ ∈ [0.2, 1.2] alone gives φ_peak 24° … 44°: 60° cannot be reached."""
    outcome = calibrate(spec([("peak_friction_angle_deg", 60.0, 1.0)], [("friction", 0.2, 1.2)]), surrogate(),
                        tmp_path / "e.csv", progress=lambda s: None)
    assert outcome.status == "unreachable"
    assert len(outcome.evaluations) == 2
    assert "peak_friction_angle_deg = 60" in outcome.message and "24 ... 44" in outcome.message


def test_a_target_just_inside_a_bound_is_reached_and_no_parameter_set_is_run_twice(tmp_path):
    """φ = 25° is μ = 0.25, 5 % of the range above the lower bound 0.2: the simplex steps past the
    bound on its way (clipped there, it collapsed onto μ = 0.2 and stalled, with the bound run
    again and counted as evaluations 6, 7, 8); reflected back inside, it reaches the target, and
    every evaluation is a new parameter set."""
    calls = []
    outcome = calibrate(spec([("peak_friction_angle_deg", 25.0, 0.1)], [("friction", 0.2, 1.2)], budget=12),
                        surrogate(calls), tmp_path / "e.csv", progress=lambda s: None)
    assert outcome.status == "reached"
    assert outcome.best.parameters["friction"] == pytest.approx(0.25, abs=0.005)
    sets = [tuple(e.parameters.values()) for e in outcome.evaluations]
    assert len(set(sets)) == len(sets) == len(calls)


def shaped_surrogate(calls):
    """Dense and loose specimens of rods of aspect ratio A: φ_peak = 16° + 20° μ + 12° (A − 1)
    dense, 8° + 20° μ + 6° (A − 1) loose, at any σ."""
    def evaluate(parameters, case, normal_stress, label):
        calls.append((case, normal_stress))
        mu, shape = parameters["friction"], parameters["aspect_ratio"] - 1.0
        base, gain = {"dense": (16.0, 12.0), "loose": (8.0, 6.0)}[case]
        return {"peak_friction_angle_deg": base + 20 * mu + gain * shape}
    return evaluate


def test_dense_and_loose_targets_over_three_stresses_find_friction_and_shape(tmp_path):
    """Targets 42° dense and 33° loose, each at 50, 100 and 200 kPa, on their own cases: the
    search runs each (case, σ) once an evaluation and finds μ and A of the closed form
    (16 + 20 μ + 12 s = 42, 8 + 20 μ + 6 s = 33: s = A − 1 = 1/6, μ = 1.2)."""
    targets = [{"quantity": "peak_friction_angle_deg", "value": v, "tolerance": 0.2, "normal_stress": p,
                "case": f"{c}.toml"} for c, v in (("dense", 42.0), ("loose", 33.0)) for p in (50e3, 100e3, 200e3)]
    spec_ = CalibrationFile.model_validate({"case": "dense.toml", "budget": 60, "targets": targets, "parameters": [
        {"name": "friction", "lower": 0.5, "upper": 1.5}, {"name": "aspect_ratio", "lower": 1.0, "upper": 2.0}]})
    calls = []
    cases = ["dense"] * 3 + ["loose"] * 3
    outcome = calibrate(spec_, shaped_surrogate(calls), tmp_path / "e.csv", progress=lambda s: None, cases=cases)
    assert outcome.status == "reached"
    assert outcome.best.parameters["friction"] == pytest.approx(1.2, abs=0.02)
    assert outcome.best.parameters["aspect_ratio"] == pytest.approx(1.0 + 1.0 / 6.0, abs=0.04)
    assert len(calls) == 6 * len(outcome.evaluations)  # each (case, σ) once an evaluation
    header = (tmp_path / "e.csv").read_text().splitlines()[0]
    assert "peak_friction_angle_deg@loose@200kPa" in header and "peak_friction_angle_deg@dense@50kPa" in header


def test_the_aspect_ratio_is_a_rod_of_two_spheres_of_that_length_over_width():
    """overrides() writes the file's fixed overrides (here: the sphere case's grains made
    clumps), then the case's one template as two equal spheres whose union is A times as long
    as it is wide, and the sand's friction into the sand material."""
    from cosim.case import load_case
    from cosim.case.validation import clump_templates
    from cosim.lab.calibrate import overrides
    case_path = RUNS / "direct_shear_small.toml"
    fixed = ['specimen.grains = "clumps"', "dem.clumps = [{members = [[0, 0, 0, 1]]}]"]
    for aspect in (1.0, 1.3, 2.0):
        case, _ = load_case(case_path, overrides(case_path, {"aspect_ratio": aspect, "friction": 0.7}, fixed))
        template, = clump_templates(case_path, case.dem)
        ends = template.centres[:, 0] + template.radii * np.array([-1.0, 1.0])
        assert np.ptp(ends) / (2.0 * template.radii.max()) == pytest.approx(aspect, rel=1e-12)
        assert case.specimen.grains == "clumps" and case.dem.materials[0].friction == 0.7


def test_the_budget_ends_the_search(tmp_path):
    outcome = calibrate(spec([("peak_friction_angle_deg", 37.3, 1e-9)], [("friction", 0.2, 1.2)], budget=6),
                        surrogate(), tmp_path / "e.csv", progress=lambda s: None)
    assert outcome.status == "budget" and len(outcome.evaluations) == 6
    assert outcome.best.achieved[0] == pytest.approx(37.3, abs=1.0)  # on its way


def _calibration_file(tmp_path, body):
    path = tmp_path / "calibration.toml"
    path.write_text(f'case = "{RUNS / "direct_shear_small.toml"}"\n' + body)
    return path


TARGET = '[[targets]]\nquantity = "peak_friction_angle_deg"\nvalue = 42.0\ntolerance = 1.0\nnormal_stress = 100e3\n'


@pytest.mark.parametrize("body, key", [
    (TARGET + '[[parameters]]\nname = "friction"\nlower = 0.9\nupper = 0.3\n', "parameters[0].upper"),  # reversed
    (TARGET + '[[parameters]]\nname = "cohesion"\nlower = 0.0\nupper = 1.0\n', "parameters[0].name"),   # no such
    (TARGET.replace("peak_friction", "peak_cohesion") + '[[parameters]]\nname = "friction"\nlower = 0.1\nupper = 1.0\n',
     "targets[0].quantity"),
    (TARGET + '[[parameters]]\nname = "rolling_friction"\nlower = 0.0\nupper = 0.5\n', "parameters"),  # no spring
    (TARGET + '[[parameters]]\nname = "friction"\nlower = 0.1\nupper = 1.0\n[[parameters]]\nname = "friction"\n'
     'lower = 0.1\nupper = 1.0\n', "parameters[1].name"),
    ('[[parameters]]\nname = "friction"\nlower = 0.1\nupper = 1.0\n', "targets"),                     # missing
    (TARGET + '[[parameters]]\nname = "friction"\nlower = 0.1\nupper = 1.0\nbudget = 1\n', "parameters[0].budget"),
    (TARGET + '[[parameters]]\nname = "aspect_ratio"\nlower = 1.0\nupper = 2.5\n', "parameters[0].upper"),
    (TARGET + '[[parameters]]\nname = "aspect_ratio"\nlower = 0.8\nupper = 1.5\n', "parameters[0].lower"),
    (TARGET + '[[parameters]]\nname = "aspect_ratio"\nlower = 1.0\nupper = 1.5\n', "case"),  # spheres: no shape
    (TARGET + 'case = "missing.toml"\n[[parameters]]\nname = "friction"\nlower = 0.1\nupper = 1.0\n',
     "targets[0].case"),
])
def test_bad_calibration_files_get_one_clear_message(tmp_path, capsys, body, key):
    """The same message from `cosim check` and `cosim calibrate`, before anything runs."""
    path = _calibration_file(tmp_path, body)
    assert main(["check", str(path)]) == 2
    checked = capsys.readouterr().err
    assert main(["calibrate", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"key '{key}'" in err and err.count("error") == 1 and err == checked
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["calibrate_thesis.toml", "calibrate_thesis_clumps.toml"])
def test_the_shipped_calibration_files_check(name):
    assert main(["check", str(RUNS / name)]) == 0


CALIBRATION = """
case = "{case}"
{confirm}
budget = 8

[[targets]]
quantity = "peak_friction_angle_deg"
value = {target}
tolerance = {tolerance}
normal_stress = 100e3

[[parameters]]
name = "friction"
lower = 0.1
upper = 0.7
"""


@pytest.mark.slow
def test_calibrating_the_friction_of_a_miniature_shear_box(tmp_path):
    """The real evaluator on the 600-grain box of tests/shear (1.5 mm of shear, ~10 s a run):
    the target is the box's own φ_peak at μ = 0.25, measured first (off the search's centre, 0.4); the search finds a μ
    that gives it within 1.5°, confirms it, and writes a case that gives it again."""
    spec_ = importlib.util.spec_from_file_location("mini", RUNS.parent / "tests" / "shear" / "test_direct_shear_run.py")
    module = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(module)
    (tmp_path / "mini.toml").write_text(module.MINI.format(name="mini_calibrate", e=0.70, mu=0.05))
    probe = tmp_path / "probe"
    assert main(["run", str(tmp_path / "mini.toml"), "--out", str(probe),
                 "--set", "dem.materials[0].friction=0.25"]) == 0
    target = json.loads((probe / "summary.json").read_text())["peak_friction_angle_deg"]
    path = tmp_path / "calibration.toml"
    path.write_text(CALIBRATION.format(case="mini.toml", confirm='confirm_case = "mini.toml"', target=target,
                                      tolerance=1.5))
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["status"] == "reached"
    row = report["targets"][0]
    assert abs(row["searched_case"] - target) <= 1.5 and row["confirm_case"] == pytest.approx(row["searched_case"])
    for name in ("evaluations.csv", "report.md", "calibration.png", "calibrated.toml"):
        assert (out / name).exists(), name
    rerun = tmp_path / "rerun"
    assert main(["run", str(out / "calibrated.toml"), "--out", str(rerun)]) == 0
    again = json.loads((rerun / "summary.json").read_text())["peak_friction_angle_deg"]
    assert again == row["confirm_case"]  # the calibrated file is the confirmed run, bit for bit
    assert math.isfinite(report["parameters"]["friction"])




def _triaxial_case(tmp_path):
    spec_ = importlib.util.spec_from_file_location("tx", RUNS.parent / "tests" / "triaxial" / "test_triaxial.py")
    module = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(module)
    (tmp_path / "tx.toml").write_text(module.MINI.format(name="tx_calibrate", specimen=module.DENSE, strain=0.06))
    return tmp_path / "tx.toml"


@pytest.mark.slow  # the search itself: the surrogate tests above; this is the end-to-end variant
def test_calibrating_against_a_triaxial_target(tmp_path):
    """The same search on the miniature triaxial cell (6 % axial strain): the target is the
    cell's own φ_peak at μ = 0.25; the search confirms it, and the written case reruns to it."""
    case = _triaxial_case(tmp_path)
    assert main(["run", str(case), "--out", str(tmp_path / "probe"), "--set", "dem.materials[0].friction=0.25"]) == 0
    target = json.loads((tmp_path / "probe" / "summary.json").read_text())["peak_friction_angle_deg"]
    path = tmp_path / "calibration.toml"
    path.write_text(CALIBRATION.format(case="tx.toml", confirm='confirm_case = "tx.toml"', target=target,
                                      tolerance=1.0))
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    row = report["targets"][0]
    assert report["status"] == "reached" and abs(row["searched_case"] - target) <= 1.0
    assert row["confirm_case"] == pytest.approx(row["searched_case"])
    assert (out / "search" / "001" / "tx" / "100kPa" / "triaxial.png").exists()
    rerun = tmp_path / "rerun"
    assert main(["run", str(out / "calibrated.toml"), "--out", str(rerun)]) == 0
    again = json.loads((rerun / "summary.json").read_text())["peak_friction_angle_deg"]
    assert again == row["confirm_case"]  # the calibrated file is the confirmed run, bit for bit


def test_a_quantity_the_kind_does_not_measure_is_refused(tmp_path, capsys):
    case = _triaxial_case(tmp_path)
    path = tmp_path / "calibration.toml"
    path.write_text(CALIBRATION.format(case="tx.toml", confirm="", target=30.0, tolerance=1.0)
                    .replace("peak_friction_angle_deg", "vertical_displacement_end"))
    assert main(["check", str(path)]) == 2
    assert "key 'targets[0].quantity'" in capsys.readouterr().err
    assert case.exists()
