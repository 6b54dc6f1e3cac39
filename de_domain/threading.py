"""Numba threading set-up of de_domain, applied when the package is imported.

* Threading layer: ``omp`` (GNU libgomp) when Numba has it, else Numba's own
  ``workqueue``. Debian's numba 0.56 ships no ``tbbpool`` (installing python3-tbb
  does not add one), so ``tbb`` is not an option here.
* libgomp waiting: ``OMP_WAIT_POLICY=PASSIVE`` (an idle worker sleeps on a futex
  at once). Spinning (the libgomp default: 300,000 spins before sleeping, or
  endless with ACTIVE; even GOMP_SPINCOUNT=10000) burns a core that a shared
  2-core machine needs: at load average 5, 2-thread runs of the W1 bed were 3-20x
  slower with spinning than with PASSIVE; PASSIVE was on par with Numba's
  ``workqueue`` layer.
* No thread pinning is set: on a shared 2-core machine pinning stops the kernel
  from moving a thread to the core that is free.

Each setting is only a default: a variable already in the environment wins
(``NUMBA_THREADING_LAYER``, ``OMP_WAIT_POLICY``, ``GOMP_SPINCOUNT``,
``OMP_PROC_BIND``). libgomp reads its variables when it is loaded, i.e. at the
first parallel launch, so :func:`configure` must run before that (it is called
from ``de_domain/__init__.py``).
"""
import os

WAIT_POLICY = "PASSIVE"
_configured = {}


def configure():
    import importlib.util

    import numba

    # libgomp reads its variables when it is loaded: set them first, and only look
    # for (never import) Numba's omppool here.
    if "GOMP_SPINCOUNT" not in os.environ:
        os.environ.setdefault("OMP_WAIT_POLICY", WAIT_POLICY)
    if "NUMBA_THREADING_LAYER" not in os.environ:
        has_omp = importlib.util.find_spec("numba.np.ufunc.omppool") is not None
        numba.config.THREADING_LAYER = "omp" if has_omp else "workqueue"
    _configured.update(layer=numba.config.THREADING_LAYER, wait_policy=os.environ.get("OMP_WAIT_POLICY"))


def describe():
    """One line: layer in use (or configured), threads, libgomp wait settings."""
    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:
        layer = f"{numba.config.THREADING_LAYER} (not launched yet)"
    env = " ".join(f"{k}={os.environ[k]}" for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT", "OMP_PROC_BIND")
                   if k in os.environ)
    return f"layer={layer}, max threads={numba.config.NUMBA_NUM_THREADS}, {env or 'libgomp defaults'}"
