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
  - other jobs already using the cores (1-minute load average + our threads × ranks
    > CPUs + 0.5): ``OMP_WAIT_POLICY=PASSIVE`` as well; on a loaded machine spinning
    workers took three times the idle CPU time. The load is read once, at import, so a
    job that starts later is not seen; :data:`CHOICE` says which policy was taken and
    why (the run info of every case records it).
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


#: the libgomp wait policy :func:`configure` chose, and why (one line)
CHOICE = "not configured"


def local_ranks(environ=os.environ):
    """MPI ranks on this node (1 outside mpirun)."""
    return next((int(environ[k]) for k in LOCAL_RANK_VARIABLES if environ.get(k, "").isdigit()), 1)


def threads_fit_cores(threads, environ=os.environ):
    """Numba threads × MPI ranks on this node ≤ the CPUs this process may run on."""
    return threads * local_ranks(environ) <= len(os.sched_getaffinity(0))


def wait_policy(threads, load, cpus, ranks=1):
    """("spin" or "passive", reason): spin only when our threads × ranks fit the CPUs that
    the load average ``load`` of other work leaves free."""
    ours = threads * ranks
    if ours > cpus:
        return "passive", f"{threads} threads x {ranks} ranks > {cpus} CPUs"
    if load + ours > cpus + 0.5:
        return "passive", f"load average {load:.2f} + {ours} threads > {cpus} CPUs: other jobs are running"
    return "spin", f"{threads} threads x {ranks} ranks fit {cpus} CPUs at load average {load:.2f}"


def configure():
    import importlib.util

    import numba

    # libgomp reads its variables when it is loaded: set them first, and only look
    # for (never import) Numba's omppool here.
    global CHOICE
    given = [k for k in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY") if k in os.environ]
    if given:
        CHOICE = "set in the environment: " + ", ".join(f"{k}={os.environ[k]}" for k in given)
    else:
        policy, reason = wait_policy(numba.config.NUMBA_NUM_THREADS, os.getloadavg()[0],
                                     len(os.sched_getaffinity(0)), local_ranks())
        if policy == "spin":
            os.environ["GOMP_SPINCOUNT"] = SPIN_COUNT
            CHOICE = f"GOMP_SPINCOUNT={SPIN_COUNT} (spin briefly): {reason}"
        else:
            os.environ["OMP_WAIT_POLICY"] = WAIT_POLICY
            CHOICE = f"OMP_WAIT_POLICY={WAIT_POLICY} (sleep at once): {reason}"
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
