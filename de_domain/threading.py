"""Numba threading set-up of de_domain (placeholder, filled in below)."""
import os


def describe():
    import numba
    try:
        layer = numba.threading_layer()
    except ValueError:
        layer = "not yet chosen"
    return (f"layer={layer} (config {numba.config.THREADING_LAYER}), max threads={numba.config.NUMBA_NUM_THREADS}, "
            f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', '-')}")
