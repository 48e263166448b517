"""Bad input: each fault builds its damaged file and checks the message and what was kept."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from holoslam.errors import IngestError
from holoslam.io.mcap import format_report, format_summary, inspect_log, read_log
from holoslam.io.mcap_write import MSGDEFS, example_records, ros2_message, write_ros2_log
from holoslam.types import Odometry, Pose2, Scan, Transform


@pytest.fixture(scope="module")
def records():
    return example_records(seconds=6.0)


def _odo_stamps(records):
    return sorted(r.stamp_ns for r in records if isinstance(r, Odometry))


def _chunks(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def _odom_log_times_in_chunk(path, ci):
    """Log times of /odom messages inside the chunk at ``ci`` of an undamaged file (via the mcap library)."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, Chunk, Message
    from mcap.stream_reader import breakup_chunk

    with open(path, "rb") as f:
        f.seek(ci.chunk_start_offset + 9)
        chunk = Chunk.read(ReadDataStream(f))
    recs = breakup_chunk(chunk)
    odom_ids = {r.id for r in recs if isinstance(r, Channel) and r.topic == "/odom"} or {
        c.id for c in _summary(path).channels.values() if c.topic == "/odom"
    }
    return [r.log_time for r in recs if isinstance(r, Message) and r.channel_id in odom_ids]


