"""Setup smoke test: the venv sees Debian's compiled stack, not a second copy from PyPI."""
import subprocess
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_stack_comes_from_debian():
    import dolfinx
    import mpi4py
    import numba
    import numpy
    import petsc4py
    for mod in (numpy, numba, mpi4py):
        assert mod.__file__.startswith("/usr/lib/python3/dist-packages/"), mod.__file__
    assert petsc4py.__file__.startswith("/usr/lib/petsc/") and dolfinx.__file__.startswith("/usr/lib/petsc/")
    assert dolfinx.__version__ == "0.5.2"


def test_setup_is_idempotent_and_quick():
    res = subprocess.run(["make", "-s", "setup"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert "installing Debian packages" not in res.stdout
