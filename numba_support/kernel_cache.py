"""Numba's on-disk cache, keyed on every source file a cached kernel may call.

Numba stamps a cached kernel with its own file's modification time and size only.
A kernel that calls (or inlines) a kernel of another module keeps its compiled copy
of the callee, so after an edit of, say, ``de_domain/contact_laws.py`` the cached pair
kernel of ``de_domain/fused.py`` would still run the old law, silently. (And an index
that names a type since removed cannot even be read: Numba unpickles it before it
compares stamps.) Here the kernels of a package directory registered with
:func:`install` are cached in a directory named by one digest of that package's
``.py`` files and of the packages it depends on, ``numba-<digest>`` inside the place
Numba would use (``__pycache__`` beside the source, or the user-wide cache when that
is not writable, or ``NUMBA_CACHE_DIR``): any edit of those sources starts an empty
cache, and the next call recompiles. The in-tree directories of earlier digests (and
entries in Numba's plain layout) are removed when the package is registered.

``de_domain`` registers itself; ``fe_domain`` too; ``cosim`` (whose coupling kernels
call both) with ``depends_on`` = both. :func:`install` must run before the first
``njit(cache=True)`` decorator of the package executes.
"""
import hashlib
import os
import shutil
from pathlib import Path

from numba.core import caching

#: registered package directory -> digest of its sources and of those it depends on
DIGESTS = {}


def source_digest(package_dir, depends_on=()):
    """SHA-256 over the names and bytes of the ``.py`` files of ``package_dir`` and of each
    directory in ``depends_on``, in that order, each in name order."""
    digest = hashlib.sha256()
    for directory in (package_dir, *depends_on):
        for path in sorted(Path(directory).glob("*.py")):
            digest.update(f"{Path(directory).name}/{path.name}".encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_dir_name(digest):
    return f"numba-{digest[:16]}"


def _package_of(py_file):
    try:
        return Path(py_file).resolve().parent
    except OSError:
        return None


class _PackageDigestStamp:
    """Locator mixin: a cache directory per package digest, for registered packages only."""

    def get_cache_path(self):
        return os.path.join(super().get_cache_path(), cache_dir_name(DIGESTS[_package_of(self._py_file)]))

    @classmethod
    def from_function(cls, py_func, py_file):
        if _package_of(py_file) not in DIGESTS:
            return None
        return super().from_function(py_func, py_file)


class _UserProvidedLocator(_PackageDigestStamp, caching._UserProvidedCacheLocator):
    pass


class _InTreeLocator(_PackageDigestStamp, caching._InTreeCacheLocator):
    pass


class _UserWideLocator(_PackageDigestStamp, caching._UserWideCacheLocator):
    pass


LOCATORS = (_UserProvidedLocator, _InTreeLocator, _UserWideLocator)


def install(package_dir, depends_on=()):
    """Register ``package_dir`` (its kernels cached under the digest of its sources and of
    ``depends_on``'s), put the digest-keyed locators first in Numba's search order
    (idempotent) and remove the package's in-tree cache directories of other digests."""
    package_dir = Path(package_dir).resolve()
    digest = source_digest(package_dir, [Path(d).resolve() for d in depends_on])
    DIGESTS[package_dir] = digest
    classes = caching.CacheImpl._locator_classes
    for locator in reversed(LOCATORS):
        if locator not in classes:
            classes.insert(0, locator)
    keep = cache_dir_name(digest)
    pycache = package_dir / "__pycache__"
    for stale in pycache.glob("numba-*"):
        if stale.name != keep:
            shutil.rmtree(stale, ignore_errors=True)
    for legacy in [*pycache.glob("*.nbi"), *pycache.glob("*.nbc")]:  # Numba's own layout
        legacy.unlink(missing_ok=True)
