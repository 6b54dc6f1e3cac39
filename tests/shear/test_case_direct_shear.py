"""Direct shear case files: the shipped ones validate, bad input is named (exit code 2)."""
import math
from pathlib import Path

import pytest

from cosim.case import load_case
from cosim.cli import main
from cosim.errors import CaseError

RUNS = Path(__file__).resolve().parents[2] / "runs"
CASES = ["direct_shear_small.toml", "direct_shear_small_loose.toml", "direct_shear_dense.toml",
         "direct_shear_loose.toml", "direct_shear_thesis_dense.toml", "direct_shear_thesis_loose.toml"]


@pytest.mark.parametrize("name", CASES)
def test_shipped_case_files_are_valid(name):
    case, _ = load_case(RUNS / name)
    assert case.case.kind == "direct_shear"
    assert case.direct_shear.box_length == 0.06 and case.direct_shear.sample_height == 0.025
    assert case.direct_shear.shear_distance == pytest.approx(0.15 * 0.06)


@pytest.mark.parametrize("override, key", [
    ("direct_shear.box_size=0.06", "direct_shear.box_size"),                 # unknown key
    ("direct_shear.sand_material='clay'", "direct_shear.sand_material"),     # undefined material
    ("direct_shear.shear_distance=0.07", "direct_shear.shear_distance"),     # longer than the box
    ("direct_shear.normal_stress=-5", "direct_shear.normal_stress"),         # out of range
    ("time.duration=1.0", "time.duration / time.steps"),                     # length follows from the shear
    ("specimen.sieve='gravel'", "specimen.sieve"),                           # unknown preset
    ("direct_shear.sample_height=0.01", "specimen.truncate_above"),          # grains too large for the box
    ("specimen.method='pluviation'", "specimen.method"),
    ("direct_shear.servo_fixed_gain=0.001", "direct_shear.servo_fixed_gain"),  # the stiffness servo has no such gain
    ("direct_shear.servo='pid'", "direct_shear.servo"),
    ("specimen.void_ratio=2.0", "specimen.void_ratio"),
    ("direct_shear.band_pictures=[0.003, 0.012]", "direct_shear.band_pictures"),  # beyond the shear distance
    ("direct_shear.band_pictures=[]", "direct_shear.band_pictures"),
    ("specimen.deposition_material='packing'", "specimen.deposition_material"),  # no such material
])
def test_bad_values_are_named(override, key):
    with pytest.raises(CaseError) as err:
        load_case(RUNS / "direct_shear_small.toml", [override])
    assert err.value.key == key


def test_cli_check_and_exit_code(capsys):
    assert main(["check", str(RUNS / "direct_shear_small.toml")]) == 0
    # a packing file instead of the generation: the generation keys are refused, not ignored
    assert main(["check", str(RUNS / "direct_shear_small.toml"), "--set", "specimen.file='missing.npz'",
                 "--set", "specimen.source='file'"]) == 2
    assert "specimen.method' = 'under_compaction': not used here" in capsys.readouterr().err


def test_series_rejects_bad_stress_before_running(capsys):
    assert main(["series", str(RUNS / "direct_shear_small.toml"), "--stresses", "-1"]) == 2
    assert main(["series", str(RUNS / "direct_shear_small.toml"), "--stresses", "1e5",
                 "--set", "direct_shear.rows=1"]) == 2


@pytest.mark.parametrize("name, void_ratio", [("direct_shear_thesis_dense.toml", 0.65),
                                              ("direct_shear_thesis_loose.toml", 0.84)])
def test_thesis_parameter_set(name, void_ratio):
    """The test has the YADE script's values (App. D.2: FrictMat young 1e7, poisson 0.25 =
    k_s/k_n, frictionAngle 0.6 / 0.8 / 0 rad, density 2650 / 7480, damping 0.5, no contact
    damping); the generation Table 4.1's (E = 100 MPa, friction 0.5, density 2655, damping
    0.7, K_T = K_N / 1.5)."""
    case, _ = load_case(RUNS / name)
    mats = {m.name: m for m in case.dem.materials}
    for key, angle in (("sand", 0.6), ("plate", 0.8), ("side_wall", 0.0)):
        m = mats[key]
        assert m.friction == pytest.approx(math.tan(angle), rel=1e-9)
        assert (m.young, m.poisson, m.restitution, 1.0 / m.stiffness_ratio) == (1e7, 0.25, 1.0, 0.25)
    assert (mats["sand"].density, mats["plate"].density, mats["side_wall"].density) == (2650.0, 7480.0, 7480.0)
    assert case.dem.local_damping == 0.5
    sp = case.specimen
    packing = mats[sp.deposition_material]
    assert (packing.young, packing.friction, packing.density, packing.stiffness_ratio) == (1e8, 0.5, 2655.0, 1.5)
    assert sp.local_damping == 0.7 and sp.void_ratio == void_ratio


def test_the_grains_are_deposited_with_the_deposition_material(monkeypatch, tmp_path):
    """make_specimen hands the generation the deposition material, not the test's sand."""
    import de_domain.deposition
    from cosim.apps.direct_shear import make_specimen
    from cosim.specimen import curve_of
    seen = {}

    def generate(method, diameters, settings, log=None, comm=None, shapes=None):
        seen["sand"] = settings.sand
        raise RuntimeError("stop here")

    monkeypatch.setattr(de_domain.deposition, "generate", generate)
    case, _ = load_case(RUNS / "direct_shear_thesis_dense.toml")
    with pytest.raises(RuntimeError, match="stop here"):
        make_specimen(case, {"curve": curve_of(case.specimen)}, tmp_path)
    assert (seen["sand"].young, seen["sand"].friction, seen["sand"].stiffness_ratio) == (1e8, 0.5, 1.5)
