"""``cosim elastic`` (cosim/lab/elastic.py, docs/design.md §7.2): the elastic constants of a
packing from a constrained axial increment."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.lab.elastic import constants

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
CASE = ROOT / "runs" / "footing_small.toml"
ENV = {**os.environ, "NUMBA_NUM_THREADS": "1"}


@pytest.mark.parametrize("E, nu", [(1.0e6, 0.2), (3.0e7, 0.35), (5.0e5, 0.0)])
def test_the_constants_of_an_isotropic_solid_are_recovered(E, nu):
    """An isotropic solid under a constrained axial strain ε: Δσ_zz = M ε, Δσ_xx = Δσ_yy = λ ε
    with M = E(1 − ν)/((1 + ν)(1 − 2ν)), λ = Eν/((1 + ν)(1 − 2ν)); constants() inverts it."""
    strain = 2e-5
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    c = constants([lam * strain, lam * strain, M * strain], strain)
    assert c["young_E"] == pytest.approx(E, rel=1e-12)
    assert c["poisson_nu"] == pytest.approx(nu, abs=1e-12)
    assert c["shear_modulus_G"] == pytest.approx(E / (2 * (1 + nu)), rel=1e-12)


def cosim(*args):
    return subprocess.run([str(COSIM), *args], capture_output=True, text=True, timeout=900, env=ENV, cwd=ROOT)


def test_a_small_cube_gives_a_positive_modulus_and_a_poisson_ratio_below_one_half(tmp_path):
    res = cosim("elastic", str(CASE), "--stress", "2e3", "--size", "0.02", "--out", str(tmp_path / "e"))
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    out = json.loads((tmp_path / "e" / "elastic.json").read_text())
    assert all(abs(s - 2e3) < 0.01 * 2e3 for s in out["stress_compressed_Pa"])  # the servo reached p within 1 %
    assert out["young_E"] > 0 and 0 < out["poisson_nu"] < 0.5
    assert out["constrained_modulus_M"] > out["lame_lambda"] > 0
    assert "[soil]" in res.stdout and "E = " in res.stdout


@pytest.mark.parametrize("args, key", [
    (["--stress", "-1"], "--stress"),
    (["--stress", "2e3", "--strain", "0.1"], "--strain"),
    (["--stress", "2e3", "--size", "0"], "--size"),
])
def test_bad_arguments_are_one_message_and_exit_2(args, key, tmp_path):
    res = cosim("elastic", str(CASE), *args, "--out", str(tmp_path / "e"))
    assert res.returncode == 2 and res.stderr.count("cosim: error:") == 1 and key in res.stderr


def test_a_case_without_grains_to_generate_is_refused(tmp_path):
    res = cosim("elastic", str(ROOT / "runs" / "fe_footing.toml"), "--stress", "2e3", "--out", str(tmp_path / "e"))
    assert res.returncode == 2 and "direct_shear' or 'footing'" in res.stderr
