"""``run.json``: the manifest that marks a run folder complete, and what readers check before they trust one.

A run folder is written whole (:mod:`holoslam.io.atomic_folder`) and its manifest is the last file written.
The manifest holds::

    format            "holoslam-run/1"
    holoslam_version  the version that wrote the folder
    written_utc       when (ISO 8601)
    input             the log: path, size (bytes), mtime_ns and sha256 of its bytes (a rosbag2 folder: of its
                      files' relative names and bytes, in name order)
    config_sha256     sha256 of the run configuration (every setting, as JSON with sorted keys, and the bytes of
                      the topic mapping file when one is named)
    files             every other file of the folder: {name: {size, sha256}}
    timings_s         the run's stage timings

A folder is complete when its manifest parses, has this format, and every file it lists is there with its size
and sha256 (:func:`require_complete`). Files the manifest does not list (a user's notes) are allowed and ignored.
A folder without ``run.json`` (written by holoslam before 0.1.0 wrote manifests, or by a run that was killed
before its folder was swapped in with an older version) is refused: re-run it.

Hashing costs ~3 ms per MB (sha256 at ~350 MB/s on this machine: the 5.9 MB intel.mcap in 17 ms), so the input
is hashed whole; a batch's up-to-date check hashes a log only when its size or mtime differ from the manifest's.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from holoslam.errors import IngestError

__all__ = [
    "MANIFEST",
    "FORMAT",
    "input_fingerprint",
    "config_sha256",
    "build_manifest",
    "write_manifest",
    "require_complete",
    "complete",
    "up_to_date",
    "holoslam_version",
    "write_batch_json",
    "BATCH",
]

MANIFEST = "run.json"
FORMAT = "holoslam-run/1"
_CHUNK = 1 << 20


def holoslam_version() -> str:
    """The running holoslam's version (the package is imported before any of its modules, so this is a lookup; a
    ``from holoslam import __version__`` here would be an import cycle through the package's lazy names)."""
    import importlib

    return str(importlib.import_module("holoslam").__version__)


def _sha256_file(path: Path, h: Any = None) -> str:
    h = h or hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(_CHUNK):
            h.update(block)
    return str(h.hexdigest())


