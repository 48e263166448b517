"""Round trips: logs written by the mcap-ros2 writer, the Foxglove protobuf writer and plain MCAP with Foxglove
JSON schemas ingest to the same records; rosbag2 split directories; mappings; clock re-basing."""

from __future__ import annotations

import base64
import json
import math

import numpy as np
import pytest
from repo_paths import REPO

from holoslam.errors import ConfigError, IngestError
from holoslam.io.mcap import (
    LogReader,
    format_report,
    format_summary,
    inspect_log,
    iter_records,
    read_log,
    report_to_dict,
    summary_to_dict,
)
from holoslam.io.mcap_write import MSGDEFS, example_records, write_ros2_log
from holoslam.types import CameraInfo, GroundTruthPose, Heading, Image, Odometry, Scan, TagSighting, Transform


@pytest.fixture(scope="module")
def records():
    return example_records(seconds=3.0)


@pytest.fixture(scope="module")
def ros2_log(tmp_path_factory, records):
    return write_ros2_log(tmp_path_factory.mktemp("ros2") / "drive.mcap", records)


def _by_type(records, cls):
    return sorted((r for r in records if type(r) is cls), key=lambda r: r.stamp_ns)


def test_ros2_round_trip_gives_back_every_record(ros2_log, records):
    data, report = read_log(ros2_log)
    assert report.ok, format_report(report)
    assert [o.stamp_ns for o in data.odometry] == [o.stamp_ns for o in _by_type(records, Odometry)]
    for got, want in zip(data.odometry, _by_type(records, Odometry), strict=True):
        np.testing.assert_allclose(got.odomTb.as_array(), want.odomTb.as_array(), atol=1e-12)
        np.testing.assert_allclose(got.cov_odomTb, want.cov_odomTb)
        assert got.speed == pytest.approx(want.speed)
    for got, want in zip(data.scans, _by_type(records, Scan), strict=True):
        assert got.stamp_ns == want.stamp_ns and got.frame_id == "laser"
        np.testing.assert_array_equal(got.ranges, want.ranges)
        np.testing.assert_array_equal(got.valid, want.valid)
        assert got.angle_increment == pytest.approx(want.angle_increment, rel=1e-6)
    for got, want in zip(data.headings, _by_type(records, Heading), strict=True):
        assert got.yaw == pytest.approx(want.yaw, abs=1e-12) and got.sigma == pytest.approx(want.sigma)
    for got, want in zip(data.images, _by_type(records, Image), strict=True):
        assert got.data == want.data and got.encoding == "jpeg"
        assert got.decode().shape == (48, 64)
    for got, want in zip(data.camera_infos, _by_type(records, CameraInfo), strict=True):
        np.testing.assert_array_equal(got.K, want.K)
    for got, want in zip(data.tags, _by_type(records, TagSighting), strict=True):
        assert got.payload == want.payload
        np.testing.assert_array_equal(got.corners, want.corners)
    assert len(data.ground_truth) == len(_by_type(records, GroundTruthPose))
    assert len(data.transforms) == len(_by_type(records, Transform))
    assert data.world_json is not None and json.loads(data.world_json) == {"walls": [], "objects": []}
    assert report.channel("/scan").decoder == "fast-cdr"
    # JSON report is serialisable and mentions every topic
    text = json.dumps(report_to_dict(report))
    assert "/tf_static" in text and "/camera/image/compressed" in text


def test_inspect_names_every_topic_and_what_a_run_uses(ros2_log):
    s = inspect_log(ros2_log)
    assert s.indexed
    topics = {c.topic: c for c in s.channels}
    assert set(topics) == {
        "/odom",
        "/compass",
        "/scan",
        "/camera/image/compressed",
        "/camera/camera_info",
        "/tf",
        "/tf_static",
        "/tags",
        "/ground_truth/pose",
        "/ground_truth/world",
    }
    assert topics["/odom"].message_count == 60 and topics["/odom"].role == "odometry"
    assert topics["/odom"].rate_hz == pytest.approx(20.0, rel=0.05)
    assert s.missing == ()
    assert dict(s.uses)["scan"] == "/scan"
    text = format_summary(s)
    assert all(t in text for t in topics)
    json.dumps(summary_to_dict(s))


def test_iter_records_streams_in_file_order(ros2_log):
    seen = {}
    for topic, rec in iter_records(ros2_log):
        seen.setdefault(topic, []).append(rec.stamp_ns)
    assert all(s == sorted(s) for s in seen.values())
    assert len(seen["/odom"]) == 60


