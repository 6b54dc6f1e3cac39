"""A direct shear of clumped grains (``[specimen] grains = "clumps"``, docs/design.md §2.19): a
miniature box of two-sphere grains made by radius expansion, end to end (under-compaction of
clumps: test_specimen_recipe.py). The specimen file keeps
the clumps, its void ratio counts each clump's union once, the consolidation comes to rest and
the servo holds σ_n (the triaxial cell: tests/triaxial/test_triaxial_clumps.py)."""
import json
import math

import numpy as np
import pytest
from test_direct_shear_run import MINI as SHEAR_MINI

from cosim.cli import main
from cosim.lab.shear_report import read_series
from cosim.specimen import read_specimen

ROD = "[[dem.clumps]]\nmembers = [[-0.25, 0.0, 0.0, 1.0], [0.25, 0.0, 0.0, 1.0]]   # aspect ratio 1.25\n"

def _run(folder, name, text):
    case = folder / f"{name}.toml"
    case.write_text(text)
    out = folder / "out"
    assert main(["run", str(case), "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text()), read_series(out / "series.csv"), out


@pytest.fixture(scope="module")
def shear(tmp_path_factory):
    text = SHEAR_MINI.format(name="ds_clumps", e=0.75, mu=0.3).replace(
        "[specimen]\n", '[specimen]\ngrains = "clumps"\nmethod = "radius_expansion"\n') + ROD
    return _run(tmp_path_factory.mktemp("ds_clumps"), "ds_clumps", text)


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
    sheared = series["shear_displacement"] > 1e-4  # past the velocity ramp
    assert np.all(series["shear_stress"][sheared] > 0)
    assert math.isfinite(summary["peak_friction_angle_deg"])


def test_a_given_time_step_is_checked_against_the_clumps_of_a_specimen_file(shear, tmp_path, capsys):
    """``source = "file"`` with a specimen of clumps: a ``time.dt`` its member spheres would take as
    free spheres but its clumps do not (their critical mass, docs/design.md §2.19) is refused before
    the run, naming the key; half the clumps' critical step passes."""
    from de_domain import Engine, Material, Particles

    specimen_file = shear[2] / "specimen.npz"
    specimen = read_specimen(specimen_file)
    sand = [Material(density=2650.0, young=5.0e7, friction=0.5)]
    members = Particles.from_spheres(specimen.positions, specimen.radii, materials=sand)
    as_spheres = Engine(members, sand).critical_timestep()
    grains, clumps = specimen.clumps.bodies(sand)
    as_clumps = Engine(grains, sand, clumps=clumps).critical_timestep()
    assert as_clumps < 0.9 * as_spheres
    head, rest = SHEAR_MINI.format(name="ds_file", e=0.75, mu=0.3).split("[specimen]")
    text = head + f'[specimen]\nsource = "file"\nfile = "{specimen_file}"\n\n[direct_shear]' \
        + rest.split("[direct_shear]")[1].replace("sample_height = 0.01\n", "")
    for dt, code in ((0.5 * (as_clumps + as_spheres), 2), (0.4 * as_clumps, 0)):
        case = tmp_path / f"dt_{code}.toml"
        case.write_text(text.replace("[time]\n", f"[time]\ndt = {dt!r}\n"))
        assert main(["check", str(case)]) == code
        assert ("key 'time.dt'" in capsys.readouterr().err) == (code == 2)
