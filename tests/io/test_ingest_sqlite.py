"""rosbag2 sqlite3 bags (.db3): built here with sqlite3 from the CDR bytes of a ROS 2 MCAP, they ingest to the
same records as the MCAP; split bags, corrupt files and bags without message_definitions."""

from __future__ import annotations

import os
import sqlite3
import tempfile
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from holoslam.errors import IngestError
from holoslam.io.mcap import format_report, inspect_log, read_log
from holoslam.io.mcap_write import example_records, write_ros2_log
from holoslam.io.ros2defs import msgdef
from holoslam.io.rosbag2_sqlite import db3_to_mcap

# the rosbag2_storage_sqlite3 schema (ROS 2 Iron+; Humble lacks message_definitions and type_description_hash)
_SCHEMA = """
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
    serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL, type_description_hash TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
    data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
"""
_DEFS = """
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, encoding TEXT NOT NULL,
    encoded_message_definition TEXT NOT NULL, type_description_hash TEXT NOT NULL);
"""


@pytest.fixture(scope="module")
def ros2_log(tmp_path_factory):
    return write_ros2_log(tmp_path_factory.mktemp("ros2") / "drive.mcap", example_records(seconds=3.0))


@pytest.fixture(scope="module")
def messages(ros2_log):
    """[(topic, type, definition, log_time, cdr bytes)] of the MCAP, in file order."""
    with open(ros2_log, "rb") as f:
        return [
            (ch.topic, sc.name, sc.data.decode(), m.log_time, bytes(m.data))
            for sc, ch, m in make_reader(f).iter_messages(log_time_order=False)
        ]


def _write_db3(path: Path, msgs, definitions: bool = True, reverse: bool = False) -> Path:
    con = sqlite3.connect(path)
    con.executescript(_SCHEMA + (_DEFS if definitions else ""))
    con.execute("INSERT INTO schema VALUES (4, 'jazzy')")
    topics: dict[str, int] = {}
    for topic, typ, _text, _t, _d in msgs:
        if topic not in topics:
            topics[topic] = len(topics) + 1
            con.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '', '')", (topics[topic], topic, typ))
    if definitions:
        defs = {typ: text for _tp, typ, text, _t, _d in msgs}
        con.executemany(
            "INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, "
            "type_description_hash) VALUES (?, 'ros2msg', ?, '')",
            sorted(defs.items()),
        )
    rows = [(topics[tp], t, d) for tp, _typ, _x, t, d in msgs]
    # reversed insertion: the converter must order by timestamp, not by row id
    con.executemany(
        "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)", rows[::-1] if reverse else rows
    )
    con.commit()
    con.close()
    return path


def _assert_same(got, want):
    for field in (
        "odometry",
        "headings",
        "scans",
        "images",
        "camera_infos",
        "transforms",
        "tags",
        "ground_truth",
    ):
        a, b = getattr(got, field), getattr(want, field)
        assert len(a) == len(b) > 0, field
        assert [r.stamp_ns for r in a] == [r.stamp_ns for r in b], field
    for a, b in zip(got.odometry, want.odometry, strict=True):
        np.testing.assert_array_equal(a.odomTb.as_array(), b.odomTb.as_array())
        np.testing.assert_array_equal(a.cov_odomTb, b.cov_odomTb)
    for a, b in zip(got.scans, want.scans, strict=True):
        np.testing.assert_array_equal(a.ranges, b.ranges)
        np.testing.assert_array_equal(a.valid, b.valid)
    assert [i.data for i in got.images] == [i.data for i in want.images]
    assert [t.payload for t in got.tags] == [t.payload for t in want.tags]
    assert [h.yaw for h in got.headings] == [h.yaw for h in want.headings]
    assert got.world_json == want.world_json is not None


def test_db3_reads_like_the_mcap_it_came_from(tmp_path, ros2_log, messages):
    db3 = _write_db3(tmp_path / "drive_0.db3", messages, reverse=True)
    want, _ = read_log(ros2_log)
    before = set(os.listdir(tempfile.gettempdir()))
    got, report = read_log(db3)
    assert report.ok, format_report(report)
    _assert_same(got, want)
    assert report.source == str(db3) and report.files == (str(db3),)
    assert f"converted from rosbag2 sqlite3 ({len(messages)} messages)" in report.warnings
    assert report.channel("/scan").decoder == "fast-cdr"
    # the temporary MCAP is gone, nothing was written beside the bag
    assert not [n for n in set(os.listdir(tempfile.gettempdir())) - before if n.startswith("holoslam-db3-")]
    assert sorted(os.listdir(tmp_path)) == ["drive_0.db3"]


