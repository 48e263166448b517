"""The ingest report: what ingestion did with each topic (``ChannelReport``) and with the log
(``IngestReport``), and its renderers."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holoslam.io.mcap.container import LostRange
from holoslam.io.mcap.convert import MOSTLY_INVALID
from holoslam.io.mcap.roles import RoleChoice, _choice_dict

GAP_FACTOR = 5.0


@dataclass(frozen=True, slots=True)
class ChannelReport:
    """What ingestion did with one topic."""

    topic: str
    schema: str
    message_encoding: str
    role: str | None
    decoder: str  # "fast-cdr", "generic-cdr", "protobuf", "json", or "" when not decoded
    messages: int  # messages seen
    decoded: int  # messages that gave records
    failed: int
    first_error: str
    skipped: int
    skip_reason: str
    records: int
    out_of_order: int
    gaps: tuple[tuple[int, int], ...]  # (from ns, to ns) of gaps > GAP_FACTOR x median period (first 20)
    gap_count: int
    median_period_ns: int
    stamp_offset_ns: int  # added to the header stamps (0 when not re-based)
    zero_covariances: int
    mostly_invalid_scans: int


@dataclass(frozen=True, slots=True)
class IngestReport:
    """Everything ingestion noticed about one log. Always produced, JSON-able via ``report_to_dict``."""

    source: str
    files: tuple[str, ...]
    channels: tuple[ChannelReport, ...]
    crc_errors: int
    truncated: bool
    lost: tuple[LostRange, ...]
    rebased: tuple[str, ...]
    missing_transforms: tuple[str, ...]
    warnings: tuple[str, ...]
    start_ns: int
    end_ns: int
    base_frame: str = "base_link"  # the robot's base frame the run uses
    base_frame_from: str = ""  # where it comes from: "the mapping", "the odometry's child frame", "default"
    choices: tuple[RoleChoice, ...] = ()  # roles several topics could fill: which one is used and why
    levelled: tuple[str, ...] = ()  # lasers not mounted upright whose scans were projected into a level frame

    @property
    def ok(self) -> bool:
        """No failed channel, no lost data, no missing transform."""
        return not (
            self.crc_errors
            or self.truncated
            or self.lost
            or self.missing_transforms
            or any(c.failed for c in self.channels)
        )

    def channel(self, topic: str) -> ChannelReport:
        for c in self.channels:
            if c.topic == topic:
                return c
        raise KeyError(f"topic {topic} is not in the report; topics: {[c.topic for c in self.channels]}")


def report_to_dict(r: IngestReport) -> dict[str, Any]:
    """JSON-able dict of an IngestReport."""
    return {
        "source": r.source,
        "files": list(r.files),
        "ok": r.ok,
        "start_ns": r.start_ns,
        "end_ns": r.end_ns,
        "crc_errors": r.crc_errors,
        "truncated": r.truncated,
        "lost": [
            {
                "file": x.file,
                "offset": x.offset,
                "start_ns": x.start_ns,
                "end_ns": x.end_ns,
                "reason": x.reason,
            }
            for x in r.lost
        ],
        "rebased": list(r.rebased),
        "missing_transforms": list(r.missing_transforms),
        "warnings": list(r.warnings),
        "base_frame": r.base_frame,
        "base_frame_from": r.base_frame_from,
        "choices": [_choice_dict(c) for c in r.choices],
        "levelled": list(r.levelled),
        "channels": [
            {
                k: (list(map(list, getattr(c, k))) if k == "gaps" else getattr(c, k))
                for k in ChannelReport.__slots__
            }
            for c in r.channels
        ],
    }


def format_report(r: IngestReport) -> str:
    """A readable ingest report."""
    out = [f"ingest report: {r.source} ({'ok' if r.ok else 'with problems'})"]
    rows = [
        [
            "topic",
            "role",
            "decoder",
            "msgs",
            "decoded",
            "failed",
            "skipped",
            "records",
            "out-of-order",
            "gaps",
        ]
    ]
    for c in r.channels:
        rows.append(
            [
                c.topic,
                c.role or "-",
                c.decoder or "-",
                str(c.messages),
                str(c.decoded),
                str(c.failed),
                str(c.skipped),
                str(c.records),
                str(c.out_of_order),
                str(c.gap_count),
            ]
        )
    out.extend(_table(rows))
    for c in r.channels:
        if c.failed:
            out.append(f"failed: {c.topic}: {c.failed} message(s); first error: {c.first_error}")
        if c.skipped and c.skip_reason:
            out.append(f"skipped: {c.topic}: {c.skipped} message(s): {c.skip_reason}")
        if c.zero_covariances:
            out.append(
                f"default covariance: {c.topic}: {c.zero_covariances} message(s) had an all-zero covariance "
                "(record carries None / NaN sigma; the graph uses its default noise)"
            )
        if c.mostly_invalid_scans:
            out.append(
                f"scans: {c.topic}: {c.mostly_invalid_scans} scan(s) with under "
                f"{MOSTLY_INVALID:.0%} valid beams"
            )
        for g0, g1 in c.gaps[:5]:
            out.append(
                f"gap: {c.topic}: {(g1 - g0) / 1e9:.3f} s from {g0 / 1e9:.3f} s "
                f"(median period {c.median_period_ns / 1e9:.3f} s)"
            )
    if r.truncated:
        out.append("truncated: the file ends early; every complete chunk was kept")
    if r.crc_errors:
        out.append(f"CRC errors: {r.crc_errors} chunk(s) dropped")
    for x in r.lost:
        span = f"{x.start_ns / 1e9:.3f}..{x.end_ns / 1e9:.3f} s" if x.end_ns else "time range unknown"
        out.append(f"lost: {Path(x.file).name} byte {x.offset}: {span}: {x.reason}")
    out.append(f"base frame: {r.base_frame}" + (f" ({r.base_frame_from})" if r.base_frame_from else ""))
    out.extend(f"chosen: {c.text()}" for c in r.choices)
    out.extend(f"levelled: {m}" for m in r.levelled)
    out.extend(f"re-based: {m}" for m in r.rebased)
    out.extend(f"missing transform: {m}" for m in r.missing_transforms)
    out.extend(f"warning: {w}" for w in r.warnings)
    return "\n".join(out)


def _table(rows: list[list[str]]) -> list[str]:
    w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w[i]) for i, c in enumerate(r)).rstrip() for r in rows]
