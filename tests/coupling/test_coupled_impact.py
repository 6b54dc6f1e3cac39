"""FE–DE coupling (docs/design.md §5.4): grains fly up into a free elastic plate.

With no gravity, walls or supports the only forces are the contacts between grains
and the plate's interface facets, so the linear momentum of FE + DEM + the impulse
in transit (collected by the DEM in the last window, not yet applied to the FE) is
conserved to round-off; the result must not depend on the number of MPI ranks (with the
FE replicated on every rank, to the last bit), and only weakly (time-discretisation error)
on the number of DEM substeps per FE step.
"""
import csv
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1"}


def impact_case(tmp_path, grain_young=1.0e7, duration=0.006, name="impact", cloud_bottom=-0.004):
    data = {
        "case": {"name": name, "kind": "coupled", "seed": 3},
        "time": {"duration": duration, "safety_factor": 0.3},
        "output": {"interval": duration / 12},
        "fe": {"mesh": "block.geo", "mesh_size": 0.004,
               "geometry_parameters": {"Lx": 0.01, "Ly": 0.01, "Lz": 0.004},
               "materials": [{"E": 1.0e7, "nu": 0.3, "rho": 2000.0}]},
        "dem": {"gravity": [0.0, 0.0, 0.0],
                "materials": [{"name": "grain", "density": 2650.0, "young": grain_young, "friction": 0.5,
                               "restitution": 0.5}],
                "particles": {"source": "cloud", "count": 30, "material": "grain", "velocity": [0.0, 0.0, 0.5],
                              "box": [[0.001, 0.001, cloud_bottom], [0.009, 0.009, -0.0002]],
                              "radius": [0.0005, 0.0006]}},
        "coupling": {"interface": "bottom", "material": "grain"},
    }
    path = tmp_path / f"{name}.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def run(case, out, *extra, mpi=0):
    cmd = [str(COSIM), "run", str(case), "--out", str(out), *extra]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=ENV, cwd=ROOT)
    assert res.returncode == 0, res.stderr + res.stdout
    with open(out / "series.csv") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}, res.stdout


@pytest.fixture(scope="module")
def one_rank(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("coupled")
    case = impact_case(tmp)
    return case, run(case, tmp / "one")[0], tmp / "one"


def is_dem_state(key):
    """A DEM checkpoint array of the state (particles, facets with their forces and impulses,
    walls, clock), not of the lists (built at other instants after a resume) nor the energy
    books (per-rank sums added in rank order: equal to round-off only)."""
    return key.startswith(("p_", "facet0_", "wall_", "clump_")) or key in ("step_count", "config", "energy_jump")


def assert_same_state(out_a, out_b):
    """The FE checkpoints, and the DEM state arrays of the two DEM checkpoints, equal bit for bit."""
    with np.load(out_a / "checkpoint.fe.rank0of1.npz") as x, np.load(out_b / "checkpoint.fe.rank0of1.npz") as y:
        assert set(x.files) == set(y.files)
        for key in x.files:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)
    with np.load(out_a / "checkpoint.npz") as x, np.load(out_b / "checkpoint.npz") as y:
        state = sorted(filter(is_dem_state, x.files))
        assert {"p_pos", "p_vel", "p_angvel", "facet0_vertices", "facet0_vertex_impulse", "step_count"} <= set(state)
        assert state == sorted(filter(is_dem_state, y.files))
        for key in state:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)


def test_momentum_of_fe_dem_and_impulse_in_transit_is_conserved_to_round_off(one_rank):
    _, s, _ = one_rank
    p0 = s["momentum_dem_z"][0]
    assert p0 > 0 and s["momentum_fe_z"][0] == 0.0
    # the grains really hit the plate and hand it a good part of their momentum
    assert s["momentum_fe_z"][-1] > 0.3 * p0
    for axis in "xyz":
        drift = np.abs(s[f"momentum_total_{axis}"] - s[f"momentum_total_{axis}"][0])
        assert drift.max() < 1e-12 * p0, axis


