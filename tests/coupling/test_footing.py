"""Strip footing on a DEM zone embedded in an FE soil block, and its all-DEM reference, both
from one case description (cosim/apps/footing.py, a preset of the embedded kind; docs/design.md §7).

A tiny version of runs/footing_small.toml: a 21 x 12 mm zone (~150 grains of 2-3 mm) in a
45 x 24 mm block, 9 mm thick, a 7 mm footing pushed 0.7 mm.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.lab.shear_report import read_series

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
CASE = ROOT / "runs" / "footing_small.toml"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1", "NUMBA_NUM_THREADS": "1"}
TINY = {"soil.width": 0.045, "soil.depth": 0.024, "soil.thickness": 0.009, "soil.mesh_size": 0.01,
        "soil.interface_mesh_size": 0.005, "zone.width": 0.021, "zone.depth": 0.012, "footing.width": 0.007,
        "footing.velocity": 0.05, "footing.rows": 10}
X0, ZB = 0.012, 0.012   # the zone's left side and bottom in the tiny block


def overrides(extra=None, generated=True):
    """--set options of the tiny case (without the generation's keys for a packing file)."""
    out = []
    for key, value in {**TINY, **(extra or {})}.items():
        if generated or not key.startswith("specimen."):
            out += ["--set", f"{key}={json.dumps(value)}"]
    return out


def cosim(*args, mpi=0, timeout=900):
    cmd = [str(COSIM), *args]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), "--bind-to", "none", *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=ENV, cwd=ROOT)


def set_options(values):
    """``--set key=value`` options of a dict of case keys (values written as JSON, which TOML reads alike)."""
    return [arg for key, value in values.items() for arg in ("--set", f"{key}={json.dumps(value)}")]


def run_ok(*args, mpi=0):
    """``cosim ARGS`` that must succeed (the tails of its output when it does not)."""
    res = cosim(*args, mpi=mpi)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return res


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The coupled model, then the all-DEM one, of the tiny case, in one case folder."""
    out = tmp_path_factory.mktemp("footing") / "tiny"
    for model in ("coupled", "dem"):
        res = cosim("run", str(CASE), "--out", str(out), *overrides({"footing.model": model}))
        assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return out


def test_the_coupled_zone_comes_to_rest_with_the_fe_carrying_the_grains_weight(runs):
    rest = json.loads((runs / "coupled" / "summary.json").read_text())["rest"]
    assert rest["at_rest"] and rest["unbalanced_force_ratio"] < 1e-3
    assert abs(rest["interface_force_over_weight"] - 1.0) < 0.01


def test_the_loaded_footing_bears_on_the_grains_and_the_interface_carries_it(runs):
    s = read_series(runs / "coupled" / "load_settlement.csv")
    assert s["settlement_ratio"][-1] == pytest.approx(0.1, rel=0.02)
    assert s["bearing_pressure"][-1] > 0 and np.all(s["footing_force_z"] >= 0)
    # momentum balance of the zone over the loading: the rows are impulses over equal intervals, so
    # sum(interface force) = -sum(grain weight + footing force) + the grains' momentum at the end
    # (they were at rest at the start; the part under the footing moves with it: ~2 % here)
    assert _momentum_balance_ratio(runs / "coupled") == pytest.approx(1.0, abs=0.05)
    for name in ("load_settlement.png", "displacement_section.png", "fields.xdmf", "particles.pvd", "rest.csv",
                 "series.csv"):
        assert (runs / "coupled" / name).exists(), name


def test_no_grain_leaves_the_zone_through_the_interface(runs):
    with np.load(runs / "coupled" / "final_packing.npz") as data:
        pos, radii = data["positions"], data["radii"]
    slack = 0.5 * radii  # elastic overlap with the interface facets is a small fraction of r
    assert np.all(pos[:, 0] - radii > X0 - slack) and np.all(pos[:, 0] + radii < X0 + 0.021 + slack)
    assert np.all(pos[:, 2] - radii > ZB - slack)
    assert np.all((pos[:, 1] - radii > -slack) & (pos[:, 1] + radii < 0.009 + slack))


def test_both_models_from_one_case_and_their_comparison(runs):
    coupled = json.loads((runs / "coupled" / "summary.json").read_text())
    dem = json.loads((runs / "dem" / "summary.json").read_text())
    assert coupled["model"] == "coupled" and dem["model"] == "dem"
    assert dem["grains"] > 3 * coupled["grains"]          # the block is all grains in the reference
    assert dem["rest"]["at_rest"]
    lines = (runs / "comparison.csv").read_text().splitlines()
    assert lines[0].startswith("settlement_ratio") and len([ln for ln in lines if ln[0].isdigit()]) == 3
    assert any(ln.startswith("mean_0.01-0.1,") for ln in lines)
    assert (runs / "comparison.png").exists()


def test_both_models_are_seated_alike_and_report_their_wall_clock_without_compilation(runs):
    """The settlement counts from the seating load in both models (runs/footing_small.toml: 300 Pa);
    the compilation inside a run's wall-clock is reported beside it, never more than it."""
    for model in ("coupled", "dem"):
        summary = json.loads((runs / model / "summary.json").read_text())
        assert summary["seating"]["pressure_Pa"] >= 300.0 and summary["seating"]["travel_m"] >= 0.0
        wall = summary["wall_clock_s"]
        assert 0.0 <= wall["compilation_s"] <= wall["total_s"]
        assert wall["total_without_compilation_s"] == pytest.approx(wall["total_s"] - wall["compilation_s"])
        assert summary["fill"]["void_ratio_bulk"] < summary["fill"]["void_ratio"]  # looser at the walls


