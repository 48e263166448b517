"""The streaming reader (``LogReader``): decoders per channel, clock re-basing, frames, and the report;
``iter_records`` and ``read_log`` on top of it."""

from __future__ import annotations

import json
import math
import struct
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.errors import IngestError
from holoslam.io.mcap.container import (
    _OP_CHANNEL,
    _OP_MESSAGE,
    _OP_SCHEMA,
    _FileState,
    _iter_file,
    _resolve_files,
    _sqlite_to_mcap,
)
from holoslam.io.mcap.convert import _Conv, _convert
from holoslam.io.mcap.levelling import level_scans
from holoslam.io.mcap.mapping import LogMapping, load_mapping
from holoslam.io.mcap.report import GAP_FACTOR, ChannelReport, IngestReport
from holoslam.io.mcap.roles import (
    _assign_roles,
    _decoder_problem,
    _scan_channels,
    _Topic,
    normalize_schema_name,
)
from holoslam.types import (
    CameraInfo,
    GroundTruthPose,
    GroundTruthWorld,
    Heading,
    Image,
    LogData,
    Odometry,
    Record,
    Role,
    Scan,
    TagSighting,
    Transform,
)

CLOCK_THRESHOLD_NS = 1_000_000_000
CLOCK_WINDOW = 8


class _TopicState:
    def __init__(self, t: _Topic) -> None:
        self.t = t
        self.messages = 0
        self.decoded = 0
        self.failed = 0
        self.first_error = ""
        self.records = 0
        self.out_of_order = 0
        self.last_stamp: int | None = None
        self.stamps = array("q")
        self.offset: int | None = None  # decided after CLOCK_WINDOW messages
        self.pending: list[tuple[int, int, list[Record]]] = []  # (log_time, stamp, records)
        self.decoder_name = ""
        self.last_frame: str | None = None
        self.conv = _Conv(t.topic, t.role, t.rule) if t.role is not None else None


