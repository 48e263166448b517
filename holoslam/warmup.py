"""Compile holoslam's numba kernels ahead of a run: ``holoslam warmup`` (run by ``./dev.sh install``) and the
first run after an install.

A kernel (``@nb.njit(**JIT)``, :mod:`holoslam._jit`) is compiled on its first call with the argument types of
that call, then loaded from numba's on-disk cache by later processes. The signatures a run uses are recorded
in ``_kernel_signatures.txt`` beside this file (one line per kernel and signature: module, function, the
argument types as a Python literal, and the seconds its compile took when recorded; written by
:func:`record_signatures` after a run of the bundled household log:
``python benchmarks/bench_jit_compile.py --record``). :func:`warm_up` compiles those signatures with
``Dispatcher.compile``, which writes numba's cache as a call would, one kernel module per process of a pool
(numba compiles under the GIL, so threads would not overlap; processes do; :func:`_pool_context` says how
they start). A signature the record misses is
still compiled by the run on its first call, as before: the record only moves work earlier.

:func:`pending` says which recorded signatures are not in the cache (the first run after an install, or after
an edit of a kernel file) and how long compiling them took when recorded, so that the command line can tell
the user once why the first run is slower.
"""

from __future__ import annotations

import ast
import importlib
import os
import sys
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["KernelSignature", "SIGNATURES_FILE", "load_signatures", "pending", "warm_up", "record_signatures",
           "compile_in_background", "estimate_seconds", "wait_for_kernels"]

SIGNATURES_FILE = Path(__file__).with_name("_kernel_signatures.txt")


@dataclass(frozen=True)
class KernelSignature:
    """One compiled specialisation of a kernel: ``module.function`` for the argument types ``args`` (encoded
    by :func:`_encode`); ``seconds`` its compile's CPU time when recorded (callees compiled inside it included)."""

    module: str
    function: str
    args: tuple
    seconds: float = 0.0

    def line(self) -> str:
        return f"{self.module}\t{self.function}\t{self.args!r}\t{self.seconds:.3f}"


# ------------------------------------------------------------------------------------ type encoding


def _encode(t: Any) -> Any:
    """A numba type as a plain literal (ValueError for a kind the record does not hold)."""
    from numba.core import types

    if isinstance(t, types.Array):
        return ("array", _encode(t.dtype), t.ndim, t.layout, not t.mutable)
    if isinstance(t, types.UniTuple):
        return ("utuple", _encode(t.dtype), t.count)
    if isinstance(t, types.Tuple):
        return ("tuple", tuple(_encode(x) for x in t.types))
    if isinstance(t, types.Literal):
        raise ValueError(f"literal type {t} not recorded (compiled inside its caller)")
    if isinstance(t, types.NoneType):
        return "none"
    if isinstance(t, types.Boolean | types.Integer | types.Float | types.Complex):
        return str(t)
    if isinstance(t, types.Record):
        raise ValueError(f"record type {t} not recorded")
    raise ValueError(f"type {t!r} not recorded")


def _decode(e: Any) -> Any:
    import numpy as np
    from numba.core import types
    from numba.np.numpy_support import from_dtype

    if isinstance(e, str):
        if e == "none":
            return types.none
        if e == "bool":
            return types.boolean
        try:
            return from_dtype(np.dtype(e))
        except TypeError:
            raise ValueError(f"unknown encoded type {e!r}") from None
    kind = e[0]
    if kind == "array":
        return types.Array(_decode(e[1]), e[2], e[3], readonly=e[4])
    if kind == "utuple":
        return types.UniTuple(_decode(e[1]), e[2])
    if kind == "tuple":
        return types.Tuple(tuple(_decode(x) for x in e[1]))
    raise ValueError(f"unknown encoded type {e!r}")


# ------------------------------------------------------------------------------------ the record


