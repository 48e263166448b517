"""The committed household log (datasets/household_small.mcap): read back with the plain mcap reader and
the mcap-ros2 decoders; images decode to exactly the visible ids; laser ranges match the floor plan."""

from __future__ import annotations

import json
import math
from collections import defaultdict

import numpy as np
import pytest

from holoslam.io.datasets import bundled_household_log
from holoslam.sim.world import raycast, world_from_json
from holoslam.sim.writer import TOPICS
from holoslam.vision.label import parse_label


@pytest.fixture(scope="module")
def log():
    """Every message of the committed log, decoded once: topic -> [(log_time, publish_time, msg)]."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = bundled_household_log()
    out = defaultdict(list)
    schemas = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        times = []
        for schema, channel, message, ros_msg in reader.iter_decoded_messages(log_time_order=False):
            out[channel.topic].append((message.log_time, message.publish_time, ros_msg))
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            times.append(message.log_time)
    return {
        "messages": out,
        "schemas": schemas,
        "header": header,
        "summary": summary,
        "metadata": metadata,
        "times": np.array(times),
        "path": path,
    }


def test_plain_reader_sees_every_topic_in_log_time_order(log):
    from mcap.reader import make_reader

    with open(log["path"], "rb") as f:
        topics = defaultdict(int)
        last = -1
        for _, channel, message in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False):
            topics[channel.topic] += 1
            assert message.log_time >= last  # written in log-time order
            last = message.log_time
    assert set(topics) == set(TOPICS)
    assert log["header"].profile == "ros2"
    for topic, (name, enc, menc) in log["schemas"].items():
        assert name == TOPICS[topic] and enc == "ros2msg" and menc == "cdr"
    chunks = log["summary"].chunk_indexes
    assert chunks and all(c.compression == "zstd" for c in chunks)


def test_rates_and_header_stamps(log):
    m = log["messages"]
    for topic, hz in (("/odom", 20), ("/compass", 10), ("/scan", 5), ("/ground_truth/pose", 20)):
        stamps = np.array([t for t, _, _ in m[topic]])
        assert np.median(np.diff(stamps)) == pytest.approx(1e9 / hz)
    for topic, rows in m.items():
        for log_time, pub_time, msg in rows[:50]:
            assert pub_time == log_time
            if hasattr(msg, "header"):
                assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == log_time, topic
    meta = log["metadata"]["holoslam"]
    assert meta["seed"] == "2" and float(meta["duration_s"]) == pytest.approx(500.0)
    assert float(meta["compass_sigma_deg"]) == 1.5 and float(meta["laser_sigma"]) == 0.01


def test_odometry_compass_and_static_transforms(log):
    m = log["messages"]
    odom = m["/odom"][10][2]
    assert odom.header.frame_id == "odom" and odom.child_frame_id == "base_link"
    last = m["/odom"][-1][2]
    cov = np.array(last.pose.covariance).reshape(6, 6)
    assert cov[0, 0] > 0 and cov[1, 1] > 0 and cov[5, 5] > 0
    imu = m["/compass"][0][2]
    assert imu.orientation_covariance[8] == pytest.approx(math.radians(1.5) ** 2)
    assert imu.angular_velocity_covariance[0] == -1 and imu.linear_acceleration_covariance[0] == -1
    tfs = {(t.header.frame_id, t.child_frame_id): t for t in m["/tf_static"][0][2].transforms}
    assert set(tfs) == {("base_link", "laser"), ("base_link", "ptz_base")}
    assert tfs[("base_link", "laser")].transform.translation.z == pytest.approx(0.30)
    # the compass agrees with the true heading within bias + disturbance + 4 sigma
    gt = {t: msg for t, _, msg in m["/ground_truth/pose"]}
    errs = []
    for t, _, msg in m["/compass"][::10]:
        g = gt.get(t - 25_000_000)
        if g is None:
            continue
        yaw_true = 2 * math.atan2(g.pose.orientation.z, g.pose.orientation.w)
        yaw = 2 * math.atan2(msg.orientation.z, msg.orientation.w)
        errs.append((yaw - yaw_true + math.pi) % (2 * math.pi) - math.pi)
    errs = np.degrees(errs)
    assert abs(np.median(errs) - 2.0) < 1.0  # the configured bias
    assert np.all(
        np.abs(errs) < 2.0 + 6.0 + 4 * 1.5 + 2.0
    )  # bias + disturbance + noise (+ rotation in 25 ms)


def test_world_ground_truth(log):
    world = world_from_json(log["messages"]["/ground_truth/world"][0][2].data)
    assert len(world.objects) == 35
    assert [o.object_id for o in world.objects if not o.reachable] == ["O22"]
    for o in world.objects:
        assert parse_label(o.payload).object_id == o.object_id


def test_every_image_decodes_to_exactly_the_visible_ids(log):
    import cv2
    from pyzbar import pyzbar

    m = log["messages"]
    images = m["/camera/image/compressed"]
    visible = {t: json.loads(msg.data) for t, _, msg in m["/ground_truth/visible"]}
    tags = {t: msg for t, _, msg in m["/tags"]}
    infos = {t: msg for t, _, msg in m["/camera/camera_info"]}
    tf = {t: msg for t, _, msg in m["/tf"]}
    assert len(images) >= 60
    seen = set()
    for t, _, img_msg in images:
        assert img_msg.format == "jpeg" and img_msg.header.frame_id == "camera_optical"
        assert t in infos and t in tags and t in tf and t in visible  # same stamps
        img = cv2.imdecode(np.frombuffer(bytes(img_msg.data), np.uint8), cv2.IMREAD_GRAYSCALE)
        assert img is not None and img.shape == (infos[t].height, infos[t].width)
        decoded = sorted(parse_label(r.data.decode()).object_id for r in pyzbar.decode(img))
        assert decoded == sorted(visible[t]["ids"]), t
        assert visible[t]["stamp_ns"] == t
        assert sorted(parse_label(d.payload).object_id for d in tags[t].detections) == decoded
        seen.update(decoded)
    assert len(seen) == 35  # every label is photographed at least once


def test_tag_corners_are_in_the_codes_order(log):
    """OpenCV's QR detector returns the code's corners TL, TR, BR, BL: the published corners agree."""
    import cv2

    m = log["messages"]
    tags = {t: msg for t, _, msg in m["/tags"]}
    det = cv2.QRCodeDetector()
    checked = 0
    for t, _, img_msg in m["/camera/image/compressed"]:
        if len(tags[t].detections) != 1:
            continue
        img = cv2.imdecode(np.frombuffer(bytes(img_msg.data), np.uint8), cv2.IMREAD_GRAYSCALE)
        text, pts, _ = det.detectAndDecode(img)
        if not text or pts is None:
            continue
        ours = np.array(tags[t].detections[0].corners).reshape(4, 2)
        assert np.abs(pts.reshape(4, 2) - ours).max() < 6.0, t
        checked += 1
    assert checked >= 20


def test_laser_ranges_agree_with_the_floor_plan_at_the_true_poses(log):
    m = log["messages"]
    world = world_from_json(m["/ground_truth/world"][0][2].data)
    gt_t = np.array([t for t, _, _ in m["/ground_truth/pose"]])
    gt = np.array(
        [
            (g.pose.position.x, g.pose.position.y, 2 * math.atan2(g.pose.orientation.z, g.pose.orientation.w))
            for _, _, g in m["/ground_truth/pose"]
        ]
    )
    laser = [t for t in m["/tf_static"][0][2].transforms if t.child_frame_id == "laser"][
        0
    ].transform.translation
    scans = m["/scan"][::5]
    st = np.array([t for t, _, _ in scans])
    th = np.unwrap(gt[:, 2])
    x, y, a = (np.interp(st, gt_t, gt[:, 0]), np.interp(st, gt_t, gt[:, 1]), np.interp(st, gt_t, th))
    lx, ly = x + np.cos(a) * laser.x - np.sin(a) * laser.y, y + np.sin(a) * laser.x + np.cos(a) * laser.y
    s0 = scans[0][2]
    n = len(s0.ranges)
    assert n == 181 and s0.range_max == pytest.approx(8.0)
    angles = s0.angle_min + s0.angle_increment * np.arange(n)
    expected = raycast(
        world.obstacle_segments(), np.column_stack([lx, ly]), a[:, None] + angles[None, :], 8.0
    )
    ranges = np.array([np.asarray(s.ranges, dtype=np.float64) for _, _, s in scans])
    valid = np.isfinite(ranges)
    assert np.array_equal(valid, np.isfinite(expected)) or (valid != np.isfinite(expected)).mean() < 0.002
    both = valid & np.isfinite(expected)
    r = np.abs(ranges[both] - expected[both])
    sigma = float(log["metadata"]["holoslam"]["laser_sigma"])
    assert np.mean(r < 4 * sigma + 0.005) >= 0.99
    assert np.std(ranges[both] - expected[both]) == pytest.approx(sigma, rel=0.25)


def test_the_committed_file_is_the_one_the_manifest_describes():
    """The sha256 guards the committed file itself (a modified or truncated copy); it is not a test of the
    simulator, whose regenerated bytes differ across machines (see the next test)."""
    from holoslam.io.datasets import load_manifest, sha256_of

    entry = load_manifest()["household_small"]
    path = bundled_household_log(verify=False)
    assert sha256_of(path) == entry.sha256
    assert path.stat().st_size == entry.extra["bytes"]


@pytest.mark.slow
def test_the_committed_log_is_what_the_manifest_command_makes(tmp_path):
    """The manifest's command, run again on this machine, makes the committed log's content: same topics,
    schemas, metadata, message counts, order, stamps, sequence numbers, strings and integers; floats within
    the tolerances of ``tests/log_compare.py`` (1e-6 of each field's magnitude; one quantum of quantised
    values; images by decoded pixels) over the first 200 s (below). Not by sha256: numpy's SIMD code paths differ between CPUs, so the last
    bits of the odometry, compass and ground-truth values (and the zstd library's bytes) are not reproducible
    across machines."""
    from collections import Counter
    from dataclasses import replace

    from log_compare import compare_logs, decode_log

    from holoslam.sim import SimConfig, simulate_to_file

    again = tmp_path / "again.mcap"
    simulate_to_file(again, SimConfig(seed=2, duration_s=500))
    ref, got = decode_log(bundled_household_log()), decode_log(again)
    # the whole log: the same topics, counts and stamps on every machine
    assert Counter(m[0] for m in ref.messages) == Counter(m[0] for m in got.messages)
    assert [m[:4] for m in ref.messages] == [m[:4] for m in got.messages]
    # the values within tolerance over the first 200 s. Later, a last-bit difference of the machine's SIMD paths
    # (1e-9 m in the odometry) can flip one of the drive's discrete decisions (a waypoint reached or not): on one
    # machine the route parts at 215.5 s, and the rest of the drive differs by centimetres, though the log is as
    # valid. The counts and stamps above hold regardless
    t_end = ref.messages[0][1] + 200 * 10**9
    problems = compare_logs(replace(ref, messages=[m for m in ref.messages if m[1] < t_end]),
                            replace(got, messages=[m for m in got.messages if m[1] < t_end]))
    assert problems == [], "\n".join(problems)
