"""What compiling holoslam's numba kernels costs, per kernel, and what ``holoslam warmup`` saves the first run.

Each measurement is a child process with its own empty numba cache (``NUMBA_CACHE_DIR`` in a temporary folder),
so nothing compiled before counts:

1. ``--record``: a pipeline run of the bundled household log records the kernel signatures it compiles
   (``holoslam/_kernel_signatures.txt``, read by ``holoslam warmup`` and the first run), then a serial compile of
   them with the workers' numba measures each one's seconds, written into the record.
2. Per kernel: the serial compile (one process, with the numba of the pools' workers), the table of the
   slowest signatures and the total per module.
3. The whole warm-up (``holoslam.warmup.warm_up``): one process with numba as it is, one with the workers'
   numba (``holoslam._numba_worker.quicken``), and N processes (one kernel module per task), medians of
   ``--repeats`` interleaved, wall and CPU seconds.

    python benchmarks/bench_jit_compile.py [--record] [--repeats 1] [--workers 2] [--top 25]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable

RECORD = """
from holoslam.warmup import record_signatures
from holoslam.pipeline import run
from holoslam.io.datasets import bundled_household_log
sigs = record_signatures(lambda: run(bundled_household_log()))
print(len(sigs))
"""

# argv: the processes; "quick" to compile serially with the numba of the pools' workers (holoslam._numba_worker),
# "plain" with numba as it is (a pool's workers are always quick)
COMPILE = """
import json, resource, sys, time
from holoslam.warmup import load_signatures, warm_up
if sys.argv[2] == "quick":
    from holoslam._numba_worker import quicken
    quicken()
t0 = time.perf_counter()
c0 = time.process_time()
done = warm_up(load_signatures(), workers=int(sys.argv[1]))
pool = resource.getrusage(resource.RUSAGE_CHILDREN)  # the pool's workers, ended
cpu = time.process_time() - c0 + pool.ru_utime + pool.ru_stime
print(json.dumps({"wall": time.perf_counter() - t0, "cpu": cpu, "done": done}))
"""


def _child(code: str, *args: str) -> str:
    with tempfile.TemporaryDirectory(prefix="holoslam-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(REPO)}
        out = subprocess.run([PY, "-c", code, *args], env=env, cwd=REPO, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"child failed:\n{out.stderr[-3000:]}")
    return out.stdout.strip().splitlines()[-1]


def record() -> None:
    t0 = time.perf_counter()
    n = _child(RECORD)
    print(f"recorded {n} kernel signatures of a household run ({time.perf_counter() - t0:.1f} s, cold cache)")
    write_seconds()


def write_seconds() -> None:
    from holoslam.warmup import SIGNATURES_FILE, load_signatures

    # with the numba of the pools' workers, which compile the record in a first run and in ``holoslam warmup``:
    # the seconds the first run's notice estimates from
    serial = json.loads(_child(COMPILE, "1", "quick"))
    seconds: dict[tuple[str, str, str], float] = {}
    for module, function, s, _err in serial["done"]:
        seconds[(module, function)] = seconds.get((module, function), 0.0) + s
    sigs = load_signatures()
    # a kernel with several signatures: its measured seconds spread evenly over them
    count: dict[tuple[str, str], int] = {}
    for s in sigs:
        count[(s.module, s.function)] = count.get((s.module, s.function), 0) + 1
    lines = SIGNATURES_FILE.read_text(encoding="utf-8").splitlines(keepends=True)
    header = [ln for ln in lines if ln.startswith("#")]
    body = [
        s.__class__(s.module, s.function, s.args, seconds.get((s.module, s.function), 0.0) / count[(s.module, s.function)]).line() + "\n"
        for s in sigs
    ]
    SIGNATURES_FILE.write_text("".join(header + body), encoding="utf-8")
    print(f"serial compile {serial['wall']:.1f} s; seconds written to {SIGNATURES_FILE.relative_to(REPO)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", action="store_true", help="re-record holoslam/_kernel_signatures.txt first")
    ap.add_argument("--seconds", action="store_true", help="re-measure the record's compile seconds only")
    ap.add_argument("--repeats", type=int, default=1, help="serial vs parallel warm-ups (0: none)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--top", type=int, default=25)
    a = ap.parse_args()
    if a.record:
        record()
    elif a.seconds:
        write_seconds()
    if a.repeats < 1:
        return
    runs = {"1 process, numba as it is": (1, "plain"), "1 process, a worker's numba": (1, "quick"),
            f"{a.workers} processes (workers)": (a.workers, "quick")}
    walls: dict[str, list[float]] = {k: [] for k in runs}
    cpus: dict[str, list[float]] = {k: [] for k in runs}
    last: dict = {}
    for _ in range(a.repeats):
        for name, (w, kind) in runs.items():  # interleaved
            r = json.loads(_child(COMPILE, str(w), kind))
            walls[name].append(r["wall"])
            cpus[name].append(r["cpu"])
            if (w, kind) == (1, "quick"):
                last = r
    rows = sorted(last["done"], key=lambda d: -d[2])
    per_module: dict[str, float] = {}
    for module, _f, s, _e in rows:
        per_module[module] = per_module.get(module, 0.0) + s
    print(f"\nslowest kernel signatures (serial compile, CPU s, callees compiled inside their first caller; {len(rows)} in all)")
    print(f"{'module':<34} {'kernel':<28} {'s':>7}")
    for module, function, s, err in rows[: a.top]:
        print(f"{module:<34} {function:<28} {s:7.2f}{'  ' + err if err else ''}")
    print(f"\n{'module':<34} {'s':>7}")
    for module, s in sorted(per_module.items(), key=lambda kv: -kv[1]):
        print(f"{module:<34} {s:7.2f}")
    print(f"\nwhole warm-up, cold cache, medians of {a.repeats} interleaved (CPU: the process's and its "
          "workers')")
    ref = statistics.median(walls[next(iter(runs))])
    print(f"{'':<34} {'wall s':>7} {'x wall':>7} {'CPU s':>7}")
    for name in runs:
        w = statistics.median(walls[name])
        print(f"{name:<34} {w:7.1f} {w / ref:7.2f} {statistics.median(cpus[name]):7.1f}")


if __name__ == "__main__":
    main()
