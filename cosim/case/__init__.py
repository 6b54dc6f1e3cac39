"""Case files: one TOML file describes one complete run.

Every key has a type, a unit and an allowed range (:mod:`cosim.case.schema`); unknown keys are
errors. A case is read in three passes, all before any computation
(:func:`cosim.case.loading.load_case`):

1. TOML syntax, then the ``--set`` overrides;
2. types, ranges and unknown keys (the pydantic models of :mod:`cosim.case.schema`);
3. the sections and keys the kind uses, the rules between fields and the files the case names
   (:mod:`cosim.case.validation`).

Each failure raises :class:`cosim.errors.CaseError` naming the file, the dotted key, the value
and what is allowed (:mod:`cosim.case.messages`). ``cosim schema`` prints the whole schema with
units; calibration files have theirs in :mod:`cosim.case.calibration`.
"""
from cosim.case.loading import load_case

__all__ = ["load_case"]
