"""Cut a time window out of an MCAP log, for tests and benchmarks on a few minutes of a long log.

The raw messages are copied as they are (no decoding): every schema and channel of the source is written
(same names, encodings, schema text, topics and metadata; ids are re-numbered 1..n in the source's id order),
then the messages whose log time is in the window, in log-time order, then the source's metadata records. Static
transforms (``/tf_static``, any topic ending in ``tf_static``) are kept whatever their log time: a cut that
begins after them still knows where its sensors are mounted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from holoslam.errors import IngestError

__all__ = ["CutLog", "cut_log"]


@dataclass(frozen=True)
class CutLog:
    """A written cut: the window [start_ns, end_ns) in the source's log time, the first message's log time in
    the source (the origin of ``start_s``), and the messages written per topic."""

    path: Path
    start_ns: int
    end_ns: int
    source_start_ns: int
    messages: dict[str, int] = field(default_factory=dict)

    @property
    def n_messages(self) -> int:
        return sum(self.messages.values())


def _is_static_tf(topic: str) -> bool:
    return topic.rstrip("/").endswith("tf_static")


def cut_log(src: str | Path, dst: str | Path, start_s: float, duration_s: float) -> CutLog:
    """Write to ``dst`` the messages of ``src`` with log time in [t0 + start_s, t0 + start_s + duration_s),
    t0 the log time of the source's first message, plus every static transform (module docstring).
    Raises :class:`IngestError` when the source cannot be read and ValueError for a negative start or a
    duration that is not positive."""
    import math

    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    if not (math.isfinite(start_s) and start_s >= 0):
        raise ValueError(f"cut_log: start_s must be a finite number >= 0, got {start_s}")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"cut_log: duration_s must be a finite number > 0, got {duration_s}")
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise ValueError(f"cut_log: {dst} is the source itself; write the cut to another file")
    try:
        fin = open(src, "rb")  # closed by the with below, also on errors
    except OSError as e:
        raise IngestError(f"{src}: cannot be opened ({e.strerror}); give an MCAP log") from None
    try:
        with fin:
            reader = make_reader(fin)
            header = reader.get_header()
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                raise IngestError(
                    f"{src}: the log has no summary section (statistics, channels); it may be truncated: "
                    "repair it first (for example 'mcap recover')"
                )
            t0 = int(summary.statistics.message_start_time)
            start = t0 + round(start_s * 1e9)
            end = start + round(duration_s * 1e9)
            with open(dst, "wb") as fout:
                w = Writer(fout, compression=CompressionType.ZSTD)
                w.start(profile=header.profile, library=f"{header.library} (cut by holoslam)".strip())
                schema_ids = {0: 0}
                for sid in sorted(summary.schemas):
                    s = summary.schemas[sid]
                    schema_ids[sid] = w.register_schema(s.name, s.encoding, s.data)
                channel_ids: dict[int, int] = {}
                static: set[int] = set()
                for cid in sorted(summary.channels):
                    c = summary.channels[cid]
                    channel_ids[cid] = w.register_channel(
                        c.topic, c.message_encoding, schema_ids[c.schema_id], dict(c.metadata)
                    )
                    if _is_static_tf(c.topic):
                        static.add(cid)
                counts: dict[str, int] = {}
                for _schema, channel, message in reader.iter_messages(log_time_order=True):
                    lt = message.log_time
                    if not (start <= lt < end or channel.id in static):
                        continue
                    w.add_message(
                        channel_ids[channel.id], lt, message.data, message.publish_time, message.sequence
                    )
                    counts[channel.topic] = counts.get(channel.topic, 0) + 1
                for md in reader.iter_metadata():
                    w.add_metadata(md.name, dict(md.metadata))
                w.finish()
    except McapError as e:
        raise IngestError(f"{src}: not a readable MCAP log ({e}); give an MCAP file") from None
    except OSError as e:
        raise IngestError(
            f"{e.filename or dst}: cannot be written ({e.strerror}); check the folder"
        ) from None
    return CutLog(dst, start, end, t0, counts)
