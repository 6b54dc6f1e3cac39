"""de_domain.threading: idle workers spin only when the threads fit the cores."""
import os

from de_domain import threading as dthreading


def test_threads_fit_cores_counts_mpi_ranks_on_the_node():
    cores = len(os.sched_getaffinity(0))
    assert dthreading.threads_fit_cores(cores, environ={})
    assert not dthreading.threads_fit_cores(cores + 1, environ={})
    assert not dthreading.threads_fit_cores(cores, environ={"OMPI_COMM_WORLD_LOCAL_SIZE": "2"})
    assert dthreading.threads_fit_cores(1, environ={"MPI_LOCALNRANKS": str(cores)})


def test_one_wait_setting_is_chosen_and_described():
    env = (os.environ.get("OMP_WAIT_POLICY"), os.environ.get("GOMP_SPINCOUNT"))
    assert env.count(None) <= 1                       # something was set before libgomp loaded
    assert any(f"{k}=" in dthreading.describe() for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT"))
