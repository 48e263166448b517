"""Logs of other robots: the base frame comes from the odometry's child frame (or the mapping), several topics
of one role are chosen between by rule (reported, overridable), and a laser mounted upside down is levelled
with the full 3D rotation of its static transform (issue 13 item 4)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from holoslam.errors import ConfigError, IngestError
from holoslam.io.mcap import (
    format_report,
    format_summary,
    inspect_log,
    load_mapping,
    read_log,
    report_to_dict,
)
from holoslam.io.mcap_write import example_records, write_ros2_log
from holoslam.types import Heading, Image, Odometry, Scan, Transform


@pytest.fixture(scope="module")
def records():
    return example_records(seconds=3.0)


def _rename_base(r, new="base_footprint"):
    if isinstance(r, Odometry):
        return dataclasses.replace(r, child_frame_id=new)
    if isinstance(r, Transform) and "base_link" in (r.parent, r.child):
        return dataclasses.replace(
            r,
            parent=new if r.parent == "base_link" else r.parent,
            child=new if r.child == "base_link" else r.child,
        )
    return r


# ------------------------------------------------------------------------------------------------ base frame


def test_the_base_frame_is_the_odometrys_child_frame(tmp_path, records):
    """A robot whose odometry child frame is base_footprint, with no base_link at all, places its laser."""
    from holoslam.submaps.frontend import base_to_laser

    path = write_ros2_log(tmp_path / "footprint.mcap", [_rename_base(r) for r in records])
    data, report = read_log(path)
    assert data.base_frame == "base_footprint" == report.base_frame
    assert report.base_frame_from == "the odometry's child frame"
    assert report.missing_transforms == ()
    np.testing.assert_allclose(base_to_laser(data, data.scans[0].frame_id), [0.15, 0.0, 0.0])
    assert "base frame: base_footprint" in format_report(report)
    assert report_to_dict(report)["base_frame"] == "base_footprint"


def test_a_mapping_names_the_base_frame(tmp_path, records):
    """Odometry whose child frame is not the frame the sensors hang from: the mapping's frames.base decides."""
    recs = [
        dataclasses.replace(r, child_frame_id="wheels") if isinstance(r, Odometry) else r for r in records
    ]
    path = write_ros2_log(tmp_path / "wheels.mcap", recs)
    data, report = read_log(path)
    assert data.base_frame == "wheels" and report.missing_transforms  # the laser hangs from base_link
    data, report = read_log(path, mapping="frames:\n  base: base_link\n")
    assert data.base_frame == "base_link" and report.base_frame_from == "named by the mapping"
    assert report.missing_transforms == ()
    assert load_mapping("frames: {base: /base_link}\ntopics: {}\n").base_frame == "base_link"


def test_a_mapping_replaces_a_wrong_laser_transform_and_says_what_the_log_had(tmp_path, records):
    """frames.static (static_transform_publisher's arguments) wins over the log's /tf_static for its child frame;
    the ingest report keeps what the log said."""
    from holoslam.submaps.frontend import base_to_laser

    path = write_ros2_log(tmp_path / "tf.mcap", records)
    text = "frames:\n  static:\n    - {parent: base_link, child: laser, xyz: [-0.04, 0.01, 0.2], rpy_deg: [0, 0, 90]}\n"
    data, report = read_log(path, mapping=text)
    np.testing.assert_allclose(base_to_laser(data, data.scans[0].frame_id), [-0.04, 0.01, math.pi / 2], atol=1e-12)
    assert [t.child for t in data.transforms].count("laser") == 1
    (note,) = [w for w in report.warnings if "frames.static" in w]
    assert "x=-0.040" in note and "replaces the log's base_link->laser (x=+0.150" in note


def test_a_mapping_supplies_the_laser_transform_a_log_lacks(tmp_path, records):
    bare = [r for r in records if not (isinstance(r, Transform) and r.child == "laser")]
    path = write_ros2_log(tmp_path / "bare.mcap", bare)
    assert read_log(path)[1].missing_transforms  # the laser cannot be placed on the robot
    data, report = read_log(path, mapping="frames: {static: [{parent: base_link, child: laser, xyz: [0.3, 0, 0]}]}")
    assert report.missing_transforms == ()
    assert any("replaces nothing in the log" in w for w in report.warnings)


