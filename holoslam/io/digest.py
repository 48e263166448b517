"""Content digests of input files (a map store names each session's log by its SHA-256)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from holoslam.errors import IngestError

__all__ = ["file_sha256"]


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """The SHA-256 of a file (hex), read in chunks; a folder (a rosbag2 bag) hashes its files in name order."""
    p = Path(path)
    h = hashlib.sha256()
    files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    try:
        for f in files:
            with open(f, "rb") as fh:
                while block := fh.read(chunk):
                    h.update(block)
    except OSError as e:
        raise IngestError(f"cannot read {p} to hash it: {e.strerror or e}") from None
    return h.hexdigest()
