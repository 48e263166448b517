"""A compile worker's numba, quicker by exact equivalents of three of its internals, two lighter pass levels, no
SSA reconstruction and a rarer garbage collector.

Only the processes of :mod:`holoslam.warmup`'s compile pools call :func:`quicken` (their initializer): a user's
process keeps numba as it is. Each replacement gives what numba's own code gives, for less CPU, and each is
skipped (numba left as it is, the function returns False) when this numba lacks what it rests on:

* :func:`quicker_flags`: ``TargetConfig.values`` and ``__hash__`` without rebuilding a dict of all ~40 options;
* :func:`one_function_pass_manager`: the function passes run on a module's functions by one pass manager,
  where numba builds one per function; the machine code is the same (the household's 71 cached kernels: the
  same object code, byte for byte, as numba's own, less the 2 whose bytes differ between two runs of numba's).
  :func:`quicken` also runs those passes at ``FUNCTION_PASS_OPT`` (-O1) and the module passes at
  ``MODULE_PASS_OPT`` (-O2) where numba runs both at ``-O3``: the deviations from numba's own output (its
  machine code, not the kernels' results: measured at the two settings);
* :func:`overloads_by_inherited_flags`: an ``@overload``'s implementation (``np.empty``, ``max``...) compiled once
  per argument types and per value of the options a compile inherits from its caller, instead of once per whole
  set of the caller's options: the others (``nogil``, the wrappers) never reach the implementation's compile;
* :func:`without_ssa`: numba's functions typed and lowered without its SSA reconstruction, as numba compiles
  what it inlines (one type per variable, unified over its assignments): a deviation in the IR numba hands to
  LLVM, like the pass levels; the household's kernels all compile so and every output of its run is the same,
  byte for byte;
* :func:`collect_rarely`: Python's cyclic garbage collector left to the objects the compiles make
  (``gc.freeze`` of what the worker inherited and imported) and run rarely (``COLLECTOR_THRESHOLDS``): numba's
  compiles make objects by the million, and the default thresholds traverse them all again and again.

Measured: :func:`quicken`.
"""

from __future__ import annotations

import gc
import inspect
import re
from collections.abc import Mapping
from typing import Any

__all__ = ["FUNCTION_PASS_OPT", "MODULE_PASS_OPT", "quicken", "quicker_flags", "one_function_pass_manager",
           "overloads_by_inherited_flags", "module_passes_at", "COLLECTOR_THRESHOLDS", "collect_rarely", "without_ssa"]


#: the optimisation level of the per-function passes numba runs on each function as its IR is added to a library
#: (numba: its ``NUMBA_OPT``, 3), in a compile worker: they only prepare the linked final module for the module
#: passes below, which every kernel's machine code comes from. At -O1 the household's recorded kernels compile
#: in 4.6 % less CPU (18.68 -> 17.81 s serially, medians of 5 alternated, 2026-12-07; 18.27 -> 17.84 and 18.71
#: -> 17.48 s in two more such comparisons), its warm run is as quick (6.93 -> 6.69 s wall, medians of 6
#: alternated with each cache), intel at full rate too (30.6 -> 29.8 s), and every output of the household's run
#: is byte-identical but the run's timestamps. -O0, or no function passes at all, compiled quicker still but ran
#: the household 5-15 % slower.
FUNCTION_PASS_OPT = 1

#: the optimisation level of numba's module passes on a kernel's final module (numba: ``NUMBA_OPT``, 3), in a
#: compile worker; the machine code generator, set up before the workers fork, keeps numba's level. At -O2 the
#: record compiles in 3 % less CPU (17.52 -> 16.98 s serially, medians of 5 alternated, with the function passes
#: at -O1), the household's warm run is as quick (7.04 -> 6.75 s, medians of 6), intel at full rate too (30.1 ->
#: 29.3 s, 2 each) with the same trajectory, byte for byte. Loop unrolling off as well saved 1.1 s more but ran
#: intel 5 % slower (CPU): not taken.
MODULE_PASS_OPT = 2

#: the cyclic garbage collector's thresholds in a compile worker (Python's: 700, 10, 10): a young collection
#: every 10,000 net allocations, the older generations practically never (a worker lives for one pool). With
#: Python's own, the collector took 2.6-2.8 s of the household's record compiled serially (16.3-16.7 s CPU,
#: ``gc.callbacks``, 2026-12-07), 2.3 s of it in full collections of numba's ever larger heap; at these, 0.3 s
#: (14.2 s CPU) for a peak of 368 MB instead of 251 MB. Collecting older generations at all cost ~0.7 s more
#: (10,000, 100, 1,000: 0.9 s, 329 MB); no collector at all, 450 MB.
COLLECTOR_THRESHOLDS = (10_000, 1_000, 1_000)


