"""holoslam.warmup: the recorded kernel signatures resolve to today's kernels and decode to numba types, and
compiling one writes numba's cache (what ``holoslam warmup`` and the first run rely on)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from repo_paths import REPO

from holoslam import warmup


def test_record_resolves_to_kernels_of_the_run():
    sigs = warmup.load_signatures()
    assert len(sigs) >= 40  # a household run compiles ~56 signatures of 10 kernel modules
    modules = {s.module for s in sigs}
    assert {"holoslam.submaps._grid_fast", "holoslam.maps._thin_fast", "holoslam.planning._fast.build"} <= modules
    for s in sigs:
        disp = warmup._dispatcher(s)  # a renamed or removed kernel fails here: re-record the file
        assert hasattr(disp, "compile"), s
        argtypes = tuple(warmup._decode(a) for a in s.args)
        assert len(argtypes) == len(disp.py_func.__code__.co_varnames[: disp.py_func.__code__.co_argcount]), s
        assert s.seconds >= 0.0


def test_types_round_trip():
    from numba import typeof

    values = [np.zeros((2, 3), np.float32), np.zeros(4, np.int64)[::2], np.asfortranarray(np.zeros((2, 2))),
              1.5, 3, True, (1.0, 2.0), (1, 2.0), None]
    for v in values:
        t = typeof(v)
        assert warmup._decode(warmup._encode(t)) == t
    ro = np.zeros(3)
    ro.flags.writeable = False
    assert warmup._decode(warmup._encode(typeof(ro))) == typeof(ro)


def _in_child(code: str, cache) -> list[str]:
    """``code`` run by a fresh interpreter with numba's cache in the empty folder ``cache``: its printed words."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def test_compiling_a_signature_fills_the_cache(tmp_path):
    # in a child process with an empty numba cache: the kernel is pending, compiled, then cached
    code = (
        "from holoslam import warmup\n"
        "sig = next(s for s in warmup.load_signatures() if s.module == 'holoslam.maps._raycast_fast')\n"
        "before = len(warmup.pending([sig]))\n"
        "done = warmup.warm_up([sig], workers=1)\n"
        "print(before, len(done), repr(done[0][3]), len(warmup.pending([sig])))\n"
    )
    assert _in_child(code, tmp_path) == ["1", "1", "''", "0"]
    assert any(tmp_path.rglob("*.nbi"))


def test_a_stage_waits_for_the_pools_compile_of_its_kernels_instead_of_compiling_them_again():
    """``wait_for_kernels``: blocks until the first run's pool has finished the modules named (then forgets them),
    leaves the others waiting, and returns at once when no pool compiles."""
    import threading
    import time
    from concurrent.futures import Future

    from holoslam import warmup

    maps, submaps = Future(), Future()
    warmup._BACKGROUND.clear()
    warmup._BACKGROUND.update({"holoslam.maps._thin_fast": maps, "holoslam.submaps._bnb_fast": submaps})
    try:
        threading.Timer(0.2, maps.set_result, ([],)).start()
        t0 = time.perf_counter()
        warmup.wait_for_kernels("holoslam.maps", "holoslam.planning")
        assert time.perf_counter() - t0 >= 0.15 and maps.done()
        assert list(warmup._BACKGROUND) == ["holoslam.submaps._bnb_fast"]  # not waited for, still there
        submaps.set_exception(RuntimeError("a compile failed"))  # the caller then compiles it on first call
        warmup.wait_for_kernels("holoslam.submaps")
        assert not warmup._BACKGROUND
    finally:
        warmup._BACKGROUND.clear()
    t0 = time.perf_counter()
    warmup.wait_for_kernels("holoslam.maps")
    assert time.perf_counter() - t0 < 0.05


def test_the_pool_forks_a_single_threaded_process_on_linux_and_compiles_there(tmp_path):
    """``_pool_context``: ``fork`` on Linux while one thread runs (the workers start with numba set up), ``spawn``
    once another thread runs (a fork could copy a lock that thread holds); a forked pool fills numba's cache."""
    code = (
        "import threading\n"
        "from holoslam import warmup\n"
        "alone = warmup._pool_context().get_start_method()\n"
        "stop = threading.Event()\n"
        "t = threading.Thread(target=stop.wait)\n"
        "t.start()\n"
        "beside = warmup._pool_context().get_start_method()\n"
        "stop.set()\n"
        "t.join()\n"
        "sigs = [s for s in warmup.load_signatures() if s.module in "
        "('holoslam.maps._raycast_fast', 'holoslam.submaps._graph_fast')]\n"
        "done = warmup.warm_up(sigs, workers=2)\n"
        "print(alone, beside, len(sigs), sum(not d[3] for d in done), len(warmup.pending(sigs)))\n"
    )
    alone, beside, n, compiled, left = _in_child(code, tmp_path)
    assert (alone, beside) == ("fork" if sys.platform.startswith("linux") else "spawn", "spawn")
    assert int(n) >= 2 and int(compiled) == int(n) and left == "0"


@pytest.mark.skipif(not hasattr(os, "nice"), reason="no process priorities here")
def test_the_first_runs_pool_compiles_at_a_lower_priority_than_the_run(tmp_path):
    """``compile_in_background``: the workers take ``BACKGROUND_NICE`` more niceness than the run (capped at 19),
    so the run keeps its pace; the kernels waited for are cached when it returns."""
    code = (
        "import os\n"
        "from holoslam import warmup\n"
        "sigs = [s for s in warmup.load_signatures() if s.module == 'holoslam.submaps._graph_fast']\n"
        "pool = warmup.compile_in_background(sigs, workers=1, wait_for=('holoslam.submaps._graph_fast',))\n"
        "left = len(warmup.pending(sigs))\n"
        "worker = pool.submit(os.nice, 0).result()\n"
        "pool.shutdown(wait=True)\n"
        "print(os.nice(0), worker, left, warmup.BACKGROUND_NICE)\n"
    )
    run, worker, left, step = map(int, _in_child(code, tmp_path))
    assert step > 0 and worker == min(19, run + step) and worker > run
    assert left == 0

