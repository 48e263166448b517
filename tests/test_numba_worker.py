"""holoslam._numba_worker: a compile worker's numba gives what numba's own code gives, for less work, and a user's
process keeps numba as it is. Each case runs in a fresh interpreter (the replacements are process-wide)."""

from __future__ import annotations

import os
import subprocess
import sys

from repo_paths import REPO

from holoslam._numba_worker import COLLECTOR_THRESHOLDS, FUNCTION_PASS_OPT, MODULE_PASS_OPT


def _in_child(code: str, cache, *args: str) -> list[str]:
    """``code`` run by a fresh interpreter with numba's cache in the folder ``cache``: its printed words."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def _own_and_quick(code: str, tmp_path) -> tuple[list[str], list[str]]:
    """``code``'s printed words with numba as it is (argument "0") and with the worker's replacement ("1"), each in
    a fresh interpreter and its own empty numba cache."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    return _in_child(code, tmp_path / "a", "0"), _in_child(code, tmp_path / "b", "1")


def test_compile_workers_flags_methods_are_numbas_own_results(tmp_path):
    """``quicker_flags`` (a compile worker's): numba's ``Flags.values`` and ``hash`` give what numba's own
    methods give, for the default flags and for flags with options set (to their defaults too), copies equal
    and hashing alike; the parent process keeps numba's methods, its workers get the quick ones."""
    code = (
        "from numba.core.compiler import Flags\n"
        "from numba.core import targetconfig\n"
        "from holoslam import warmup, _numba_worker\n"
        "def cases():\n"
        "    a = Flags(); b = Flags(); b.nrt = True; b.error_model = 'numpy'; b.fastmath = True\n"
        "    c = Flags(); c.nrt = Flags.options['nrt'].default; d = b.copy(); d.fastmath = False\n"
        "    return a, b, c, d\n"
        "def facts():\n"
        "    fs = cases()\n"
        "    return [sorted(f.values().items(), key=str) for f in fs], [hash(f) for f in fs], "
        "[[x == y for y in fs] for x in fs]\n"
        "def quick():\n"
        "    return targetconfig.TargetConfig.values.__qualname__.startswith('quicker_flags')\n"
        "before = facts()\n"
        "pool = warmup.compile_in_background([], workers=1, wait_for=())\n"
        "worker = pool.submit(quick).result()\n"
        "pool.shutdown()\n"
        "parent = quick()\n"
        "ok = _numba_worker.quicker_flags()\n"
        "after = facts()\n"
        "print(worker, parent, ok, before == after, after[2][0][2], after[2][1][3])\n"
    )
    # c sets an option to its default: equal to the default flags (a), as numba's __eq__ says; d differs from b
    assert _in_child(code, tmp_path) == ["True", "False", "True", "True", "True", "False"]


def test_one_function_pass_manager_gives_numbas_machine_code(tmp_path):
    """``one_function_pass_manager``: a kernel with inner helpers and numpy calls (the ray caster) compiles to
    the same assembly as with numba's own function passes."""
    code = (
        "import hashlib, sys\n"
        "from holoslam import _numba_worker, warmup\n"
        "took = _numba_worker.one_function_pass_manager() if sys.argv[1] == '1' else 'off'\n"
        "sig = next(s for s in warmup.load_signatures() if s.function == 'cast_counts_into')\n"
        "disp = warmup._dispatcher(sig)\n"
        "types = tuple(warmup._decode(a) for a in sig.args)\n"
        "disp.compile(types)\n"
        "asm = disp.inspect_asm(types)\n"
        "print(took, len(asm) > 1000, hashlib.sha256(asm.encode()).hexdigest())\n"
    )
    own, quick = _own_and_quick(code, tmp_path)
    assert own[:2] == ["off", "True"] and quick[:2] == ["True", "True"]
    assert quick[2] == own[2]


_OVERLOADS = (
    "import sys\n"
    "import numba as nb, numpy as np\n"
    "from numba.core.typing import templates\n"
    "from holoslam import _numba_worker\n"
    "took = _numba_worker.overloads_by_inherited_flags() if sys.argv[1] == '1' else 'off'\n"
    "built = []\n"
    "own = templates._OverloadFunctionTemplate._build_impl\n"
    "def count(self, key, args, kws):\n"
    "    if 'empty' in str(getattr(self, 'key', '')):\n"
    "        built.append(str(args))\n"
    "    return own(self, key, args, kws)\n"
    "templates._OverloadFunctionTemplate._build_impl = count\n"
    "def body(n):\n"
    "    out = np.empty(n, np.int64)\n"
    "    for i in range(n):\n"
    "        out[i] = 2 * i\n"
    "    return out.sum()\n"
    "plain = nb.njit(body)\n"
    "released = nb.njit(nogil=True)(body)\n"
    "fast = nb.njit(fastmath=True)(body)\n"
    "a, b = plain(5), released(5)\n"
    "two = len(built)\n"
    "c = fast(5)\n"
    "print(took, a, b, c, two, len(built))\n"
)


def test_an_overload_is_built_once_for_callers_that_differ_only_in_options_it_does_not_inherit(tmp_path):
    """``overloads_by_inherited_flags``: ``np.empty(n, np.int64)`` called from a kernel and from one that releases
    the GIL is built once (numba's own key builds it twice), and again for a caller with ``fastmath`` (an option
    its compile inherits); every caller's result is right."""
    own, quick = _own_and_quick(_OVERLOADS, tmp_path)
    assert own == ["off", "20", "20", "20", "2", "3"]
    assert quick == ["True", "20", "20", "20", "1", "2"]


