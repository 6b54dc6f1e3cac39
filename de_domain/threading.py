"""Numba threading set-up of de_domain, applied when the package is imported.

* Threading layer: ``omp`` (GNU libgomp) when Numba has it, else Numba's own
  ``workqueue``. Debian's numba 0.56 ships no ``tbbpool`` (installing python3-tbb
  does not add one), so ``tbb`` is not an option here.
* libgomp waiting, between the two parallel regions of every DEM step:
  - the threads of this process fit the cores it may use (Numba threads × MPI ranks
    on this node ≤ CPUs in its affinity mask): ``GOMP_SPINCOUNT=30000``, i.e. an idle
    worker spins briefly (about a millisecond) before it sleeps, so it is awake when
    the next region starts. On the W1 bed, 2 threads, an idle 2-core machine: +36 %
    at 5,000 spheres, +7 % at 20,000 against sleeping at once;
  - more threads than cores (e.g. ``mpirun -n 2`` with 2 threads each on 2 cores):
    ``OMP_WAIT_POLICY=PASSIVE`` (an idle worker sleeps on a futex at once). Spinning
    there takes the core from a thread that has work: two 2-thread processes on 2
    cores ran 33 % slower each with spinning, and at load average 5 from other jobs
    2-thread runs were 3-20× slower.
  Other jobs on the machine cannot be seen at import: on a shared machine set
  ``OMP_WAIT_POLICY=PASSIVE`` yourself.
* No thread pinning is set: on a shared machine pinning stops the kernel from
  moving a thread to the core that is free.

Each setting is only a default: a variable already in the environment wins
(``NUMBA_THREADING_LAYER``, ``OMP_WAIT_POLICY``, ``GOMP_SPINCOUNT``,
``OMP_PROC_BIND``). libgomp reads its variables when it is loaded, i.e. at the
first parallel launch, so :func:`configure` must run before that (it is called
from ``de_domain/__init__.py``).
"""
import os

SPIN_COUNT = "30000"
WAIT_POLICY = "PASSIVE"
LOCAL_RANK_VARIABLES = ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "PMI_LOCAL_SIZE")


def threads_fit_cores(threads, environ=os.environ):
    """Numba threads × MPI ranks on this node ≤ the CPUs this process may run on."""
    ranks = next((int(environ[k]) for k in LOCAL_RANK_VARIABLES if environ.get(k, "").isdigit()), 1)
    return threads * ranks <= len(os.sched_getaffinity(0))


def configure():
    import importlib.util

    import numba

    # libgomp reads its variables when it is loaded: set them first, and only look
    # for (never import) Numba's omppool here.
    if "GOMP_SPINCOUNT" not in os.environ and "OMP_WAIT_POLICY" not in os.environ:
        if threads_fit_cores(numba.config.NUMBA_NUM_THREADS):
            os.environ["GOMP_SPINCOUNT"] = SPIN_COUNT
        else:
            os.environ["OMP_WAIT_POLICY"] = WAIT_POLICY
    if "NUMBA_THREADING_LAYER" not in os.environ:
        has_omp = importlib.util.find_spec("numba.np.ufunc.omppool") is not None
        numba.config.THREADING_LAYER = "omp" if has_omp else "workqueue"


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
