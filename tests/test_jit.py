"""holoslam's numba policy (``holoslam._jit``): the settings of the kernels, and a cached kernel recompiled
when a kernel file it calls into changes (numba alone looks at the caller's own file only)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from repo_paths import REPO

pytest.importorskip("numba")


def _run(tmp_path: Path, code: str) -> str:
    """Run ``code`` in a fresh interpreter (a new process loads kernels from the on-disk cache) with the
    probe modules in ``tmp_path`` importable; its stdout."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # the cache next to the probes
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(tmp_path)])
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env, cwd=tmp_path
    )
    return out.stdout.strip()


@pytest.mark.parametrize(
    ("imports", "call"), [("from probe_callee import f", "f()"), ("import probe_callee as m", "m.f()")]
)
def test_a_cached_kernel_is_rebuilt_when_a_kernel_it_calls_in_another_file_changes(tmp_path, imports, call):
    callee = textwrap.dedent(
        """
        import numba as nb
        from holoslam._jit import JIT

        @nb.njit(**JIT)
        def f():
            return 1
        """
    )
    (tmp_path / "probe_callee.py").write_text(callee)
    (tmp_path / "probe_caller.py").write_text(
        textwrap.dedent(
            f"""
            import numba as nb
            from holoslam._jit import JIT
            {imports}

            @nb.njit(**JIT)
            def g():
                return {call} + 10
            """
        )
    )
    show = "import probe_caller as c; print(c.g(), sum(c.g.stats.cache_hits.values()))"
    assert _run(tmp_path, show) == "11 0"  # compiled
    assert _run(tmp_path, show) == "11 1"  # loaded from the cache
    (tmp_path / "probe_callee.py").write_text(callee.replace("return 1", "return 2"))
    assert _run(tmp_path, show) == "12 0"  # the callee changed: recompiled, not the stale 11
    assert _run(tmp_path, show) == "12 1"


def test_the_planning_kernels_follow_the_policy():
    """Every kernel of the planner and the shared primitives is cached and releases the GIL; fastmath only on
    the one kernel that asks for it; each is cached by the policy's dependency-aware locator."""
    import numba as nb

    from holoslam import _common_fast, _jit
    from holoslam.planning._fast import astar, build, queries, smoothing, tiles

    assert _jit.LOCATORS_INSTALLED
    fast = set()
    for mod in (_common_fast, astar, build, queries, smoothing, tiles):
        for name, k in vars(mod).items():
            if not isinstance(k, nb.core.dispatcher.Dispatcher) or k.py_func.__module__ != mod.__name__:
                continue
            assert k._cache is not None and type(k._cache).__name__ != "NullCache", name
            assert isinstance(k._cache._impl.locator, _jit._DependencyStamp), name
            assert k.targetoptions["nogil"], name
            if k.targetoptions.get("fastmath"):
                fast.add(name)
    assert fast == {"_alt_finite"}
    # the query is compiled with the kernels of the files it calls into, so their sources stamp its cache
    deps = {Path(p).name for p in queries.query._cache._impl.locator._holoslam_deps}
    assert {"_jit.py", "astar.py", "smoothing.py", "tiles.py", "_common_fast.py"} <= deps


def test_stable_argsort_kernel_is_numpys_mergesort():
    """``_common_fast.argsort_stable`` (the branch and bound's and the line splitter's order) is
    ``np.argsort(kind="mergesort")``: same order, ties in index order, on floats and integers."""
    import numpy as np

    from holoslam._common_fast import argsort_stable

    rng = np.random.default_rng(2)
    for n in (0, 1, 2, 5, 64, 1025):
        for key in (rng.normal(size=n), rng.integers(0, 4, n).astype(np.float64), rng.integers(-3, 3, n)):
            assert np.array_equal(argsort_stable(key), np.argsort(key, kind="mergesort"))
            assert np.array_equal(argsort_stable(-key), np.argsort(-key, kind="mergesort"))
