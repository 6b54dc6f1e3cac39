"""``cosim run`` on a case of clumps (runs/demo_dem_clumps.toml, cut down): the grains are made as
the templates say, stay rigid, come out in the frames and files, and a resumed run is the
uninterrupted one."""
import subprocess
import sys
import tomllib
from pathlib import Path

import meshio
import numpy as np
import tomli_w

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
DEMO = ROOT / "runs" / "demo_dem_clumps.toml"


def small_case(tmp_path, count=120, steps=600):
    data = tomllib.loads(DEMO.read_text())
    data["case"]["name"] = "clumps"
    data["dem"]["particles"]["count"] = count
    data["time"] = {"steps": steps, "safety_factor": 0.3}
    data["output"] = {"interval": 2e-4, "vtk": True}
    path = tmp_path / "clumps.toml"
    path.write_text(tomli_w.dumps(data))
    return path, data


def cosim(*args):
    return subprocess.run([str(COSIM), *args], capture_output=True, text=True, timeout=600)


def test_a_case_of_clumps_runs_and_its_grains_stay_rigid(tmp_path):
    case, data = small_case(tmp_path)
    out = tmp_path / "out"
    res = cosim("run", str(case), "--out", str(out))
    assert res.returncode == 0, res.stderr + res.stdout
    assert "120 clumps of" in res.stdout
    with np.load(out / "final_clumps.npz") as c:
        clumps = {k: c[k] for k in c.files}
    positions = np.load(out / "final_packing.npz")["positions"]
    start = clumps["member_start"]
    shapes = [np.asarray(t["members"]) for t in data["dem"]["clumps"]]
    counts = np.diff(start)
    assert set(counts.tolist()) == {len(s) for s in shapes}  # both shapes drawn
    lo, hi = np.array(data["dem"]["particles"]["box"])
    for c in range(counts.size):
        members = positions[clumps["member_index"][start[c]:start[c + 1]]]
        body = clumps["member_body"][start[c]:start[c + 1]]
        # rigid: the members' distances are the template's, scaled, after 600 steps of falling and colliding
        gaps = np.linalg.norm(members[:, None] - members[None], axis=2)
        assert np.allclose(gaps, np.linalg.norm(body[:, None] - body[None], axis=2), rtol=1e-9, atol=1e-15)
        shape = next(s for s in shapes if len(s) == counts[c])
        template = np.linalg.norm(shape[:, None, :3] - shape[None, :, :3], axis=2)
        if counts[c] > 1:  # the same shape: distances in proportion to the template's
            ratio = gaps[template > 0] / template[template > 0]
            assert np.allclose(ratio, ratio[0], rtol=1e-6)
        assert np.all(clumps["pos"][c] > lo) and np.all(clumps["pos"][c] < hi[0:3] + 1.0)
    # equal-volume radii in the drawn range: mass / density = 4/3 π r³
    r_eq = (clumps["mass"] / data["dem"]["materials"][0]["density"] * 3 / (4 * np.pi)) ** (1 / 3)
    r_min, r_max = data["dem"]["particles"]["radius"]
    assert np.all(r_eq > r_min * (1 - 1e-3)) and np.all(r_eq < r_max * (1 + 1e-3))
    frames = sorted((out / "frames").glob("particles_*.vtu"))
    frame = meshio.read(frames[-1])
    assert np.array_equal(frame.point_data["clump"], clumps["member_of"])


def test_a_resumed_run_of_clumps_is_the_uninterrupted_one(tmp_path):
    case, _ = small_case(tmp_path, count=60, steps=400)
    straight, split = tmp_path / "straight", tmp_path / "split"
    assert cosim("run", str(case), "--out", str(straight)).returncode == 0
    assert cosim("run", str(case), "--out", str(split), "--set", "time.steps=200").returncode == 0
    res = cosim("run", str(case), "--out", str(split), "--resume")
    assert res.returncode == 0, res.stderr
    with np.load(straight / "checkpoint.npz") as x, np.load(split / "checkpoint.npz") as y:
        assert "clump_quat" in x.files
        for key in x.files:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)
