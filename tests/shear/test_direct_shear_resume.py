"""A direct shear run killed while shearing resumes from its checkpoint and ends with
the same CSV rows, to the last digit, as a run that was never interrupted."""
import csv
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from test_direct_shear_run import MINI

COSIM = Path(sys.executable).parent / "cosim"


def cosim(*args):
    return subprocess.run([str(COSIM), *args], capture_output=True, text=True, timeout=900)


def rows(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


def from_file(case, specimen):
    """The case with its specimen read from ``specimen`` (the generation keys and the
    sample height, which the file then fixes, removed)."""
    text = case.read_text()
    start, end = text.index("[specimen]"), text.index("[direct_shear]")
    text = text[:start] + f'[specimen]\nsource = "file"\nfile = "{specimen}"\n\n' + text[end:]
    text = "\n".join(line for line in text.splitlines() if not line.startswith("sample_height")) + "\n"
    path = case.with_name("from_file.toml")
    path.write_text(text)
    return path


def test_killed_shear_run_resumes_to_the_same_result(tmp_path, mini_dense_run):
    _, _, reference = mini_dense_run  # the uninterrupted run (tests/shear/conftest.py)
    case = tmp_path / "mini.toml"
    shutil.copy(reference.parent / "mini_dense.toml", case)
    # the same specimen from its file, sheared in a process that is killed mid-way
    specimen = tmp_path / "specimen.npz"
    shutil.copy(reference / "specimen.npz", specimen)
    case = from_file(case, specimen)
    split = tmp_path / "split"
    sets = ["--set", "output.checkpoint_interval=0.5"]
    proc = subprocess.Popen([str(COSIM), "run", str(case), "--out", str(split), *sets],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:
        if (split / "shear_state.json").exists() and len(rows(split / "series.csv")) > 6:
            break
        time.sleep(0.1)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.kill()
    proc.wait()
    assert not (split / "summary.json").exists()
    res = cosim("run", str(case), "--out", str(split), *sets, "--resume")
    assert res.returncode == 0, res.stderr
    assert "resumed at step" in res.stdout + res.stderr
    assert rows(split / "series.csv") == rows(reference / "series.csv")
    # the shear band, measured against the positions saved when shearing began
    reference_summary = json.loads((reference / "summary.json").read_text())
    assert json.loads((split / "summary.json").read_text())["shear_band"] == reference_summary["shear_band"]
    # the summary of the resumed run counts the killed process's time too
    summary = json.loads((split / "summary.json").read_text())
    assert summary["wall_clock_total_s"] >= summary["wall_clock_shear_s"] + summary["wall_clock_consolidation_s"]
    assert summary["wall_clock_consolidation_s"] > 0
    assert "from " in (split / "summary.txt").read_text().splitlines()[1]   # e from the file, not "generated nan"


def test_resume_without_a_shear_checkpoint_is_a_clear_error(tmp_path):
    case = tmp_path / "mini.toml"
    case.write_text(MINI.format(name="mini", e=0.70, mu=0.3))
    res = cosim("run", str(case), "--out", str(tmp_path / "none"), "--resume")
    assert res.returncode == 2
    assert "no shear checkpoint" in res.stderr
