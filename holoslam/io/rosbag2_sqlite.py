"""rosbag2 sqlite3 storage (``.db3``, the default of ROS 2 Humble and older) -> one MCAP file.

A rosbag2 ``.db3`` holds ``topics(id, name, type, serialization_format, offered_qos_profiles, ...)`` and
``messages(id, topic_id, timestamp, data)`` (timestamp int ns, data = the CDR bytes an MCAP ros2 message holds);
since ROS 2 Iron also ``message_definitions(topic_type, encoding, encoded_message_definition, ...)``.
``db3_to_mcap`` streams one or more such files (a split bag, in metadata.yaml order) into an MCAP written with
the ``mcap`` Writer, so the MCAP reader in :mod:`holoslam.io.mcap` ingests them unchanged. Only the standard
library ``sqlite3`` is needed; the databases are opened read-only.
"""

from __future__ import annotations

import heapq
import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from holoslam.errors import IngestError
from holoslam.io.ros2defs import msgdef

__all__ = ["SQLITE_MAGIC", "Db3Summary", "db3_to_mcap", "is_sqlite"]

SQLITE_MAGIC = b"SQLite format 3\x00"

_REQUIRED: dict[str, tuple[str, ...]] = {
    "topics": ("id", "name", "type", "serialization_format"),
    "messages": ("id", "topic_id", "timestamp", "data"),
}


@dataclass(frozen=True, slots=True)
class Db3Summary:
    """What ``db3_to_mcap`` wrote: source files, message count, per-topic counts and where each type's
    definition came from (``bag``: the file's message_definitions table; ``ros2defs``: holoslam's copy;
    ``none``: an empty schema, so the reader reports that channel as undecodable)."""

    files: tuple[str, ...]
    out_path: str
    messages: int
    topic_counts: tuple[tuple[str, int], ...]  # (topic, messages), sorted by topic
    definitions: tuple[tuple[str, str], ...]  # (type, "bag" | "ros2defs" | "none"), sorted by type
    orphans: int = 0  # messages whose topic id is not in table 'topics' (not written; reported)


def is_sqlite(head: bytes) -> bool:
    """True when ``head`` (the first 16 bytes of a file) is the SQLite 3 magic."""
    return head.startswith(SQLITE_MAGIC[:15])


def _connect(path: Path) -> sqlite3.Connection:
    uri = path.resolve().as_uri() + "?mode=ro"
    try:
        con = sqlite3.connect(uri, uri=True)
        tables = {
            name: [r[1] for r in con.execute(f"PRAGMA table_info({name})")]
            for (name,) in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
        }
    except sqlite3.Error as exc:
        raise IngestError(
            f"{path}: not a readable rosbag2 sqlite3 database ({exc}); the file is corrupt or not a bag. "
            "If the recorder crashed, try `sqlite3 FILE .recover` or re-record"
        ) from exc
    problems = []
    for table, cols in _REQUIRED.items():
        if table not in tables:
            problems.append(f"table '{table}' is missing")
            continue
        missing = [c for c in cols if c not in tables[table]]
        if missing:
            problems.append(f"table '{table}' lacks column(s) {', '.join(missing)}")
    if problems:
        con.close()
        raise IngestError(
            f"{path}: not a rosbag2 sqlite3 bag ({'; '.join(problems)}; tables present: "
            f"{', '.join(sorted(tables)) or 'none'}); give a .db3 written by `ros2 bag record`"
        )
    con.text_factory = lambda b: b.decode("utf-8", "replace")
    return con


def _bag_definitions(con: sqlite3.Connection, path: Path) -> dict[str, str]:
    """type -> ros2msg text from the ``message_definitions`` table (ROS 2 Iron and later), when present."""
    has = con.execute(
        "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'message_definitions'"
    ).fetchone()
    if not has:
        return {}
    try:
        rows = con.execute(
            "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
        ).fetchall()
    except sqlite3.Error as exc:
        raise IngestError(f"{path}: cannot read table 'message_definitions' ({exc})") from exc
    return {t: d for t, enc, d in rows if enc == "ros2msg" and d}


