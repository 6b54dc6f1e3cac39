"""The triaxial test (kind ``triaxial``, cosim/apps/triaxial.py) on a miniature cell: a
15 mm cube of ~500 grains of 1.6–2.4 mm. The servo holds σ₃; a dense specimen dilates and
softens, a loose one contracts; a killed run resumes to the same rows; bad input is named."""
import csv
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.apps.triaxial import summarize
from cosim.case import load_case
from cosim.cli import main
from cosim.errors import CaseError
from cosim.lab.shear_report import read_series

COSIM = Path(sys.executable).parent / "cosim"

MINI = """
[case]
name = "{name}"
kind = "triaxial"
seed = 11

[time]
safety_factor = 0.3

[output]
vtk = false
progress_interval = 60.0

[dem]
local_damping = 0.3

[[dem.materials]]
name = "sand"
density = 2650.0
young = 5.0e7
friction = 0.5
stiffness_ratio = 1.5

[[dem.materials]]
name = "side_wall"
density = 7480.0
young = 5.0e7
friction = 0.0

[[dem.materials]]
name = "plate"
density = 7480.0
young = 5.0e7
friction = 0.8

[specimen]
sieve_diameters = [1.6e-3, 2.4e-3]
sieve_passing = [0.0, 1.0]
{specimen}

[triaxial]
size = 0.015
cell_pressure = 100e3
axial_strain = {strain}
rows = 30
"""
DENSE = "void_ratio = 0.62\ndeposition_friction = 0.05"
LOOSE = ("void_ratio = 0.85\ndeposition_friction = 1.0\ndeposition_rolling_friction = 0.3\nhold_friction = 1.0\n"
         "plate_stress_limit = 5e4\nfriction_reduction = 0.75")


