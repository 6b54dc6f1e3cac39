"""numba_support.dispatch.CachedEntry: the dispatcher's answer, with the typing skipped only
while the array arguments are the same objects."""
from collections import namedtuple

import numpy as np
from numba import njit

from numba_support.dispatch import CachedEntry

Pair = namedtuple("Pair", ["a", "scale"])


@njit
def _weighted_sum(pair, out):
    out[0] = pair.a.sum() * pair.scale
    return out[0]


def test_cached_entry_agrees_with_the_dispatcher_and_follows_new_arrays_and_types():
    """(A fresh kernel: its first calls have one overload, the shortcut; later ones several.)"""
    kernel = CachedEntry(_weighted_sum)
    out = np.zeros(1)
    a = np.arange(4.0)
    assert kernel(Pair(a, 2.0), out) == 12.0
    entry = kernel._entry
    assert kernel(Pair(a, 3.0), out) == 18.0 and kernel._entry is entry  # same array: the cached entry
    a[:] = 1.0                                                             # (contents may change)
    assert kernel(Pair(a, 1.0), out) == 4.0 and kernel._entry is entry
    ints = np.arange(4, dtype=np.int32)                                    # a new array of another type
    assert kernel(Pair(ints, 1.0), out) == 6.0 and kernel._entry is not entry
    assert kernel(Pair(ints, 2), out) == 12.0                              # an int scale: another overload
    assert len(_weighted_sum.signatures) == 3
    assert kernel(Pair(a[::2], 1.0), out) == 2.0                           # a strided view: the dispatcher again