def test_the_displacement_section_has_the_fe_soil_of_the_coupled_model(runs):
    """loading_start.npz keeps every FE node's displacement at the loading's start (for the
    picture's Δu, also after a resume): one row per node, moved by the rest phase."""
    with np.load(runs / "coupled" / "loading_start.npz") as start:
        u0 = start["fe_displacement"]
    fields = (runs / "coupled" / "fields.xdmf").read_text()
    assert f'Dimensions="{u0.shape[0]} 3"' in fields  # as many nodes as the FE field output
    assert np.all(np.isfinite(u0)) and np.abs(u0).max() > 0.0  # the soil settled under the grains
    with np.load(runs / "dem" / "loading_start.npz") as start:
        assert "fe_displacement" not in start.files
    assert (runs / "coupled" / "displacement_section.png").exists()


@pytest.fixture(scope="module")
def two_ranks(runs, tmp_path_factory):
    """The coupled tiny case under mpirun -n 2, from the 1-rank run's specimen: (case file, outputs)."""
    folder = tmp_path_factory.mktemp("two_ranks")
    case = _file_case(folder, runs / "coupled" / "specimen.npz")
    res = cosim("run", str(case), "--out", str(folder / "out"), *overrides(generated=False), mpi=2)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert res.stdout.count("outputs: ") == 1
    return case, folder / "out"


def _momentum_balance_ratio(folder):
    """Σ interface force / −Σ (grain weight + footing force) over the loading's rows (equal
    intervals): 1 + the grains' momentum at the end (test above: ~2 %)."""
    s = read_series(folder / "load_settlement.csv")
    rest = json.loads((folder / "summary.json").read_text())["rest"]
    assert np.ptp(np.diff(s["time"])) < 1e-9
    return np.sum(s["interface_force_z"]) / -(len(s["time"]) * rest["grain_weight_N"] + np.sum(s["footing_force_z"]))


def test_two_ranks_run_the_same_model_bit_for_bit(two_ranks, tmp_path):
    """The coupled tiny case under mpirun -n 2 (the DEM over both ranks, the FE soil on each:
    ``soil.fe_partition = "replicated"``, the default) and on one rank, from the same packing
    file: the same rows, grains and FE state, to the last bit. (With the FE soil partitioned the
    FE's sums follow the partition, and a loaded packing amplifies any last-bit difference:
    1-rank runs whose E differs in the 15th digit part by up to ±50 % after the peak.)"""
    case, two_out = two_ranks
    res = cosim("run", str(case), "--out", str(tmp_path / "one"), *overrides(generated=False))
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    one, two = tmp_path / "one" / "coupled", two_out / "coupled"
    assert json.loads((two / "summary.json").read_text())["ranks"] == 2
    assert (two / "series.csv").read_text() == (one / "series.csv").read_text()
    for name in ("loading_start.npz", "final_packing.npz"):  # grains (and FE soil) at rest, grains at the end
        with np.load(one / name) as a, np.load(two / name) as b:
            assert a.files == b.files
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}: {key}")


