"""A batch of logs that resumes: ``holoslam run logs/ -o OUT`` skips every log whose folder is already complete
for the same input and configuration, runs the others, and ends with a summary table and ``OUT/batch.json``.

A log is *up to date* when its folder has a valid ``run.json`` (:mod:`holoslam.io.run_manifest`) written by this
holoslam version, with this configuration's hash and this log's size and content (the log is hashed only when
its mtime differs from the manifest's). Any other log is run again; ``force`` runs them all. An interrupted
batch restarted with the same command therefore redoes only the logs whose folders were not complete: folders
are swapped into place whole (:mod:`holoslam.io.atomic_folder`), so a log killed mid-write has no folder, or the
previous one.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from holoslam.timing import Progress

if TYPE_CHECKING:
    from holoslam.batch import BatchItem
    from holoslam.config import RunConfig

__all__ = ["run_batch", "DONE", "UP_TO_DATE", "FAILED"]

DONE, UP_TO_DATE, FAILED = "done", "up to date", "failed"


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _noop(*_a: Any, **_k: Any) -> None:
    return None


def run_batch(
    job: Callable[..., dict[str, Any]],
    logs: Sequence[Path],
    out_root: str | Path,
    config: RunConfig,
    config_hash: str,
    *,
    force: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
    **cluster: Any,
) -> dict[str, Any]:
    """Run ``job`` (``holoslam.run_jobs.run_log_to_folder``) on many logs into one folder each under ``out_root``,
    the configuration ``config`` hashed ``config_hash`` (what the manifests record), skipping the up-to-date ones (unless ``force``),
    locally (``workers`` processes) or on a Dask cluster (``scheduler``; ``cluster``: :func:`run_many`'s
    cluster options). Returns ``{"ok", "counts", "logs": [...], "text", "batch_json"}``; every log's row has
    its ``status`` (done / up to date / failed) and a failure's one-line ``error``."""
    from holoslam.batch import output_folder_for, run_many
    from holoslam.io.run_manifest import holoslam_version, up_to_date, write_batch_json

    progress = progress or _noop
    started = _now()
    root = Path(out_root)
    paths = [Path(p) for p in logs]
    outs = [output_folder_for(p, root, paths) for p in paths]
    chash, version = config_hash, holoslam_version()
    rows: list[dict[str, Any] | None] = [None] * len(paths)
    todo = []
    for k, (log, out) in enumerate(zip(paths, outs, strict=True)):
        ok, why = (False, "--force") if force else up_to_date(out, log, chash, version)
        if ok:
            rows[k] = {"log": str(log), "out_dir": str(out), "status": UP_TO_DATE, "ok": True, "seconds": 0.0}
            progress(f"up to date {log} -> {out}")
        else:
            todo.append(k)
    t0 = time.perf_counter()

    def on_done(item: BatchItem, done: int, total: int) -> None:
        progress(f"{done}/{total} {'done' if item.ok else 'FAILED'} {item.log} ({item.seconds:.1f} s)")

    items = run_many(
        job,
        [paths[k] for k in todo],
        root,
        out_dirs=[str(outs[k]) for k in todo],
        workers=workers,
        scheduler=scheduler,
        on_done=on_done,
        config=config,
        **cluster,
    )
    for k, item in zip(todo, items, strict=True):
        rows[k] = {**dataclasses.asdict(item), "status": DONE if item.ok else FAILED}
    final = [r for r in rows if r is not None]
    counts = {s: sum(r["status"] == s for r in final) for s in (DONE, UP_TO_DATE, FAILED)}
    batch = {
        "format": "holoslam-batch/1",
        "holoslam_version": version,
        "config_sha256": chash,
        "started_utc": started,
        "finished_utc": _now(),
        "seconds": round(time.perf_counter() - t0, 3),
        "counts": counts,
        "logs": [{k: v for k, v in r.items() if k != "summary"} for r in final],
    }
    path = write_batch_json(root, batch)
    return {
        "ok": counts[FAILED] == 0,
        "counts": counts,
        "logs": final,
        "batch_json": str(path),
        "text": summary_table(final, root, counts, path),
    }


def summary_table(rows: Sequence[dict[str, Any]], root: Path, counts: dict[str, int], path: Path) -> str:
    """The batch's table: one line per log (status, seconds, log -> folder, a failure's reason) and the counts."""
    lines = [
        f"{len(rows)} logs into {root}: {counts[DONE]} done, {counts[UP_TO_DATE]} up to date, "
        f"{counts[FAILED]} failed (each log's row: {path})",
        f"  {'status':<10} {'seconds':>8}  log -> folder",
    ]
    for r in rows:
        secs = "-" if r["status"] == UP_TO_DATE else f"{r['seconds']:.1f}"
        why = f": {r.get('error')}" if r["status"] == FAILED else ""
        lines.append(f"  {r['status']:<10} {secs:>8}  {r['log']} -> {r['out_dir']}{why}")
    return "\n".join(lines)
