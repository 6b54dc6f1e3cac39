"""cosim: coupling manager, case loader, CLI and outputs of the FE-DE simulator."""
from pathlib import Path as _Path

from numba_support import kernel_cache as _kernel_cache

__version__ = "0.1.0"

# before any cosim module defines an njit(cache=True) kernel: the coupling kernels call
# de_domain's and fe_domain's, so their cache follows those sources too
_HERE = _Path(__file__).parent
_kernel_cache.install(_HERE, depends_on=[_HERE.parent / "de_domain", _HERE.parent / "fe_domain"])