def _run(folder, name, specimen, strain):
    case = folder / f"{name}.toml"
    case.write_text(MINI.format(name=name, specimen=specimen, strain=strain))
    out = folder / "out"
    assert main(["run", str(case), "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text()), read_series(out / "series.csv"), out


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("dense"), "tx_dense", DENSE, 0.15)


def test_the_servo_holds_the_cell_pressure_within_two_percent(dense):
    summary, series, _ = dense
    assert np.all(np.abs(series["sigma_3"] / 100e3 - 1.0) < 0.02)
    assert summary["servo_max_relative_error"] < 0.02


def test_a_dense_specimen_peaks_softens_and_dilates(dense):
    summary, series, _ = dense
    assert summary["peak_friction_angle_deg"] > summary["residual_friction_angle_deg"] + 2.0
    assert summary["volumetric_strain_end"] < 0.0 and summary["volume_change"] == "dilation"
    assert series["axial_strain"][-1] >= 0.15
    # the measures are the definitions: q = σ₁ − σ₃, ε_v from the cell's volume, e from it
    np.testing.assert_allclose(series["deviator_stress"], series["sigma_1"] - series["sigma_3"], atol=1e-3)  # 10 digits
    v0 = summary["void_ratio_consolidated"] + 1.0
    np.testing.assert_allclose(series["void_ratio"] + 1.0, v0 * (1.0 - series["volumetric_strain"]), rtol=1e-7)


def test_outputs_of_a_run(dense):
    summary, _, out = dense
    for name in ("series.csv", "summary.json", "summary.txt", "triaxial.png", "specimen.npz", "case.resolved.toml"):
        assert (out / name).exists(), name
    assert summary["inertial_number"] == pytest.approx(1e-3, rel=1e-6)
    assert summary["grains"] > 400


def test_a_loose_specimen_contracts(tmp_path):
    summary, _, _ = _run(tmp_path, "tx_loose", LOOSE, 0.05)
    assert summary["void_ratio_consolidated"] > 0.80
    assert summary["volumetric_strain_end"] > 0.0 and summary["volume_change"] == "contraction"
    assert summary["servo_max_relative_error"] < 0.02


def test_friction_angles_from_the_principal_stresses():
    """sin φ = (σ₁ − σ₃)/(σ₁ + σ₃): σ₁ = 3 σ₃ is φ = 30°; the critical state is the mean of
    the last 20 % of ε₁."""
    e1 = np.linspace(0.0, 0.2, 21)
    s3 = np.full_like(e1, 100e3)
    s1 = np.where(e1 < 0.05, 100e3 + 4e6 * e1, 300e3)
    s1[5] = 400e3  # the peak: sin φ = 0.6
    data = {"axial_strain": e1, "sigma_1": s1, "sigma_3": s3, "volumetric_strain": -0.1 * e1}
    s = summarize(data)
    assert s["peak_friction_angle_deg"] == pytest.approx(math.degrees(math.asin(0.6)))
    assert s["residual_friction_angle_deg"] == pytest.approx(30.0)
    assert s["peak_axial_strain"] == pytest.approx(0.05) and s["volume_change"] == "dilation"


def test_a_killed_run_resumes_to_the_same_rows(tmp_path):
    case = tmp_path / "tx.toml"
    case.write_text(MINI.format(name="tx_resume", specimen=DENSE, strain=0.06))
    reference = tmp_path / "reference"
    assert main(["run", str(case), "--out", str(reference)]) == 0
    text = case.read_text()
    start, end = text.index("[specimen]"), text.index("[triaxial]")
    case.write_text(text[:start] + f'[specimen]\nsource = "file"\nfile = "{reference / "specimen.npz"}"\n\n'
                    + text[end:])
    split = tmp_path / "split"
    sets = ["--set", "output.checkpoint_interval=0.3"]
    proc = subprocess.Popen([str(COSIM), "run", str(case), "--out", str(split), *sets],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:
        if (split / "triaxial_state.json").exists() and (split / "series.csv").exists() and \
                len((split / "series.csv").read_text().splitlines()) > 8:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.kill()
    proc.wait()
    done = subprocess.run([str(COSIM), "run", str(case), "--out", str(split), *sets, "--resume"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "resumed at step" in done.stdout + done.stderr

    def rows(folder):
        with open(folder / "series.csv") as f:
            return list(csv.reader(f))
    assert rows(split) == rows(reference)


@pytest.mark.parametrize("override, key", [
    ("triaxial.size=0.01", "triaxial.size"),                      # under 6 of the largest grains
    ("time.duration=1.0", "time.duration / time.steps"),
    ("triaxial.ramp_strain=0.2", "triaxial.ramp_strain"),
    ("triaxial.wall_material='glass'", "triaxial.wall_material"),
    ("triaxial.axial_strain=0.9", "triaxial.axial_strain"),
    ("direct_shear.box_length=0.06", "direct_shear"),             # a section the kind does not use
])
def test_bad_input_is_named(tmp_path, override, key):
    case = tmp_path / "tx.toml"
    case.write_text(MINI.format(name="tx_bad", specimen=DENSE, strain=0.15))
    with pytest.raises(CaseError) as err:
        load_case(case, [override])
    assert err.value.key == key


@pytest.mark.slow  # the envelope fit itself: the common-tangent test; this is the run over three pressures
def test_a_series_over_the_cell_pressure_fits_the_envelope(tmp_path):
    """`cosim series` on a triaxial case: one specimen, σ₃ = 50 and 150 kPa, the envelope
    tangent to the two peak circles."""
    case = tmp_path / "tx.toml"
    case.write_text(MINI.format(name="tx_series", specimen=DENSE, strain=0.06))
    out = tmp_path / "series"
    assert main(["series", str(case), "--stresses", "50e3", "150e3", "--out", str(out)]) == 0
    with open(out / "mohr_coulomb.csv") as f:
        rows = {r["strength"]: r for r in csv.DictReader(f)}
    runs = [json.loads((out / "tx_series" / f"{s}kPa" / "summary.json").read_text()) for s in (50, 150)]
    assert [r["cell_pressure"] for r in runs] == [50e3, 150e3]
    # two circles: the envelope is their common tangent, exactly
    (s_a, t_a), (s_b, t_b) = [(r["peak_normal_stress"], r["peak_shear_stress"]) for r in runs]
    sin_phi = (t_b - t_a) / (s_b - s_a)
    assert float(rows["peak"]["phi_deg"]) == pytest.approx(math.degrees(math.asin(sin_phi)), abs=0.01)
    for name in ("mohr_coulomb.png", "series_curves.png", "mohr_coulomb.md"):
        assert (out / name).exists()


def test_the_shipped_case_checks():
    case, _ = load_case(Path(__file__).resolve().parents[2] / "runs" / "triaxial_small.toml")
    assert case.case.kind == "triaxial" and case.triaxial.axial_strain >= 0.2
