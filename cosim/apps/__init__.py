"""Runnable applications, one module per case kind (``[case] kind``).

Each module has

* ``prepare(case, case_path, out_dir, resume)``: every input check the kind needs
  (packings read, meshes built, time steps against their stability limits, the
  checkpoint to resume from), raising :class:`cosim.errors.CaseError`; called on every
  MPI rank, before anything is written;
* ``run(prepared)``: the run itself, given the :class:`Prepared` case.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass
class Prepared:
    """A validated case, ready to run: every input check has passed on every rank."""
    case: object          # cosim.case.Case
    resolved: dict        # the case with defaults filled in (written as case.resolved.toml)
    case_path: Path
    out_dir: Path
    resume: bool
    built: object         # what the kind's prepare() read, generated or built


def on_root(comm, work):
    """``work()`` on rank 0 only, inside a collective part of prepare(): a CaseError there is
    sent to every rank and raised on all of them (no rank goes on into the next collective
    alone). Returns work()'s result on rank 0, None elsewhere."""
    from cosim.errors import CaseError
    result, failure = None, None
    if comm.rank == 0:
        try:
            result = work()
        except CaseError as exc:
            failure = (exc.file, exc.key, exc.value, exc.allowed)
    failure = comm.bcast(failure, root=0) if comm.size > 1 else failure
    if failure is not None:
        raise CaseError(*failure)
    return result