def test_clumps_on_the_interface_conserve_momentum_and_give_the_one_rank_run_on_two(tmp_path):
    """Rods (two-sphere clumps) thrown at the FE plate: FE, grains (counted as clumps: a
    member carries its clump's mass for its dashpots) and impulse in transit keep the momentum to
    round-off, the plate takes it up, and under ``mpirun -n 2`` (clumps straddling the ranks)
    the FE and DEM states, clumps included, are the one-rank run's bit for bit."""
    case = impact_case(tmp_path, name="impact_clumps")
    data = tomllib.loads(case.read_text())
    data["dem"]["particles"]["grains"] = "clumps"
    data["dem"]["clumps"] = [{"members": [[0.0, 0.0, 0.0, 1.0], [0.5, 0.0, 0.0, 1.0]]}]
    case.write_text(tomli_w.dumps(data))
    s1, _ = run(case, tmp_path / "one")
    s2, out = run(case, tmp_path / "two", mpi=2)
    assert "DEM on 2 MPI ranks" in out
    with np.load(tmp_path / "one" / "checkpoint.npz") as f:
        assert f["clump_mass"].size == 30 and np.any(f["clump_angmom"] != 0.0)
    assert_same_state(tmp_path / "one", tmp_path / "two")
    for s in (s1, s2):
        p0 = s["momentum_dem_z"][0]
        assert p0 > 0 and s["momentum_fe_z"][-1] > 0.3 * p0
        for axis in "xyz":
            drift = np.abs(s[f"momentum_total_{axis}"] - s[f"momentum_total_{axis}"][0])
            assert drift.max() < 1e-12 * p0, axis
    np.testing.assert_array_equal(s2["momentum_dem_z"], s1["momentum_dem_z"])