def test_converted_mcap_keeps_order_definitions_and_times(tmp_path, messages):
    db3 = _write_db3(tmp_path / "a.db3", messages, reverse=True)
    s = db3_to_mcap(db3, tmp_path / "a.mcap")
    assert s.messages == len(messages) and dict(s.definitions)["sensor_msgs/msg/LaserScan"] == "bag"
    with open(tmp_path / "a.mcap", "rb") as f:
        out = [
            (ch.topic, sc.name, sc.encoding, ch.message_encoding, m.log_time, m.publish_time, bytes(m.data))
            for sc, ch, m in make_reader(f).iter_messages(log_time_order=False)
        ]
    times = [o[4] for o in out]
    assert times == sorted(times) and all(o[4] == o[5] for o in out)
    assert all(o[2] == "ros2msg" and o[3] == "cdr" for o in out)
    # same multiset of messages (ties in time keep insertion-id order, which was reversed here)
    assert sorted((o[0], o[4], o[6]) for o in out) == sorted((m[0], m[3], m[4]) for m in messages)


def test_split_rosbag2_directory_with_sqlite_storage(tmp_path, ros2_log, messages):
    bag = tmp_path / "bag"
    bag.mkdir()
    half = len(messages) // 2
    _write_db3(bag / "bag_0.db3", messages[:half])
    _write_db3(bag / "bag_1.db3", messages[half:])
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
        "  relative_file_paths:\n    - bag_0.db3\n    - bag_1.db3\n",
        encoding="utf-8",
    )
    want, _ = read_log(ros2_log)
    got, report = read_log(bag)
    assert report.ok, format_report(report)
    _assert_same(got, want)
    assert report.files == (str(bag / "bag_0.db3"), str(bag / "bag_1.db3"))
    s = inspect_log(bag)
    assert s.files == report.files and s.message_count == len(messages)
    assert {c.topic for c in s.channels} >= {"/odom", "/scan", "/tf_static"}
    assert any("converted from rosbag2 sqlite3" in n for n in s.notes)
    assert sorted(os.listdir(bag)) == ["bag_0.db3", "bag_1.db3", "metadata.yaml"]


def test_db3_without_message_definitions_uses_ros2defs(tmp_path, ros2_log, messages):
    db3 = _write_db3(tmp_path / "humble.db3", messages, definitions=False)
    s = db3_to_mcap(db3, tmp_path / "h.mcap")
    defs = dict(s.definitions)
    assert (
        defs["nav_msgs/msg/Odometry"] == "ros2defs"
        and defs["holoslam_msgs/msg/TagDetectionArray"] == "ros2defs"
    )
    with open(tmp_path / "h.mcap", "rb") as f:
        schemas = {sc.name: sc.data.decode() for sc in make_reader(f).get_summary().schemas.values()}
    assert schemas["sensor_msgs/msg/LaserScan"] == msgdef("sensor_msgs/msg/LaserScan")
    got, report = read_log(db3)
    assert report.ok, format_report(report)
    _assert_same(got, read_log(ros2_log)[0])


def test_unknown_type_without_definition_is_reported_undecodable(tmp_path, messages):
    odd = [("/weird", "my_pkg/msg/Weird", "", messages[0][3], b"\x00\x01\x00\x00")]
    db3 = _write_db3(tmp_path / "odd.db3", messages + odd, definitions=False)
    assert dict(db3_to_mcap(db3, tmp_path / "o.mcap").definitions)["my_pkg/msg/Weird"] == "none"
    s = inspect_log(db3)
    weird = next(c for c in s.channels if c.topic == "/weird")
    assert weird.status.startswith("undecodable") and "empty schema" in weird.status


def test_corrupt_db3_is_an_ingest_error_naming_the_file(tmp_path, messages):
    good = _write_db3(tmp_path / "good.db3", messages)
    bad = tmp_path / "bad.db3"
    bad.write_bytes(good.read_bytes()[:100] + os.urandom(4096))
    with pytest.raises(IngestError, match="bad.db3"):
        read_log(bad)
    with pytest.raises(IngestError, match="bad.db3"):
        inspect_log(bad)


def test_sqlite_file_that_is_not_a_bag_names_what_is_missing(tmp_path):
    p = tmp_path / "other.db3"
    con = sqlite3.connect(p)
    con.execute("CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT)")
    con.commit()
    con.close()
    with pytest.raises(
        IngestError, match=r"other\.db3.*'topics' lacks column\(s\) type.*'messages' is missing"
    ):
        read_log(p)


def test_ros1_bag_keeps_its_conversion_hint(tmp_path):
    p = tmp_path / "old.bag"
    p.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 64)
    with pytest.raises(IngestError, match="ROS 1 bag"):
        read_log(p)


def test_messages_of_an_unknown_topic_id_are_skipped_and_reported(tmp_path, ros2_log, messages):
    db3 = _write_db3(tmp_path / "a.db3", messages)
    con = sqlite3.connect(db3)
    con.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (99, 1, x'00')")
    con.commit()
    con.close()
    s = db3_to_mcap(db3, tmp_path / "a.mcap")
    assert s.orphans == 1 and s.messages == len(messages)
    got, report = read_log(db3)  # every good record is kept, the skipped one is named
    _assert_same(got, read_log(ros2_log)[0])
    assert any("1 messages skipped: their topic id is not in table 'topics'" in w for w in report.warnings)
