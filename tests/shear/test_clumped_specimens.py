"""Lab tests of clumped grains (``[specimen] grains = "clumps"``, docs/design.md §2.19): a
miniature direct shear (under-compaction) and a miniature triaxial cell (radius expansion) of
two-sphere grains, end to end. The specimen file keeps the clumps, its void ratio counts each
clump's union once, the servos hold their stresses and the consolidation comes to rest."""
import json
import math

import numpy as np
import pytest
from test_direct_shear_run import MINI as SHEAR_MINI

from cosim.cli import main
from cosim.lab.shear_report import read_series
from cosim.specimen import read_specimen

ROD = "[[dem.clumps]]\nmembers = [[-0.25, 0.0, 0.0, 1.0], [0.25, 0.0, 0.0, 1.0]]   # aspect ratio 1.25\n"

TRIAXIAL = """
[case]
name = "tx_clumps"
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
grains = "clumps"
method = "radius_expansion"
sieve_diameters = [1.6e-3, 2.4e-3]
sieve_passing = [0.0, 1.0]
void_ratio = 0.70
deposition_friction = 0.1

[triaxial]
size = 0.015
cell_pressure = 100e3
axial_strain = 0.03
rows = 10
"""


def _run(folder, name, text):
    case = folder / f"{name}.toml"
    case.write_text(text)
    out = folder / "out"
    assert main(["run", str(case), "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text()), read_series(out / "series.csv"), out


@pytest.fixture(scope="module")
def shear(tmp_path_factory):
    text = SHEAR_MINI.format(name="ds_clumps", e=0.75, mu=0.3).replace(
        "[specimen]\n", '[specimen]\ngrains = "clumps"\ntolerance = 0.02\n') + ROD
    return _run(tmp_path_factory.mktemp("ds_clumps"), "ds_clumps", text)


@pytest.fixture(scope="module")
def triaxial(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("tx_clumps"), "tx_clumps", TRIAXIAL + "\n" + ROD)


def _void_ratio_of_file(path, box_volume):
    """e of a specimen file from its clumps' union volumes."""
    specimen = read_specimen(path)
    solid = float(np.sum(specimen.clumps.volumes()))
    return specimen, box_volume(specimen.height) / solid - 1.0


def test_a_clumped_shear_specimen_is_made_to_its_void_ratio_and_kept_with_its_clumps(shear):
    summary, _, out = shear
    assert summary["clumps"] == summary["grains"] and summary["spheres"] == 2 * summary["grains"]
    assert summary["void_ratio_within_tolerance"]
    specimen, e = _void_ratio_of_file(out / "specimen.npz", lambda h: 0.02 * 0.02 * h)
    assert specimen.clumps.count == summary["grains"]
    assert e == pytest.approx(summary["void_ratio_generated"], rel=1e-12)
    # the members overlap: counting them as spheres would read a void ratio lower by their overlaps
    members = 4.0 / 3.0 * math.pi * np.sum(specimen.radii**3)
    assert members > 1.1 * np.sum(specimen.clumps.volumes())


def test_clumps_consolidate_to_rest_and_the_servo_holds_the_normal_stress(shear):
    summary, series, _ = shear
    assert summary["steps_consolidation"] < 100000  # it came to rest (max_consolidation_steps)
    assert summary["servo_max_relative_error"] < 0.02
    assert summary["love_weber_normal_over_wall"] == pytest.approx(1.0, abs=0.15)
    assert np.all(series["shear_stress"][1:] > 0)
    assert math.isfinite(summary["peak_friction_angle_deg"])


def test_a_clumped_triaxial_cell_grows_to_its_void_ratio_and_holds_the_cell_pressure(triaxial):
    summary, series, out = triaxial
    assert summary["clumps"] == summary["grains"]
    specimen, e = _void_ratio_of_file(out / "specimen.npz", lambda h: 0.015 * 0.015 * h)
    assert e == pytest.approx(summary["void_ratio_generated"], rel=1e-12)
    assert abs(summary["void_ratio_generated"] - 0.70) <= 0.01
    assert np.all(np.abs(series["sigma_3"] / 100e3 - 1.0) < 0.02)
