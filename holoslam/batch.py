"""Many logs at once: one output folder per log, processed in parallel on the local cores or on a Dask cluster.

A fleet of robots produces many logs; ``run_many`` maps one job function over them. Locally it uses a process
pool (one process per core by default); given a Dask scheduler address (``tcp://host:8786``) it submits the
same jobs to that cluster with ``dask.distributed``. A log that fails is reported with its error and never stops
the others.
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holoslam.errors import ConfigError, HoloslamError

__all__ = ["BatchItem", "collect_logs", "output_folder_for", "run_many"]


@dataclass(frozen=True)
class BatchItem:
    """The outcome of one log: ``ok`` with the job's summary, or the error message that stopped it."""

    log: str
    out_dir: str
    ok: bool
    seconds: float
    summary: dict[str, Any] | None = None
    error: str | None = None


def collect_logs(inputs: Iterable[str | Path]) -> list[Path]:
    """Expand files and folders into the list of logs to run: ``*.mcap`` files in folders (a folder holding a
    rosbag2 ``metadata.yaml`` counts as one log), files as given. Raises ConfigError for a missing path."""
    logs: list[Path] = []
    for item in inputs:
        p = Path(item)
        if not p.exists():
            raise ConfigError(f"input {p} does not exist; give MCAP files or folders holding them")
        if p.is_dir() and not (p / "metadata.yaml").exists():
            found = sorted(q for q in p.rglob("*.mcap") if not (q.parent / "metadata.yaml").exists())
            bags = sorted({q.parent for q in p.rglob("metadata.yaml")})
            logs.extend(found + bags)
        else:
            logs.append(p)
    seen: set[Path] = set()
    unique = []
    for p in logs:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            unique.append(p)
    return unique


def output_folder_for(log: Path, out_root: Path, all_logs: Sequence[Path]) -> Path:
    """A distinct folder under ``out_root`` per log, named after the log's file (or folder) stem."""
    stem = log.stem if log.is_file() else log.name
    same = [q for q in all_logs if (q.stem if q.is_file() else q.name) == stem]
    if len(same) > 1:
        stem = f"{stem}-{same.index(log)}"
    return out_root / stem


def _timed(job: Callable[..., dict[str, Any]], log: str, out_dir: str, kwargs: dict[str, Any]) -> BatchItem:
    t0 = time.perf_counter()
    try:
        summary = job(log, out_dir, **kwargs)
        return BatchItem(log, out_dir, True, time.perf_counter() - t0, summary=summary)
    except HoloslamError as e:
        return BatchItem(log, out_dir, False, time.perf_counter() - t0, error=str(e))
    except Exception as e:  # a bug or a library failure: keep the others going, keep the evidence
        tb = traceback.format_exception_only(type(e), e)[-1].strip()
        return BatchItem(log, out_dir, False, time.perf_counter() - t0, error=f"unexpected error: {tb}")


def _timed_cluster(
    job: Callable[..., dict[str, Any]], log: str, out_dir: str, kwargs: dict[str, Any]
) -> BatchItem:
    """``_timed`` on a cluster worker: a holoslam error (bad input: the same on any worker) is the log's outcome;
    anything else (out of memory, an OSError of a node, a bug) is raised so that Dask retries the job."""
    t0 = time.perf_counter()
    try:
        summary = job(log, out_dir, **kwargs)
    except HoloslamError as e:
        return BatchItem(log, out_dir, False, time.perf_counter() - t0, error=str(e))
    return BatchItem(log, out_dir, True, time.perf_counter() - t0, summary=summary)


RETRIES = 2
"""Times a job that raised an unexpected exception (not a holoslam error: an OSError of a node, a MemoryError)
is run again on the cluster (Dask ``retries=``). A job whose *worker died* under it is recomputed by the
scheduler itself until it has killed more than ``distributed.scheduler.allowed-failures`` workers (Dask's
default 3; holoslam's README recommends 1 for a batch of logs: a log that kills two workers is bad)."""


def _killed_reason(client: Any, e: Any, since: float) -> str:
    """One line for a log whose workers died under it (Dask's ``KilledWorker``): memory beyond the worker's
    limit (the nanny restarts a worker above 95 % of it: its event names the worker) or a crash."""
    n = int(getattr(e, "allowed_failures", 0)) + 1
    ws = getattr(e, "last_worker", None)
    addr = getattr(ws, "address", "?")
    limit = getattr(ws, "memory_limit", None)
    try:
        events = client.get_events("worker-restart-memory")
    except Exception:
        events = ()
    hits = [ev for t, ev in events if t >= since and isinstance(ev, dict) and ev.get("worker") == addr]
    failures = f"distributed.scheduler.allowed-failures = {n - 1}"
    if hits:
        gib = f"{limit / 2**30:.2f} GiB" if limit else "its limit"
        return (
            f"needs more memory than its worker's memory limit of {gib}: {n} workers exceeded 95 % of it running "
            f"this log and were restarted (last {addr}, {hits[-1].get('rss', 0) / 2**30:.2f} GiB; {failures}); "
            "give the workers more memory (dask worker --memory-limit) or cut the log"
        )
    return (
        f"its worker process died {n} times while running it (last {addr}; {failures}): a crash in native code "
        "or the process killed from outside; run the log alone ('holoslam run LOG -o OUT') to see why"
    )