def _stamp_pb(ns):
    from google.protobuf.timestamp_pb2 import Timestamp

    return Timestamp(seconds=ns // 10**9, nanos=ns % 10**9)


def _quat_yaw(yaw):
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def _foxglove_dicts(records):
    """(topic, foxglove type, JSON-like dict, stamp) for the records Foxglove schemas can carry."""
    out = []
    for r in records:
        ts = {"sec": r.stamp_ns // 10**9, "nsec": r.stamp_ns % 10**9}
        if isinstance(r, Odometry):
            p = r.odomTb
            c = np.zeros((6, 6))
            c[np.ix_([0, 1, 5], [0, 1, 5])] = r.cov_odomTb
            out.append(
                (
                    "/odom",
                    "foxglove.Odometry",
                    {
                        "timestamp": ts,
                        "frame_id": r.frame_id,
                        "body_frame_id": r.child_frame_id,
                        "pose": {
                            "position": {"x": p.x, "y": p.y, "z": 0.0},
                            "orientation": _quat_yaw(p.theta),
                        },
                        "linear_velocity": {"x": r.speed, "y": 0.0, "z": 0.0},
                        "pose_covariance": c.ravel().tolist(),
                    },
                )
            )
        elif isinstance(r, Scan):
            n = r.ranges.size
            out.append(
                (
                    "/scan",
                    "foxglove.LaserScan",
                    {
                        "timestamp": ts,
                        "frame_id": r.frame_id,
                        "start_angle": r.angle_min,
                        "end_angle": r.angle_min + r.angle_increment * (n - 1),
                        "ranges": [float(x) if np.isfinite(x) else float("inf") for x in r.ranges],
                    },
                )
            )
        elif isinstance(r, Image):
            out.append(
                (
                    "/camera/image/compressed",
                    "foxglove.CompressedImage",
                    {"timestamp": ts, "frame_id": r.frame_id, "format": r.encoding, "data": r.data},
                )
            )
        elif isinstance(r, CameraInfo):
            out.append(
                (
                    "/camera/camera_info",
                    "foxglove.CameraCalibration",
                    {
                        "timestamp": ts,
                        "frame_id": r.frame_id,
                        "width": r.width,
                        "height": r.height,
                        "distortion_model": r.distortion_model,
                        "D": r.D.tolist(),
                        "K": r.K.ravel().tolist(),
                    },
                )
            )
        elif isinstance(r, Transform):
            t, q = r.translation, r.rotation_xyzw
            out.append(
                (
                    "/tf_static" if r.static else "/tf",
                    "foxglove.FrameTransforms",
                    {
                        "transforms": [
                            {
                                "timestamp": ts,
                                "parent_frame_id": r.parent,
                                "child_frame_id": r.child,
                                "translation": {"x": t[0], "y": t[1], "z": t[2]},
                                "rotation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]},
                            }
                        ]
                    },
                )
            )
        elif isinstance(r, GroundTruthPose):
            p = r.wTb
            out.append(
                (
                    "/ground_truth/pose",
                    "foxglove.PoseInFrame",
                    {
                        "timestamp": ts,
                        "frame_id": "map",
                        "pose": {
                            "position": {"x": p.x, "y": p.y, "z": 0.0},
                            "orientation": _quat_yaw(p.theta),
                        },
                    },
                )
            )
        else:
            continue
        out[-1] = (*out[-1], r.stamp_ns)
    return out


def _write_protobuf(path, records):
    import foxglove_schemas_protobuf as fsp  # noqa: F401
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
    from foxglove_schemas_protobuf.Odometry_pb2 import Odometry as FoxOdometry
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from google.protobuf.json_format import ParseDict
    from mcap_protobuf.writer import Writer

    classes = {
        "foxglove.Odometry": FoxOdometry,
        "foxglove.LaserScan": LaserScan,
        "foxglove.CompressedImage": CompressedImage,
        "foxglove.CameraCalibration": CameraCalibration,
        "foxglove.FrameTransforms": FrameTransforms,
        "foxglove.PoseInFrame": PoseInFrame,
    }

    def fix(d):  # JSON-ish dict -> protobuf JSON names (timestamps as RFC 3339 handled by objects below)
        if isinstance(d, dict):
            return {k: fix(v) for k, v in d.items() if k != "timestamp"}
        if isinstance(d, list):
            return [fix(v) for v in d]
        return d

    with open(path, "wb") as f:
        w = Writer(f)
        for topic, typ, d, stamp in _foxglove_dicts(records):
            m = classes[typ]()
            dd = fix(d)
            if typ == "foxglove.CompressedImage":
                dd["data"] = base64.b64encode(d["data"]).decode()
            if typ == "foxglove.LaserScan":
                dd["ranges"] = ["Infinity" if math.isinf(x) else x for x in dd["ranges"]]
            ParseDict(dd, m)
            if typ == "foxglove.FrameTransforms":
                for tr in m.transforms:
                    tr.timestamp.CopyFrom(_stamp_pb(stamp))
            else:
                m.timestamp.CopyFrom(_stamp_pb(stamp))
            w.write_message(topic, m, log_time=stamp, publish_time=stamp)
        w.finish()
    return path


def _write_json(path, records):
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        schemas, chans = {}, {}
        for topic, typ, d, stamp in _foxglove_dicts(records):
            if typ not in schemas:
                schemas[typ] = w.register_schema(
                    typ, "jsonschema", json.dumps({"title": typ, "type": "object"}).encode()
                )
            if topic not in chans:
                chans[topic] = w.register_channel(topic, "json", schemas[typ])
            if "data" in d:
                d = dict(d, data=base64.b64encode(d["data"]).decode())
            if "ranges" in d:
                d = dict(d, ranges=[x if math.isfinite(x) else None for x in d["ranges"]])
            w.add_message(chans[topic], log_time=stamp, publish_time=stamp, data=json.dumps(d).encode())
        w.finish()
    return path


@pytest.mark.parametrize("writer", ["protobuf", "json"])
def test_foxglove_logs_ingest_to_the_same_records(tmp_path, records, ros2_log, writer):
    path = tmp_path / f"fox_{writer}.mcap"
    (_write_protobuf if writer == "protobuf" else _write_json)(path, records)
    fox, report = read_log(path)
    ros, _ = read_log(ros2_log)
    assert not any(c.failed for c in report.channels), format_report(report)
    assert report.channel("/scan").decoder == writer
    assert len(fox.odometry) == len(ros.odometry) > 0
    for a, b in zip(fox.odometry, ros.odometry, strict=True):
        assert a.stamp_ns == b.stamp_ns and a.frame_id == b.frame_id and a.child_frame_id == b.child_frame_id
        np.testing.assert_allclose(a.odomTb.as_array(), b.odomTb.as_array(), atol=1e-12)
        np.testing.assert_allclose(a.cov_odomTb, b.cov_odomTb)
    assert len(fox.scans) == len(ros.scans) > 0
    for a, b in zip(fox.scans, ros.scans, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.valid, b.valid)  # JSON null (no return) ingests as NaN, invalid
        np.testing.assert_array_equal(a.ranges[a.valid], b.ranges[b.valid])
        assert a.angle_min == pytest.approx(b.angle_min, abs=1e-6)
        assert a.angle_increment == pytest.approx(b.angle_increment, rel=1e-5)
    assert [i.data for i in fox.images] == [i.data for i in ros.images]
    for a, b in zip(fox.camera_infos, ros.camera_infos, strict=True):
        np.testing.assert_array_equal(a.K, b.K)
        assert (a.width, a.height) == (b.width, b.height)
    assert [(t.parent, t.child, t.static) for t in fox.transforms] == [
        (t.parent, t.child, t.static) for t in ros.transforms
    ]
    for a, b in zip(fox.transforms, ros.transforms, strict=True):
        np.testing.assert_allclose(a.matrix(), b.matrix(), atol=1e-12)
    np.testing.assert_allclose(fox.ground_truth_arrays()[1], ros.ground_truth_arrays()[1], atol=1e-12)


def test_rosbag2_directory_chains_split_files(tmp_path, records):
    half = len(records) // 2
    bag = tmp_path / "bag"
    bag.mkdir()
    write_ros2_log(bag / "bag_0.mcap", records[:half])
    write_ros2_log(bag / "bag_1.mcap", records[half:])
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n"
        "  relative_file_paths: [bag_0.mcap, bag_1.mcap]\n"
    )
    data, report = read_log(bag)
    assert report.ok
    assert len(data.odometry) == len(_by_type(records, Odometry))
    assert len(report.files) == 2
    assert inspect_log(bag).message_count == sum(c.messages for c in report.channels)


def test_simulator_clock_is_rebased_and_static_tf_held(tmp_path, records):
    # stamps on a clock starting at 0, log time in 2023: every channel shifts by the same offset
    t0 = records[0].stamp_ns
    sim = [_restamp(r, r.stamp_ns - t0 + 5_000_000) for r in records]
    path = write_ros2_log(tmp_path / "sim.mcap", sim, log_time_offset_ns=t0)
    data, report = read_log(path)
    assert report.rebased and any("/odom" in m for m in report.rebased)
    offsets = {c.stamp_offset_ns for c in report.channels if c.stamp_offset_ns}
    assert len(offsets) == 1  # one clock, one offset
    want = [o.stamp_ns for o in _by_type(records, Odometry)]
    assert [o.stamp_ns + 0 for o in data.odometry] == [w + 5_000_000 for w in want]
    assert any(t.static for t in data.transforms)


def _restamp(r, ns):
    from dataclasses import replace

    return replace(r, stamp_ns=ns)


def test_mapping_assigns_a_custom_heading_type_in_degrees(tmp_path):
    from mcap_ros2.writer import Writer

    defn = (
        "std_msgs/Header header\nfloat64 heading_deg\nfloat64 accuracy_deg\n"
        + MSGDEFS["std_msgs/msg/Header"].split("std_msgs/Header header\n", 1)[-1]
    )
    defn = (
        "std_msgs/Header header\nfloat64 heading_deg\nfloat64 accuracy_deg\n"
        + "=" * 80
        + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
        + "=" * 80
        + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    )
    path = tmp_path / "custom.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        s = w.register_msgdef("acme_msgs/msg/Compass", defn)
        for i in range(10):
            t = 1_000_000_000 + i * 100_000_000
            w.write_message(
                "/acme/compass",
                s,
                {
                    "header": {"stamp": {"sec": 1, "nanosec": i * 100_000_000}, "frame_id": "base_link"},
                    "heading_deg": 10.0 * i,
                    "accuracy_deg": 2.0,
                },
                log_time=t,
            )
        w.finish()
    data, report = read_log(path)
    assert data.headings == () and report.channel("/acme/compass").skipped == 10  # no role out of the box
    mapping = (
        "topics:\n  /acme/compass:\n    role: heading\n    fields: {yaw: heading_deg, sigma: accuracy_deg}\n"
        "    units: {yaw: deg, sigma: deg}\n"
    )
    data, report = read_log(path, mapping=mapping)
    assert len(data.headings) == 10
    np.testing.assert_allclose([h.yaw for h in data.headings], np.radians(10.0 * np.arange(10)), atol=1e-12)
    assert data.headings[0].sigma == pytest.approx(math.radians(2.0))
    assert report.channel("/acme/compass").decoder == "generic-cdr"


@pytest.mark.parametrize(
    "text, needle",
    [
        ("topics:\n  /odom: odometri\n", "is not one of"),
        ("topics:\n  /odom: {role: heading, fields: {speed: v}}\n", "not used by role heading"),
        ("topics:\n  /odom: {role: heading, units: {yaw: furlongs}}\n", "unit 'furlongs'"),
        ("topic:\n  /odom: odometry\n", "unknown key"),
        ("- /odom\n", "YAML dictionary"),
        ("topics: [\n", "not valid YAML"),
    ],
)
def test_mapping_nonsense_is_a_config_error(text, needle):
    from holoslam.io.mcap import load_mapping

    with pytest.raises(ConfigError, match=needle):
        load_mapping(text)


def test_two_odometry_topics_stop_with_the_fix(tmp_path, records):
    from mcap_ros2.writer import Writer

    path = tmp_path / "two_odom.mcap"
    from holoslam.io.mcap_write import ros2_message

    with open(path, "wb") as f:
        w = Writer(f)
        s = w.register_msgdef("nav_msgs/msg/Odometry", MSGDEFS["nav_msgs/msg/Odometry"])
        for r in _by_type(records, Odometry)[:5]:
            w.write_message("/odom", s, ros2_message(r), log_time=r.stamp_ns)
            w.write_message("/wheel/odom", s, ros2_message(r), log_time=r.stamp_ns)
        w.finish()
    with pytest.raises(IngestError, match=r"'/odom'.*'/wheel/odom'.*/wheel/odom: ignored"):
        read_log(path)
    assert any("two topics" in p for p in inspect_log(path).problems)  # inspect reports, never raises
    data, report = read_log(path, mapping="topics:\n  /wheel/odom: ignored\n")
    assert len(data.odometry) == 5 and report.channel("/wheel/odom").skipped == 5


def test_reader_streams_once(ros2_log):
    r = LogReader(ros2_log)
    n = sum(1 for _ in r)
    assert n > 0 and r.report().channel("/odom").records == 60
    with pytest.raises(IngestError, match="streams once"):
        list(r)


@pytest.mark.skipif(
    not (REPO / "datasets" / "household_small.mcap").exists(), reason="simulator log not written yet"
)
def test_bundled_household_log_ingests_without_failures():
    data, report = read_log(REPO / "datasets" / "household_small.mcap")
    assert not any(c.failed for c in report.channels), format_report(report)
    assert data.odometry and data.scans and data.world_json


def test_simulator_log_ingests_with_no_failed_channel(tmp_path):
    from holoslam.sim import SimConfig, simulate_to_file

    out = simulate_to_file(tmp_path / "sim.mcap", SimConfig(seed=2, duration_s=10))
    data, report = read_log(tmp_path / "sim.mcap")
    assert not any(c.failed for c in report.channels), format_report(report)
    assert report.lost == () and report.missing_transforms == ()
    assert len(data.odometry) == out["messages"]["/odom"]
    assert len(data.scans) == out["messages"]["/scan"]
    assert len(data.headings) == out["messages"]["/compass"]
    assert data.world_json and json.loads(data.world_json)
    assert all(s.ranges.shape == (181,) for s in data.scans)
    if data.images:
        assert data.images[0].decode().shape[:2] == (480, 640)
