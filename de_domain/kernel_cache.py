"""Numba's on-disk cache for de_domain, keyed on every de_domain source file.

Numba stamps a cached kernel with its own file's modification time and size only.
A kernel that calls (or inlines) a kernel of another module keeps its compiled copy
of the callee, so after an edit of, say, ``contact_laws.py`` the cached pair kernel
of ``fused.py`` would still run the old law, silently. (And an index that names a
type since removed from ``state.py`` cannot even be read: Numba unpickles it before
it compares stamps.) Here every de_domain kernel is cached in a directory named by
one digest of all the package's ``.py`` files, ``numba-<digest>`` inside the place
Numba would use (``__pycache__`` beside the source, or the user-wide cache when that
is not writable, or ``NUMBA_CACHE_DIR``): any edit anywhere in the package starts
an empty cache, and the next call recompiles. The in-tree directories of earlier
digests (and entries in Numba's plain layout) are removed when the package is imported.

:func:`install` must run before the first ``njit(cache=True)`` decorator of the
package executes (``de_domain/__init__.py`` calls it first).
"""
import hashlib
import os
import shutil
from pathlib import Path

from numba.core import caching

PACKAGE_DIR = Path(__file__).resolve().parent


def source_digest(package_dir=PACKAGE_DIR):
    """SHA-256 over the names and bytes of the package's ``.py`` files, in name order."""
    digest = hashlib.sha256()
    for path in sorted(package_dir.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_dir_name(digest):
    return f"numba-{digest[:16]}"


def _in_package(py_file):
    try:
        return Path(py_file).resolve().parent == PACKAGE_DIR
    except OSError:
        return False


class _PackageDigestStamp:
    """Locator mixin: a cache directory per package digest, for de_domain files only."""

    digest = None

    def get_cache_path(self):
        return os.path.join(super().get_cache_path(), cache_dir_name(self.digest))

    @classmethod
    def from_function(cls, py_func, py_file):
        if not _in_package(py_file):
            return None
        return super().from_function(py_func, py_file)


class _UserProvidedLocator(_PackageDigestStamp, caching._UserProvidedCacheLocator):
    pass


class _InTreeLocator(_PackageDigestStamp, caching._InTreeCacheLocator):
    pass


class _UserWideLocator(_PackageDigestStamp, caching._UserWideCacheLocator):
    pass


LOCATORS = (_UserProvidedLocator, _InTreeLocator, _UserWideLocator)


def install():
    """Put the digest-keyed locators first in Numba's search order (idempotent) and
    remove the in-tree cache directories of other digests."""
    digest = source_digest()
    _PackageDigestStamp.digest = digest
    classes = caching.CacheImpl._locator_classes
    for locator in reversed(LOCATORS):
        if locator not in classes:
            classes.insert(0, locator)
    keep = cache_dir_name(digest)
    pycache = PACKAGE_DIR / "__pycache__"
    for stale in pycache.glob("numba-*"):
        if stale.name != keep:
            shutil.rmtree(stale, ignore_errors=True)
    for legacy in [*pycache.glob("*.nbi"), *pycache.glob("*.nbc")]:  # Numba's own layout, before this module
        legacy.unlink(missing_ok=True)
