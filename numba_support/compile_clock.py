"""Seconds this process has spent compiling Numba kernels.

Numba signals every real compilation (not a load from the on-disk cache) with a
``numba:compile`` event; a kernel that compiles its callees nests further events inside
the first, so :class:`numba.core.event.TimingListener` counts the outermost span only.
A run reports its wall-clock with and without this one-time cost (a second run of the
same code loads the kernels from the cache instead). DOLFINx's FFCx forms have their own
clock in :mod:`fe_domain.jit`.
"""
from numba.core import event

_LISTENER = event.TimingListener()
event.register("numba:compile", _LISTENER)


def seconds():
    """Total seconds spent in outermost Numba compilations since this module was imported."""
    return _LISTENER.duration if _LISTENER.done else 0.0