def load_signatures(path: str | Path = SIGNATURES_FILE) -> list[KernelSignature]:
    """The recorded signatures ([] when the file is missing: then runs compile as they go)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError:
        return []
    out = []
    for raw in text.splitlines():
        if not raw.strip() or raw.startswith("#"):
            continue
        module, function, args, seconds = raw.split("\t")
        out.append(KernelSignature(module, function, ast.literal_eval(args), float(seconds)))
    return out


def _dispatcher(sig: KernelSignature):
    """The kernel of ``sig``: an attribute of its module."""
    return getattr(importlib.import_module(sig.module), sig.function)


def _kernel_dispatchers(module_names: Iterable[str]) -> list[tuple[str, str, Any]]:
    """(module, name, dispatcher) of every kernel defined in the given modules."""
    from numba.core.dispatcher import Dispatcher

    def own(v: Any, name: str) -> bool:
        py = getattr(v, "py_func", None)
        return isinstance(v, Dispatcher) and py is not None and py.__module__ == name

    out = []
    for name in module_names:
        mod = importlib.import_module(name)
        for attr, v in sorted(vars(mod).items()):
            if own(v, name):
                out.append((name, attr, v))
    return out


def record_signatures(
    run: Callable[[], Any], path: str | Path = SIGNATURES_FILE, seconds: dict[tuple[str, str], float] | None = None
) -> list[KernelSignature]:
    """Call ``run`` (e.g. a pipeline run of the bundled log), then write every signature the kernel modules
    compiled to ``path``; ``seconds`` gives each (module, function) its measured compile time."""
    run()
    modules = sorted(
        m for m in list(sys.modules) if m.startswith("holoslam.") and _is_kernel_module(m)
    )
    sigs = []
    for module, name, disp in _kernel_dispatchers(modules):
        for s in disp.signatures:
            try:
                args = tuple(_encode(t) for t in s)
            except ValueError:
                continue
            sigs.append(KernelSignature(module, name, args, (seconds or {}).get((module, name), 0.0)))
    header = (
        "# holoslam.warmup: the kernel signatures a run of the bundled household log compiles "
        "(module, function, argument types, compile seconds when recorded).\n"
        "# Written by: python benchmarks/bench_jit_compile.py --record\n"
    )
    Path(path).write_text(header + "".join(s.line() + "\n" for s in sigs), encoding="utf-8")
    return sigs


def _is_kernel_module(name: str) -> bool:
    from holoslam._jit import takes_policy

    mod = sys.modules.get(name)
    path = getattr(mod, "__file__", None)
    return isinstance(path, str) and takes_policy(path)


# ------------------------------------------------------------------------------------ compiling


def _cached(disp: Any, argtypes: tuple) -> bool | None:
    """Whether numba's on-disk cache holds ``disp`` for ``argtypes`` (None when this numba cannot say)."""
    try:
        cache = disp._cache
        key = cache._index_key(argtypes, disp.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # numba's private cache API changed: unknown, not an error
        return None


def pending(signatures: list[KernelSignature] | None = None) -> list[KernelSignature]:
    """The recorded signatures missing from numba's cache (imports the kernel modules: ~0.5 s)."""
    out = []
    for sig in load_signatures() if signatures is None else signatures:
        try:
            disp = _dispatcher(sig)
            argtypes = tuple(_decode(a) for a in sig.args)
        except (ImportError, AttributeError, ValueError):
            continue  # a record older than the code: nothing to compile ahead
        if _cached(disp, argtypes) is False:
            out.append(sig)
    return out


def _compile_module(sigs: list[KernelSignature]) -> list[tuple[str, str, float, str]]:
    """Compile one module's signatures in this process: (module, function, CPU seconds, error or "")."""
    out = []
    for sig in sigs:
        t0 = time.process_time()  # CPU seconds: on a shared machine wall time would count the neighbours too
        err = ""
        try:
            _dispatcher(sig).compile(tuple(_decode(a) for a in sig.args))
        except Exception as e:  # a stale record entry: the run compiles what it needs on its own
            err = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
        out.append((sig.module, sig.function, time.process_time() - t0, err))
    return out


def _pool_context() -> Any:
    """The compile pool's start method: ``fork`` on Linux while this process runs one thread (a worker starts
    with the kernel modules imported and numba's compiler set up: the household's first run compiles with
    ~2.5 s less CPU, 21.7 against 24.3 s, and ends ~1.5 s sooner on 2 cores), else ``spawn`` (a fresh
    interpreter: forking a threaded process can copy a lock held by another thread; macOS does not fork
    safely). No kernel runs ``parallel=True``, so no threading layer is copied."""
    import multiprocessing
    import threading

    fork = sys.platform.startswith("linux") and threading.active_count() == 1
    return multiprocessing.get_context("fork" if fork else "spawn")


def warm_up(
    signatures: list[KernelSignature] | None = None, workers: int | None = None
) -> list[tuple[str, str, float, str]]:
    """Compile the given (default: the pending) signatures into numba's cache, one kernel module per task of
    a process pool of ``workers`` (default: the cores; 1 compiles in this process). Returns (module, function,
    seconds, error) per signature, in the order compiled."""
    sigs = pending() if signatures is None else signatures
    if not sigs:
        return []
    by_module: dict[str, list[KernelSignature]] = {}
    for s in sigs:
        by_module.setdefault(s.module, []).append(s)
    # the longest modules first, so the pool's last task is a short one
    groups = sorted(by_module.values(), key=lambda g: -sum(s.seconds for s in g))
    workers = workers or os.cpu_count() or 1
    if workers <= 1 or len(groups) == 1:
        return [r for g in groups for r in _compile_module(g)]
    with ProcessPoolExecutor(max_workers=min(workers, len(groups)), mp_context=_pool_context(),
                             initializer=_compile_worker, initargs=(0,)) as pool:
        return [r for rs in pool.map(_compile_module, groups) for r in rs]


# the kernel modules local SLAM calls from its first scan: a first run waits for them, then runs while the rest
# compiles in the background; the stages that call the others wait for theirs (``wait_for_kernels``: the loop
# search and the wide search for the branch and bound's, the maps stages for theirs) instead of compiling them a
# second time beside the pool
FRONT_END = ("holoslam.submaps._grid_fast", "holoslam.submaps._fast", "holoslam._common_fast")
#: after ``FRONT_END``, the kernel modules in the order a run first calls them: the scan features and the anchor
#: graph (the front end's first finished submap), the branch and bound (its first loop search), then the maps'
NEEDED_NEXT = (("holoslam.submaps._features_fast", "holoslam.submaps._graph_fast"), ("holoslam.submaps",))

#: module -> its compile task in the first run's pool (``compile_in_background``), until the task is done
_BACKGROUND: dict[str, Any] = {}


def wait_for_kernels(*prefixes: str) -> None:
    """Block until the first run's pool has compiled the kernel modules named by ``prefixes`` (at once when no
    pool compiles, or when those are done): otherwise the caller would compile them itself, a second time."""
    if not _BACKGROUND:
        return
    from concurrent.futures import wait

    # a snapshot: the loop search's and the keyframe stage's threads call this at once, and pop below
    mine = {m: f for m, f in list(_BACKGROUND.items()) if m.startswith(prefixes)}
    wait(mine.values())  # done, failed or cancelled: a kernel not compiled is compiled by the caller on first call
    for module in mine:
        _BACKGROUND.pop(module, None)


def compile_in_background(
    signatures: list[KernelSignature], workers: int | None = None, wait_for: tuple[str, ...] = FRONT_END
) -> ProcessPoolExecutor:
    """Compile ``signatures`` in a process pool of ``workers`` (default: the cores), one kernel module per
    task, the modules named by the prefixes ``wait_for`` first (the largest first); return once those are in
    numba's cache, with the rest still compiling. The caller runs meanwhile (numba reads its cache index at
    each compile: a kernel the pool has finished is loaded, one it has not is compiled by the caller) and shuts
    the pool down (``shutdown(wait=True)``) when its run is over."""
    from concurrent.futures import wait

    by_module: dict[str, list[KernelSignature]] = {}
    for s in signatures:
        by_module.setdefault(s.module, []).append(s)

    def first(module: str) -> bool:
        return module.startswith(wait_for)

    # the modules waited for first, then in the order the run first calls them (``NEEDED_NEXT``), then the rest;
    # the largest first within each
    def rank(module: str) -> int:
        if first(module):
            return 0
        return 1 + next((i for i, p in enumerate(NEEDED_NEXT) if module.startswith(p)), len(NEEDED_NEXT))

    groups = sorted(by_module.values(), key=lambda g: (rank(g[0].module), -sum(s.seconds for s in g)))
    context = _pool_context()
    if context.get_start_method() == "fork":
        _set_up_compiler()
    pool = ProcessPoolExecutor(max_workers=workers or os.cpu_count() or 1, mp_context=context,
                               initializer=_compile_worker, initargs=(BACKGROUND_NICE,))
    futures = [(pool.submit(_compile_module, g), first(g[0].module)) for g in groups]
    _BACKGROUND.clear()
    _BACKGROUND.update({g[0].module: f for g, (f, _w) in zip(groups, futures, strict=True)})
    wait([f for f, w in futures if w])
    return pool


#: the niceness the first run's compile processes take (``nice``: 0 normal, 19 the lowest; 10 is the ``nice``
#: command's own default): on a machine whose cores the run and the pool share, the run keeps its pace and the
#: pool takes what it leaves (the stages that need a kernel still compiling wait for it, and the pool then has
#: the cores). The household's first run on 2 cores: 21.0 -> 20.3 s, medians of 3 alternated (19: 20.8 s)
BACKGROUND_NICE = 10


def _compile_worker(nice: int) -> None:
    """A compile pool's initializer: lower the worker's priority by ``nice`` (where the system allows; the
    first run's pool: ``BACKGROUND_NICE``) and make its numba quicker (``holoslam._numba_worker.quicken``)."""
    if nice:
        try:
            os.nice(nice)
        except (AttributeError, OSError):  # no ``nice`` (Windows) or not permitted: the run's priority
            pass
    from holoslam._numba_worker import quicken

    quicken()


def _set_up_compiler() -> None:
    """Set numba's code generator up in this process (its lowering registries: ~0.4 s of CPU, paid by the first
    compile or the first cached kernel loaded in a process) before it forks the compile pool: the workers
    inherit it instead of each paying it, and this process pays it no later than its first kernel."""
    from numba.core.registry import cpu_target

    cpu_target.target_context.refresh()


def estimate_seconds(sigs: list[KernelSignature], workers: int | None = None) -> float:
    """Compile seconds of ``sigs`` as recorded, spread over ``workers`` processes (default: the cores)."""
    workers = workers or os.cpu_count() or 1
    return sum(s.seconds for s in sigs) / max(1, min(workers, len({s.module for s in sigs}) or 1))