@pytest.mark.parametrize("ranks", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_more_ranks_with_the_fe_on_each_give_the_one_rank_run_bit_for_bit(one_rank, tmp_path, ranks):
    """The DEM spread over the ranks, the FE replicated (the default): FE and DEM states, the
    interface force and motion are the 1-rank run's to the last bit; the books close."""
    case, s1, out1 = one_rank
    s2, out = run(case, tmp_path / f"ranks{ranks}", mpi=ranks)
    assert f"DEM on {ranks} MPI ranks, FE on each (replicated)" in out
    assert_same_state(out1, tmp_path / f"ranks{ranks}")
    assert not list((tmp_path / f"ranks{ranks}").glob("checkpoint.fe.*of[2-9].npz"))  # one FE file, rank 0's
    for key in ("interface_force_z", "interface_displacement_z", "momentum_fe_z"):
        np.testing.assert_array_equal(s2[key], s1[key], err_msg=key)
    p0 = s2["momentum_dem_z"][0]
    for axis in "xyz":
        drift = np.abs(s2[f"momentum_total_{axis}"] - s2[f"momentum_total_{axis}"][0])
        assert drift.max() < 1e-12 * p0, axis


def test_more_ranks_with_the_fe_partitioned_give_the_one_rank_result_and_conserve_momentum(one_rank, tmp_path):
    """FE and DEM both spread over the ranks (``coupling.fe_partition = "distributed"``): the
    same history to summation-order round-off (the FE's sums follow its partition), the
    same closed books."""
    case, s1, _ = one_rank
    ranks = 2
    s2, out = run(case, tmp_path / "distributed", "--set", 'coupling.fe_partition="distributed"', mpi=ranks)
    assert f"DEM on {ranks} MPI ranks, FE partitioned over them" in out
    for key in ("momentum_fe_z", "momentum_dem_z", "interface_displacement_z"):
        # agreement to the CSV's 10 significant digits, up to summation-order round-off
        np.testing.assert_allclose(s2[key], s1[key], rtol=1e-8, atol=1e-9 * np.abs(s1[key]).max(), err_msg=key)
    p0 = s2["momentum_dem_z"][0]
    for axis in "xyz":
        drift = np.abs(s2[f"momentum_total_{axis}"] - s2[f"momentum_total_{axis}"][0])
        assert drift.max() < 1e-12 * p0, axis


def output_row_in_contact(series):
    """A duration that ends a run on the first output row (not the last) where grains touch:
    its checkpoint sits on that row, whose contact diagnostics a resume must not read as
    "no contacts" (unbalanced force ratio 1, coordination number 0)."""
    touching = np.flatnonzero(series["unbalanced_force_ratio"][:-1] < 1.0)
    assert touching.size, "no grain touches at an output row: the test shows nothing"
    return float(series["time"][touching[0]]) * (1.0 - 1e-7)  # ceil(duration / Δt) is that row's step


def assert_same_rows(s, reference):
    """Row for row: the same instants, every column to the CSV's 10 digits (the momentum sums,
    round-off around zero, to 1e-12 of the grains' initial momentum)."""
    np.testing.assert_array_equal(s["fe_step"], reference["fe_step"])
    np.testing.assert_array_equal(s["time"], reference["time"])
    p0 = reference["momentum_dem_z"][0]
    for key in reference:
        atol = 1e-12 * p0 if key.startswith(("momentum", "impulse")) else 1e-9 * np.abs(reference[key]).max()
        np.testing.assert_allclose(s[key], reference[key], rtol=1e-8, atol=atol, err_msg=key)


@pytest.mark.parametrize("fe_partition", ["replicated", pytest.param("distributed", marks=pytest.mark.slow)])
def test_a_two_rank_checkpoint_resumes_on_one_rank(one_rank, tmp_path, fe_partition):
    """Part of the run on 2 ranks, the rest on 1 (the DEM from its rank-count-free checkpoint),
    the checkpoint on an output row with grains in contact. With the FE replicated its
    checkpoint is the 1-rank one: the 1-rank run to the last bit; partitioned, the FE nodes
    are found by their mesh-input index: the 1-rank history to the CSV's 10 digits. Every row,
    the resume row's contact diagnostics too (they read 1 and 0 when the row was computed again
    from a checkpoint without the last step's contacts)."""
    case, s1, out1 = one_rank
    out = tmp_path / "split"
    run(case, out, "--set", f"time.duration={output_row_in_contact(s1)!r}",
        "--set", f'coupling.fe_partition="{fe_partition}"', mpi=2)
    s, stdout = run(case, out, "--resume")
    assert "resumed at FE step" in stdout
    if fe_partition == "replicated":
        assert_same_state(out1, out)
    assert_same_rows(s, s1)


def test_subcycling_one_or_four_dem_steps_per_fe_step_agree(tmp_path):
    # stiffer grains: the DEM step is 4x+ below the FE step; grains close to the plate
    case = impact_case(tmp_path, grain_young=2.0e8, duration=0.004, name="stiff", cloud_bottom=-0.0016)
    s1, out1 = run(case, tmp_path / "n1", "--set", "coupling.subcycles=1")
    s4, out4 = run(case, tmp_path / "n4", "--set", "coupling.subcycles=4")
    assert "(1 DEM steps per FE step)" in out1 and "(4 DEM steps per FE step)" in out4
    # same physics, FE step 4x larger: transferred momentum and plate motion within 1 %,
    # compared at the end time both runs reached (their output instants differ by < 1 FE step)
    t_end = min(s1["time"][-1], s4["time"][-1])
    for key in ("momentum_fe_z", "interface_displacement_z"):
        expected = np.interp(t_end, s1["time"], s1[key])
        assert np.interp(t_end, s4["time"], s4[key]) == pytest.approx(expected, rel=1e-2), key


@pytest.mark.parametrize("smoothing_time, stop", [pytest.param(0.0, "between rows", marks=pytest.mark.slow),
                                                  (2e-5, "on a row")])
def test_a_stopped_run_resumes_bit_for_bit(tmp_path, smoothing_time, stop):
    """Run part, resume to the end: the CSV rows, the FE state, the grains with their
    contact history and the impulse in transit (with the smoothing on, the part held back
    too) are those of the uninterrupted run, to the last bit, whether the first part ends
    between output rows (its last row is dropped) or on one with grains in contact (kept).
    With the smoothing on the momentum of FE + DEM + impulse in transit is conserved to
    round-off as well. (Under mpirun the FE checkpoint needs the same mesh partition, which
    DOLFINx does not promise from run to run: a resume that does not fit is refused.)"""
    case = impact_case(tmp_path, duration=0.004, name="resumed")
    straight, split = tmp_path / "straight", tmp_path / "split"
    smoothing = ("--set", f"coupling.smoothing_time={smoothing_time}")
    a, _ = run(case, straight, *smoothing)
    duration = 0.002 if stop == "between rows" else output_row_in_contact(a)
    run(case, split, "--set", f"time.duration={duration!r}", *smoothing)
    b, out = run(case, split, "--resume", *smoothing)
    assert "resumed at FE step" in out
    p0 = a["momentum_dem_z"][0]
    assert a["momentum_fe_z"][-1] > 0.3 * p0
    for axis in "xyz":
        assert np.abs(a[f"momentum_total_{axis}"] - a[f"momentum_total_{axis}"][0]).max() < 1e-12 * p0, axis
    assert all(np.array_equal(a[k], b[k]) for k in a), [k for k in a if not np.array_equal(a[k], b[k])]
    with np.load(straight / "checkpoint.npz") as x, np.load(split / "checkpoint.npz") as y:
        for key in x.files:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)
    with np.load(straight / "checkpoint.fe.rank0of1.npz") as x, np.load(split / "checkpoint.fe.rank0of1.npz") as y:
        for key in x.files:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)
    assert list(split.glob("fields_from_step*.xdmf"))  # the continued FE fields have their own file


def test_resume_without_a_coupled_checkpoint_is_bad_input(tmp_path):
    case = impact_case(tmp_path, duration=0.001, name="none")
    res = subprocess.run([str(COSIM), "run", str(case), "--out", str(tmp_path / "none"), "--resume"],
                         capture_output=True, text=True, timeout=300, env=ENV, cwd=ROOT)
    assert res.returncode == 2 and "no coupled checkpoint" in res.stderr