class LogReader:
    """Streams ``(topic, record)`` from a log; call ``report()`` after iterating (or at any point).

    Raises IngestError at construction for a missing/empty/foreign file, a mapping topic that is not in the
    log, or two topics competing for one role.
    """

    def __init__(
        self,
        path: str | Path,
        mapping: str | Path | dict | LogMapping | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> None:
        self.source = str(path)
        self.files = _resolve_files(path)
        self.mapping = load_mapping(mapping)
        self.progress = progress
        self._read_files, self._tmp, note = _sqlite_to_mcap(self.files)
        try:
            topics, _indexed, _s, _e, _notes = _scan_channels(self._read_files)
            choices, problems = _assign_roles(topics, self.mapping)
            if problems:
                raise IngestError(f"{path}: " + " | ".join(problems))
        except BaseException:
            self._cleanup()
            raise
        self._topics = topics
        self._state = {name: _TopicState(t) for name, t in topics.items()}
        self._clocks: list[int] = []
        self._rebased: list[str] = []
        self._warnings: list[str] = [note] if note else []
        self._files: list[_FileState] = []
        self._edges: dict[str, str] = {}  # child -> parent
        for t in self.mapping.static_transforms if self.mapping is not None else ():
            self._edges[t.child] = t.parent  # the mapping's static transforms replace the log's
        self._sensor_frames: dict[str, str] = {}  # frame -> topic
        self._choices = tuple(choices)
        # the robot's base frame: the mapping's frames.base, else the odometry's child frame (see _note_frames)
        fixed_base = self.mapping.base_frame if self.mapping is not None else None
        self._base_frame_fixed = fixed_base is not None
        self._base_frame = fixed_base or "base_link"
        self._base_frame_seen = self._base_frame_fixed
        self._start: int | None = None
        self._end: int | None = None
        self._done = False

    # -- decoding ------------------------------------------------------------------------------------------
    def _decoder_for(self, ts: _TopicState, schema: Any, channel: Any) -> Callable[[memoryview], Any]:
        from holoslam.io import cdr

        enc = channel.message_encoding
        kind = normalize_schema_name(schema.name) if schema is not None else ""
        if enc == "cdr":
            fields = ts.conv.fields if ts.conv is not None else {}
            fast = cdr.FAST_DECODERS.get(kind) if not fields else None
            if fast is None:
                generic = cdr.generic_decoder(schema.name, schema.data.decode("utf-8"))
                ts.decoder_name = "generic-cdr"
                return lambda d: generic(bytes(d))
            lazy: list[Callable[[bytes], Any]] = []  # the generic decoder, built on the first fallback

            def dec(d: memoryview) -> Any:
                try:
                    return fast(d)
                except (cdr.CdrFallback, struct.error, UnicodeDecodeError):
                    if not lazy:
                        lazy.append(cdr.generic_decoder(schema.name, schema.data.decode("utf-8")))
                    return lazy[0](bytes(d))

            ts.decoder_name = "fast-cdr"
            return dec
        if enc == "protobuf":
            from mcap_protobuf.decoder import DecoderFactory

            f = DecoderFactory().decoder_for("protobuf", schema)
            if f is None:
                raise ValueError("no protobuf decoder for this schema")
            ts.decoder_name = "protobuf"
            return lambda d: f(bytes(d))
        if enc == "json":
            ts.decoder_name = "json"
            return lambda d: json.loads(bytes(d))
        raise ValueError(_decoder_problem(schema, channel) or f"cannot decode encoding {enc}")

    def _cleanup(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __iter__(self) -> Iterator[tuple[str, Record]]:
        try:
            yield from self._iter_files()
        finally:
            self._cleanup()

    def _iter_files(self) -> Iterator[tuple[str, Record]]:
        if self._done:
            raise IngestError(f"{self.source}: a LogReader streams once; make a new one to read again")
        self._done = True
        total = sum(p.stat().st_size for p in self._read_files)
        done_bytes = 0
        for fi, path in enumerate(self._read_files):
            st = _FileState(path)
            self._files.append(st)
            schemas: dict[int, Any] = {}
            decoders: dict[int, tuple[_TopicState | None, Callable[[memoryview], Any] | None, str]] = {}
            last_progress = 0
            for op, rec in _iter_file(st):
                if op == _OP_MESSAGE:
                    cid, log_time, data = rec
                    entry = decoders.get(cid)
                    if entry is None:
                        self._warnings.append(
                            f"{path.name}: message on unknown channel id {cid} (no Channel record)"
                        )
                        decoders[cid] = entry = (None, None, "")
                    ts, dec, kind = entry
                    if ts is None:
                        continue
                    ts.messages += 1
                    if self._start is None:
                        self._start = self._end = log_time
                    elif log_time < self._start:
                        self._start = log_time
                    elif log_time > self._end:
                        self._end = log_time
                    if dec is None or ts.conv is None:  # a channel without a role has no decoder
                        continue
                    try:
                        stamp, records = _convert(ts.conv, kind, dec(data))
                    except Exception as exc:
                        ts.failed += 1
                        if not ts.first_error:
                            ts.first_error = f"log time {log_time} ns: {type(exc).__name__}: {exc}"
                        continue
                    ts.decoded += 1
                    out = self._timed(ts, log_time, stamp, records)
                    if out:
                        yield from out
                    if self.progress is not None and st.bytes_read - last_progress > (1 << 22):
                        last_progress = st.bytes_read
                        self.progress(done_bytes + st.bytes_read, total)
                elif op == _OP_SCHEMA:
                    schemas[rec.id] = rec
                elif op == _OP_CHANNEL:
                    decoders[rec.id] = self._channel(fi, rec, schemas)
            done_bytes += st.size
            if self.progress is not None:
                self.progress(done_bytes, total)
        for ts in self._state.values():
            yield from self._flush(ts)

    def _channel(
        self, fi: int, rec: Any, schemas: dict[int, Any]
    ) -> tuple[_TopicState, Callable[[memoryview], Any] | None, str]:
        """A channel record -> (its topic's state, its decoder or None when not used, normalised schema name)."""
        ts = self._state.get(rec.topic)
        if ts is None:  # a channel the pre-scan did not see (damaged summary): not used
            t = _Topic(
                rec.topic,
                schemas.get(rec.schema_id),
                [(fi, rec)],
                None,
                "skipped: not in summary",
            )
            self._topics[rec.topic] = t
            ts = self._state[rec.topic] = _TopicState(t)
        schema = schemas.get(rec.schema_id) if rec.schema_id else None
        dec = None
        if ts.conv is not None and ts.t.status == "used":
            try:
                dec = self._decoder_for(ts, schema, rec)
            except Exception as exc:
                ts.first_error = ts.first_error or f"no decoder: {exc}"
        return ts, dec, normalize_schema_name(schema.name) if schema else ""

    # -- time --------------------------------------------------------------------------------------------
    # These return lists rather than being generators: nearly every call gives one record, and a list is far
    # cheaper to build and drain per message than a generator object (measured in benchmarks/bench_ingest.py).
    def _timed(
        self, ts: _TopicState, log_time: int, stamp: int, records: list[Record]
    ) -> list[tuple[str, Record]]:
        if stamp == 0:
            stamp = log_time
        if ts.offset is None:
            if ts.t.role is not Role.TF_STATIC and ts.t.role is not Role.GROUND_TRUTH_WORLD:
                ts.pending.append((log_time, stamp, records))
                if len(ts.pending) >= CLOCK_WINDOW:
                    return self._flush(ts)
                return []
            ts.offset = 0
            if ts.t.role is Role.TF_STATIC and abs(log_time - stamp) > CLOCK_THRESHOLD_NS:
                self._warnings.append(
                    f"{ts.t.topic}: static transforms stamped {(log_time - stamp) / 1e9:.1f} s before their log time "
                    "(latched); they hold for the whole log"
                )
        out: list[tuple[str, Record]] = []
        self._emit(ts, log_time, stamp, records, out)
        return out

    def _flush(self, ts: _TopicState) -> list[tuple[str, Record]]:
        if ts.offset is None and ts.pending:
            d = sorted(lt - s for lt, s, _ in ts.pending)
            med = d[len(d) // 2]
            if abs(med) > CLOCK_THRESHOLD_NS:
                snap = next((c for c in self._clocks if abs(c - med) <= CLOCK_THRESHOLD_NS), None)
                if snap is None:
                    self._clocks.append(med)
                    snap = med
                ts.offset = snap
                self._rebased.append(
                    f"{ts.t.topic}: header stamps are {med / 1e9:+.3f} s from log time (another clock); "
                    f"re-based by {snap / 1e9:+.3f} s"
                )
            else:
                ts.offset = 0
        pending, ts.pending = ts.pending, []
        out: list[tuple[str, Record]] = []
        for lt, s, recs in pending:
            self._emit(ts, lt, s, recs, out)
        return out

    def _emit(
        self, ts: _TopicState, log_time: int, stamp: int, records: list[Record], out: list[tuple[str, Record]]
    ) -> None:
        off = ts.offset or 0
        s = stamp + off
        if ts.last_stamp is not None and s < ts.last_stamp:
            ts.out_of_order += 1
        ts.last_stamp = s
        ts.stamps.append(s)
        topic = ts.t.topic
        for r in records:
            if isinstance(r, Transform):
                if not r.static:
                    rs = r.stamp_ns
                    if rs == 0:
                        r = replace(r, stamp_ns=log_time)
                    elif off:
                        r = replace(r, stamp_ns=rs + off)
                fr = None
            elif isinstance(r, GroundTruthWorld):
                r = replace(r, stamp_ns=log_time)
                fr = None
            else:
                rs = r.stamp_ns
                if rs == 0:
                    r = replace(r, stamp_ns=log_time)
                elif off:
                    r = replace(r, stamp_ns=rs + off)
                fr = getattr(r, "frame_id", None)
            ts.records += 1
            if fr is None or fr != ts.last_frame:
                ts.last_frame = fr
                self._note_frames(topic, r)
            out.append((topic, r))

    def _note_frames(self, topic: str, r: Record) -> None:
        if isinstance(r, Transform):
            if r.child not in self._edges:
                self._edges[r.child] = r.parent
        elif isinstance(r, Odometry):
            if not self._base_frame_seen and r.child_frame_id:
                self._base_frame, self._base_frame_seen = r.child_frame_id, True
        elif isinstance(r, (Scan, Image)) and r.frame_id and r.frame_id not in self._sensor_frames:
            self._sensor_frames[r.frame_id] = topic

    # -- report ------------------------------------------------------------------------------------------
    def _root(self, f: str) -> str:
        seen = set()
        while f in self._edges and f not in seen:
            seen.add(f)
            f = self._edges[f]
        return f

    def report(self) -> IngestReport:
        chans = []
        for name in sorted(self._state):
            ts = self._state[name]
            t = ts.t
            stamps = (
                np.sort(np.frombuffer(ts.stamps, dtype=np.int64)) if len(ts.stamps) else np.empty(0, np.int64)
            )
            gaps: list[tuple[int, int]] = []
            gap_count = 0
            med = 0
            if stamps.size >= 3:
                dt = np.diff(stamps)
                med = int(np.median(dt))
                if med > 0:
                    idx = np.flatnonzero(dt > GAP_FACTOR * med)
                    gap_count = int(idx.size)
                    gaps = [(int(stamps[i]), int(stamps[i + 1])) for i in idx[:20]]
            conv = ts.conv
            skipped = ts.messages if (conv is None or t.status != "used") else conv.skipped
            reason = t.status if (conv is None or t.status != "used") else conv.skip_reason
            failed = ts.failed
            first_error = ts.first_error
            if t.status.startswith("undecodable"):
                if t.role is not None:
                    failed, skipped, first_error = ts.messages, 0, t.status
                else:
                    reason = t.status
            chans.append(
                ChannelReport(
                    topic=name,
                    schema=t.schema.name if t.schema is not None else "",
                    message_encoding=t.channels[0][1].message_encoding if t.channels else "",
                    role=t.role.value if t.role is not None else None,
                    decoder=ts.decoder_name,
                    messages=ts.messages,
                    decoded=ts.decoded,
                    failed=failed,
                    first_error=first_error,
                    skipped=skipped,
                    skip_reason=reason if skipped else "",
                    records=ts.records,
                    out_of_order=ts.out_of_order,
                    gaps=tuple(gaps),
                    gap_count=gap_count,
                    median_period_ns=med,
                    stamp_offset_ns=ts.offset or 0,
                    zero_covariances=conv.zero_cov if conv else 0,
                    mostly_invalid_scans=conv.mostly_invalid if conv else 0,
                )
            )
        missing = []
        if self._edges or self._sensor_frames:
            base_root = self._root(self._base_frame)
            for frame, topic in sorted(self._sensor_frames.items()):
                if frame != self._base_frame and self._root(frame) != base_root:
                    missing.append(
                        f"frame '{frame}' of {topic} is not connected to '{self._base_frame}' by /tf or /tf_static; "
                        "its data cannot be placed on the robot (add the static transform or a mapping)"
                    )
        lost = tuple(x for st in self._files for x in st.lost)
        warnings = list(self._warnings)
        for st in self._files:
            warnings.extend(f"{st.path.name}: {n}" for n in st.notes)
        return IngestReport(
            source=self.source,
            files=tuple(str(p) for p in self.files),
            channels=tuple(chans),
            crc_errors=sum(st.crc_errors for st in self._files),
            truncated=any(st.truncated for st in self._files),
            lost=lost,
            rebased=tuple(self._rebased),
            missing_transforms=tuple(missing),
            warnings=tuple(warnings),
            start_ns=self._start or 0,
            end_ns=self._end or 0,
            base_frame=self._base_frame,
            base_frame_from=(
                "named by the mapping"
                if self._base_frame_fixed
                else "the odometry's child frame"
                if self._base_frame_seen
                else "default: no odometry names a child frame"
            ),
            choices=self._choices,
        )


def iter_records(
    path: str | Path, mapping: str | Path | dict | LogMapping | None = None
) -> Iterator[tuple[str, Record]]:
    """Stream ``(topic, record)`` pairs of a log in file order (memory bounded by one chunk plus a window of
    ``CLOCK_WINDOW`` messages per topic). Use ``LogReader`` to get the report too."""
    yield from LogReader(path, mapping)


def read_log(
    path: str | Path,
    mapping: str | Path | dict | LogMapping | None = None,
    progress: Callable[[int, int], None] | None = None,
    require: Iterable[Role | str] = (),
) -> tuple[LogData, IngestReport]:
    """Read a whole log: records grouped by kind and sorted by stamp, and the ingest report.

    ``require`` lists roles that must be present (e.g. odometry and scan for a SLAM run); IngestError names
    what is missing and what the log offers.
    """
    reader = LogReader(path, mapping, progress)
    buckets: dict[type, list] = {
        k: [] for k in (Odometry, Heading, Scan, Image, CameraInfo, Transform, TagSighting, GroundTruthPose)
    }
    world: str | None = None
    for _topic, rec in reader:
        if isinstance(rec, GroundTruthWorld):
            world = world or rec.json_text
        else:
            buckets[type(rec)].append(rec)
    report = reader.report()
    for r in require:
        role = Role(r)
        if not any(c.role == role.value and c.records for c in report.channels):
            offered = ", ".join(f"{c.topic} ({c.schema})" for c in report.channels) or "none"
            damage = ""
            if report.truncated or report.crc_errors or report.lost:
                damage = (
                    f" The file is damaged ({'truncated' if report.truncated else 'corrupt'}, "
                    f"{report.crc_errors} CRC errors, {len(report.lost)} lost ranges): what it held before the "
                    "damage was read; `holoslam inspect` lists what survived."
                )
            raise IngestError(
                f"{path}: no {role.value} data (a required input). Topics in the log: {offered}.{damage} "
                "If one of them carries it, assign it in a mapping file, e.g. 'topics: {/my_topic: "
                + role.value
                + "}'"
            )
    key = lambda r: r.stamp_ns  # noqa: E731
    transforms, notes = _with_mapping_transforms(tuple(sorted(buckets[Transform], key=key)), reader.mapping)
    if notes:
        report = replace(report, warnings=report.warnings + notes)
    scans, level_tfs, levelled, tilted = level_scans(
        tuple(sorted(buckets[Scan], key=key)), transforms, report.base_frame
    )
    if levelled or tilted:
        report = replace(report, levelled=tuple(levelled), warnings=report.warnings + tuple(tilted))
    data = LogData(
        source=str(path),
        odometry=tuple(sorted(buckets[Odometry], key=key)),
        headings=tuple(sorted(buckets[Heading], key=key)),
        scans=scans,
        images=tuple(sorted(buckets[Image], key=key)),
        camera_infos=tuple(sorted(buckets[CameraInfo], key=key)),
        transforms=level_tfs + transforms,
        tags=tuple(sorted(buckets[TagSighting], key=key)),
        ground_truth=tuple(sorted(buckets[GroundTruthPose], key=key)),
        world_json=world,
        base_frame=report.base_frame,
    )
    return data, report


def _describe(t: Transform) -> str:
    from holoslam.frames import yaw_from_quaternion

    x, y, z = t.translation
    return f"x={x:+.3f} y={y:+.3f} z={z:+.3f} m, yaw {math.degrees(yaw_from_quaternion(*t.rotation_xyzw)):+.1f} deg"


def _with_mapping_transforms(
    transforms: tuple[Transform, ...], mapping: LogMapping | None
) -> tuple[tuple[Transform, ...], tuple[str, ...]]:
    """The log's transforms with the mapping's ``frames.static`` in place of every transform of the same child
    frame, and a note per replacement saying what the log had (nothing is dropped unsaid)."""
    if mapping is None or not mapping.static_transforms:
        return transforms, ()
    ours = {t.child: t for t in mapping.static_transforms}
    notes = []
    for child, t in ours.items():
        theirs = [r for r in transforms if r.child == child]
        was = (f"the log's {theirs[0].parent}->{child} ({_describe(theirs[0])}"
               + (f", {len(theirs)} messages" if len(theirs) > 1 else "") + ")") if theirs else "nothing in the log"
        notes.append(f"{mapping.source}: frames.static sets {t.parent}->{child} to {_describe(t)}; it replaces {was}")
    kept = tuple(r for r in transforms if r.child not in ours)
    return tuple(mapping.static_transforms) + kept, tuple(notes)