def input_fingerprint(log: str | Path, *, content: bool = True) -> dict[str, Any]:
    """Size, mtime_ns and (``content``) sha256 of a log file or a rosbag2 folder (every file under it)."""
    p = Path(log)
    if p.is_dir():
        files = sorted(q for q in p.rglob("*") if q.is_file())
        stats = [q.stat() for q in files]
        out: dict[str, Any] = {
            "path": str(p.absolute()),
            "size": int(sum(s.st_size for s in stats)),
            "mtime_ns": int(max((s.st_mtime_ns for s in stats), default=0)),
        }
        if content:
            h = hashlib.sha256()
            for q in files:
                h.update(str(q.relative_to(p)).encode() + b"\0")
                _sha256_file(q, h)
            out["sha256"] = h.hexdigest()
        return out
    st = p.stat()
    out = {"path": str(p.absolute()), "size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}
    if content:
        out["sha256"] = _sha256_file(p)
    return out


def config_sha256(settings: Any, mapping_file: str | Path | None = None) -> str:
    """sha256 of a configuration given as JSON-able settings (``holoslam.config.to_mapping``), with the bytes of
    the topic mapping file it names (its content decides the run, not its path)."""
    h = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    if mapping_file is not None and Path(mapping_file).is_file():
        h.update(b"\0mapping\0" + Path(mapping_file).read_bytes())
    return h.hexdigest()


def build_manifest(
    folder: Path,
    *,
    version: str,
    log_fingerprint: dict[str, Any] | None,
    config_hash: str | None,
    timings_s: dict[str, float] | None = None,
) -> dict[str, Any]:
    """The manifest of the files now in ``folder`` (every file but the manifest itself)."""
    files = {
        p.name: {"size": p.stat().st_size, "sha256": _sha256_file(p)}
        for p in sorted(folder.iterdir())
        if p.is_file() and p.name != MANIFEST
    }
    return {
        "format": FORMAT,
        "holoslam_version": version,
        "written_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "input": log_fingerprint,
        "config_sha256": config_hash,
        "files": files,
        "timings_s": dict(timings_s or {}),
    }


def write_manifest(folder: Path, manifest: dict[str, Any]) -> Path:
    """Write ``run.json`` into ``folder`` (strict JSON) and return its path."""
    from holoslam.io.jsonsafe import dumps

    path = folder / MANIFEST
    with open(path, "w", encoding="utf-8") as f:
        f.write(dumps(manifest, indent=2) + "\n")
        f.flush()
        os.fsync(f.fileno())
    return path


def _rerun(folder: Path) -> str:
    return f"re-run it: 'holoslam run LOG -o {folder}'"


def require_complete(folder: str | Path, *, hashes: bool = True) -> dict[str, Any]:
    """The manifest of a complete run folder; raises ``IngestError`` (one line: what is wrong, what to do) for a
    folder without a valid manifest or whose files differ from it (sizes, and sha256 when ``hashes``)."""
    from holoslam.io.atomic_folder import settle

    f = Path(folder)
    settle(f, complete)  # a swap killed between its two renames is finished first
    if not f.is_dir():
        raise IngestError(f"run folder {f} does not exist; give the folder 'holoslam run' wrote")
    m = f / MANIFEST
    if not m.is_file():
        if (f / "trajectory.tum").is_file() or (f / "report.json").is_file():
            raise IngestError(
                f"{f} has no {MANIFEST}: written by a holoslam without run manifests, or a run that did not finish, "
                f"so it may mix files of two runs; {_rerun(f)}"
            )
        raise IngestError(f"{f} has no {MANIFEST}: not a holoslam run folder; give the folder 'holoslam run' wrote")
    try:
        man = json.loads(m.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise IngestError(f"{m} is not valid JSON ({e}); {_rerun(f)}") from None
    if not isinstance(man, dict) or man.get("format") != FORMAT or not isinstance(man.get("files"), dict):
        raise IngestError(f"{m} is not a holoslam run manifest (format {FORMAT!r}); {_rerun(f)}")
    for name, entry in man["files"].items():
        p = f / name
        if not p.is_file():
            raise IngestError(f"{f}: {name}, listed in {MANIFEST}, is missing; {_rerun(f)}")
        if p.stat().st_size != entry.get("size") or (hashes and _sha256_file(p) != entry.get("sha256")):
            raise IngestError(
                f"{f}: {name} is not the file the run wrote (size or sha256 differ from {MANIFEST}); {_rerun(f)}"
            )
    return man


def complete(folder: str | Path) -> bool:
    """Whether ``folder`` is a complete run folder (a valid manifest, every file as it lists)."""
    try:
        require_complete(folder)
    except IngestError:
        return False
    return True


def up_to_date(
    folder: str | Path, log: str | Path, config: str, version: str
) -> tuple[bool, str]:
    """Whether ``folder`` is a complete run of ``log`` with the configuration hashed ``config`` by holoslam
    ``version``; with the reason when it is not. The log is hashed only when its size or mtime changed."""
    try:
        man = require_complete(folder)
    except IngestError as e:
        return False, str(e)
    if man.get("holoslam_version") != version:
        return False, f"written by holoslam {man.get('holoslam_version')}, this is {version}"
    if man.get("config_sha256") != config:
        return False, "the configuration changed"
    was = man.get("input") or {}
    now = input_fingerprint(log, content=False)
    if now["size"] != was.get("size"):
        return False, "the log changed (size)"
    if now["mtime_ns"] != was.get("mtime_ns") and input_fingerprint(log)["sha256"] != was.get("sha256"):
        return False, "the log changed (content)"
    return True, "up to date"


BATCH = "batch.json"


def write_batch_json(out_root: str | Path, batch: dict[str, Any]) -> Path:
    """Write ``batch.json`` into ``out_root`` whole (a temporary file, flushed, renamed over the previous one)."""
    from holoslam.errors import OutputError
    from holoslam.io.jsonsafe import dumps

    path = Path(out_root) / BATCH
    tmp = path.with_name(f".{BATCH}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(dumps(batch, indent=2) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {path}: {e.strerror or e}; the run folders are written") from None
    return path
