"""The household demo's speed as a user sees it: whole ``holoslam run`` processes on the bundled log.

Printed, medians of ``--repeats`` (default 3), wall and CPU seconds (user + system of the child; the machine is
shared, CPU time measures the process, wall time its neighbours too), with the run's accuracy:

1. Warm runs (numba's cache filled) of this checkout against a reference checkout (``--ref``, default
   ``/work/ref0dc``: ``git worktree add --detach /work/ref0dc 0dc094a``, the commit of 2026-12-01 the issue
   measured against), interleaved; the goal is <= 1.2x the reference. Skipped when the reference is absent.
2. The first run after an install (an empty numba cache: ``NUMBA_CACHE_DIR`` in a fresh temporary folder, so
   the run compiles what it uses, in parallel, as ``holoslam run`` does when the cache lacks its kernels)
   against a warm run in the same cache; the goal is <= 2x.

    python benchmarks/bench_household_speed.py [--repeats 3] [--ref /work/ref0dc] [--no-first]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LOG = REPO / "datasets" / "household_small.mcap"


def run(checkout: Path, out: Path, env: dict[str, str] | None = None, quiet: bool = True) -> dict:
    """One whole ``holoslam run`` of the bundled log with ``checkout`` on the path: wall, CPU, accuracy.
    ``quiet`` False: without ``--quiet``, so that the run's notice of compiling (stderr) can be checked."""
    # bytecode written and read as an installed package's is (a shell with PYTHONDONTWRITEBYTECODE would make
    # every run compile each module it imports from source, the checkout with more modules paying more)
    env = {k: v for k, v in {**os.environ, **(env or {}), "PYTHONPATH": str(checkout)}.items()
           if k != "PYTHONDONTWRITEBYTECODE"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "holoslam.cli", "run", str(LOG), "-o", str(out)]
                       + (["--quiet"] if quiet else []),
                       env=env, cwd=out.parent, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.exit(f"{checkout}: holoslam run failed:\n{p.stderr[-2000:]}")
    acc = json.loads((out / "report.json").read_text())["accuracy"]
    return {
        "wall": wall,
        "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
        "anchors_mm": 1000 * acc["anchors"]["rmse_m"],
        "objects_mm": 1000 * acc["objects"]["rmse_m"],
        "coverage": acc["anchors"]["coverage95"],
        "said": "compiling holoslam's kernels" in p.stderr,
    }


def _med(rows: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in rows)


def _line(name: str, rows: list[dict], ref: list[dict] | None) -> str:
    w, c = _med(rows, "wall"), _med(rows, "cpu")
    ratio = "" if ref is None else f"{w / _med(ref, 'wall'):8.2f} {c / _med(ref, 'cpu'):7.2f}"
    return (f"{name:<34} {w:7.1f} {c:7.1f} {ratio:>16} {_med(rows, 'anchors_mm'):8.1f} "
            f"{_med(rows, 'objects_mm'):8.1f} {_med(rows, 'coverage'):6.3f}")


HEAD = f"{'run':<34} {'wall s':>7} {'cpu s':>7} {'x wall':>8} {'x cpu':>7} {'anch mm':>8} {'obj mm':>8} {'cov':>6}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ref", type=Path, default=Path("/work/ref0dc"))
    ap.add_argument("--no-first", action="store_true", help="skip the first-run measurement")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="holoslam-speed-") as tmp:
        t = Path(tmp)
        have_ref = (a.ref / "holoslam" / "__init__.py").is_file()
        run(REPO, t / "w")  # fill the caches (ours, and numba's) before timing warm runs
        if have_ref:
            run(a.ref, t / "r")
        cur: list[dict] = []
        ref: list[dict] = []
        for _ in range(a.repeats):
            cur.append(run(REPO, t / "w"))
            if have_ref:
                ref.append(run(a.ref, t / "r"))
        print(f"## warm household runs (bundled log, whole processes, interleaved, medians of {a.repeats})")
        print(HEAD)
        if have_ref:
            print(_line(f"reference {a.ref}", ref, ref))
        print(_line("this checkout", cur, ref or None))
        if have_ref:
            print("goal: warm <= 1.2x the reference's wall time")
        if a.no_first:
            return
        first: list[dict] = []
        warm: list[dict] = []
        for k in range(a.repeats):
            cache = t / f"numba{k}"
            cache.mkdir()
            env = {"NUMBA_CACHE_DIR": str(cache)}
            first.append(run(REPO, t / "f", env, quiet=False))
            warm.append(run(REPO, t / "f", env))
        print(f"\n## first run after an install (empty numba cache) against a warm one, medians of {a.repeats}")
        print(HEAD)
        print(_line("warm (same cache)", warm, warm))
        print(_line("first (compiles, in parallel)", first, warm))
        print(f"the first run said it was compiling: {sum(r['said'] for r in first)} of {len(first)}; "
              f"goal: first <= 2x warm")


if __name__ == "__main__":
    main()
