"""Calling one compiled kernel again and again without Numba typing its arguments each time.

Numba picks the compiled overload of a call by typing every argument in Python when
the arguments are tuples: for :func:`de_domain.fused.advance` (seven named tuples,
about 60 arrays) that costs ≈ 150 µs per call, more than half a DEM step of 3,000
grains (measured, ``benchmarks/coupled_overhead.py``). A long run pays it once; the
FE–DE coupling calls the DEM once per FE step and paid it every time.

:class:`CachedEntry` calls the machine-code entry point of the overload that the
dispatcher chose for the first call directly, as long as every array argument (at
any depth of the tuples) is the same object as then and every other argument has the
same Python type. Numba's type of an array depends only on its dtype, dimensions,
layout and writability, which an array object keeps for life; that of a Python or
NumPy scalar only on its Python type. So the types, and the overload, are the same
as the dispatcher would pick. Any other call goes through the dispatcher (which
compiles the kernel if it must) and becomes the new reference.
"""
from __future__ import annotations

import numpy as np

_ONLY_ARRAYS = {np.ndarray}


def _argument_key(args):
    """Each array's identity and every other value's type, through the tuples, in order
    (a tuple of arrays only, the engine's usual, in one pass of C loops)."""
    key = []
    for value in args:
        if type(value) is np.ndarray:
            key.append(id(value))
        elif isinstance(value, tuple):
            key.append(type(value))
            if set(map(type, value)) == _ONLY_ARRAYS:
                key.extend(map(id, value))
            else:
                key.extend(_argument_key(value))
        else:
            key.append(type(value))
    return key


class CachedEntry:
    """``CachedEntry(dispatcher)(*args)`` is ``dispatcher(*args)``, faster when called again
    with the same array objects (module docstring)."""

    def __init__(self, dispatcher):
        self.dispatcher = dispatcher
        self._key = None
        self._arguments = None  # kept alive, so that no new array can reuse an id in the key
        self._entry = None

    @property
    def entry(self):
        """The machine-code entry point of the last call: ``entry(*args)`` with arguments of that
        call's types and array objects is that call again, without even the key's check (for a
        loop whose arguments are the same objects from one iteration to the next)."""
        return self._entry

    def __call__(self, *args):
        key = _argument_key(args)
        if key == self._key:
            return self._entry(*args)
        result = self.dispatcher(*args)
        overloads = self.dispatcher.overloads
        if len(overloads) == 1:  # the call used the only one (typing ≈ 150 arrays again costs ≈ 0.5 ms)
            self._entry = next(iter(overloads.values())).entry_point
        else:
            self._entry = overloads[tuple(self.dispatcher.typeof_pyval(value) for value in args)].entry_point
        self._key, self._arguments = key, args
        return result
