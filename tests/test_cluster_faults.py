"""A real dask.distributed cluster (a scheduler and 3 worker processes over TCP) that loses workers: a log whose
worker is SIGKILLed mid-batch is recomputed on another, a log that kills its workers (a crash, memory beyond the
worker's limit) is reported failed with the reason and never stops the batch, and every other log's outputs
equal those of a run without faults.

The cluster's scheduler runs with ``allowed-failures: 1`` (a log that killed two workers is failed: README) and
``worker-saturation: 1.0`` (a worker holds one log at a time, so a dying worker takes only its own log down)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from holoslam.batch import run_many
from holoslam.io.trajectory import read_tum
from holoslam.run_jobs import run_log_to_folder

distributed = pytest.importorskip("distributed")
pytestmark = pytest.mark.slow

MEMORY_LIMIT = "1.5GB"  # a worker that ran a short log holds ~330 MB (measured: psutil rss after a run)


# jobs the workers import from this module (the test folder is on their sys.path: the workers are spawned)
def crash_on_log07(log: str, out_dir: str, **kw):
    """run_log_to_folder, but the process running log07 dies at once (as a native library crashing on it)."""
    if Path(log).name == "log07.mcap":
        os.kill(os.getpid(), signal.SIGKILL)
    return run_log_to_folder(log, out_dir, **kw)


def hog_on_log03(log: str, out_dir: str, **kw):
    """run_log_to_folder, but log03 needs 6 GB (touched, 50 MB every 50 ms): beyond its worker's limit (the
    nanny looks every 100 ms)."""
    if Path(log).name == "log03.mcap":
        held = []
        for _ in range(120):
            held.append(np.ones(50_000_000 // 8))
            time.sleep(0.05)
    return run_log_to_folder(log, out_dir, **kw)


def oserror_once(log: str, out_dir: str, **kw):
    """run_log_to_folder after an OSError on the first try of each log (a node's file system hiccup)."""
    flag = Path(out_dir).parent / f".tried-{Path(log).name}"
    if not flag.exists():
        flag.parent.mkdir(parents=True, exist_ok=True)
        flag.write_text("1")
        raise OSError(5, "Input/output error", str(flag))
    return run_log_to_folder(log, out_dir, **kw)


def oserror_always(log: str, out_dir: str, **kw):
    raise OSError(5, "Input/output error", log)


def _cluster():
    import dask

    with dask.config.set(
        {"distributed.scheduler.allowed-failures": 1, "distributed.scheduler.worker-saturation": 1.0}
    ):
        return distributed.LocalCluster(
            n_workers=3,
            processes=True,
            threads_per_worker=1,
            protocol="tcp",
            dashboard_address=None,
            memory_limit=MEMORY_LIMIT,
        )


def _same_outputs(items, reference) -> None:
    for i in items:
        got = read_tum(Path(i.out_dir) / "trajectory.tum")[1]
        assert np.allclose(got, reference[Path(i.log).name], atol=1e-9, rtol=0), i.log


def _kill_a_busy_worker(cluster, spare: set[str]) -> tuple[str, set[str]]:
    """SIGKILL a worker process that is running a log none of ``spare`` (logs already on a killed worker). Read
    from the LocalCluster's own scheduler and nannies (in this process): a second Client beside run_many's can
    trip over its event loop."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        busy = {ws.address: {str(ts.key) for ts in ws.processing} for ws in list(cluster.scheduler.workers.values())}
        pids = {n.worker_address: n.pid for n in list(cluster.workers.values())}
        victims = [w for w, keys in busy.items() if keys and not keys & spare and pids.get(w)]
        if victims:
            w = victims[0]
            os.kill(pids[w], signal.SIGKILL)
            return w, busy[w]
        time.sleep(0.02)
    raise AssertionError("no worker was running a log")


def test_a_cluster_that_loses_workers_loses_no_log(twenty_short_logs, tmp_path):
    """One test (one cluster: pytest-xdist would start a cluster per test process otherwise), four batches:
    a worker SIGKILLed twice mid-batch (all 20 logs complete, outputs equal to a run without faults); a log that
    crashes its worker (failed after 2 workers died, the other 19 complete); an OSError retried; a log beyond its
    worker's memory limit (failed, naming the limit). 147 s on the 2-core machine shared with a load average of
    15 (2026-12-03); most of it the workers importing holoslam (3 at the start, then after each of 6 deaths)."""
    from holoslam.config import load_run_config

    _, logs, cfg = twenty_short_logs
    config = load_run_config(cfg)
    with _cluster() as lc:
        address = lc.scheduler_address
        lc.wait_for_workers(3, timeout=120)
        assert address.startswith("tcp://") and len(lc.scheduler_info["workers"]) == 3
        reference = {}  # the run without faults: every log in this process, one after the other
        for i in run_many(run_log_to_folder, logs, tmp_path / "reference", workers=1, config=config):
            assert i.ok, i.error
            reference[Path(i.log).name] = read_tum(Path(i.out_dir) / "trajectory.tum")[1]

        # a worker SIGKILLed twice mid-batch, each time while it runs a log: the log is recomputed elsewhere
        killed: list[tuple[str, set[str]]] = []

        def on_done(item, done, total):
            if done in (3, 9):
                killed.append(_kill_a_busy_worker(lc, set().union(*(k for _, k in killed))))

        items = run_many(
            run_log_to_folder, logs, tmp_path / "killed", scheduler=address, config=config, on_done=on_done
        )
        assert len(killed) == 2 and all(keys for _, keys in killed)  # each kill took a running log down
        assert len(items) == 20 and all(i.ok for i in items), [i.error for i in items if not i.ok]
        _same_outputs(items, reference)

        # a log that kills every worker it runs on: failed after 2 (allowed-failures 1), the other 19 complete
        items = run_many(crash_on_log07, logs, tmp_path / "crash", scheduler=address, config=config)
        failed = [i for i in items if not i.ok]
        assert [Path(i.log).name for i in failed] == ["log07.mcap"]
        assert "died 2 times" in failed[0].error and "allowed-failures = 1" in failed[0].error
        assert "\n" not in failed[0].error
        ok = [i for i in items if i.ok]
        assert len(ok) == 19
        _same_outputs(ok, reference)

        # an unexpected exception is retried (Dask retries=), and reported once the retries are spent
        items = run_many(oserror_once, logs[:2], tmp_path / "once", scheduler=address, config=config)
        assert all(i.ok for i in items), [i.error for i in items]
        _same_outputs(items, reference)
        items = run_many(oserror_always, logs[:2], tmp_path / "always", scheduler=address, retries=2)
        assert all(not i.ok and i.error.startswith("failed 3 times on the cluster: OSError") for i in items)

        # a log beyond its worker's memory limit: the nanny restarts the worker at 95 %; failed, naming the limit
        items = run_many(hog_on_log03, logs[:5], tmp_path / "memory", scheduler=address, config=config)
        failed = [i for i in items if not i.ok]
        assert [Path(i.log).name for i in failed] == ["log03.mcap"]
        assert "memory limit of 1.40 GiB" in failed[0].error, failed[0].error  # 1.5 GB = 1.40 GiB
        _same_outputs([i for i in items if i.ok], reference)
