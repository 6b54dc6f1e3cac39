"""The error types a user sees, and the exit codes.

* :class:`CaseError`: bad input, found before any computation (exit 2).
* :class:`RunFailed`: a run that cannot go on (e.g. a state that stopped being
  finite), raised on every MPI rank alike after a collective check (exit 1).

Any other exception is a bug or a failure on one rank: under ``mpirun -n N`` the CLI
prints it from the rank it happened on and aborts every rank (``MPI_Abort``), so no
rank waits forever in a collective the failed one will never reach.
"""

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1


class CaseError(Exception):
    """Bad case input: names the file, the key, the value and what is allowed.

    Raised before any computation starts; the CLI prints it and exits with
    ``EXIT_BAD_INPUT``.
    """

    def __init__(self, file, key, value, allowed):
        self.file, self.key, self.value, self.allowed = str(file), key, value, allowed
        super().__init__(f"{self.file}: key '{key}' = {_short(value)}: {allowed}")


class RunFailed(Exception):
    """A run stopped on a condition every rank agreed on (raised on all ranks alike)."""


def _short(value, limit=200):
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"
