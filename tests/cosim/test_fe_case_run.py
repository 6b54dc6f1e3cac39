"""``cosim run`` on small ``fe`` cases: static equilibrium, bit-exact resume, 1 vs 2 ranks."""
import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1"}
PRESSURE = 50.0e3  # Pa on the 1 x 1 m top face


def block_case(tmp_path, steps=1500, **time):
    data = {
        "case": {"name": "block", "kind": "fe"},
        "time": {"steps": steps, "safety_factor": 0.5, **time},
        "output": {"interval": 0.0},
        "fe": {"mesh": "block.geo", "mesh_size": 0.5, "reactions": ["bottom"],
               "materials": [{"E": 10.0e6, "nu": 0.3, "rho": 2000.0}],
               "boundary_conditions": [{"type": "fixed", "boundary": "bottom"}],
               "loads": [{"type": "pressure", "boundary": "top", "pressure": PRESSURE, "ramp": 0.02}],
               "damping": {"type": "local", "alpha": 0.5}},
    }
    path = tmp_path / "block.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def cosim(*args, mpi=0):
    cmd = [str(COSIM), *args]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=ENV, cwd=ROOT)
    assert res.returncode == 0, res.stderr + res.stdout
    return res


def last_row(path):
    with open(path) as f:
        return list(csv.DictReader(f))[-1]


def test_support_reaction_balances_the_applied_load(tmp_path):
    out = tmp_path / "out"
    cosim("run", str(block_case(tmp_path)), "--out", str(out))
    row = last_row(out / "series.csv")
    assert float(row["bottom_z"]) == pytest.approx(PRESSURE * 1.0, rel=1e-2)
    assert abs(float(row["bottom_x"])) < 1e-3 * PRESSURE and abs(float(row["bottom_y"])) < 1e-3 * PRESSURE
    for name in ("fields.xdmf", "fields.h5", "energies.csv", "series.png", "energies.png", "run_info.json"):
        assert (out / name).exists(), name


def test_resume_matches_an_uninterrupted_run(tmp_path):
    """Stopped on an output row (step 150) or between two (step 145: its final row is dropped),
    then resumed: the end state, and series.csv and energies.csv row for row, are the
    uninterrupted run's."""
    case = block_case(tmp_path, steps=300)
    every = ("--set", "output.interval=0.012")  # 10 steps (Δt = 1.209e-3 s): the same rows whatever time.steps
    cosim("run", str(case), "--out", str(tmp_path / "a"), *every)
    for stop in (150, 145):
        split = tmp_path / f"b{stop}"
        cosim("run", str(case), "--out", str(split), "--set", f"time.steps={stop}", *every)
        assert last_row(split / "series.csv")["step"] == str(stop)
        cosim("run", str(case), "--out", str(split), "--resume", *every)
        with (np.load(tmp_path / "a" / "checkpoint.rank0of1.npz") as a,
              np.load(split / "checkpoint.rank0of1.npz") as b):
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        for name in ("series.csv", "energies.csv"):
            assert (split / name).read_text() == (tmp_path / "a" / name).read_text(), (stop, name)


def test_two_ranks_give_the_one_rank_history(tmp_path):
    case = block_case(tmp_path, steps=400)
    cosim("run", str(case), "--out", str(tmp_path / "one"))
    cosim("run", str(case), "--out", str(tmp_path / "two"), mpi=2)
    with open(tmp_path / "one" / "series.csv") as f1, open(tmp_path / "two" / "series.csv") as f2:
        one = np.array([[float(v) for v in r.values()] for r in csv.DictReader(f1)])
        two = np.array([[float(v) for v in r.values()] for r in csv.DictReader(f2)])
    assert one.shape == two.shape
    # reactions and displacements agree to the CSV's 10 significant digits (round-off of sums)
    np.testing.assert_allclose(two, one, rtol=1e-8, atol=1e-8 * np.abs(one).max())


