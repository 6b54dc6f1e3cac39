"""Quiet DOLFINx JIT: one short line when FE kernels are compiled, never the compiler's commands.

DOLFINx compiles every finite element (``fem.FunctionSpace``), form (``fem.form``) and
expression (``fem.Expression``) just in time with FFCx, and keeps the compiled modules
in its cache, ``$XDG_CACHE_HOME/fenics`` (default ``~/.cache/fenics``).  On a cache miss
FFCx (``ffcx.codegeneration.jit._compile_objects``) generates C and builds it with
``cffi.FFI.compile(verbose=True)``.  cffi runs distutils' ``build_ext`` after
``distutils.log.set_verbosity(1)``; the distutils that setuptools provides logs through
the *root* logger (``setuptools/_distutils/_log.py``: ``log = logging.getLogger()``),
``set_verbosity(1)`` lowers the root level to INFO for the build, and ``import ffcx``
has called ``logging.basicConfig()``.  So each kernel printed four ``INFO:root:...``
lines on stderr ("running build_ext", "building '...' extension", the gcc and link
command lines): 52 lines on the first ``make demo``.  FFCx redirects stdout around the
build, not logging, and its own logger ("ffcx") stays at WARNING.

``install()`` (called on import by ``explicit.py`` and ``output.py``, the modules that
create function spaces, forms and expressions) wraps ``_compile_objects``, the function
FFCx calls only on a cache miss (a hit loads the module from the cache directory
before reaching it; under MPI, DOLFINx compiles on rank 0 and the other ranks then
load from the cache):

* while it runs, a filter on the root logger turns the records below WARNING that are
  logged *directly* on the root logger (that is distutils' logger) into DEBUG records
  of the logger ``"fe_domain.jit"``, which shows nothing by default.  Warnings and
  errors pass unchanged; a failed compile still raises (cffi's ``VerificationError``
  with the compiler's message), and gcc's own diagnostics still go to stderr;
* the first miss of the process prints ``MESSAGE`` once on stdout (MPI rank 0 of
  ``COMM_WORLD`` only), before FFCx generates and compiles the first kernel.

To see the compiler's lines: set ``FE_DOMAIN_JIT_VERBOSE=1`` in the environment, or
``logging.getLogger("fe_domain.jit").setLevel(logging.DEBUG)`` in Python (they then
read ``DEBUG:fe_domain.jit:x86_64-linux-gnu-gcc ...``).

If the installed FFCx has no ``_compile_objects`` (another version than Debian's
0.5.0), ``install()`` falls back to keeping the filter on the root logger for good
(still only sub-WARNING records logged directly on the root logger by distutils) and
prints no line.
"""

from __future__ import annotations

import functools
import logging
import os
import time

#: Printed once per process on the first JIT cache miss (the 13 kernels of ``make demo``,
#: elements, forms and the von Mises expression, compile in 4.3-4.9 s on 2 idle cores).
MESSAGE = "compiling FE kernels (first run only, ~5 s)..."
#: Set to 1 to show the C compiler's command lines.
VERBOSE_ENV = "FE_DOMAIN_JIT_VERBOSE"

logger = logging.getLogger("fe_domain.jit")
_announced = False
_compile_seconds = 0.0


def compile_seconds() -> float:
    """Seconds this process has spent in FFCx compilations (cache misses only)."""
    return _compile_seconds


class _CompilerLogFilter(logging.Filter):
    """On the root logger: its own sub-WARNING records → DEBUG on ``fe_domain.jit``.

    A logger's filters see only the records logged on that logger itself, never
    those propagated from child loggers, so ``logging.getLogger("x").info`` is left
    alone; what is caught is distutils (and bare ``logging.info()`` calls).
    """

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            return True
        if logger.isEnabledFor(logging.DEBUG):
            logger.debug(record.getMessage())
        return False


_FILTER = _CompilerLogFilter()


def _announce() -> None:
    global _announced
    if _announced:
        return
    _announced = True
    from mpi4py import MPI
    if MPI.COMM_WORLD.rank == 0:
        print(MESSAGE, flush=True)


def _quiet(compile_objects):
    @functools.wraps(compile_objects)
    def quiet_compile_objects(*args, **kwargs):
        global _compile_seconds
        _announce()
        root = logging.getLogger()
        root.addFilter(_FILTER)
        start = time.perf_counter()
        try:
            return compile_objects(*args, **kwargs)
        finally:
            _compile_seconds += time.perf_counter() - start
            root.removeFilter(_FILTER)

    quiet_compile_objects._fe_domain_quiet = True
    return quiet_compile_objects


def install() -> None:
    """Make DOLFINx's JIT quiet (idempotent); see the module docstring."""
    if os.environ.get(VERBOSE_ENV, "").strip() not in ("", "0"):
        logger.setLevel(logging.DEBUG)
    import ffcx.codegeneration.jit as ffcx_jit
    original = getattr(ffcx_jit, "_compile_objects", None)
    if original is None:
        logging.getLogger().addFilter(_FILTER)     # addFilter ignores a second add
        logger.debug("ffcx.codegeneration.jit._compile_objects not found: compiler lines "
                     "hidden for good, no first-run notice")
        return
    if not getattr(original, "_fe_domain_quiet", False):
        ffcx_jit._compile_objects = _quiet(original)
