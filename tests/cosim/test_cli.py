"""The ``cosim`` console entry point, exercised through subprocesses as a user would."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
DEMO = ROOT / "runs" / "demo_dem_settling.toml"
MPI_ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_rmaps_base_oversubscribe": "1"}


def cosim(*args, mpi=0):
    cmd = [str(COSIM), *args]
    if mpi:
        cmd = ["mpirun", "-n", str(mpi), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=MPI_ENV, cwd=ROOT, timeout=300)


@pytest.mark.parametrize("command", [[], ["run"], ["check"], ["info"], ["schema"]])
def test_help_on_every_command(command):
    res = cosim(*command, "--help")
    assert res.returncode == 0
    assert res.stdout.startswith("usage: cosim")


def test_info_reports_the_stack():
    res = cosim("info")
    assert res.returncode == 0, res.stderr
    for name in ("dolfinx", "numba", "mpi4py", "petsc4py", "gmsh", "meshio", "mpi_size", "numba_threads"):
        assert name in res.stdout
    assert "0.5.2" in res.stdout  # DOLFINx from Debian


def test_every_shipped_case_passes_check():
    """A user's first command on a shipped case (runs/*.toml: cases and calibration files) is
    not refused; cosim check also meshes the coupled ones."""
    from cosim.cli import main
    cases = sorted((ROOT / "runs").glob("*.toml"))
    assert len(cases) >= 15
    refused = [case.name for case in cases if main(["check", str(case)]) != 0]
    assert refused == []


def test_check_exit_codes():
    assert cosim("check", str(DEMO)).returncode == 0
    bad = cosim("check", str(DEMO), "--set", "dem.materials=3")
    assert bad.returncode == 2
    assert "key 'dem.materials' = 3" in bad.stderr


def test_unknown_command_is_a_usage_error():
    assert cosim("frobnicate").returncode == 2


def test_only_rank_zero_prints_under_mpirun():
    res = cosim("info", mpi=2)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("dolfinx") == 1
    assert "mpi_size   2" in res.stdout
    bad = cosim("check", str(DEMO), "--set", "time.dt=-1", mpi=2)
    assert bad.returncode == 2
    assert bad.stderr.count("key 'time.dt'") == 1


def test_schema_lists_units():
    res = cosim("schema")
    assert res.returncode == 0
    assert "dem.materials.density" in res.stdout and "[kg/m^3]" in res.stdout


@pytest.mark.parametrize("case, folder", [("direct_shear_small.toml", "direct_shear_series"),
                                          ("triaxial_small.toml", "triaxial_series")])
def test_a_series_goes_to_a_folder_named_by_its_kind_unless_told(case, folder):
    """Validation only (no run): the jobs of a series land under runs/out/<kind>_series."""
    from cosim.cli import _parser, _series_jobs
    jobs, out_root = _series_jobs(_parser().parse_args(["series", str(ROOT / "runs" / case), "--stresses", "5e4"]))
    assert out_root == Path("runs/out") / folder
    assert all(prepared.out_dir.is_relative_to(out_root) for _, _, prepared in jobs)
    _, told = _series_jobs(_parser().parse_args(["series", str(ROOT / "runs" / case), "--out", "elsewhere"]))
    assert told == Path("elsewhere")