@pytest.mark.parametrize(
    "text, needle",
    [
        ("frames: {static: {parent: a}}\n", "frames.static must be a list"),
        ("frames: {static: [{parent: a, child: a, xyz: [0, 0, 0]}]}\n", "two different frame names"),
        ("frames: {static: [{parent: a, child: b, xyz: [0, 0]}]}\n", r"xyz must be three finite numbers in metres"),
        ("frames: {static: [{parent: a, child: b, xyz: [0, 0, .nan]}]}\n", "three finite numbers"),
        ("frames: {static: [{parent: a, child: b, xyz: [0, 0, 0], rpy: [0, 0, 0]}]}\n", "optionally rpy_deg"),
        ("frames: {static: [{parent: a, child: b, xyz: [0, 0, 0]}, {parent: c, child: b, xyz: [0, 0, 0]}]}\n",
         "already a child"),
    ],
)
def test_mapping_static_transform_nonsense_is_a_config_error(text, needle):
    with pytest.raises(ConfigError, match=needle):
        load_mapping(text)


@pytest.mark.parametrize(
    "text, needle",
    [
        ("frames: {laser: x}\n", "under 'frames'"),
        ("frames: base_link\n", "'frames' must map"),
        ("frames: {base: 3}\n", "frames.base must be a frame name"),
        ("frame: {base: x}\n", "'topics' and 'frames'"),
    ],
)
def test_mapping_frames_nonsense_is_a_config_error(text, needle):
    with pytest.raises(ConfigError, match=needle):
        load_mapping(text)


def test_the_run_configuration_takes_the_logs_base_frame():
    from holoslam.config import VisionConfig
    from holoslam.submaps.frontend import FrontEndConfig

    assert VisionConfig().base_frame == "" and FrontEndConfig().base_frame == ""


# ------------------------------------------------------------------------------------------------ roles


def _with_twin(records, cls, twin_topic, keep=lambda r: True):
    """Every record, plus the records of type ``cls`` that ``keep`` accepts again on ``twin_topic``."""
    out = []
    for r in records:
        out.append(r)
        if isinstance(r, cls) and keep(r):
            out.append((twin_topic, r))
    return out


def test_the_unfiltered_scan_is_chosen_over_a_filtered_copy(tmp_path, records):
    path = write_ros2_log(tmp_path / "two_scans.mcap", _with_twin(records, Scan, "/scan_filtered"))
    data, report = read_log(path)
    assert len(data.scans) == sum(isinstance(r, Scan) for r in records)
    (c,) = report.choices
    assert (c.role, c.topic, c.others) == ("scan", "/scan", ("/scan_filtered",)) and "unfiltered" in c.rule
    assert report.channel("/scan_filtered").records == 0
    assert "chosen: scan: /scan used, not /scan_filtered" in format_report(report)
    s = inspect_log(path)
    assert not s.problems and dict(s.uses)["scan"] == "/scan" and "chosen: scan" in format_summary(s)
    # the mapping overrides the rule
    _data, report = read_log(path, mapping="topics:\n  /scan_filtered: scan\n")
    assert report.channel("/scan_filtered").records > 0 and report.channel("/scan").records == 0
    assert report.choices[0].topic == "/scan_filtered" and "mapping" in report.choices[0].rule


def test_the_compressed_image_is_chosen_beside_a_raw_one(tmp_path, records):
    import cv2

    out = []
    for r in records:
        out.append(r)
        if isinstance(r, Image):
            px = cv2.imdecode(np.frombuffer(r.data, np.uint8), cv2.IMREAD_GRAYSCALE)
            raw = Image(
                r.stamp_ns,
                r.frame_id,
                "mono8",
                px.tobytes(),
                width=px.shape[1],
                height=px.shape[0],
                step=px.shape[1],
            )
            out.append(("/camera/image_raw", raw))
    path = write_ros2_log(tmp_path / "raw_and_compressed.mcap", out)
    data, report = read_log(path)
    assert data.images and all(im.encoding == "jpeg" for im in data.images)
    (c,) = report.choices
    assert c.topic == "/camera/image/compressed" and c.others == ("/camera/image_raw",)
    assert "compressed" in c.rule


def test_the_most_complete_topic_is_chosen(tmp_path, records):
    """A filtered scan that has every message beats an unfiltered one that lost half of them."""
    scans = [r for r in records if isinstance(r, Scan)]
    half = {r.stamp_ns for r in scans[::2]}
    recs = [r for r in records if not isinstance(r, Scan) or r.stamp_ns in half]
    recs += [("/scan_filtered", r) for r in scans]
    recs.sort(key=lambda x: (x[1] if isinstance(x, tuple) else x).stamp_ns)
    path = write_ros2_log(tmp_path / "gappy.mcap", recs)
    data, report = read_log(path)
    assert len(data.scans) == len(scans)
    assert report.choices[0].topic == "/scan_filtered" and "most complete" in report.choices[0].rule


