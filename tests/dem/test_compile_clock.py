"""numba_support.compile_clock counts real compilations, not calls of a compiled kernel."""
import numba

from numba_support import compile_clock


def test_a_compilation_is_counted_and_a_call_of_the_compiled_kernel_is_not():
    @numba.njit(cache=False)
    def twice(x):
        return 2.0 * x

    before = compile_clock.seconds()
    assert twice(1.5) == 3.0
    compiled = compile_clock.seconds()
    assert compiled > before
    for _ in range(100):
        twice(2.0)
    assert compile_clock.seconds() == compiled
