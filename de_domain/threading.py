"""Numba threading set-up of de_domain, applied when the package is imported.

* Threading layer: ``omp`` (GNU libgomp) when Numba has it, else Numba's own
  ``workqueue``. Debian's numba 0.56 ships no ``tbbpool`` (installing python3-tbb
  does not add one), so ``tbb`` is not an option here.
* libgomp waiting: ``GOMP_SPINCOUNT`` (how long an idle worker spins before it
  sleeps on a futex) defaults to ``SPINCOUNT`` below. A step has two parallel
  regions a few µs apart, so a short spin bridges the serial gap between them;
  the libgomp default (300,000 spins, or endless with OMP_WAIT_POLICY=ACTIVE)
  burns a core that a loaded 2-core machine needs: measured 20-100x slowdowns of a
  2-thread run on a machine with load average 5.
* No thread pinning is set: on a shared 2-core machine pinning stops the kernel
  from moving a thread to the core that is free.

Each setting is only a default: a variable already in the environment wins
(``NUMBA_THREADING_LAYER``, ``OMP_WAIT_POLICY``, ``GOMP_SPINCOUNT``,
``OMP_PROC_BIND``). libgomp reads its variables when it is loaded, i.e. at the
first parallel launch, so :func:`configure` must run before that (it is called
from ``de_domain/__init__.py``).
"""
import os

SPINCOUNT = "10000"
_configured = {}


def configure():
    import numba

    if "NUMBA_THREADING_LAYER" not in os.environ:
        try:
            from numba.np.ufunc import omppool  # noqa: F401
            numba.config.THREADING_LAYER = "omp"
        except ImportError:
            numba.config.THREADING_LAYER = "workqueue"
    if "OMP_WAIT_POLICY" not in os.environ:
        os.environ.setdefault("GOMP_SPINCOUNT", SPINCOUNT)
    _configured.update(layer=numba.config.THREADING_LAYER, spincount=os.environ.get("GOMP_SPINCOUNT"))


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
