"""A triaxial cell of clumped grains (``[specimen] grains = "clumps"``, docs/design.md §2.19):
the miniature cell of test_triaxial.py made of two-sphere grains by radius expansion, end to
end: the void ratio the specimen file's clumps give is the reported one and lands on the
target, the servo holds σ₃."""
import json

import numpy as np
import pytest
from test_triaxial import MINI

from cosim.cli import main
from cosim.lab.shear_report import read_series
from cosim.specimen import read_specimen

ROD = "[[dem.clumps]]\nmembers = [[-0.25, 0.0, 0.0, 1.0], [0.25, 0.0, 0.0, 1.0]]   # aspect ratio 1.25\n"
SPECIMEN = 'grains = "clumps"\nmethod = "radius_expansion"\nvoid_ratio = 0.70\ndeposition_friction = 0.1'


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tx_clumps")
    case = folder / "tx_clumps.toml"
    case.write_text(MINI.format(name="tx_clumps", specimen=SPECIMEN, strain=0.03) + "\n" + ROD)
    out = folder / "out"
    assert main(["run", str(case), "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text()), read_series(out / "series.csv"), out


def test_a_clumped_triaxial_cell_grows_to_its_void_ratio_and_holds_the_cell_pressure(run):
    summary, series, out = run
    assert summary["clumps"] == summary["grains"] and summary["spheres"] == 2 * summary["grains"]
    specimen = read_specimen(out / "specimen.npz")
    e = 0.015**2 * specimen.height / float(np.sum(specimen.clumps.volumes())) - 1.0  # from the union volumes
    assert e == pytest.approx(summary["void_ratio_generated"], rel=1e-12)
    assert abs(summary["void_ratio_generated"] - 0.70) <= 0.01
    assert np.all(np.abs(series["sigma_3"] / 100e3 - 1.0) < 0.02)
