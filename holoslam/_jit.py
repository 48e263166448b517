"""holoslam's numba policy: the settings every compiled kernel is built with, and when its on-disk cache is fresh.

Every kernel file (``*_fast.py`` and the modules of ``holoslam.planning._fast``) decorates its kernels with
``@nb.njit(**JIT)``: compiled once per machine and loaded from numba's on-disk cache (``cache=True``, in the
``__pycache__`` folder next to the file) by later processes, and without the GIL (``nogil=True``: a kernel
called from several threads runs in parallel). ``JIT_FASTMATH`` adds ``fastmath=True``, for a kernel whose
result is the same under reassociation (a max over finite values that vectorises); no other kernel uses it.
A kernel file imports this module before it defines a kernel, and imports the kernels of other files it calls
at its top.

Cache freshness. Numba keeps a cached kernel while its own source file is unchanged, but a kernel that calls
kernels of *other* files has them compiled into it, and numba does not look at those files (numba issues
#1833, #9483): after an edit of a called file the caller would silently run the old code. Importing this
module therefore puts a cache locator in front of numba's own ones for holoslam's kernels; it is numba's
(in-tree or ``NUMBA_CACHE_DIR``) locator with a source stamp that also holds the content hashes of this
file and of every kernel file whose kernels the kernel's module imports (transitively), so editing any of
them recompiles what depends on it, as editing the single file did before the kernels were split by job.
"""

from __future__ import annotations

import hashlib
import os
import sys
from functools import cache

from numba.core import caching
from numba.core.dispatcher import Dispatcher

__all__ = ["JIT", "JIT_FASTMATH", "LOCATORS_INSTALLED", "kernel_files"]

JIT = {"cache": True, "nogil": True}
JIT_FASTMATH = {**JIT, "fastmath": True}


@cache
def _file_hash(path: str, mtime_ns: int, size: int) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _content_hash(path: str) -> str:
    st = os.stat(path)
    return _file_hash(path, st.st_mtime_ns, st.st_size)


def kernel_files(py_func) -> tuple[str, ...]:
    """The other source files whose kernels ``py_func``'s module has imported, transitively, sorted: the
    files compiled into ``py_func``'s kernels besides its own (numba dispatchers among the module's globals,
    then theirs)."""
    own = os.path.abspath(py_func.__code__.co_filename)
    seen: set[str] = set()
    todo = [py_func.__globals__]
    visited: set[int] = set()
    while todo:
        g = todo.pop()
        if id(g) in visited:
            continue
        visited.add(id(g))
        for v in list(g.values()):
            f = getattr(v, "py_func", None)
            if isinstance(v, Dispatcher) and f is not None:
                path = os.path.abspath(f.__code__.co_filename)
                if path != own and path not in seen:
                    seen.add(path)
                todo.append(f.__globals__)
    return tuple(sorted(seen))


class _DependencyStamp:
    """Mixin for numba's cache locators: the source stamp of a kernel whose file imports this policy (its
    ``JIT`` settings or the module) also holds the hashes of this file and of the kernel files its module
    imports (see the module docstring)."""

    @classmethod
    def from_function(cls, py_func, py_file):
        g = getattr(py_func, "__globals__", {})
        if not any(v is JIT or v is JIT_FASTMATH or v is _THIS for v in g.values()):
            return None  # not a kernel of a file that takes its settings from here: numba's locators decide
        self = super().from_function(py_func, py_file)
        if self is not None:
            self._holoslam_deps = (os.path.abspath(__file__), *kernel_files(py_func))
        return self

    def get_source_stamp(self):
        deps = tuple((os.path.basename(p), _content_hash(p)) for p in self._holoslam_deps)
        return super().get_source_stamp(), deps


def _install_locators() -> bool:
    """Put a dependency-stamped copy of each of numba's source-file locators (``NUMBA_CACHE_DIR``, in-tree
    ``__pycache__``, user-wide when the tree is read-only) in front of it, once per process; False when this
    numba has none of them (then numba's per-file rule applies, and ``tests/test_jit.py`` fails)."""
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    if classes is None:
        return False
    if any(issubclass(c, _DependencyStamp) for c in classes):
        return True
    found = False
    for name in ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator"):
        # numba < 0.61 names them with a leading underscore
        base = getattr(caching, name, None) or getattr(caching, "_" + name, None)
        if base is None or base not in classes:
            continue
        classes.insert(
            classes.index(base), type(f"Holoslam{name}", (_DependencyStamp, base), {"__module__": __name__})
        )
        found = True
    return found


_THIS = sys.modules[__name__]
LOCATORS_INSTALLED = _install_locators()
