"""The ``embedded`` kind under mpirun and through a kill: a small retaining wall
(runs/retaining_wall_small.toml made smaller, as tests/cosim/test_embedded_case.py) run on 2
ranks — the fill, the rest and the loading — writes the 1-rank run's rows and grains to the
last bit; killed during the loading, it resumes from its checkpoint to the same rows."""
import json

import numpy as np
import pytest
from test_footing import ROOT, cosim, kill_during_loading, run_ok, set_options

CASE = "runs/retaining_wall_small.toml"
SMALL = {"embedded.parameters.L": 0.09, "embedded.parameters.H": 0.04, "embedded.parameters.a": 0.03,
         "embedded.loading_time": 0.02, "embedded.rows": 8}


def overrides(extra=None):
    return set_options({**SMALL, **(extra or {})})


@pytest.fixture(scope="module")
def one_rank(tmp_path_factory):
    out = tmp_path_factory.mktemp("embedded_one")
    run_ok("run", CASE, "--out", str(out), *overrides())
    return out


def test_two_ranks_fill_rest_and_load_the_same_model_bit_for_bit(one_rank, tmp_path):
    res = run_ok("run", CASE, "--out", str(tmp_path), *overrides(), mpi=2)
    assert res.stdout.count("outputs: ") == 1
    one, two = one_rank / "coupled", tmp_path / "coupled"
    assert json.loads((two / "summary.json").read_text())["ranks"] == 2
    assert (two / "series.csv").read_text() == (one / "series.csv").read_text()
    assert (two / "rest.csv").read_text() == (one / "rest.csv").read_text()
    assert (two / "rest_stress.csv").read_text() == (one / "rest_stress.csv").read_text()
    for name in ("specimen.npz", "loading_start.npz", "final_packing.npz"):
        with np.load(one / name) as a, np.load(two / name) as b:
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}: {key}")


def test_a_killed_loading_resumes_to_the_same_rows(one_rank, tmp_path):
    sets = overrides({"output.checkpoint_interval": 0.05})
    kill_during_loading([CASE, "--out", str(tmp_path), *sets], tmp_path)
    res = run_ok("run", CASE, "--out", str(tmp_path), *sets, "--resume")
    assert "resumed the loading at row" in res.stdout
    assert (tmp_path / "coupled" / "series.csv").read_text() == (one_rank / "coupled" / "series.csv").read_text()
    resumed = json.loads((tmp_path / "coupled" / "summary.json").read_text())
    assert resumed["rigid"] == json.loads((one_rank / "coupled" / "summary.json").read_text())["rigid"]


def test_resume_without_a_checkpoint_is_one_message(tmp_path):
    res = cosim("run", CASE, "--out", str(tmp_path), "--resume", *overrides())
    assert res.returncode == 2 and "no checkpoint of the loading" in res.stderr


def test_clumped_grains_fill_rest_and_load_the_same_on_two_ranks(tmp_path):
    """The small wall with rods of two spheres (aspect 1.5) for grains, in a slice 12 mm thick
    (three of the longest rods across): on 1 and 2 ranks the fill (clumps and their member
    spheres), the rest and the rows are the same to the last bit, and at rest the supports
    carry the grains' weight, each clump's once (the members carry their clump's mass); its
    specimen.npz, read back as a packing file, rests the same to the last bit; final_clumps.npz
    holds the clumps at the end, the same on either."""
    case = tmp_path / "rods.toml"
    case.write_text((ROOT / CASE).read_text() + "\n[[dem.clumps]]\nmembers = [[-0.5, 0, 0, 1], [0.5, 0, 0, 1]]\n")
    sets = overrides({"embedded.parameters.Ly": 0.012, "specimen.grains": "clumps"})
    for ranks in (1, 2):
        run_ok("run", str(case), "--out", str(tmp_path / f"n{ranks}"), *sets, mpi=ranks if ranks > 1 else 0)
    one, two = tmp_path / "n1" / "coupled", tmp_path / "n2" / "coupled"
    for name in ("series.csv", "rest.csv"):
        assert (two / name).read_text() == (one / name).read_text()
    with np.load(one / "specimen.npz") as a, np.load(two / "specimen.npz") as b:
        assert "clump_template_of" in a.files
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert len(a["radii"]) == 2 * len(a["clump_template_of"])
    with np.load(one / "final_clumps.npz") as a, np.load(two / "final_clumps.npz") as b:  # the clumps at the end
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert np.array_equal(np.bincount(a["member_of"]), np.full(len(a["mass"]), 2))
    summary = json.loads((one / "summary.json").read_text())
    assert summary["rest"]["support_force_over_weight"] == pytest.approx(1.0, abs=0.01)
    assert summary["fill"]["spheres"] == 2 * summary["fill"]["grains"]
    # its specimen.npz read back (source = "file") is the same model: the same rest to the last bit
    text = case.read_text()
    start, end = text.index("[specimen]"), text.index("[embedded]")
    reread = tmp_path / "reread.toml"
    reread.write_text(text[:start] + f'[specimen]\nsource = "file"\nfile = "{one / "specimen.npz"}"\n\n'
                      + text[end:text.index("[[dem.clumps]]")])
    run_ok("run", str(reread), "--out", str(tmp_path / "file"), *overrides({"embedded.parameters.Ly": 0.012}))
    assert (tmp_path / "file" / "coupled" / "rest.csv").read_text() == (one / "rest.csv").read_text()
    reread_fill = json.loads((tmp_path / "file" / "coupled" / "summary.json").read_text())["fill"]
    assert (reread_fill["grains"], reread_fill["spheres"]) == (summary["fill"]["grains"], summary["fill"]["spheres"])