def test_a_state_that_stops_being_finite_ends_the_run(tmp_path):
    """The check every output of an ``fe`` or ``coupled`` run makes, on all ranks together:
    one NaN in the velocity is a RunFailed naming the step (exit 1, the outputs so far kept)."""
    from cosim.apps import fe as fe_app
    from cosim.case import load_case
    from cosim.errors import RunFailed
    path = block_case(tmp_path)
    case, _ = load_case(path)
    solver = fe_app.build_solid(case, path)
    fe_app.check_finite(solver)
    solver.velocity[0, 2] = np.nan
    with pytest.raises(RunFailed, match="not finite at step 0"):
        fe_app.check_finite(solver)


@pytest.mark.slow  # resume: test_resume_matches_an_uninterrupted_run; 2 ranks: test_two_ranks_give_the_one_rank_history
def test_a_checkpoint_resumes_on_another_rank_count_and_partition(tmp_path):
    """Written by 2 ranks, continued by 1, then by 3 (each from the newest complete set of
    checkpoint files, every node found by its mesh-input index): the history is the one of an
    uninterrupted 1-rank run to the CSV's 10 digits, as between rank counts without a resume."""
    case = block_case(tmp_path, steps=400)
    cosim("run", str(case), "--out", str(tmp_path / "one"))
    split = tmp_path / "split"
    cosim("run", str(case), "--out", str(split), "--set", "time.steps=200", mpi=2)
    cosim("run", str(case), "--out", str(split), "--set", "time.steps=300", "--resume")
    cosim("run", str(case), "--out", str(split), "--resume", mpi=3)
    # each continuation wrote its fields from the step it resumed at
    assert (split / "fields_from_step200.xdmf").exists() and (split / "fields_from_step300.xdmf").exists()
    with open(tmp_path / "one" / "series.csv") as f1, open(split / "series.csv") as f2:
        one = np.array([[float(v) for v in r.values()] for r in csv.DictReader(f1)])
        resumed = np.array([[float(v) for v in r.values()] for r in csv.DictReader(f2)])
    # rows at the steps both wrote (the output interval follows each run's time.steps)
    steps = np.intersect1d(one[:, 1], resumed[:, 1])
    assert len(steps) >= 10 and steps[-1] == 400
    resumed, one = resumed[np.isin(resumed[:, 1], steps)], one[np.isin(one[:, 1], steps)]
    np.testing.assert_allclose(resumed, one, rtol=1e-8, atol=1e-8 * np.abs(one).max())


def test_a_resume_takes_the_newest_set_of_checkpoint_files(tmp_path):
    """An output folder with an older 1-rank FE checkpoint and a newer set of 2 ranks (a run
    with another rank count or FE layout since): a 1-rank resume continues from the newer set,
    every node from the rank that owned it, not from its own stale file."""
    from cosim.apps import fe as fe_app
    from cosim.case import load_case
    path = block_case(tmp_path)
    case, _ = load_case(path)
    solver = fe_app.build_solid(case, path)
    out = tmp_path / "out"
    out.mkdir()
    older = solver.checkpoint_state()
    np.savez(out / "checkpoint.rank0of1.npz", **older)
    os.utime(out / "checkpoint.rank0of1.npz", (1.0e9, 1.0e9))
    newer = {**older, "clock": np.array([0.5, 100.0, older["clock"][2]]),
             "displacement": older["displacement"] + 1e-3 * np.arange(older["displacement"].size).reshape(-1, 3)}
    half = solver.n_owned_nodes // 2
    for rank, rows in enumerate((slice(0, half), slice(half, None))):
        part = {k: v[rows] if k in ("displacement", "velocity", "pressure", "velocity_change", "input_node_index")
                else v for k, v in newer.items() if k != "n_owned_nodes"}
        np.savez(out / f"checkpoint.rank{rank}of2.npz", **part, n_owned_nodes=np.int64(len(part["input_node_index"])))
    fe_app.restore_checkpoint(solver, path, out, "checkpoint")
    assert solver.step_count == 100 and solver.time == 0.5
    np.testing.assert_array_equal(solver.displacement, newer["displacement"])


def test_resume_without_a_checkpoint_is_bad_input(tmp_path):
    res = subprocess.run([str(COSIM), "run", str(block_case(tmp_path)), "--out", str(tmp_path / "none"), "--resume"],
                         capture_output=True, text=True, timeout=300, env=ENV, cwd=ROOT)
    assert res.returncode == 2 and "no complete set of FE checkpoint files" in res.stderr
