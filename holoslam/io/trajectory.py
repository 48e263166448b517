"""TUM trajectory text: one pose per line, ``stamp x y z qx qy qz qw`` (stamp in seconds of the log's sensor time).

holoslam's trajectories are planar: z = 0 and the quaternion is a yaw rotation. Reading accepts any TUM file
and keeps x, y and the yaw of the quaternion (the rotation about z of a general quaternion).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from holoslam.errors import IngestError

__all__ = ["to_tum_text", "write_tum", "parse_tum", "read_tum"]


def to_tum_text(stamps_ns: np.ndarray, wTb: np.ndarray) -> str:
    """TUM text of (N,) int ns stamps and (N, 3) planar poses. Stamps are written as exact decimal seconds."""
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    wTb = np.asarray(wTb, dtype=np.float64).reshape(-1, 3)
    if stamps_ns.shape[0] != wTb.shape[0]:
        raise ValueError(f"{stamps_ns.shape[0]} stamps for {wTb.shape[0]} poses")
    half = 0.5 * wTb[:, 2]
    lines = [
        f"{s // 1_000_000_000}.{s % 1_000_000_000:09d} {x!r} {y!r} 0.0 0.0 0.0 {qz!r} {qw!r}"
        for s, x, y, qz, qw in zip(
            stamps_ns.tolist(),
            wTb[:, 0].tolist(),
            wTb[:, 1].tolist(),
            np.sin(half).tolist(),
            np.cos(half).tolist(),
            strict=True,
        )
    ]
    return "# timestamp x y z qx qy qz qw\n" + "".join(line + "\n" for line in lines)


def write_tum(path: str | Path, stamps_ns: np.ndarray, wTb: np.ndarray) -> Path:
    path = Path(path)
    path.write_text(to_tum_text(stamps_ns, wTb), encoding="utf-8")
    return path


def _stamp_ns(tok: str) -> int:
    """Decimal seconds -> int ns without going through a float (exact for up to 9 decimals)."""
    neg = tok.startswith("-")
    whole, _, frac = tok.lstrip("+-").partition(".")
    if "e" in tok.lower():
        return int(round(float(tok) * 1e9))
    ns = int(whole or "0") * 1_000_000_000 + int((frac + "000000000")[:9] or "0")
    return -ns if neg else ns


def parse_tum(text: str, source: str = "<memory>") -> tuple[np.ndarray, np.ndarray]:
    """(stamps_ns (N,) int64, wTb (N, 3)) from TUM text; comments (#) and blank lines are skipped."""
    stamps: list[int] = []
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = body.replace(",", " ").split()
        if len(parts) != 8:
            raise IngestError(
                f"{source}:{lineno}: a TUM line has 8 fields (stamp x y z qx qy qz qw), "
                f"found {len(parts)}: {line.strip()!r}"
            )
        try:
            stamps.append(_stamp_ns(parts[0]))
            rows.append([float(v) for v in parts[1:]])
        except ValueError:
            raise IngestError(f"{source}:{lineno}: not a number in {line.strip()!r}") from None
    a = np.array(rows, dtype=np.float64).reshape(-1, 7)
    qx, qy, qz, qw = a[:, 3], a[:, 4], a[:, 5], a[:, 6]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return np.array(stamps, dtype=np.int64), np.column_stack([a[:, 0], a[:, 1], yaw])


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise IngestError(f"{path}: no such file") from None
    return parse_tum(text, source=str(path))