def test_the_trench_interface_is_closed_and_the_fe_lies_behind_it():
    """The preset's model (meshes/strip_footing.geo): the interface found from the cells tiles the
    trench's bottom and two sides exactly; its free edges are on the open top or the slice's
    faces; each facet faces the grains (the FE on its far side); no sliver elements (the FE step
    is set by the element size)."""
    from mpi4py import MPI

    from cosim.apps import embedded, embedded_model
    from cosim.apps.footing import Geometry, as_embedded
    from cosim.case import load_case
    from fe_domain.zone_model import split_model
    case, _ = load_case(CASE, [f"{k}={json.dumps(v)}" for k, v in TINY.items()])
    g = Geometry.of(case)
    em = as_embedded(case).embedded
    split = split_model(embedded.mesh_file(as_embedded(case), CASE), em.mesh_size, em.parameters, ["zone"], ["soil"],
                        MPI.COMM_SELF)
    a, b, c = (split.zone.interface[:, k] for k in range(3))
    normal = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(normal, axis=1)
    assert area.sum() == pytest.approx((g.zone_width + 2 * g.zone_depth) * g.thickness, rel=1e-12)
    corners = split.zone.interface.reshape(-1, 3)
    x1 = g.zone_x0 + g.zone_width
    assert np.all(np.isclose(corners[:, 0], g.zone_x0) | np.isclose(corners[:, 0], x1)
                  | np.isclose(corners[:, 2], g.zone_bottom))
    v, tri = np.unique(corners, axis=0, return_inverse=True)
    tri = tri.reshape(-1, 3)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    ends = v[unique[count == 1].ravel()]
    assert np.all(np.isclose(ends[:, 1], 0) | np.isclose(ends[:, 1], g.thickness) | np.isclose(ends[:, 2], g.depth))

    def in_cavity(p):
        return (p[:, 0] > g.zone_x0) & (p[:, 0] < x1) & (p[:, 2] > g.zone_bottom)

    centre = (a + b + c) / 3
    unit = normal / np.linalg.norm(normal, axis=1)[:, None]
    eps = 1e-4
    assert np.all(in_cavity(centre + eps * unit)) and not np.any(in_cavity(centre - eps * unit))
    solid = embedded_model.build_fe(as_embedded(case), split, embedded_model.Roles.of(em), 1500.0)
    assert solid.h_cells.min() > 0.2 * case.soil.interface_mesh_size  # smallest altitude of a tetrahedron


@pytest.mark.parametrize("extra, key", [
    ({"zone.depth": 0.006}, "zone.depth"),                 # shallower than 3 of the largest grains
    ({"footing.width": 0.03}, "footing.width"),            # wider than the zone
    ({"zone.width": 0.05}, "zone.width"),                  # the zone is not inside the block
    ({"soil.interface_mesh_size": 0.02}, "soil.interface_mesh_size"),
    ({"footing.settlement": 0.5, "footing.width": 0.02, "zone.depth": 0.009}, "footing.settlement"),
    ({"specimen.source": "file", "specimen.file": "packings/sand_bed_30mm.npz"}, "specimen.file"),  # does not fit
])
def test_bad_footing_input_is_one_message_and_exit_2(extra, key, tmp_path):
    if "specimen.source" in extra:
        extra = {**extra, "specimen.file": str(ROOT / "runs" / "packings" / "sand_bed_30mm.npz")}
        if not Path(extra["specimen.file"]).exists():
            pytest.skip("the 30 mm bed packing is made by runs/sand_bed_30mm.toml")
    sets = overrides(extra)
    if "specimen.source" in extra:  # a file source takes no generation keys
        res = cosim("check", str(_file_case(tmp_path, extra["specimen.file"])), *overrides(generated=False))
    else:
        res = cosim("check", str(CASE), *sets)
    assert res.returncode == 2, res.stdout + res.stderr
    assert res.stderr.count("cosim: error:") == 1 and key in res.stderr