def test_an_optional_role_with_tied_candidates_never_stops_the_run(tmp_path, records):
    """Two IMUs no rule tells apart: the first by name is used and the choice is reported."""
    path = write_ros2_log(tmp_path / "two_imus.mcap", _with_twin(records, Heading, "/imu/data"))
    data, report = read_log(path, require=["odometry", "scan"])
    assert data.headings
    (c,) = report.choices
    assert c.role == "heading" and c.topic == "/compass" and "first by name" in c.rule


def test_a_required_role_with_tied_candidates_names_the_fix(tmp_path, records):
    path = write_ros2_log(tmp_path / "two_odom.mcap", _with_twin(records, Odometry, "/wheel/odom"))
    with pytest.raises(IngestError, match=r"no rule tells them apart.*'/odom'.*'/wheel/odom'.*ignored"):
        read_log(path)
    assert any("odometry" in p for p in inspect_log(path).problems)
    data, _ = read_log(path, mapping="topics:\n  /wheel/odom: odometry\n")
    assert data.odometry


# ------------------------------------------------------------------------------------------------ upside-down laser


def _quat(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return (*(a * math.sin(angle / 2)), math.cos(angle / 2))


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _beam_ends_in_base(T, scan):
    """The beam end points of ``scan`` in the base frame by the full 3D transform (x, y only)."""
    a, r = scan.angles[scan.valid], scan.ranges[scan.valid].astype(float)
    p = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r), np.ones_like(r)])
    return (T @ p.T).T[:, :2]


@pytest.mark.parametrize(
    "rotation",
    [
        _quat((1, 0, 0), math.pi),  # rolled over
        _quat((0, 1, 0), math.pi),  # pitched over: looks backwards, mirrored
        _qmul(_quat((0, 0, 1), 0.7), _quat((1, 0, 0), math.pi)),  # turned 40 deg, then rolled over
    ],
)
def test_an_upside_down_laser_is_levelled_with_its_full_rotation(tmp_path, records, rotation):
    from holoslam.frames import quat_to_matrix
    from holoslam.submaps.frontend import base_to_laser

    tf = Transform(records[0].stamp_ns, "base_link", "laser", (0.2, -0.1, 0.4), rotation, static=True)
    recs = [tf if isinstance(r, Transform) and r.child == "laser" else r for r in records]
    path = write_ros2_log(tmp_path / "upside_down.mcap", recs)
    data, report = read_log(path)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = quat_to_matrix(np.array(rotation)), tf.translation
    raw = [r for r in records if isinstance(r, Scan)]
    assert len(data.scans) == len(raw) and report.levelled and "upside down" in report.levelled[0]
    bTs = base_to_laser(data, data.scans[0].frame_id)
    for got, orig in zip(data.scans, raw, strict=True):
        want = _beam_ends_in_base(T, orig)
        pts = got.points()
        c, s = math.cos(bTs[2]), math.sin(bTs[2])
        in_base = np.column_stack(
            [bTs[0] + c * pts[:, 0] - s * pts[:, 1], bTs[1] + s * pts[:, 0] + c * pts[:, 1]]
        )
        np.testing.assert_allclose(np.sort(in_base, axis=0), np.sort(want, axis=0), atol=1e-5)
        np.testing.assert_allclose(in_base[::-1], want, atol=1e-5)  # beam for beam, in reverse order


def test_an_upright_laser_is_left_alone_and_a_tilted_one_is_reported(records):
    from holoslam.io.mcap import level_scans

    scans = tuple(r for r in records if isinstance(r, Scan))
    tfs = tuple(r for r in records if isinstance(r, Transform))
    out, extra, done, tilted = level_scans(scans, tfs, "base_link")
    assert out is scans and extra == () and done == [] and tilted == []
    tilt = Transform(
        0, "base_link", "laser", (0.0, 0.0, 0.3), _quat((0, 1, 0), math.radians(20)), static=True
    )
    out, extra, done, tilted = level_scans(scans, (tilt,), "base_link")
    assert out is scans and "tilted 20.0 deg" in tilted[0]


def test_mirrored_scan_negates_every_beam_angle():
    from holoslam.io.mcap import mirrored_scan

    r = np.array([1.0, 2.0, np.inf, 4.0], np.float32)
    for a0, da in ((-1.0, 0.25), (1.0, -0.25)):
        s = Scan(0, "laser", a0, da, 0.1, 10.0, r, np.isfinite(r))
        m = mirrored_scan(s, "laser_level")
        np.testing.assert_allclose(m.angles, -s.angles[::-1])
        np.testing.assert_array_equal(m.ranges, r[::-1])
        assert m.frame_id == "laser_level" and m.angle_increment == da
