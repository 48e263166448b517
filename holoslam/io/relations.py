"""Relation files of the Freiburg SLAM benchmark (Kümmerle et al. 2009): manually verified relative poses.

One relation per line, ``t1 t2 x y z roll pitch yaw``: the base pose at stamp ``t2`` expressed in the frame of
the base pose at stamp ``t1`` (stamps in decimal seconds of the log's sensor time; metres and radians). The
benchmark is planar: x, y and yaw are kept, z / roll / pitch are read and ignored. Blank lines and ``#``
comments are skipped; commas count as spaces.

Stamps become int nanoseconds from their decimal text exactly (``976052905.167303`` ->
``976052905167303000``), never through a float64 of seconds, so they equal the scan header stamps that
:func:`holoslam.io.mcap.read_log` gives (``LogData.scans[i].stamp_ns``).
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from holoslam.errors import IngestError

__all__ = [
    "Relations",
    "parse_relations",
    "read_relations",
    "to_relations_text",
    "write_relations",
    "cut_relations",
]

_FIELDS = "t1 t2 x y z roll pitch yaw"
_NS = Decimal(1_000_000_000)
_INT64_MAX = 2**63 - 1


@dataclass(frozen=True, eq=False)
class Relations:
    """N relations: stamps ``t1_ns``, ``t2_ns`` (N,) int64 and ``T`` (N, 3) float64, the relative pose
    ``X(t1)^-1 X(t2)`` as x (m), y (m), yaw (rad, wrapped to [-pi, pi))."""

    t1_ns: np.ndarray
    t2_ns: np.ndarray
    T: np.ndarray

    def __post_init__(self) -> None:
        t1 = np.array(self.t1_ns, dtype=np.int64).reshape(-1)
        t2 = np.array(self.t2_ns, dtype=np.int64).reshape(-1)
        T = np.array(self.T, dtype=np.float64).reshape(-1, 3)
        if not (t1.shape[0] == t2.shape[0] == T.shape[0]):
            raise ValueError(
                f"Relations: {t1.shape[0]} t1, {t2.shape[0]} t2 and {T.shape[0]} poses; pass N of each"
            )
        T[:, 2] = (T[:, 2] + np.pi) % (2.0 * np.pi) - np.pi
        for name, a in (("t1_ns", t1), ("t2_ns", t2), ("T", T)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.t1_ns.shape[0])


def _stamp_ns(tok: str) -> int:
    """Decimal seconds -> int ns, exactly (rounded half-even below a nanosecond); ValueError when not a finite
    number or out of the int64 range."""
    try:
        d = Decimal(tok)
    except InvalidOperation:
        raise ValueError(f"stamp {tok!r} is not a number") from None
    if not d.is_finite():
        raise ValueError(f"stamp {tok!r} is not a finite number")
    ns = int((d * _NS).to_integral_value(rounding=ROUND_HALF_EVEN))
    if abs(ns) > _INT64_MAX:
        raise ValueError(f"stamp {tok!r} is out of range (more than 292 years of nanoseconds)")
    return ns


def parse_relations(text: str, source: str = "<memory>") -> Relations:
    """:class:`Relations` from the text of a ``.relations`` file; ``source`` names it in error messages.
    Raises :class:`IngestError` (``source:line: what; how to fix``) on a malformed line or when no relation
    is given."""
    t1: list[int] = []
    t2: list[int] = []
    rows: list[tuple[float, float, float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = body.replace(",", " ").split()
        where = f"{source}:{lineno}"
        if len(parts) != 8:
            raise IngestError(
                f"{where}: a relation line has 8 fields ({_FIELDS}), found {len(parts)}: {line.strip()!r}; "
                "fix or remove the line (comments start with #)"
            )
        try:
            a, b = _stamp_ns(parts[0]), _stamp_ns(parts[1])
        except ValueError as e:
            raise IngestError(
                f"{where}: {e}; t1 and t2 are decimal seconds such as 976052905.167303"
            ) from None
        try:
            vals = [float(v) for v in parts[2:]]
        except ValueError:
            raise IngestError(
                f"{where}: not a number among x y z roll pitch yaw in {line.strip()!r}; "
                "give metres and radians as decimal numbers"
            ) from None
        if not all(np.isfinite(vals)):
            raise IngestError(
                f"{where}: a relation holds a non-finite number (nan or inf) in {line.strip()!r}; "
                "give finite metres and radians"
            )
        t1.append(a)
        t2.append(b)
        rows.append((vals[0], vals[1], vals[5]))
    if not rows:
        raise IngestError(
            f"{source}: no relation in the file; expected lines '{_FIELDS}' (the Freiburg benchmark's "
            ".relations format)"
        )
    return Relations(np.array(t1, dtype=np.int64), np.array(t2, dtype=np.int64), np.array(rows))


def read_relations(path: str | Path) -> Relations:
    """:func:`parse_relations` of a file; a missing or unreadable file is an :class:`IngestError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise IngestError(f"{path}: no such file; give the path of a .relations file") from None
    except IsADirectoryError:
        raise IngestError(f"{path}: is a folder; give the path of a .relations file") from None
    except UnicodeDecodeError:
        raise IngestError(f"{path}: not a text file; a .relations file holds lines '{_FIELDS}'") from None
    except OSError as e:
        raise IngestError(f"{path}: cannot be read ({e.strerror}); check its permissions") from None
    return parse_relations(text, source=str(path))


def _seconds(ns: int) -> str:
    sign = "-" if ns < 0 else ""
    ns = abs(ns)
    return f"{sign}{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def to_relations_text(relations: Relations) -> str:
    """The ``.relations`` text of ``relations`` (exact decimal stamps; z, roll, pitch written as 0)."""
    return "".join(
        f"{_seconds(a)} {_seconds(b)} {x!r} {y!r} 0.0 0.0 0.0 {yaw!r}\n"
        for a, b, (x, y, yaw) in zip(
            relations.t1_ns.tolist(), relations.t2_ns.tolist(), relations.T.tolist(), strict=True
        )
    )


def write_relations(path: str | Path, relations: Relations) -> Path:
    path = Path(path)
    path.write_text(to_relations_text(relations), encoding="utf-8")
    return path


def cut_relations(relations: Relations, t0_ns: int, t1_ns: int) -> Relations:
    """The relations whose two stamps both lie in [t0_ns, t1_ns) (a new record; the input is unchanged)."""
    keep = (
        (relations.t1_ns >= t0_ns)
        & (relations.t1_ns < t1_ns)
        & (relations.t2_ns >= t0_ns)
        & (relations.t2_ns < t1_ns)
    )
    return Relations(relations.t1_ns[keep], relations.t2_ns[keep], relations.T[keep])
