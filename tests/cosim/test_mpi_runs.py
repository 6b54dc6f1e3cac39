"""Every case kind under ``mpirun -n 2`` ends, whatever happens: a short run of each kind
exits 0; bad input exits 2 on every rank with one message; a run that diverges, or a
failure on one rank only, ends all ranks within seconds with the cause printed once.

Each command runs under a timeout far above its normal time: a hang fails the test
instead of stalling the suite. (The ``dem`` and ``coupled`` kinds distribute their DEM
over the ranks, see test_dem_distributed_case.py and tests/coupling; the direct shear
kind still runs its DEM on rank 0.)
"""
import importlib.util
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
RUNS = ROOT / "runs"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1", "NUMBA_NUM_THREADS": "1"}
TIMEOUT = 240  # s; each run below takes 5-40 s


def mpirun(*args, n=2, program=(str(COSIM),)):
    """(exit code, stdout, stderr, wall seconds) of ``mpirun -n N program args``."""
    t0 = time.perf_counter()
    done = subprocess.run(["mpirun", "-n", str(n), *program, *args], capture_output=True, text=True, env=ENV,
                          cwd=ROOT, timeout=TIMEOUT)
    return done.returncode, done.stdout, done.stderr, time.perf_counter() - t0


SHORT_RUNS = {
    "dem": [str(RUNS / "demo_dem_settling.toml"), "--set", "time.duration=0.004", "--set", "output.interval=0.002",
            "--set", "dem.particles.count=500"],
    "fe": [str(RUNS / "fe_footing.toml"), "--set", "time.duration=0.004", "--set", "output.interval=0.002"],
    "coupled": [str(RUNS / "coupled_footing_on_sand.toml"), "--set", "time.duration=0.0004",
                "--set", "output.interval=0.0002"],
}

def mini_shear():
    """The miniature direct shear case of tests/shear/test_direct_shear_run.py (~600 grains),
    sheared 0.2 mm only."""
    spec = importlib.util.spec_from_file_location("mini", ROOT / "tests" / "shear" / "test_direct_shear_run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.MINI.format(name="mini_shear_mpi", e=0.70, mu=0.3)


SHORT_SHEAR = ["--set", "direct_shear.shear_distance=2e-4", "--set", "direct_shear.ramp_distance=5e-5",
               "--set", "direct_shear.rows=10"]


@pytest.mark.slow  # each kind under mpirun, bit for bit against one rank, is in the default suite: dem in
# test_dem_distributed_case.py, fe in test_fe_case_run.py, coupled in tests/coupling, the lab tests in tests/shear
# and tests/triaxial; rank 0 alone speaking in test_cli.py
@pytest.mark.parametrize("kind", sorted(SHORT_RUNS) + ["direct_shear"])
def test_every_kind_runs_under_mpirun(kind, tmp_path):
    if kind == "direct_shear":
        case = tmp_path / "mini.toml"
        case.write_text(mini_shear())
        args = [str(case), *SHORT_SHEAR]
    else:
        args = SHORT_RUNS[kind]
    code, out, err, _ = mpirun("run", *args, "--out", str(tmp_path / "out"))
    assert code == 0, out[-3000:] + err[-3000:]
    assert out.count("outputs: ") == 1           # rank 0 speaks, once
    assert (tmp_path / "out" / "run_info.json").exists()


def test_bad_input_ends_every_rank_with_one_message(tmp_path):
    code, out, err, _ = mpirun("run", str(RUNS / "demo_dem_settling.toml"), "--set", "time.dt=1.0",
                               "--out", str(tmp_path / "out"))
    assert code == 2, out + err
    assert err.count("cosim: error:") == 1 and "critical step" in err
    assert not (tmp_path / "out").exists()


def test_fewer_particles_than_ranks_is_bad_input_on_every_rank(tmp_path):
    """A DEM that cannot be spread over the ranks: exit 2, one message naming the key."""
    code, out, err, _ = mpirun("run", str(RUNS / "demo_dem_settling.toml"), "--set", "dem.particles.count=2",
                               "--out", str(tmp_path / "out"), n=3)
    assert code == 2, out + err
    assert err.count("cosim: error:") == 1 and "dem.particles.count" in err and "3 MPI ranks" in err
    assert not (tmp_path / "out").exists()


def test_an_error_on_one_rank_ends_all_ranks(tmp_path):
    """Rank 1 alone fails before the (distributed) DEM run: MPI_Abort ends both, at once."""
    script = textwrap.dedent(f"""
        import sys
        from mpi4py import MPI
        import cosim.apps.dem as dem
        if MPI.COMM_WORLD.rank == 1:
            def broken(*args, **kwargs):
                raise OSError("disk full (a failure on rank 1 only)")
            dem.write_run_metadata = broken
        from cosim.cli import main
        sys.exit(main(["run", "{RUNS / 'demo_dem_settling.toml'}", "--set", "time.duration=10.0",
                       "--out", "{tmp_path / 'out'}"]))
        """)
    code, out, err, wall = mpirun(program=(sys.executable, "-c", script))
    assert code != 0
    assert err.count("disk full (a failure on rank 1 only)") >= 1 and "rank 1 of 2 failed" in err
    assert wall < 60            # the other rank did not run its 10 s of simulated time


@pytest.mark.parametrize("kind, sets, cause", [
    ("dem", ["--set", "dem.gravity=[0.0, 0.0, -1e300]"], "the run has diverged"),
    ("coupled", ["--set", "dem.gravity=[0.0, 0.0, -1e300]"], "the run has diverged"),
])
def test_a_diverging_run_ends_every_rank_with_its_cause(kind, sets, cause, tmp_path):
    """A body force so large that the grains' state overflows: the next neighbour build of
    the distributed DEM finds it on all ranks together (de_domain.distributed.check_finite),
    and every rank ends with exit 1, the cause printed once, within seconds, and the rows
    written so far kept."""
    out = tmp_path / "out"
    code, stdout, err, wall = mpirun("run", *SHORT_RUNS[kind], *sets, "--out", str(out))
    assert code == 1, stdout[-2000:] + err[-3000:]
    assert err.count(cause) == 1 and err.count("cosim: run failed") == 1, err
    assert "Traceback" not in err
    assert wall < 120
    assert (out / "series.csv").exists()
