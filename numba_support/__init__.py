"""Numba set-up shared by the compiled kernels of ``de_domain``, ``fe_domain`` and ``cosim``
(it imports none of them):

    kernel_cache.py  on-disk kernel cache keyed on a digest of the sources a kernel may call,
                     so that a cached caller never runs a stale callee
    dispatch.py      CachedEntry: a compiled kernel called again without Numba typing its
                     arguments each time
    compile_clock.py seconds spent compiling kernels (not loading them from the cache)
"""
