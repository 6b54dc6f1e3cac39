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


def test_wait_policy_follows_the_load_of_other_jobs():
    assert dthreading.wait_policy(2, load=0.1, cpus=2)[0] == "spin"
    assert dthreading.wait_policy(2, load=1.5, cpus=2)[0] == "passive"      # another job holds a core
    assert dthreading.wait_policy(1, load=0.9, cpus=2)[0] == "spin"         # one thread, one core free
    assert dthreading.wait_policy(2, load=0.0, cpus=2, ranks=2)[0] == "passive"
    policy, reason = dthreading.wait_policy(2, load=3.0, cpus=2)
    assert "load average 3.00" in reason


def test_the_choice_is_recorded():
    assert any(k in dthreading.CHOICE for k in ("GOMP_SPINCOUNT=", "OMP_WAIT_POLICY="))
