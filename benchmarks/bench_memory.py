"""Peak memory and run time of a long ``holoslam run``: a shared real log played several times end to end.

    .venv/bin/python benchmarks/bench_memory.py [--log intel] [--times 1 2] [--budget-mb 2000] [--write]

The issue's budget: a log of 80 minutes maps in under 2 GB. The shared logs are shorter (intel: 45 min), so the
log is played ``N`` times in a row in memory: the copies' stamps follow each other, and each copy's odometry
continues from where the last ended (``holoslam.derive.repeat``: the robot carried back to its start with its laser
on; local SLAM sees its scans stop fitting the map where the odometry puts them, starts afresh, and the global
loop search joins the copy to the first). Each row runs in a child process (this script with
``--child``) doing what ``holoslam run`` does on the read log (``holoslam.pipeline.run_data``, default
settings, nothing written); the child's peak resident set is the largest of its stages' peaks and of
``os.wait4``'s rusage (the stages reset the kernel's peak as they begin), and the parent times it. Columns: minutes of log, scans, submaps, wall s, peak RSS MB, RSS per log minute above the 1-copy
row, and whether the peak is within the budget. Exit status 1 when a row exceeds it. With ``--write`` the child also writes the run folder (every file of ``holoslam run``, pictures
and results MCAP included), so the peak is that of the whole run; each row then lists the stages' times and the
files' sizes. Each row also lists every stage's resident peak (``stage peaks``: Linux VmHWM, reset when the
stage begins, so a stage's peak includes what the earlier stages left resident) and, with ``--write``, the peak
while each file was written; the map's size in cells, the loop search's counts, and, for a simulated log (one
with ground truth: ``holoslam simulate --building --seed 26 -o building.mcap``, an 80-minute drive through a
350 m building), the trajectory's and the anchors' errors against the truth after alignment.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "realdata"


def _vm_mb(field: str) -> float:
    """The process's ``VmHWM`` / ``VmRSS`` (MB) from /proc/self/status; 0 where there is none."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return 0.0


class StagePeaks:
    """A run's progress callback that records each stage's resident peak (Linux VmHWM, reset through
    /proc/self/clear_refs when a stage begins; a stage's peak includes what earlier stages left resident)."""

    def __init__(self, first: str) -> None:
        self.current, self.peaks = first, {}
        self._reset()

    @staticmethod
    def _reset() -> None:
        with contextlib.suppress(OSError):
            Path("/proc/self/clear_refs").write_text("5")

    def __call__(self, name: str, *done_total: int) -> None:
        if done_total or name == self.current:
            return
        self.close()
        self.current = name
        self._reset()

    def close(self) -> None:
        self.peaks[self.current] = round(max(self.peaks.get(self.current, 0.0), _vm_mb("VmHWM")), 1)


def _accuracy(report) -> dict | None:
    """The run's errors against the log's ground truth (m, deg), None without one."""
    acc = report.accuracy
    if acc is None:
        return None
    return {k: {"rmse_m": getattr(acc, k).rmse_m, "max_m": getattr(acc, k).max_m,
                "heading_rmse_deg": getattr(acc, k).heading_rmse_deg}
            for k in ("trajectory", "trajectory_dead_reckoning", "anchors")}


def child(log_path: str, times: int, out: str, write: bool) -> None:
    from holoslam import derive
    from holoslam.io.mcap import read_log
    from holoslam.pipeline import run_data

    peaks = StagePeaks("ingest")
    log, ingest = read_log(log_path, require=["odometry", "scan"])
    log = derive.repeat(log, times)
    result = run_data(log, ingest, progress=peaks)
    peaks.close()
    minutes = (log.scans[-1].stamp_ns - log.scans[0].stamp_ns) / 60e9
    sub = result.report.submaps
    row = {"minutes": minutes, "scans": len(log.scans), "submaps": len(result.frontend.submaps),
           "stages_s": {k: round(v, 2) for k, v in result.report.timings_s.items()},
           "loops": {"tried": sub.loops_tried, "pairs": sub.loop_pairs, "search": sub.loop_search},
           "accuracy": _accuracy(result.report), "cells": list(result.grid.shape)}
    if write:  # the run folder as holoslam run writes it (pictures and results MCAP included)
        from holoslam.io import atomic_folder
        from holoslam.io.run_folder import write_run

        folder = Path(out).parent / "run"
        peaks("writing the folder")
        files: dict[str, float] = {}
        checkpoint = atomic_folder._checkpoint

        def file_peak(kind: str, name: str = "") -> None:  # each written file's own resident peak
            files[name or kind] = round(_vm_mb("VmHWM"), 1)
            peaks.close()
            StagePeaks._reset()
            checkpoint(kind, name)

        t0 = time.perf_counter()
        atomic_folder._checkpoint = file_peak
        try:
            write_run(result, folder)
        finally:
            atomic_folder._checkpoint = checkpoint
        row["write_s"] = time.perf_counter() - t0
        peaks.close()
        row["file_peak_mb"] = files
        row["files_mb"] = {p.name: round(p.stat().st_size / 2**20, 2) for p in sorted(folder.iterdir())}
    row["stage_peak_mb"] = peaks.peaks
    Path(out).write_text(json.dumps(row))


