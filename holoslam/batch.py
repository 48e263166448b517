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


def run_many(
    job: Callable[..., dict[str, Any]],
    logs: Sequence[str | Path],
    out_root: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    on_done: Callable[[BatchItem, int, int], None] | None = None,
    connect_timeout_s: float = 10.0,
    **kwargs: Any,
) -> list[BatchItem]:
    """Run ``job(log, out_dir, **kwargs) -> summary`` for every log; results in the order of ``logs``.

    ``job`` must be a module-level function (it is pickled to worker processes). ``on_done(item, done,
    total)`` is called as each log finishes, for progress display.
    """
    paths = [Path(p) for p in logs]
    root = Path(out_root)
    outs = [str(output_folder_for(p, root, paths)) for p in paths]
    total = len(paths)
    results: dict[int, BatchItem] = {}

    def finished(i: int, item: BatchItem) -> None:
        results[i] = item
        if on_done is not None:
            on_done(item, len(results), total)

    if scheduler:
        try:
            from distributed import Client, as_completed
        except ImportError:
            raise ConfigError(
                "a Dask scheduler was given but dask.distributed is not installed; pip install 'holoslam[dask]'"
            ) from None
        try:
            client = Client(scheduler, timeout=f"{connect_timeout_s}s")
        except OSError as e:
            raise ConfigError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
        try:
            futures = {
                client.submit(_timed, job, str(p), o, kwargs, pure=False, key=f"holoslam-{i}-{p.name}"): i
                for i, (p, o) in enumerate(zip(paths, outs, strict=True))
            }
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    item = fut.result()
                except Exception as e:  # the worker died
                    item = BatchItem(str(paths[i]), outs[i], False, 0.0, error=f"worker failed: {e}")
                finished(i, item)
        finally:
            client.close()
    elif total == 1 or (workers or os.cpu_count() or 1) == 1:
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
