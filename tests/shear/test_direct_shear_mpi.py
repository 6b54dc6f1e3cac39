"""The direct shear test with its DEM spread over MPI ranks: the specimen is made on
rank 0, the consolidation and the shear run on all ranks, and the measured curves
(from the plate and box forces, summed over the ranks in the serial order) are
bit-identical to the one-rank run at every row."""
import csv
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1", "NUMBA_NUM_THREADS": "1"}
EXACT = ("time", "shear_displacement", "shear_stress", "normal_stress", "vertical_displacement", "void_ratio",
         "shear_stress_lower", "shear_velocity", "step")


def mini_case(tmp_path):
    spec = importlib.util.spec_from_file_location("mini", ROOT / "tests" / "shear" / "test_direct_shear_run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    path = tmp_path / "mini.toml"
    path.write_text(module.MINI.format(name="mini_shear_ranks", e=0.70, mu=0.3))
    return path


def shear(case, out, ranks):
    cmd = [str(COSIM), "run", str(case), "--out", str(out), "--set", "direct_shear.shear_distance=3e-4",
           "--set", "direct_shear.ramp_distance=5e-5", "--set", "direct_shear.rows=10"]
    if ranks > 1:
        cmd = ["mpirun", "--bind-to", "none", "-n", str(ranks), *cmd]
    done = subprocess.run(cmd, capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    with open(out / "series.csv") as f:
        rows = list(csv.DictReader(f))
    return {k: [r[k] for r in rows] for k in rows[0]}, done.stdout


def test_two_ranks_shear_the_one_rank_specimen_bit_for_bit(tmp_path):
    case = mini_case(tmp_path)
    one, _ = shear(case, tmp_path / "one", 1)
    two, out = shear(case, tmp_path / "two", 2)
    assert "DEM on 2 MPI ranks" in out
    for key in EXACT:  # the CSV's digits of quantities summed in the serial order: identical
        assert one[key] == two[key], key
    for key in ("void_ratio_sphere_045h", "lw_normal_stress", "unbalanced_force_ratio", "coordination_number"):
        # summed over ranks in rank order: the same to round-off
        np.testing.assert_allclose(np.array(two[key], float), np.array(one[key], float), rtol=1e-9, err_msg=key)
    assert len(one["step"]) >= 10 and float(one["shear_stress"][-1]) > 0.0
