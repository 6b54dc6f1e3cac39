"""Direct shear case files: the shipped ones validate, bad input is named (exit code 2)."""
from pathlib import Path

import pytest

from cosim.case import load_case
from cosim.cli import main
from cosim.errors import CaseError

RUNS = Path(__file__).resolve().parents[2] / "runs"
CASES = ["direct_shear_small.toml", "direct_shear_small_loose.toml", "direct_shear_dense.toml",
         "direct_shear_loose.toml"]


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