def _run_cluster(
    job: Callable[..., dict[str, Any]],
    paths: list[Path],
    outs: list[str],
    kwargs: dict[str, Any],
    scheduler: str,
    connect_timeout_s: float,
    retries: int,
    finished: Callable[[int, BatchItem], None],
) -> None:
    try:
        from distributed import Client, as_completed
        from distributed.scheduler import KilledWorker
    except ImportError:
        raise ConfigError(
            "a Dask scheduler was given but dask.distributed is not installed; pip install 'holoslam[dask]'"
        ) from None
    try:
        client = Client(scheduler, timeout=f"{connect_timeout_s}s")
    except OSError as e:
        raise ConfigError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
    since = time.time()
    try:
        futures = {
            client.submit(
                _timed_cluster, job, str(p), o, kwargs, pure=False, retries=retries, key=f"holoslam-{i}-{p.name}"
            ): i
            for i, (p, o) in enumerate(zip(paths, outs, strict=True))
        }
        # each result fetched as soon as its job completes and its future released: a result left on a worker
        # would be lost with it and its log recomputed
        for fut in as_completed(futures):
            i = futures.pop(fut)
            try:
                item = fut.result()
            except KilledWorker as e:
                item = BatchItem(str(paths[i]), outs[i], False, 0.0, error=_killed_reason(client, e, since))
            except Exception as e:
                why = traceback.format_exception_only(type(e), e)[-1].strip()
                what = (
                    f"failed {retries + 1} times on the cluster"  # the job raised on every try
                    if fut.status == "error"
                    else f"its result could not be fetched from the cluster ({fut.status})"
                )
                item = BatchItem(str(paths[i]), outs[i], False, 0.0, error=f"{what}: {why}")
            fut.release()
            finished(i, item)
    finally:
        client.close()


def run_many(
    job: Callable[..., dict[str, Any]],
    logs: Sequence[str | Path],
    out_root: str | Path,
    *,
    out_dirs: Sequence[str | Path] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    on_done: Callable[[BatchItem, int, int], None] | None = None,
    connect_timeout_s: float = 10.0,
    retries: int = RETRIES,
    **kwargs: Any,
) -> list[BatchItem]:
    """Run ``job(log, out_dir, **kwargs) -> summary`` for every log; results in the order of ``logs``.

    ``job`` must be a module-level function (it is pickled to worker processes). ``on_done(item, done,
    total)`` is called as each log finishes, for progress display. ``out_dirs``: each log's folder (default
    :func:`output_folder_for` under ``out_root``). On a cluster (``scheduler``) a job is submitted with
    ``retries`` (for unexpected exceptions), a job whose worker is lost is recomputed on another worker, and a
    job that killed more workers than the scheduler allows is failed with the reason (:func:`_killed_reason`):
    one log never stops the batch.
    """
    paths = [Path(p) for p in logs]
    root = Path(out_root)
    if out_dirs is None:
        outs = [str(output_folder_for(p, root, paths)) for p in paths]
    else:
        outs = [str(o) for o in out_dirs]
    total = len(paths)
    results: dict[int, BatchItem] = {}

    def finished(i: int, item: BatchItem) -> None:
        results[i] = item
        if on_done is not None:
            on_done(item, len(results), total)

    if scheduler:
        _run_cluster(job, paths, outs, kwargs, scheduler, connect_timeout_s, retries, finished)
    elif total <= 1 or (workers or os.cpu_count() or 1) == 1:
        for i, (p, o) in enumerate(zip(paths, outs, strict=True)):
            finished(i, _timed(job, str(p), o, kwargs))
    else:
        n = min(total, workers or os.cpu_count() or 1)
        with ProcessPoolExecutor(max_workers=n) as pool:
            pending: dict[Future, int] = {
                pool.submit(_timed, job, str(p), o, kwargs): i
                for i, (p, o) in enumerate(zip(paths, outs, strict=True))
            }
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    i = pending.pop(fut)
                    try:
                        item = fut.result()
                    except Exception as e:  # the process died (killed, out of memory)
                        item = BatchItem(
                            str(paths[i]), outs[i], False, 0.0, error=f"worker process failed: {e}"
                        )
                    finished(i, item)
    return [results[i] for i in range(total)]
