import pytest
from dem_scenes import box_gas


@pytest.fixture
def make_gas():
    return box_gas


@pytest.fixture(autouse=True)
def single_numba_thread():
    """Run each test on one Numba thread: on shared 2-core CI machines a parallel
    region costs ~1 ms of scheduling per launch. Thread-count invariance is tested
    explicitly (test_determinism_restart.py), which sets its own counts."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)
