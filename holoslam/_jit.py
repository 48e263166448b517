"""holoslam's numba policy: the settings every compiled kernel is built with, and when its cache is fresh.

Every kernel file (``*_fast.py`` and the modules of ``holoslam.planning._fast``) imports this module and
decorates its kernels with ``@nb.njit(**JIT)``: compiled once per machine and loaded from numba's on-disk
cache (``cache=True``, in the ``__pycache__`` folder next to the file) by later processes, and without the GIL
(``nogil=True``: a kernel called from several threads runs in parallel). ``JIT_FASTMATH`` adds
``fastmath=True`` for a kernel whose result does not change under reassociation (a max over finite values,
which then vectorises); ``JIT_INNER`` is for a helper that only other kernels call (no CPython wrapper);
per-kernel options (``inline="always"``) are added at the decorator. A kernel file
imports this module before it defines a kernel, and the kernels (or kernel modules) of other files it calls
at its top.

Compile time (a first run compiles every kernel it calls). A kernel called from a kernel is compiled once more
for every literal argument type the caller's typing sees: a constant (``f(x, 0)``, ``f(x, True)``) or a count
started at a constant and passed on; such arguments are written ``np.int64(0)``, ``np.bool_(True)``. A helper
with one call site is ``inline="always"`` when that compiles faster (measured: not for large ones).

Cache freshness. Numba keeps a cached kernel while its own source file is unchanged, but a kernel that calls
kernels of *other* files has them compiled into it, and numba does not look at those files (numba issues
#1833, #9483): after an edit of a called file the caller would silently run the old code. Importing this
module therefore puts, in front of each of numba's source-file cache locators, the same locator with a
source stamp that also holds the content hashes of this file and of every kernel file the kernel's module
can call into (transitively, :func:`kernel_files`), for the kernels of the files that import this module:
editing any of them recompiles what depends on it, as editing the one file did before the planning kernels
were split by job.
"""

from __future__ import annotations

import hashlib
import os
import re
from functools import cache
from types import ModuleType
from typing import Literal, TypedDict, cast

from numba.core import caching
from numba.core.dispatcher import Dispatcher

__all__ = ["JIT", "JIT_FASTMATH", "JIT_INNER", "JitOptions", "LOCATORS_INSTALLED", "kernel_files", "takes_policy"]


class JitOptions(TypedDict, total=False):
    """The keyword arguments of ``nb.njit`` this policy sets (typed, so ``njit(**JIT)`` type-checks)."""

    cache: bool
    nogil: bool
    fastmath: bool
    error_model: Literal["python", "numpy"]


# ``error_model="numpy"``: a float division by zero gives inf or nan as numpy's does (the rest of holoslam is
# numpy), instead of numba's default raising ZeroDivisionError from a check compiled into every division: the
# kernels' inputs are validated before them, and the checks cost ~5 % of the first run's compile (26.8, 25.6 ->
# 25.0, 24.8 s CPU: the household's record compiled serially, two interleaved pairs; the outputs byte-identical)
# ``no_cfunc_wrapper``: no C-callable wrapper (numba builds one per kernel for first-class function values, which
# holoslam never passes around): the household's record compiles in ~6 % less CPU with ``JIT_INNER`` below (20.97
# -> 19.75 s serially, medians of 3 interleaved; the kernels' machine code is the same)
# (numba's own stub of ``njit`` lacks the two wrapper options: a cast, the dict holds them at run time)
JIT: JitOptions = cast(JitOptions, {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True})
JIT_FASTMATH: JitOptions = {**JIT, "fastmath": True}
# a helper called only from other kernels (never from Python, tests included): no CPython wrapper either (the
# unboxing of its arguments from Python objects is code that would never run)
JIT_INNER: JitOptions = cast(JitOptions, {**JIT, "no_cpython_wrapper": True})

_PARENT, _, _NAME = __name__.rpartition(".")
_IMPORTS_ME = re.compile(
    rf"^\s*(from\s+{re.escape(__name__)}\s+import|import\s+{re.escape(__name__)}\b"
    rf"|from\s+{re.escape(_PARENT)}\s+import\s+.*\b{_NAME}\b)",
    re.M,
)


@cache
def _file_facts(path: str, mtime_ns: int, size: int) -> tuple[str, bool]:
    with open(path, "rb") as f:
        text = f.read()
    return hashlib.sha256(text).hexdigest(), bool(_IMPORTS_ME.search(text.decode("utf-8", "replace")))


def _facts(path: str) -> tuple[str, bool]:
    """(content hash, imports this module) of a source file; (``""``, False) when it cannot be read."""
    try:
        st = os.stat(path)
        return _file_facts(path, st.st_mtime_ns, st.st_size)
    except OSError:
        return "", False


def takes_policy(path: str) -> bool:
    """The source file imports this module: its kernels are built and cached by this policy."""
    return _facts(path)[1]


def kernel_files(py_func) -> tuple[str, ...]:
    """The other source files whose kernels ``py_func``'s module can call, transitively, sorted: the files
    compiled into ``py_func``'s kernels besides its own (the numba dispatchers among the module's globals and
    among those of the kernel modules it holds, then theirs)."""
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
            if isinstance(v, ModuleType):
                path = getattr(v, "__file__", None)
                if path and takes_policy(path):  # a kernel module used as ``module.kernel``
                    todo.append(vars(v))
                continue
            f = getattr(v, "py_func", None)
            if isinstance(v, Dispatcher) and f is not None:
                path = os.path.abspath(f.__code__.co_filename)
                if path != own:
                    seen.add(path)
                todo.append(f.__globals__)
    return tuple(sorted(seen))


class _DependencyStamp:
    """Mixin for numba's cache locators: the source stamp of a kernel whose file imports this module also
    holds the hashes of this file and of the kernel files its module can call into (module docstring)."""

    _holoslam_deps: tuple[str, ...] = ()  # this file and the kernel files, set per locator by from_function

    @classmethod
    def from_function(cls, py_func, py_file):
        if not takes_policy(py_file):
            return None  # not a kernel of a file that takes its settings from here: numba's locators decide
        # a mixin: numba's locator class follows it in the MRO (``_install_locators``)
        self = super().from_function(py_func, py_file)  # type: ignore[misc]
        if self is not None:
            self._holoslam_deps = (os.path.abspath(__file__), *kernel_files(py_func))
        return self

    def get_source_stamp(self):
        deps = tuple((os.path.basename(p), _facts(p)[0]) for p in self._holoslam_deps)
        return super().get_source_stamp(), deps  # type: ignore[misc]  # numba's locator (a mixin, as above)


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
        locator = type(f"Holoslam{name}", (_DependencyStamp, base), {"__module__": __name__})
        classes.insert(classes.index(base), locator)
        found = True
    return found


LOCATORS_INSTALLED = _install_locators()
