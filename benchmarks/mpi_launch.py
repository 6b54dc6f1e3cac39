"""Launching benchmark workers under ``mpirun`` and reading back what they print.

* :func:`mpi_env`: the environment for ``mpirun``, with OpenMPI's permissions to run as root
  and to oversubscribe the cores added where the caller's environment does not set them (run as
  root outside ``make``, ``mpirun`` refuses to start without them);
* :func:`run`: run a command, and when it fails end with one message: the command, its exit
  code and the tail of its stderr (and stdout), which ``check=True`` alone would swallow;
* :func:`parse_json`: the JSON object a worker printed, found in the output even when
  ``mpirun`` or a terminal wraps it in escape sequences or adds lines after it.

No MPI and no project imports here: the parent process of a benchmark stays light.
"""
from __future__ import annotations

import json
import os
import re
import subprocess

OPENMPI_DEFAULTS = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                    "OMPI_MCA_rmaps_base_oversubscribe": "1"}

# ANSI/VT escape sequences: CSI (ESC [ ... final byte), OSC (ESC ] ... BEL or ESC \), and the
# two-byte ones (ESC and one character); a bare CSI byte (0x9b) too
_ESCAPES = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x9b[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)?"
                      r"|\x1b[@-Z\\-_]|\x1b[ -/]*[0-~]")


def mpi_env(base=None, **extra):
    """A copy of ``base`` (default ``os.environ``) with :data:`OPENMPI_DEFAULTS` where unset,
    then ``extra`` (str values) on top."""
    env = dict(os.environ if base is None else base)
    for key, value in OPENMPI_DEFAULTS.items():
        env.setdefault(key, value)
    env.update({k: str(v) for k, v in extra.items()})
    return env


def strip_escapes(text):
    """``text`` without terminal escape sequences (and carriage returns)."""
    return _ESCAPES.sub("", text).replace("\r", "")


def parse_json(output, prefix=""):
    """The last JSON object (a dict) in ``output``, the worker's stdout: each line is cleaned of
    escape sequences and searched for an object (after ``prefix`` when given), from the last
    line up, so text and escapes before or after it do not matter. ValueError if none."""
    decoder = json.JSONDecoder()
    for line in reversed(strip_escapes(output).splitlines()):
        if prefix:
            at = line.rfind(prefix)
            if at < 0:
                continue
            line = line[at + len(prefix):]
        for start in [m.start() for m in re.finditer(r"\{", line)]:
            try:
                value, _ = decoder.raw_decode(line, start)
            except ValueError:
                continue
            if isinstance(value, dict):
                return value
    shown = strip_escapes(output)[-2000:]
    raise ValueError(f"no JSON object{f' after {prefix!r}' if prefix else ''} in the worker's output:\n{shown}")


class WorkerFailed(SystemExit):
    """A worker command that exited non-zero (or timed out); its message is the whole report."""


def failure_report(cmd, returncode, stdout, stderr):
    """One message: the command, its exit code, the tail of its stderr and of its stdout."""
    def tail(text, n):
        text = strip_escapes(text or "").strip()
        return text[-n:] if text else "(empty)"
    return (f"worker failed with exit code {returncode}: {' '.join(map(str, cmd))}\n"
            f"--- stderr (last lines) ---\n{tail(stderr, 4000)}\n--- stdout (last lines) ---\n{tail(stdout, 1500)}")


def run(cmd, env=None, timeout=None, **kwargs):
    """``subprocess.run(cmd)`` capturing text output, with :func:`mpi_env` as the default
    environment; returns the CompletedProcess, or raises :class:`WorkerFailed` (which ends the
    benchmark with the report on stderr, exit status 1) if it fails or times out."""
    try:
        done = subprocess.run(cmd, env=mpi_env() if env is None else env, capture_output=True, text=True,
                              timeout=timeout, **kwargs)
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode(errors="replace") if isinstance(exc.stdout, bytes) else exc.stdout
        err = exc.stderr.decode(errors="replace") if isinstance(exc.stderr, bytes) else exc.stderr
        raise WorkerFailed(failure_report(cmd, f"none (timed out after {timeout} s)", out, err)) from None
    if done.returncode:
        raise WorkerFailed(failure_report(cmd, done.returncode, done.stdout, done.stderr))
    return done


def run_json(cmd, prefix="", **kwargs):
    """:func:`run`, then :func:`parse_json` of its stdout (a missing object is a
    :class:`WorkerFailed` with the output shown)."""
    done = run(cmd, **kwargs)
    try:
        return parse_json(done.stdout, prefix)
    except ValueError as exc:
        raise WorkerFailed(f"{exc}\n{failure_report(cmd, done.returncode, done.stdout, done.stderr)}") from None