def quicken() -> dict[str, bool]:
    """Apply the three replacements in this process (a compile worker's), the function passes at
    ``FUNCTION_PASS_OPT`` and the module passes at ``MODULE_PASS_OPT`` (neither above a lower ``NUMBA_OPT`` the
    user set; ``NUMBA_OPT=max`` left as it is), no SSA pass and the collector's thresholds; which ones took. The
    household's recorded kernels compiled serially (``python benchmarks/bench_jit_compile.py --repeats 3``):
    18.6 s CPU with numba as it is, 16.8 s with the three replacements (2026-12-06; ``quicker_flags`` alone: 19.8
    -> 18.9 s, medians of 6 alternated, an earlier day); 17.4 against 12.3 s with all of them (2026-12-07)."""
    from numba.core import config

    level = getattr(config, "OPT", 3)
    user_max = bool(getattr(level, "is_opt_max", False))
    function_opt = None if user_max else min(FUNCTION_PASS_OPT, level)
    return {
        # before any compile: a default of numba's flags, which quicker_flags' ``values`` caches at its first call
        "without_ssa": without_ssa(),
        "quicker_flags": quicker_flags(),
        "one_function_pass_manager": one_function_pass_manager(function_opt),
        "overloads_by_inherited_flags": overloads_by_inherited_flags(),
        "module_passes_at": False if user_max else module_passes_at(min(MODULE_PASS_OPT, level)),
        "collect_rarely": collect_rarely(),
    }


def without_ssa() -> bool:
    """numba's compiles in this process without its SSA reconstruction (``Flags.enable_ssa``'s default off: the
    pass numba skips when it compiles a function to inline); False when this numba's flags lack the option. A
    kernel that would not type so fails in the worker and is compiled by the run as numba does. Measured on the
    household's record compiled serially: 16.5 -> 15.6 s CPU (medians of 5 alternated, 2026-12-07), the same
    outputs of its run byte for byte but the timings, its warm run as quick (6.26 -> 6.24 s, medians of 6
    alternated with each cache), intel at full rate too (27.3 -> 26.4 s, 2 each) with the same trajectory."""
    from numba.core.compiler import Flags

    option = getattr(Flags, "options", {}).get("enable_ssa")
    if option is None or not isinstance(getattr(option, "_default", None), bool):
        return False
    option._default = False  # numba's Option keeps its default in a slot, read by the flag's property
    return True


def collect_rarely(thresholds: tuple[int, int, int] = COLLECTOR_THRESHOLDS) -> bool:
    """The objects this process holds now moved out of the cyclic collector's reach (``gc.freeze``: a forked
    worker's inheritance and its imports, never garbage for the pool's lifetime, and not traversed, so their
    pages stay shared with the parent), and the collector's thresholds set to ``thresholds``."""
    gc.freeze()
    gc.set_threshold(*thresholds)
    return True


def module_passes_at(level: int) -> bool:
    """numba's optimisation level in this process (``numba.core.config.OPT``, which its module pass managers read
    at every compile) set to ``level``; False when this numba keeps it elsewhere. The code generator already set
    up (``warmup._set_up_compiler``, before a pool forks) keeps the level it was made with."""
    from numba.core import config

    kind = getattr(config, "_OptLevel", None)
    if kind is None or not isinstance(getattr(config, "OPT", None), kind):
        return False
    setattr(config, "OPT", kind(int(level)))  # noqa: B010 - set at run time in numba, untyped
    return True


def quicker_flags() -> bool:
    """numba's ``TargetConfig.values`` and ``__hash__`` replaced by exact equivalents. Its compiler hashes and
    compares the flags of the compile under way at every overload it resolves (``_OverloadFunctionTemplate.
    _get_impl``'s cache key), and both methods build a dict of all ~40 options through their properties each
    time: ~7 % of a compile's CPU (cProfile of the household's kernels). ``values`` is the class's defaults
    updated with the options set (what each property's getter returns); ``__hash__`` hashes the sorted option
    names, as numba's does (``sorted`` of the values' dict sorts its keys: one hash per class)."""
    from numba.core import targetconfig

    cls = targetconfig.TargetConfig
    if getattr(cls, "_holoslam_quick", False):
        return True
    if not (isinstance(getattr(cls, "options", None), Mapping) and "_values" in getattr(cls, "__slots__", ())):
        return False
    defaults: dict[type, dict[str, Any]] = {}
    hashes: dict[type, int] = {}

    def values(self: Any) -> dict[str, Any]:
        kind = type(self)
        d = defaults.get(kind)
        if d is None:
            d = defaults[kind] = {k: o.default for k, o in kind.options.items()}
        return {**d, **self._values}

    def __hash__(self: Any) -> int:
        kind = type(self)
        h = hashes.get(kind)
        if h is None:
            h = hashes[kind] = hash(tuple(sorted(kind.options)))
        return h

    for name, method in (("values", values), ("__hash__", __hash__), ("_holoslam_quick", True)):
        setattr(cls, name, method)
    return True


