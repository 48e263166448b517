"""``inspect_log``: a log's channels, counts, roles and time range from its summary section, and its
renderers (``format_summary``, ``summary_to_dict``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holoslam.io.mcap.container import _resolve_files, _sqlite_to_mcap
from holoslam.io.mcap.mapping import LogMapping, load_mapping
from holoslam.io.mcap.report import _table
from holoslam.io.mcap.roles import (
    RUN_ROLES,
    ChannelInfo,
    RoleChoice,
    _assign_roles,
    _choice_dict,
    _scan_channels,
)


@dataclass(frozen=True, slots=True)
class LogSummary:
    """What ``holoslam inspect`` prints: every topic, the time range, index state, and the run's inputs."""

    source: str
    files: tuple[str, ...]
    indexed: bool
    start_ns: int
    end_ns: int
    message_count: int
    channels: tuple[ChannelInfo, ...]
    uses: tuple[tuple[str, str], ...]  # (role, topic)
    missing: tuple[str, ...]  # roles a SLAM run needs that no topic fills
    problems: tuple[str, ...]
    notes: tuple[str, ...] = ()
    choices: tuple[RoleChoice, ...] = ()  # roles several topics could fill: which one is used and why


def inspect_log(path: str | Path, mapping: str | Path | dict | LogMapping | None = None) -> LogSummary:
    """Summarise a log from its summary section (a full read only when the file has none).

    Raises IngestError for a missing, empty or non-MCAP file; ambiguous roles are listed, not raised.
    """
    files = _resolve_files(path)
    m = load_mapping(mapping)
    read_files, tmp, note = _sqlite_to_mcap(files)
    try:
        topics, indexed, start, end, notes = _scan_channels(read_files)
    finally:
        if tmp is not None:
            tmp.cleanup()
    if note:
        notes = [note, *notes]
    choices, problems = _assign_roles(topics, m)
    dur = (end - start) / 1e9 if end > start else 0.0
    chans = []
    for t in sorted(topics.values(), key=lambda t: t.topic):
        sc = t.schema
        ch = t.channels[0][1]
        if t.first_ns is not None and t.last_ns is not None and t.last_ns > t.first_ns and not indexed:
            rate = (t.count - 1) / ((t.last_ns - t.first_ns) / 1e9)
        else:
            rate = t.count / dur if dur > 0 else 0.0
        chans.append(
            ChannelInfo(
                topic=t.topic,
                schema=sc.name if sc is not None else "",
                schema_encoding=sc.encoding if sc is not None else "",
                message_encoding=ch.message_encoding,
                message_count=t.count,
                rate_hz=rate,
                role=t.role.value if t.role is not None else None,
                status=t.status,
                channel_ids=tuple(c.id for _, c in t.channels),
            )
        )
        if t.problem and t.role is None and not t.status.startswith("skipped: service"):
            problems.append(f"{t.topic}: cannot be decoded ({t.problem})")
        elif t.problem and t.role is not None:
            problems.append(
                f"{t.topic}: cannot be decoded ({t.problem}); its {t.role.value} data will be missing"
            )
    uses = tuple(
        sorted((t.role.value, t.topic) for t in topics.values() if t.role is not None and t.status == "used")
    )
    used_roles = {r for r, _ in uses}
    missing = tuple(r.value for r in RUN_ROLES if r.value not in used_roles)
    return LogSummary(
        source=str(path),
        files=tuple(str(f) for f in files),
        indexed=indexed,
        start_ns=start,
        end_ns=end,
        message_count=sum(t.count for t in topics.values()),
        channels=tuple(chans),
        uses=uses,
        missing=missing,
        problems=tuple(problems),
        notes=tuple(notes),
        choices=tuple(choices),
    )


def summary_to_dict(s: LogSummary) -> dict[str, Any]:
    """JSON-able dict of a LogSummary."""
    return {
        "source": s.source,
        "files": list(s.files),
        "indexed": s.indexed,
        "start_ns": s.start_ns,
        "end_ns": s.end_ns,
        "duration_s": (s.end_ns - s.start_ns) / 1e9,
        "message_count": s.message_count,
        "channels": [
            {
                "topic": c.topic,
                "schema": c.schema,
                "schema_encoding": c.schema_encoding,
                "message_encoding": c.message_encoding,
                "count": c.message_count,
                "rate_hz": round(c.rate_hz, 3),
                "role": c.role,
                "status": c.status,
            }
            for c in s.channels
        ],
        "uses": dict(s.uses),
        "missing": list(s.missing),
        "problems": list(s.problems),
        "notes": list(s.notes),
        "choices": [_choice_dict(c) for c in s.choices],
    }


def format_summary(s: LogSummary) -> str:
    """The readable channel table of ``holoslam inspect``."""
    out = [f"log: {s.source}"]
    if len(s.files) > 1:
        out.append(f"files: {len(s.files)} (" + ", ".join(Path(f).name for f in s.files) + ")")
    out.append(
        f"time: {s.start_ns / 1e9:.3f} .. {s.end_ns / 1e9:.3f} s (log time, {(s.end_ns - s.start_ns) / 1e9:.1f} s), "
        f"{s.message_count} messages, {'indexed' if s.indexed else 'NOT indexed (no summary; read in full)'}"
    )
    rows = [["topic", "type", "encoding", "count", "rate Hz", "role", "status"]]
    for c in s.channels:
        rows.append(
            [
                c.topic,
                c.schema or "-",
                c.message_encoding or "-",
                str(c.message_count),
                f"{c.rate_hz:.1f}",
                c.role or "-",
                c.status,
            ]
        )
    out.extend(_table(rows))
    out.append("a run would use: " + (", ".join(f"{r}={t}" for r, t in s.uses) or "nothing"))
    if s.missing:
        out.append("missing for a SLAM run: " + ", ".join(s.missing))
    for choice in s.choices:
        out.append(f"chosen: {choice.text()}")
    for p in s.problems:
        out.append(f"problem: {p}")
    for n in s.notes:
        out.append(f"note: {n}")
    return "\n".join(out)
