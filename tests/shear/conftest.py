"""The dense mini direct shear run (e = 0.70, shearing friction 0.05), made once per session:
the run's own checks (test_direct_shear_run.py) read it, and the resume test takes it as the
uninterrupted reference."""
import pytest


@pytest.fixture(scope="session")
def mini_dense_run(tmp_path_factory):
    """(summary, series, output folder) of the run; its case file is ``mini_dense.toml`` beside the folder."""
    from test_direct_shear_run import _run
    return _run(tmp_path_factory, "mini_dense", 0.70, 0.05)