def _file_case(tmp_path, packing):
    """runs/footing_small.toml with its [specimen] replaced by a packing file."""
    text = CASE.read_text()
    head, rest = text.split("[specimen]", 1)
    tail = rest[rest.index("[footing]"):]
    path = tmp_path / "file_case.toml"
    path.write_text(head + f'[specimen]\nsource = "file"\nfile = "{packing}"\n\n' + tail)
    return path


def test_resume_without_a_checkpoint_is_one_message(tmp_path):
    res = cosim("run", str(CASE), "--resume", "--out", str(tmp_path / "x"), *overrides())
    assert res.returncode == 2 and "no checkpoint of the loading" in res.stderr


def kill_during_loading(args, out, mpi=0, state="embedded_state.json"):
    """Start ``cosim run ARGS`` (under mpirun -n MPI if given) and SIGKILL it, every rank, once
    the loading has checkpointed (its ``state`` file written) and written a few rows."""
    import signal
    import time
    cmd = [str(COSIM), "run", *args]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), "--bind-to", "none", *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV, cwd=ROOT,
                            start_new_session=True)  # its own session: mpirun and its ranks
    series = out / "coupled" / "series.csv"
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:
        if (out / "coupled" / state).exists() and series.exists() and \
                len(series.read_text().splitlines()) > 4:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed"
    # every process of the session: OpenMPI puts each rank in a process group of its own, and
    # a rank that outlived mpirun would go on writing into the folder the resumed run uses
    while members := session_members(proc.pid):
        for pid in members:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.05)
    proc.wait()
    assert not (out / "coupled" / "summary.json").exists()


def session_members(sid):
    """Process ids of the live processes of session ``sid`` (from /proc/<pid>/stat)."""
    members = []
    for entry in os.listdir("/proc"):
        try:
            fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if entry.isdigit() and int(fields[3]) == sid and fields[0] != "Z":
            members.append(int(entry))
    return members


def assert_resumed_to(reference, res, out):
    """The resumed run wrote the uninterrupted run's rows and answer, to the last digit."""
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "resumed the loading at row" in res.stdout
    assert (out / "coupled" / "series.csv").read_text() == (reference / "coupled" / "series.csv").read_text()
    summary = json.loads((out / "coupled" / "summary.json").read_text())
    assert summary["bearing_pressure_at"] == json.loads((reference / "coupled" / "summary.json").read_text())[
        "bearing_pressure_at"]


def test_a_killed_coupled_loading_resumes_to_the_same_rows(runs, tmp_path):
    """The coupled tiny case, killed during the loading (a checkpoint after every row), resumes
    from its DEM and FE checkpoints to the rows of the uninterrupted run, to the last digit."""
    out = tmp_path / "split"
    sets = overrides({"footing.model": "coupled"}) + ["--set", "output.checkpoint_interval=0.05"]
    kill_during_loading([str(CASE), "--out", str(out), *sets], out)
    assert_resumed_to(runs, cosim("run", str(CASE), "--out", str(out), *sets, "--resume"), out)


@pytest.mark.slow  # the 1-rank kill and resume: test_a_killed_coupled_loading_resumes_to_the_same_rows
def test_a_killed_two_rank_loading_resumes_to_the_same_rows(two_ranks, tmp_path):
    """The same under mpirun -n 2 (DEM over both ranks, the FE soil on each), killed and
    resumed on 2 ranks: the rows of the uninterrupted 2-rank run, to the last digit."""
    case, reference = two_ranks
    out = tmp_path / "split"
    sets = overrides(generated=False) + ["--set", "output.checkpoint_interval=0.05"]
    kill_during_loading([str(case), "--out", str(out), *sets], out, mpi=2)
    assert_resumed_to(reference, cosim("run", str(case), "--out", str(out), *sets, "--resume", mpi=2), out)
