"""The triaxial test with its DEM spread over MPI ranks: the specimen generation, the
consolidation and the compression run on all ranks; the specimen and the CSV rows (wall
forces summed over the ranks in the serial order) are bit-identical to one rank."""
import csv
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1", "NUMBA_NUM_THREADS": "1"}
EXACT = ("time", "axial_strain", "volumetric_strain", "sigma_1", "sigma_x", "sigma_y", "void_ratio", "step")


def compress(case, out, ranks):
    cmd = [str(COSIM), "run", str(case), "--out", str(out)]
    if ranks > 1:
        cmd = ["mpirun", "--bind-to", "none", "-n", str(ranks), *cmd]
    done = subprocess.run(cmd, capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    with open(out / "series.csv") as f:
        rows = list(csv.DictReader(f))
    return {k: [r[k] for r in rows] for k in rows[0]}, done.stdout


def _module(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "tests" / "triaxial" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(ROOT / "tests" / "triaxial"))
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow  # a lab test under mpirun, bit for bit: tests/shear/test_direct_shear_mpi.py
@pytest.mark.parametrize("grains", ["spheres", "clumps"])
def test_two_ranks_compress_the_one_rank_specimen_bit_for_bit(tmp_path, grains):
    """Spheres, and two-sphere grains (radius expansion; clumps straddle the ranks' slabs)."""
    module = _module("test_triaxial")
    case = tmp_path / "tx.toml"
    if grains == "spheres":
        case.write_text(module.MINI.format(name="tx_ranks", specimen=module.DENSE, strain=0.02))
    else:
        clumped = _module("test_triaxial_clumps")
        case.write_text(module.MINI.format(name="tx_ranks", specimen=clumped.SPECIMEN, strain=0.02) + "\n"
                        + clumped.ROD)
    one, _ = compress(case, tmp_path / "one", 1)
    two, out = compress(case, tmp_path / "two", 2)
    assert "DEM on 2 MPI ranks" in out
    names = ("positions", "radii") + (("clump_centres", "clump_orientations") if grains == "clumps" else ())
    for name in names:
        with np.load(tmp_path / "one" / "specimen.npz") as a, np.load(tmp_path / "two" / "specimen.npz") as b:
            assert np.array_equal(a[name], b[name]), name
    for key in EXACT:
        assert one[key] == two[key], key
    np.testing.assert_allclose(np.array(two["coordination_number"], float), np.array(one["coordination_number"], float),
                               rtol=1e-9)
    assert len(one["step"]) >= 10