def run_child(log: Path, times: int, write: bool = False) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "child.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(log), str(times), str(out),
               "1" if write else "0"]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"bench_memory: the child for {log.name} x{times} failed")
        row = json.loads(out.read_text())
    # the stages reset the kernel's peak (VmHWM, which ru_maxrss reads too) as they begin: the run's peak is the
    # largest of theirs and the rusage's (what came after the last reset)
    peaks = [*row.get("stage_peak_mb", {}).values(), *row.get("file_peak_mb", {}).values()]
    row.update(times=times, wall_s=wall, rss_mb=max([usage.ru_maxrss / 1024.0, *peaks]))
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default="intel",
                    help="a log of the data folder (default intel, 45 min) or the path of any MCAP log, e.g. a "
                         "dense laser's: holoslam simulate --profile dense-lidar --duration 120 -o dense.mcap")
    ap.add_argument("--times", type=int, nargs="+", default=[1, 2], help="copies played end to end")
    ap.add_argument("--budget-mb", type=float, default=2000.0, help="peak RSS budget (MB)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--write", action="store_true",
                    help="also write the run folder (every file holoslam run writes) inside the measured process")
    ap.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child[0], int(args.child[1]), args.child[2], args.child[3] == "1")
        return 0
    given = Path(args.log)
    log = given if given.suffix == ".mcap" and given.is_file() else args.data / f"{args.log}.mcap"
    if not log.is_file():
        print(f"bench_memory: no {log} (the shared real logs, see ../shared/realdata/README.md)")
        return 0
    rows = [run_child(log, t, args.write) for t in sorted(set(args.times))]
    base = rows[0]
    print(f"\npeak memory of a whole run on {log.stem} played N times end to end (budget {args.budget_mb:.0f} MB)")
    print(f"{'N':>3} {'minutes':>8} {'scans':>7} {'submaps':>8} {'wall s':>7} {'RSS MB':>7} {'MB/min':>7}  budget")
    failed = False
    for r in rows:
        grow = ((r["rss_mb"] - base["rss_mb"]) / (r["minutes"] - base["minutes"])
                if r["minutes"] > base["minutes"] else float("nan"))
        ok = r["rss_mb"] <= args.budget_mb
        failed |= not ok
        print(f"{r['times']:>3} {r['minutes']:>8.1f} {r['scans']:>7} {r['submaps']:>8} {r['wall_s']:>7.1f} "
              f"{r['rss_mb']:>7.0f} {grow:>7.1f}  {'within' if ok else 'OVER'}")
        print("    stages (s):", ", ".join(f"{k} {v}" for k, v in r["stages_s"].items())
              + (f", writing the folder {r['write_s']:.1f}" if "write_s" in r else ""))
        print("    stage peaks (MB RSS):", ", ".join(f"{k} {v:.0f}" for k, v in r["stage_peak_mb"].items()))
        if "file_peak_mb" in r:
            print("    writing, peak per file (MB RSS):", ", ".join(f"{k} {v:.0f}" for k, v in r["file_peak_mb"].items()))
        if "files_mb" in r:
            print("    files (MB):", ", ".join(f"{k} {v}" for k, v in r["files_mb"].items()))
        print(f"    map {r['cells'][1]} x {r['cells'][0]} cells; loops: {r['loops']}")
        if r.get("accuracy"):
            print("    accuracy (m, m, deg: rmse, max, heading rmse):", "; ".join(
                f"{k} {v['rmse_m']:.3f} {v['max_m']:.3f} {v['heading_rmse_deg']:.2f}" for k, v in r["accuracy"].items()))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