def _definition(typ: str, bag: dict[str, str]) -> tuple[str, str]:
    if typ in bag:
        return bag[typ], "bag"
    try:
        return msgdef(typ), "ros2defs"
    except KeyError:
        return "", "none"


def _rows(con: sqlite3.Connection, fi: int, path: Path) -> Iterator[tuple[int, int, int, int, bytes]]:
    """(timestamp, file index, row id, topic id, data) in (timestamp, id) order."""
    try:
        for ts, rid, tid, data in con.execute(
            "SELECT timestamp, id, topic_id, data FROM messages ORDER BY timestamp, id"
        ):
            yield int(ts), fi, int(rid), int(tid), bytes(data)
    except sqlite3.Error as exc:
        raise IngestError(
            f"{path}: reading table 'messages' failed ({exc}); the database is corrupt past this point"
        ) from exc


def db3_to_mcap(db3_paths: Sequence[str | Path] | str | Path, out_path: str | Path) -> Db3Summary:
    """Convert rosbag2 ``.db3`` file(s) (one bag, split files in metadata.yaml order) into one MCAP.

    One schema per type (encoding ``ros2msg``; definition from the bag's ``message_definitions`` table, else
    ``holoslam.io.ros2defs.msgdef``, else empty), one channel per (topic, type) with the bag's serialization
    format (``cdr``), messages merged across files in (timestamp, file, id) order with
    log_time = publish_time = timestamp. Raises IngestError naming the file for a missing, corrupt or
    non-rosbag2 database; messages whose topic id is not in table ``topics`` are counted in ``orphans``.
    """
    from mcap.writer import CompressionType, Writer

    paths = [Path(db3_paths)] if isinstance(db3_paths, (str, Path)) else [Path(p) for p in db3_paths]
    if not paths:
        raise IngestError("db3_to_mcap: no .db3 files given")
    for p in paths:
        if not p.is_file():
            raise IngestError(f"{p}: no such .db3 file; check the path or the bag's metadata.yaml")
    cons = [_connect(p) for p in paths]
    try:
        out = Path(out_path)
        counts: dict[str, int] = {}
        sources: dict[str, str] = {}
        with open(out, "wb") as fh:
            w = Writer(fh, compression=CompressionType.NONE)
            w.start(profile="ros2", library="holoslam rosbag2_sqlite")
            schema_ids: dict[str, int] = {}
            channel_ids: dict[tuple[str, str, str], int] = {}
            topic_map: dict[tuple[int, int], tuple[int, str]] = {}  # (file, topic id) -> (channel, topic)
            for fi, (con, p) in enumerate(zip(cons, paths, strict=True)):
                bag = _bag_definitions(con, p)
                try:
                    topics = con.execute("SELECT id, name, type, serialization_format FROM topics").fetchall()
                except sqlite3.Error as exc:
                    raise IngestError(f"{p}: reading table 'topics' failed ({exc})") from exc
                for tid, name, typ, fmt in topics:
                    if typ not in schema_ids:
                        text, src = _definition(typ, bag)
                        schema_ids[typ] = w.register_schema(typ, "ros2msg", text.encode("utf-8"))
                        sources[typ] = src
                    key = (name, typ, fmt or "cdr")
                    if key not in channel_ids:
                        channel_ids[key] = w.register_channel(name, fmt or "cdr", schema_ids[typ])
                        counts.setdefault(name, 0)
                    topic_map[(fi, int(tid))] = (channel_ids[key], name)
            streams = [_rows(con, fi, p) for fi, (con, p) in enumerate(zip(cons, paths, strict=True))]
            n = orphans = 0
            for ts, fi, _rid, tid, data in heapq.merge(*streams):
                ch = topic_map.get((fi, tid))
                if ch is None:  # no topic, no type: undecodable; the others go on
                    orphans += 1
                    continue
                w.add_message(ch[0], log_time=ts, data=data, publish_time=ts)
                counts[ch[1]] += 1
                n += 1
            w.finish()
    finally:
        for con in cons:
            con.close()
    return Db3Summary(
        files=tuple(str(p) for p in paths),
        out_path=str(out),
        messages=n,
        topic_counts=tuple(sorted(counts.items())),
        definitions=tuple(sorted(sources.items())),
        orphans=orphans,
    )
