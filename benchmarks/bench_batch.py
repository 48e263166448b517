"""Batch throughput on a local dask.distributed cluster (worker processes over TCP): logs per minute on 1, 2 and
4 workers, and on 2 workers of which one is SIGKILLed mid-batch (its log recomputed elsewhere, the worker
restarted by its nanny and importing holoslam again).

    .venv/bin/python benchmarks/bench_batch.py [--logs 16] [--duration 20] [--repeats 3] [--pictures]

Generates ``--logs`` simulated household logs of ``--duration`` s (seeds 0..; into a temporary folder, deleted
afterwards) and runs them with ``holoslam.batch.run_many`` as ``holoslam run logs/ --scheduler ...`` does. Each
cluster is warmed first (every worker runs one log, not timed: the first run in a process imports holoslam and
loads the compiled kernels), then the batch is timed ``--repeats`` times; medians and the ratio of throughput
against 1 worker are printed. Without ``--pictures`` the runs write no pictures and no results MCAP (matplotlib
is most of a short log's run). Throughput cannot exceed the machine's cores: on 2 cores, 4 workers is 2 workers.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path


def _cluster(n: int):
    import dask
    import distributed

    with dask.config.set(
        {"distributed.scheduler.allowed-failures": 1, "distributed.scheduler.worker-saturation": 1.0}
    ):
        return distributed.LocalCluster(
            n_workers=n, processes=True, threads_per_worker=1, protocol="tcp", dashboard_address=None
        )


def _batch(lc, logs: list[Path], out: Path, config, kill_after: int | None = None) -> tuple[float, int]:
    """Seconds for the batch and the number of logs that completed; ``kill_after``: SIGKILL a worker that runs
    a log once that many logs are done (read from the LocalCluster's scheduler and nannies in this process)."""
    from holoslam.batch import run_many
    from holoslam.run_jobs import run_log_to_folder

    def on_done(item, done, total):
        if done == kill_after:
            busy = [ws.address for ws in list(lc.scheduler.workers.values()) if ws.processing]
            pids = {n.worker_address: n.pid for n in list(lc.workers.values())}
            if busy and pids.get(busy[0]):
                os.kill(pids[busy[0]], signal.SIGKILL)

    t0 = time.perf_counter()
    items = run_many(run_log_to_folder, logs, out, scheduler=lc.scheduler_address, config=config, on_done=on_done)
    return time.perf_counter() - t0, sum(i.ok for i in items)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", type=int, default=16)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds of each simulated log")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--pictures", action="store_true", help="write pictures and the results MCAP too")
    a = ap.parse_args(argv)

    from holoslam.config import RunConfig
    from holoslam.sim import SimConfig, simulate_to_file

    config = dataclasses.replace(RunConfig(), pictures=a.pictures, results_mcap=a.pictures)
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        root = Path(tmp)
        logs = []
        for k in range(a.logs):
            p = root / "logs" / f"log{k:02d}.mcap"
            p.parent.mkdir(parents=True, exist_ok=True)
            simulate_to_file(p, SimConfig(seed=k, duration_s=a.duration, image_rate_hz=0.0))
            logs.append(p)
        print(f"{a.logs} simulated logs of {a.duration:g} s, {os.cpu_count()} cores, {a.repeats} repeats", flush=True)
        rows = []
        for label, n, kill in (("1 worker", 1, None), ("2 workers", 2, None), ("4 workers", 4, None),
                               ("2 workers, 1 killed", 2, a.logs // 3)):  # fmt: skip
            with _cluster(n) as lc:
                lc.wait_for_workers(n, timeout=120)
                _batch(lc, logs[:n], root / "warm", config)  # imports, kernels: not timed
                times, completed = [], []
                for r in range(a.repeats):
                    s, ok = _batch(lc, logs, root / f"{label}-{r}", config, kill)
                    times.append(s)
                    completed.append(ok)
                    if kill is not None:
                        lc.wait_for_workers(n, timeout=120)
            med = statistics.median(times)
            rows.append((label, med, 60.0 * a.logs / med, min(completed)))
            print(f"  {label}: {', '.join(f'{t:.1f}' for t in times)} s", file=sys.stderr, flush=True)
    ref = rows[0][2]
    print(f"{'cluster':<22} {'median s':>9} {'logs/min':>9} {'x 1 worker':>11} {'logs done':>10}")
    for label, med, rate, ok in rows:
        print(f"{label:<22} {med:9.1f} {rate:9.1f} {rate / ref:11.2f} {ok:>6}/{a.logs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