def _summary(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return make_reader(f).get_summary()


def test_truncated_file_keeps_every_complete_chunk(tmp_path, records):
    full = write_ros2_log(tmp_path / "full.mcap", records, chunk_size=4096)
    chunks = _chunks(full)
    assert len(chunks) > 4
    cut_in = chunks[len(chunks) // 2]
    cut = cut_in.chunk_start_offset + cut_in.chunk_length // 2  # the recorder died inside this chunk
    bad = tmp_path / "crashed.mcap"
    bad.write_bytes(full.read_bytes()[:cut])

    data, report = read_log(bad)
    assert report.truncated and not report.ok
    assert any("truncated" in x.reason for x in report.lost)
    lost = [x for x in report.lost if x.start_ns]
    assert (
        lost and lost[0].start_ns == cut_in.message_start_time and lost[0].end_ns == cut_in.message_end_time
    )
    # exactly the messages of the complete chunks before the cut are kept
    kept_expected = [s for s in _odo_stamps(records) if s < cut_in.message_start_time]
    assert [o.stamp_ns for o in data.odometry] == kept_expected
    assert "truncated" in format_report(report)

    s = inspect_log(bad)  # no summary: inspect reads the file and says so
    assert not s.indexed
    assert any("no summary" in n for n in s.notes)
    assert {c.topic for c in s.channels} >= {"/odom", "/scan"}
    assert "NOT indexed" in format_summary(s)


def test_file_cut_inside_the_magic_or_header(tmp_path, records):
    full = write_ros2_log(tmp_path / "full.mcap", records)
    tiny = tmp_path / "tiny.mcap"
    tiny.write_bytes(full.read_bytes()[:5])
    with pytest.raises(IngestError, match="stops inside the MCAP magic"):
        read_log(tiny)
    head = tmp_path / "head.mcap"
    head.write_bytes(full.read_bytes()[:30])
    data, report = read_log(head)
    assert report.truncated and data.odometry == ()


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_flipped_byte_in_a_chunk_loses_only_that_chunk(tmp_path, records, compression):
    full = write_ros2_log(tmp_path / "full.mcap", records, chunk_size=4096, compression=compression)
    chunks = _chunks(full)
    victim = chunks[2]
    raw = bytearray(full.read_bytes())
    pos = victim.chunk_start_offset + victim.chunk_length // 2
    raw[pos] ^= 0xFF
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(raw))

    data, report = read_log(bad)
    assert report.crc_errors == 1 and not report.truncated
    (lost,) = report.lost
    assert (lost.start_ns, lost.end_ns) == (victim.message_start_time, victim.message_end_time)
    assert "CRC" in lost.reason or "decompress" in lost.reason
    lost_stamps = _odom_log_times_in_chunk(full, victim)
    assert lost_stamps
    want = sorted(set(_odo_stamps(records)) - set(lost_stamps))
    assert [o.stamp_ns for o in data.odometry] == want
    assert "lost:" in format_report(report)


def test_the_run_report_text_names_a_lost_stretch_with_its_place_in_the_log(tmp_path, records):
    """What ``holoslam run`` prints: the damaged stretch with its byte, its seconds into the log and the reason,
    not only a count (a user who reads the printed report learns what the run did without)."""
    from holoslam.io.mcap import report_to_dict
    from holoslam.report_text import _ingest_text

    full = write_ros2_log(tmp_path / "full.mcap", records, chunk_size=4096)
    victim = _chunks(full)[2]
    raw = bytearray(full.read_bytes())
    raw[victim.chunk_start_offset + victim.chunk_length // 2] ^= 0xFF
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(raw))
    _, report = read_log(bad)
    lines = _ingest_text(report_to_dict(report))
    assert lines[0].endswith("1 damaged stretch(es) left out; base frame base_link")
    (lost,) = [line for line in lines if line.startswith("    lost: flipped.mcap byte ")]
    t0, t1 = (victim.message_start_time - report.start_ns) / 1e9, (victim.message_end_time - report.start_ns) / 1e9
    assert f"byte {victim.chunk_start_offset}: {t0:.1f}..{t1:.1f} s into the log" in lost
    assert "CRC" in lost or "decompress" in lost
    assert lines[-1] == f"    (holoslam inspect {bad} lists every problem of the log by channel)"
    # an undamaged log prints no problem lines
    _, clean = read_log(full)
    assert len(_ingest_text(report_to_dict(clean))) == 1


def _plain_writer(f):
    from mcap.writer import Writer

    w = Writer(f)
    w.start(profile="ros2", library="test")
    return w


def _odom_channel(w):
    sid = w.register_schema("nav_msgs/msg/Odometry", "ros2msg", MSGDEFS["nav_msgs/msg/Odometry"].encode())
    return w.register_channel("/odom", "cdr", sid)


def _encode(typ, rec):
    from mcap_ros2._dynamic import serialize_dynamic

    return serialize_dynamic(typ, MSGDEFS[typ])[typ](ros2_message(rec))


def test_unknown_encoding_empty_schema_and_service_events_do_not_stop_others(tmp_path, records):
    odo = [r for r in records if isinstance(r, Odometry)][:10]
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = _plain_writer(f)
        c_odom = _odom_channel(w)
        s_scan = w.register_schema(
            "sensor_msgs/msg/LaserScan", "ros2msg", MSGDEFS["sensor_msgs/msg/LaserScan"].encode()
        )
        c_cbor = w.register_channel("/scan", "cbor", s_scan)
        s_empty = w.register_schema("sensor_msgs/msg/Imu", "ros2msg", b"")
        c_empty = w.register_channel("/compass", "cdr", s_empty)
        c_noschema = w.register_channel("/mystery", "cdr", 0)
        s_srv = w.register_schema("example_interfaces/srv/AddTwoInts_Event", "ros2msg", b"int64 a\n")
        c_srv = w.register_channel("/add_two_ints/_service_event", "cdr", s_srv)
        for r in odo:
            t = r.stamp_ns
            w.add_message(c_odom, t, _encode("nav_msgs/msg/Odometry", r), t)
            for c in (c_cbor, c_empty, c_noschema, c_srv):
                w.add_message(c, t, b"\x00\x01\x00\x00garbage", t)
        w.finish()

    data, report = read_log(path)
    assert len(data.odometry) == 10
    scan = report.channel("/scan")
    assert scan.failed == 10 and "unknown message encoding 'cbor'" in scan.first_error
    imu = report.channel("/compass")
    assert imu.failed == 10 and "empty schema" in imu.first_error
    mystery = report.channel("/mystery")
    assert mystery.skipped == 10 and "no schema" in mystery.skip_reason
    srv = report.channel("/add_two_ints/_service_event")
    assert srv.skipped == 10 and "service event" in srv.skip_reason
    # nothing silently dropped: every message is decoded, failed or skipped
    for c in report.channels:
        assert c.decoded + c.failed + c.skipped == c.messages, c
    s = inspect_log(path)
    assert {c.topic for c in s.channels} == {
        "/odom",
        "/scan",
        "/compass",
        "/mystery",
        "/add_two_ints/_service_event",
    }
    assert any("cbor" in p for p in s.problems)
    assert "scan" in s.missing


def test_corrupt_messages_are_counted_with_the_first_error(tmp_path, records):
    odo = [r for r in records if isinstance(r, Odometry)][:6]
    path = tmp_path / "garbled.mcap"
    with open(path, "wb") as f:
        w = _plain_writer(f)
        c = _odom_channel(w)
        for i, r in enumerate(odo):
            data = _encode("nav_msgs/msg/Odometry", r)
            w.add_message(c, r.stamp_ns, data[:30] if i == 3 else data, r.stamp_ns)
        w.finish()
    data, report = read_log(path)
    ch = report.channel("/odom")
    assert (ch.decoded, ch.failed) == (5, 1)
    assert f"log time {odo[3].stamp_ns}" in ch.first_error
    assert [o.stamp_ns for o in data.odometry] == [o.stamp_ns for k, o in enumerate(odo) if k != 3]


@pytest.mark.parametrize(
    "content, needle",
    [
        (b"", "empty"),
        (b"hello, this is a text file\n", "not an MCAP file"),
        (b"#ROSBAG V2.0\n" + b"\x00" * 100, "ROS 1 bag"),
        (b"SQLite format 3\x00" + b"\x00" * 100, "sqlite3"),
    ],
)
def test_foreign_and_empty_files_raise_a_clear_error(tmp_path, content, needle):
    p = tmp_path / "x.mcap"
    p.write_bytes(content)
    with pytest.raises(IngestError, match=needle):
        read_log(p)
    with pytest.raises(IngestError, match=needle):
        inspect_log(p)


def test_missing_path_and_bad_rosbag_dir(tmp_path):
    with pytest.raises(IngestError, match="no such file"):
        read_log(tmp_path / "nope.mcap")
    d = tmp_path / "bag"
    d.mkdir()
    (d / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  storage_identifier: foo\n")
    with pytest.raises(IngestError, match="storage 'foo' is not supported.*ros2 bag convert"):
        read_log(d)
    (d / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n")
    with pytest.raises(IngestError, match="lists no files"):  # sqlite3 is read, but this bag has no files
        read_log(d)


def test_mapping_naming_an_absent_topic(tmp_path, records):
    path = write_ros2_log(tmp_path / "a.mcap", records[:50])
    with pytest.raises(IngestError, match=r"line 3: topic '/wheel_odom' is not in the log.*/odom"):
        read_log(path, mapping="# my robot\ntopics:\n  /wheel_odom: odometry\n")


def test_required_role_missing(tmp_path, records):
    path = write_ros2_log(tmp_path / "a.mcap", [r for r in records if not isinstance(r, Scan)])
    with pytest.raises(IngestError, match="no scan data"):
        read_log(path, require=["odometry", "scan"])


def test_required_role_missing_from_a_damaged_file_says_it_is_damaged(tmp_path, records):
    path = write_ros2_log(tmp_path / "a.mcap", records)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:200])  # the recorder died before the first chunk was complete
    with pytest.raises(IngestError, match=r"no odometry data .* The file is damaged \(truncated"):
        read_log(cut, require=["odometry"])
    with pytest.raises(IngestError, match="no scan data") as info:  # an intact file: no damage claimed
        read_log(write_ros2_log(tmp_path / "b.mcap", [r for r in records if not isinstance(r, Scan)]),
                 require=["scan"])
    assert "damaged" not in str(info.value)


def test_zero_covariance_invalid_scans_missing_tf_gaps_and_order(tmp_path):
    t0 = 1_700_000_000_000_000_000
    recs = []
    stamps = [t0 + i * 50_000_000 for i in range(40)]
    stamps[20:] = [s + 3_000_000_000 for s in stamps[20:]]  # a 3 s gap
    stamps[10], stamps[11] = stamps[11], stamps[10]  # one out of order
    for s in stamps:
        recs.append(Odometry(s, Pose2(0, 0, 0), None, 0.1))
    r = np.full(181, np.inf, np.float32)
    r[:10] = 2.0
    for i in range(5):
        recs.append(
            Scan(t0 + i * 200_000_000, "laser", -math.pi / 2, math.pi / 180, 0.05, 8.0, r, np.isfinite(r))
        )
    path = write_ros2_log(tmp_path / "faults.mcap", recs)
    data, report = read_log(path)
    odom = report.channel("/odom")
    assert odom.zero_covariances == 40 and all(o.cov_odomTb is None for o in data.odometry)
    assert odom.out_of_order == 1
    assert odom.gap_count == 1 and odom.gaps[0] == (stamps[19], stamps[20])
    assert report.channel("/scan").mostly_invalid_scans == 5
    (missing,) = report.missing_transforms
    assert "'laser'" in missing and "base_link" in missing
    text = format_report(report)
    assert "default covariance" in text and "gap:" in text and "missing transform" in text
    json.dumps(__import__("holoslam.io.mcap", fromlist=["report_to_dict"]).report_to_dict(report))


def test_latched_static_tf_hours_old_holds_and_is_not_rebased(tmp_path, records):
    old = 3 * 3600 * 10**9
    recs = [
        replace(r, stamp_ns=r.stamp_ns - old) if isinstance(r, Transform) and r.static else r for r in records
    ]
    path = write_ros2_log(tmp_path / "latched.mcap", recs)
    from holoslam.io.mcap import LogReader

    # write_ros2_log uses the stamp as log time: put the static transforms' log time at the start
    with open(path, "rb"):
        pass
    reader = LogReader(path)
    recs_out = list(reader)
    report = reader.report()
    static = [r for _, r in recs_out if isinstance(r, Transform) and r.static]
    assert len(static) == 2
    assert not any("/tf_static" in m for m in report.rebased)
    assert report.missing_transforms == ()


def test_corrupt_chunk_length_resumes_at_the_next_indexed_chunk(tmp_path, records):
    full = write_ros2_log(tmp_path / "full.mcap", records, chunk_size=4096)
    chunks = _chunks(full)
    victim = chunks[3]
    raw = bytearray(full.read_bytes())
    raw[victim.chunk_start_offset + 1 + 6] ^= 0x40  # a high byte of the record length: points past the end
    bad = tmp_path / "badlen.mcap"
    bad.write_bytes(bytes(raw))
    data, report = read_log(bad)
    assert not report.truncated and any("unreadable record" in x.reason for x in report.lost)
    want = sorted(set(_odo_stamps(records)) - set(_odom_log_times_in_chunk(full, victim)))
    assert [o.stamp_ns for o in data.odometry] == want
    assert any("resumed at the next indexed chunk" in w for w in report.warnings)
