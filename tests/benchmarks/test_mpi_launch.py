"""benchmarks/mpi_launch.py: a worker's JSON is found in what mpirun hands back (it once died
with JSONDecodeError on escape sequences after the line); mpirun gets OpenMPI's root and
oversubscribe permissions where the environment lacks them, and keeps the caller's own; a
failed worker is reported once, with its exit code and stderr. No MPI run."""
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
_spec = importlib.util.spec_from_file_location("mpi_launch", ROOT / "benchmarks" / "mpi_launch.py")
mpi_launch = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mpi_launch)

RESULT = {"rate": 1.5e6, "wall": 2.0, "ghosts": [10, 12], "nested": {"a": [1, 2]}}
LINE = '{"rate": 1500000.0, "wall": 2.0, "ghosts": [10, 12], "nested": {"a": [1, 2]}}'


@pytest.mark.parametrize("output", [
    LINE + "\n",
    LINE,                                                          # no newline
    LINE + "\x1b[0m\x1b[?25h\n",                                   # escapes after the line (the reported case)
    "\x1b]0;mpirun\x07" + LINE + "\x1b[K\r\n",                     # a title (OSC) before, erase-line after
    "numba: a warning\n" + LINE + "\n--------\nmpirun: trailing notice {not json}\n",  # text after the line
    "  " + LINE + "   \x1b(B\x1b[m\n\n",                            # padding, a charset switch, empty lines
    "progress {1/2}\n" + LINE + " done\n",                         # text after the object on its line
])
def test_the_workers_json_object_is_found_whatever_surrounds_it(output):
    assert mpi_launch.parse_json(output) == RESULT


def test_a_prefixed_result_line_is_found_and_other_json_ignored():
    output = f'{{"other": 1}}\nRESULT \x1b[1m{LINE}\x1b[0m\n{{"later": 2}}\n'
    assert mpi_launch.parse_json(output, prefix="RESULT ") == RESULT
    assert mpi_launch.parse_json(output) == {"later": 2}  # without a prefix: the last object


def test_output_without_an_object_is_a_clear_error():
    with pytest.raises(ValueError, match="no JSON object in the worker's output"):
        mpi_launch.parse_json("\x1b[31mSegmentation fault\x1b[0m\n[1, 2]\n")


def test_openmpi_permissions_are_added_where_missing_and_the_callers_kept():
    env = mpi_launch.mpi_env({"PATH": "/usr/bin"}, NUMBA_NUM_THREADS=1)
    assert env["OMPI_ALLOW_RUN_AS_ROOT"] == "1" and env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] == "1"
    assert env["OMPI_MCA_rmaps_base_oversubscribe"] == "1"
    assert env["PATH"] == "/usr/bin" and env["NUMBA_NUM_THREADS"] == "1"
    assert mpi_launch.mpi_env({"OMPI_MCA_rmaps_base_oversubscribe": "0"})["OMPI_MCA_rmaps_base_oversubscribe"] == "0"


def test_a_failed_worker_is_reported_once_with_its_exit_code_and_stderr():
    cmd = [sys.executable, "-c", "import sys; print('partial'); sys.stderr.write('mpirun: rank %d died\\n' % 1); "
                                 "sys.exit(3)"]  # (the message is not in the command line shown)
    with pytest.raises(mpi_launch.WorkerFailed) as failed:
        mpi_launch.run_json(cmd)
    message = str(failed.value)
    assert "exit code 3" in message and message.count("mpirun: rank 1 died") == 1 and "partial" in message


def test_a_worker_that_printed_no_object_is_reported_with_its_output():
    with pytest.raises(mpi_launch.WorkerFailed, match="no JSON object"):
        mpi_launch.run_json([sys.executable, "-c", "print('no result here')"])
    ok = [sys.executable, "-c", f"print({LINE!r} + '\\x1b[0m')"]
    assert mpi_launch.run_json(ok) == RESULT
