"""Each script in ``examples/`` runs to the end and prints the line its docstring promises.

The scripts check their own physics (a resumed run bit-identical to the uninterrupted
one; the servo holding σ_n; momentum conserved across the FE–DE interface) and fail with
an AssertionError otherwise, so exit 0 plus the promised last line is the whole test.
"""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).parents[2] / "examples"

# script → regular expression its last printed line must match
LAST_LINE = {
    "dem_scene.py": r"resumed run bit-identical: True",
    "direct_shear_steps.py": r"servo held sigma_n within \d+\.\d % of 100 kPa",
    "coupled_without_toml.py": r"momentum conserved to [0-9.e+-]+ relative",
}


def test_every_example_is_listed():
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == sorted(LAST_LINE)


@pytest.mark.parametrize("script", sorted(LAST_LINE))
def test_example_runs(script, tmp_path):
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    done = subprocess.run([sys.executable, str(EXAMPLES / script), str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    last = done.stdout.strip().splitlines()[-1]
    assert re.fullmatch(LAST_LINE[script], last), last
    assert any((tmp_path / "out").iterdir())