def test_quicken_takes_on_this_numba_and_leaves_the_importing_process_alone(tmp_path):
    """The pinned numba has what each replacement rests on (a newer one that lacks it is left as it is: then a
    replacement says False, and this test says which); importing holoslam replaces nothing."""
    code = (
        "import holoslam.warmup, holoslam.pipeline\n"
        "from numba.core import codegen\n"
        "from numba.core.typing import templates\n"
        "before = (getattr(codegen.CPUCodeLibrary, '_holoslam_one_fpm', False), "
        "getattr(templates._OverloadFunctionTemplate, '_holoslam_by_inherited', False))\n"
        "from holoslam import _numba_worker\n"
        "took = _numba_worker.quicken()\n"
        "print(*before, *(f'{k}={v}' for k, v in sorted(took.items())))\n"
    )
    assert _in_child(code, tmp_path) == [
        "False", "False", "collect_rarely=True", "module_passes_at=True", "one_function_pass_manager=True",
        "overloads_by_inherited_flags=True", "quicker_flags=True", "without_ssa=True",
    ]


def test_without_ssa_compiles_without_numbas_ssa_pass_to_the_same_result(tmp_path):
    """``without_ssa`` (a compile worker's): a kernel whose variable changes type (an int, then a float sum) is
    compiled without numba's SSA reconstruction and returns what numba's own compile returns; the flag's
    default is back to numba's in a process that did not call it."""
    code = (
        "import sys\n"
        "import numba as nb\n"
        "from numba.core.compiler import Flags\n"
        "from holoslam import _numba_worker\n"
        "took = _numba_worker.without_ssa() if sys.argv[1] == '1' else 'off'\n"
        "@nb.njit\n"
        "def f(n):\n"
        "    x = 0\n"
        "    for i in range(n):\n"
        "        x = x + 0.5 * i\n"
        "    return x\n"
        "r = f(7)\n"
        "passes = f.overloads[f.signatures[0]].metadata['pipeline_times']['nopython']\n"
        "print(took, r, any(k.endswith('_reconstruct_ssa') for k in passes), Flags().enable_ssa)\n"
    )
    own, quick = _own_and_quick(code, tmp_path)
    assert own == ["off", "10.5", "True", "True"]
    assert quick == ["True", "10.5", "False", "False"]


def test_a_compile_worker_collects_rarely_and_its_parent_as_before(tmp_path):
    """``collect_rarely`` in the first run's compile workers: the collector's thresholds are
    ``COLLECTOR_THRESHOLDS`` and what the worker held when it started is frozen out of its reach; the process
    that started the pool keeps its own thresholds and freezes nothing."""
    code = (
        "import gc\n"
        "from holoslam import warmup\n"
        "def facts():\n"
        "    return gc.get_threshold(), gc.get_freeze_count() > 0\n"
        "before = facts()\n"
        "pool = warmup.compile_in_background([], workers=1, wait_for=())\n"
        "worker = pool.submit(facts).result()\n"
        "pool.shutdown()\n"
        "print(repr(before).replace(' ', ''), repr(worker).replace(' ', ''), repr(facts()).replace(' ', ''))\n"
    )
    before, worker, after = _in_child(code, tmp_path)
    assert worker == repr((COLLECTOR_THRESHOLDS, True)).replace(" ", "")
    assert before == after and before.endswith(",False)") and before != worker


def test_a_workers_passes_run_at_its_levels_and_its_kernels_compute_the_same(tmp_path):
    """``quicken`` (a compile worker's) builds numba's LLVM passes at its levels (``FUNCTION_PASS_OPT``,
    ``MODULE_PASS_OPT``; numba's cheap inlining pass at 0 as numba's), not at numba's -O3; the ray caster so
    compiled counts the same cells, beam for beam, as compiled by numba as it is."""
    code = (
        "import hashlib, sys\n"
        "import numpy as np\n"
        "from numba.core import codegen\n"
        "from holoslam import _numba_worker\n"
        "levels = set()\n"
        "own = codegen.create_pass_builder\n"
        "def spy(tm, opt=2, **kw):\n"
        "    levels.add(str(int(opt)))\n"
        "    return own(tm, opt=opt, **kw)\n"
        "codegen.create_pass_builder = spy\n"
        "took = _numba_worker.quicken()['module_passes_at'] if sys.argv[1] == '1' else 'off'\n"
        "from holoslam.maps import _raycast_fast as rf\n"
        "rng = np.random.default_rng(7)\n"
        "n, h, w = 5000, 60, 80\n"
        "ox, oy = rng.uniform(-20, 100, n), rng.uniform(-20, 80, n)\n"
        "ex, ey = rng.uniform(-20, 100, n), rng.uniform(-20, 80, n)\n"
        "hits, misses = np.zeros(h * w, np.int32), np.zeros(h * w, np.int32)\n"
        "rf.cast_counts_into(ox, oy, ex, ey, rng.random(n) < 0.7, h, w, hits, misses)\n"
        "digest = hashlib.sha256(hits.tobytes() + misses.tobytes()).hexdigest()\n"
        "print(took, ','.join(sorted(levels)), int(misses.sum()) > 10000, digest)\n"
    )
    own, quick = _own_and_quick(code, tmp_path)
    assert own[:3] == ["off", "0,3", "True"]
    assert quick[:3] == ["True", f"0,{FUNCTION_PASS_OPT},{MODULE_PASS_OPT}", "True"]
    assert quick[3] == own[3]