def one_function_pass_manager(opt: int | None = None) -> bool:
    """``CPUCodeLibrary._optimize_functions`` with one function pass manager for the module's functions (numba's
    builds a pass builder and a manager for each, ~3,300 for the household's kernels) and no run on a mere
    declaration (no body: a pass has nothing to do). Same passes, same options, same order; ``opt`` (0-3) sets
    their optimisation level instead of numba's (``FUNCTION_PASS_OPT``). Once per process: a later call keeps
    the level the first one set."""
    from numba.core import codegen

    cls = codegen.CPUCodeLibrary
    if getattr(cls, "_holoslam_one_fpm", False):
        return True
    options = {} if opt is None else {"opt": int(opt)}
    if not hasattr(codegen.CPUCodegen, "_function_pass_manager"):
        return False
    # the replacement rests on numba's body being exactly this: a new manager per function, run on it
    src = _source(getattr(cls, "_optimize_functions", None))
    if "_function_pass_manager()" not in src or "fpm.run(func, pb)" not in src:
        return False

    def _optimize_functions(self: Any, ll_module: Any) -> None:
        ll_module.data_layout = self._codegen._data_layout
        fpm, pb = self._codegen._function_pass_manager(**options)
        for func in ll_module.functions:
            if not func.is_declaration:
                fpm.run(func, pb)

    setattr(cls, "_optimize_functions", _optimize_functions)  # noqa: B010 - numba's class, typed without them
    setattr(cls, "_holoslam_one_fpm", True)  # noqa: B010
    return True


def _source(obj: Any) -> str:
    """numba's source of ``obj`` ("" when it cannot be read: the replacement resting on it is then skipped)."""
    try:
        return inspect.getsource(obj)
    except (OSError, TypeError):
        return ""


def _inherited_options() -> tuple[str, ...] | None:
    """The options a CPU compile takes from its caller's when it does not set them (``CPUTargetOptions.finalize``'s
    ``inherit_if_not_set``), read from numba's source; None when it cannot be read."""
    from numba.core import cpu

    src = _source(getattr(getattr(cpu, "CPUTargetOptions", None), "finalize", None))
    names = tuple(re.findall(r"inherit_if_not_set\(\s*[\"'](\w+)[\"']", src))
    return names or None


def overloads_by_inherited_flags() -> bool:
    """``_OverloadFunctionTemplate._get_impl`` keyed by the caller's inherited options (``_inherited_options``:
    ``nrt``, ``fastmath``, ``error_model``, ``forceinline`` in numba 0.68) instead of all of its flags. numba keys
    the implementation it builds for an ``@overload`` by the whole flags of the compile that calls it, so a call
    of ``np.empty(n, np.int64)`` from a kernel and from a helper without a CPython wrapper (``JIT_INNER``), or
    from one of numba's own jitted functions (no ``nogil``), compiles the same implementation again (~1 s of the
    household's ~19 s serially): the options that differ never reach that compile, which sets its own."""
    from numba.core import targetconfig
    from numba.core.typing import templates

    cls = getattr(templates, "_OverloadFunctionTemplate", None)
    if cls is None:
        return False
    if getattr(cls, "_holoslam_by_inherited", False):
        return True
    from numba.core.compiler import Flags

    inherited = _inherited_options()
    if inherited is None or not hasattr(cls, "_build_impl") or not set(inherited) <= set(Flags.options):
        return False
    # numba's body: the key of (context, args, kws, flags), a hit returned, else ``_build_impl(cache_key, ...)``
    if "cache_key = self.context, tuple(args), tuple(kws.items()), flags" not in _source(cls._get_impl):
        return False

    def value(v: Any) -> Any:  # an option's value as a hashable (fastmath's is a set of flags)
        encode = getattr(v, "encode", None)
        return encode() if callable(encode) and not isinstance(v, str) else v

    def _get_impl(self: Any, args: Any, kws: Any) -> Any:
        flags = targetconfig.ConfigStack.top_or_none()
        key = None if flags is None else tuple(value(getattr(flags, n)) for n in inherited)
        cache_key = self.context, tuple(args), tuple(kws.items()), key
        try:
            return self._impl_cache[cache_key]
        except KeyError:
            pass
        return self._build_impl(cache_key, args, kws)

    setattr(cls, "_get_impl", _get_impl)  # noqa: B010 - numba's class, typed without them
    setattr(cls, "_holoslam_by_inherited", True)  # noqa: B010
    return True
