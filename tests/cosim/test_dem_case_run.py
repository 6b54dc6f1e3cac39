"""``cosim run`` on a small DEM case: outputs, provenance, checkpoint/resume, crash safety."""
import csv
import json
import os
import signal
import subprocess
import sys
import time
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import tomli_w

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
DEMO = ROOT / "runs" / "demo_dem_settling.toml"


def small_case(tmp_path, count=300, steps=400, **output):
    data = tomllib.loads(DEMO.read_text())
    data["case"]["name"] = "small"
    data["dem"]["particles"]["count"] = count
    data["dem"]["particles"]["box"] = [[0.0, 0.0, 0.0], [0.015, 0.015, 0.03]]
    for w in data["dem"]["walls"]:
        w["point"] = [min(c, 0.015) for c in w["point"]]
    data["time"] = {"steps": steps, "safety_factor": 0.3}
    data["output"] = {"interval": 1e-4, "vtk": True, **output}
    path = tmp_path / "small.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def cosim(*args, **kw):
    return subprocess.run([str(COSIM), *args], capture_output=True, text=True, timeout=600, **kw)


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_run_writes_series_frames_and_provenance(tmp_path):
    out = tmp_path / "out"
    res = cosim("run", str(small_case(tmp_path)), "--out", str(out))
    assert res.returncode == 0, res.stderr + res.stdout
    assert f"outputs: {out}" in res.stdout
    assert "steps/s" in res.stdout and "ETA" in res.stdout
    series = rows(out / "series.csv")
    assert float(series[-1]["step"]) == 400
    times = [float(r["time"]) for r in series]
    assert times == sorted(times) and times[0] == 0.0
    assert (out / "series.png").stat().st_size > 10_000
    from de_domain.packing import load_packing
    positions, radii = load_packing(out / "final_packing.npz")   # reusable as a case's packing file
    assert positions.shape == (300, 3) and np.all(radii >= 0.0008)
    # ParaView: a valid PVD whose frames exist
    datasets = ET.parse(out / "particles.pvd").getroot().iter("DataSet")
    files = [out / d.get("file") for d in datasets]
    assert len(files) >= len(series) and all(f.exists() for f in files)
    info = json.loads((out / "run_info.json").read_text())
    assert info["seed"] == 2026 and info["mpi_size"] == 1 and info["numba_threads"] >= 1
    assert info["versions"]["dolfinx"] == "0.5.2"
    resolved = tomllib.loads((out / "case.resolved.toml").read_text())
    assert resolved["dem"]["materials"][0]["rolling_friction"] == 0.0  # defaults are filled in
    # the resolved case is itself a valid case
    assert cosim("check", str(out / "case.resolved.toml")).returncode == 0


def test_resume_continues_exactly_where_an_uninterrupted_run_would_be(tmp_path):
    """Stopped on an output row (step 200: kept) or between two (step 220: its final row is
    dropped, the uninterrupted run has none there), then resumed: every row and the end state
    are the uninterrupted run's."""
    case = small_case(tmp_path)
    straight = tmp_path / "straight"
    assert cosim("run", str(case), "--out", str(straight)).returncode == 0
    a = rows(straight / "series.csv")
    assert "200" in [r["step"] for r in a] and "220" not in [r["step"] for r in a]
    for stop in (200, 220):
        split = tmp_path / f"split{stop}"
        assert cosim("run", str(case), "--out", str(split), "--set", f"time.steps={stop}").returncode == 0
        assert rows(split / "series.csv")[-1]["step"] == str(stop)
        res = cosim("run", str(case), "--out", str(split), "--resume")
        assert res.returncode == 0, res.stderr
        assert rows(split / "series.csv") == a, stop
        with np.load(straight / "checkpoint.npz") as x, np.load(split / "checkpoint.npz") as y:
            for key in x.files:
                np.testing.assert_array_equal(x[key], y[key], err_msg=key)


def test_resume_without_checkpoint_is_a_clear_error(tmp_path):
    res = cosim("run", str(small_case(tmp_path)), "--out", str(tmp_path / "none"), "--resume")
    assert res.returncode == 2
    assert "no checkpoint" in res.stderr


def test_killed_run_leaves_readable_outputs(tmp_path):
    out = tmp_path / "out"
    case = small_case(tmp_path, steps=10_000_000, checkpoint_interval=0.5)
    proc = subprocess.Popen([str(COSIM), "run", str(case), "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while time.time() < deadline:
        if (out / "checkpoint.npz").exists() and (out / "series.csv").exists() and len(rows(out / "series.csv")) >= 3:
            break
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    series = rows(out / "series.csv")
    assert len(series) >= 3 and all(r["kinetic"] for r in series)
    ET.parse(out / "particles.pvd")  # still a complete XML document
    with np.load(out / "checkpoint.npz") as ck:
        assert len(ck.files) > 0
    # and the run can be resumed from what the crash left
    res = cosim("run", str(case), "--out", str(out), "--resume", "--set", "time.steps=3000")
    assert res.returncode == 0, res.stderr


def test_a_time_step_near_critical_is_warned_before_and_after_the_run(tmp_path):
    """A settled bed (~4 contacts per sphere), restitution 1, no damping: at 0.95 x the
    critical step the energy balance is off by about a quarter of the work (the step is
    stable for one contact, not for four); at the default 0.3 x it closes (< 0.1 %)."""
    def case(dt=None):
        data = {"case": {"name": "near_critical", "kind": "dem"}, "time": {"steps": 500},
                "output": {"interval": 1e-3, "vtk": False},
                "dem": {"local_damping": 0.0,
                        "materials": [{"name": "sand", "density": 2650.0, "young": 5e7, "restitution": 1.0}],
                        "particles": {"source": "file", "file": str(ROOT / "runs/packings/sand_bed_30mm.npz"),
                                      "material": "sand"},
                        "walls": [{"type": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
                                   "material": "sand"}]}}
        if dt is not None:
            data["time"]["dt"] = dt
        path = tmp_path / f"case_{dt}.toml"
        path.write_text(tomli_w.dumps(data))
        return path

    near = cosim("run", str(case(8.0e-6)), "--out", str(tmp_path / "near"))   # critical: 8.43e-6 s
    assert near.returncode == 0, near.stderr
    assert "0.95 x the critical step" in near.stderr
    assert "the energy balance is off by" in near.stderr
    default = cosim("run", str(case()), "--out", str(tmp_path / "default"))
    assert default.returncode == 0, default.stderr
    assert "warning" not in default.stderr