@pytest.mark.slow  # a SIGKILL between checkpoints; the resume itself: test_a_stopped_run_resumes_bit_for_bit
def test_a_killed_run_resumes_from_its_last_checkpoint(tmp_path):
    """SIGKILL in the middle of a run that checkpoints every 0.5 s: --resume goes on from
    the last checkpoint, and the CSV continues without a repeated or a missing instant."""
    import signal
    import time

    case = impact_case(tmp_path, duration=0.05, name="killed")
    out = tmp_path / "out"
    proc = subprocess.Popen([str(COSIM), "run", str(case), "--out", str(out), "--set", "output.checkpoint_interval=0.5",
                             "--set", "output.interval=0.0002"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=ENV, cwd=ROOT)
    deadline = time.time() + 300
    while time.time() < deadline and not ((out / "checkpoint.npz").exists() and (out / "series.csv").exists()
                                          and len((out / "series.csv").read_text().splitlines()) > 8):
        time.sleep(0.2)
    assert proc.poll() is None, "the run ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    # resumed to a duration well past the first checkpoint (0.5 s of wall clock: t < 0.015 s here)
    s, stdout = run(case, out, "--resume", "--set", "time.duration=0.03", "--set", "output.interval=0.0002")
    assert "resumed at FE step" in stdout
    resumed_at = float(stdout.split("resumed at FE step")[1].split("t = ")[1].split(" s")[0])
    assert resumed_at < 0.03
    assert np.all(np.diff(s["time"]) > 0) and s["time"][-1] == pytest.approx(0.03, rel=1e-2)
    steps = np.diff(s["fe_step"])[:-1]  # rows every output interval (the last at the end): none missing
    assert np.all(steps == steps[0])


@pytest.mark.slow  # subcycling invariance: test_subcycling_one_or_four_dem_steps_per_fe_step_agree
def test_the_shipped_subcycling_case_gives_the_same_answer_with_1_and_20_substeps(tmp_path):
    """runs/coupled_soft_plate_subcycling.toml: the plate's stable step is > 10 DEM steps.
    1 and 20 DEM steps per FE step transfer the same momentum to the plate and move it
    alike, within 1 % (compared at the end time both runs reached)."""
    case = ROOT / "runs" / "coupled_soft_plate_subcycling.toml"
    auto, out = run(case, tmp_path / "auto")
    n_auto = int(out.split(" DEM steps per FE step")[0].rsplit("(", 1)[1])
    assert n_auto >= 10
    s1, out1 = run(case, tmp_path / "n1", "--set", "coupling.subcycles=1")
    s20, out20 = run(case, tmp_path / "n20", "--set", "coupling.subcycles=20")
    assert "(1 DEM steps per FE step)" in out1 and "(20 DEM steps per FE step)" in out20
    p0 = s1["momentum_dem_z"][0]
    assert s1["momentum_fe_z"][-1] > 0.2 * p0  # the grains did hit the plate
    t_end = min(s1["time"][-1], s20["time"][-1])
    for key in ("momentum_fe_z", "interface_displacement_z"):
        expected = np.interp(t_end, s1["time"], s1[key])
        assert np.interp(t_end, s20["time"], s20[key]) == pytest.approx(expected, rel=1e-2), key
    for s in (s1, s20, auto):
        assert np.abs(s["momentum_total_z"] - s["momentum_total_z"][0]).max() < 1e-12 * p0


def test_the_fe_safety_factor_steps_the_fe_at_its_fraction_of_the_exact_limit(tmp_path):
    """time.fe_safety_factor = 0.8 in a coupled run (the soft plate in the displacement form):
    the FE's step is 0.8 × 2/ω_max of the plate (ExplicitSolid.refine_critical_step on the same
    mesh), n DEM steps to it, and the grains still hand the plate their momentum."""
    from mpi4py import MPI

    from cosim.apps import fe as fe_app
    from cosim.case import load_case
    case = ROOT / "runs" / "coupled_soft_plate_subcycling.toml"
    sets = ['fe.formulation="displacement"', "time.fe_safety_factor=0.8", "time.duration=0.004"]
    series, out = run(case, tmp_path / "exact", *[a for s in sets for a in ("--set", s)])
    solid = fe_app.build_solid(load_case(case, sets)[0], case, MPI.COMM_SELF)
    limit = solid.refine_critical_step()
    fe_dt = float(out.split("FE dt = ")[1].split(" s")[0])
    n = int(out.split(" DEM steps per FE step")[0].rsplit("(", 1)[1])
    dem_dt = float(out.split("DEM dt = ")[1].split(" s")[0])
    assert fe_dt <= 0.8 * limit * (1 + 1e-3) and fe_dt == pytest.approx(n * dem_dt, rel=1e-3)  # printed to 4 digits
    assert (n + 1) * dem_dt > 0.8 * limit                 # as many DEM steps as the limit allows
    assert series["momentum_fe_z"][-1] > 0.0
