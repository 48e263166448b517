"""The CDR fast paths agree with mcap_ros2's generic decoder (little endian), read big-endian CDR built by
hand, and fall back on anything else. Also image decoding."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam.errors import ImageDecodeError
from holoslam.io import cdr
from holoslam.io.images import decode_image as decode_pixels
from holoslam.io.mcap_write import MSGDEFS
from holoslam.types import Image


def _encode(typ, msg):
    from mcap_ros2._dynamic import serialize_dynamic

    return serialize_dynamic(typ, MSGDEFS[typ])[typ](msg)


def _generic(typ, data):
    return cdr.generic_decoder(typ, MSGDEFS[typ])(data)


def _hdr(sec, nsec, frame):
    return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame}


frames = st.text(alphabet="abcdefgh_/", min_size=0, max_size=9)


@settings(max_examples=60, deadline=None)
@given(frame=frames, n=st.integers(0, 40), nint=st.integers(0, 5), seed=st.integers(0, 2**31))
def test_laser_scan_fast_path_equals_generic(frame, n, nint, seed):
    rng = np.random.default_rng(seed)
    ranges = rng.random(n).astype(np.float32) * 8
    ranges[rng.random(n) < 0.2] = np.inf
    msg = {
        "header": _hdr(12, 345, frame),
        "angle_min": -1.5,
        "angle_max": 1.5,
        "angle_increment": 0.01,
        "time_increment": 0.0,
        "scan_time": 0.2,
        "range_min": 0.05,
        "range_max": 8.0,
        "ranges": ranges.tolist(),
        "intensities": rng.random(nint).astype(np.float32).tolist(),
    }
    data = _encode("sensor_msgs/msg/LaserScan", msg)
    fast = cdr.decode_laser_scan(data)
    gen = _generic("sensor_msgs/msg/LaserScan", data)
    assert fast["stamp_ns"] == 12 * 10**9 + 345 and fast["frame_id"] == gen.header.frame_id == frame
    np.testing.assert_array_equal(fast["ranges"], np.asarray(gen.ranges, dtype=np.float32))
    np.testing.assert_array_equal(fast["intensities"], np.asarray(gen.intensities, dtype=np.float32))
    for k in ("angle_min", "angle_max", "angle_increment", "scan_time", "range_min", "range_max"):
        assert fast[k] == getattr(gen, k)
    assert fast["ranges"].dtype == np.float32 and fast["ranges"].flags.writeable


@settings(max_examples=30, deadline=None)
@given(frame=frames, child=frames, vals=st.lists(st.floats(-1e3, 1e3), min_size=85, max_size=85))
def test_odometry_fast_path_equals_generic(frame, child, vals):
    msg = {
        "header": _hdr(1, 2, frame),
        "child_frame_id": child,
        "pose": {
            "pose": {
                "position": dict(zip("xyz", vals[0:3], strict=True)),
                "orientation": dict(zip("xyzw", vals[3:7], strict=True)),
            },
            "covariance": vals[7:43],
        },
        "twist": {
            "twist": {
                "linear": dict(zip("xyz", vals[43:46], strict=True)),
                "angular": dict(zip("xyz", vals[46:49], strict=True)),
            },
            "covariance": vals[49:85],
        },
    }
    data = _encode("nav_msgs/msg/Odometry", msg)
    f = cdr.decode_odometry(data)
    g = _generic("nav_msgs/msg/Odometry", data)
    assert f["frame_id"] == frame and f["child_frame_id"] == child
    p, q = g.pose.pose.position, g.pose.pose.orientation
    assert f["position"] == (p.x, p.y, p.z) and f["orientation_xyzw"] == (q.x, q.y, q.z, q.w)
    assert list(f["pose_covariance"]) == list(g.pose.covariance)
    assert f["linear"][0] == g.twist.twist.linear.x and list(f["twist_covariance"]) == list(
        g.twist.covariance
    )


@settings(max_examples=30, deadline=None)
@given(frame=frames, vals=st.lists(st.floats(-10, 10), min_size=37, max_size=37))
def test_imu_fast_path_equals_generic(frame, vals):
    msg = {
        "header": _hdr(3, 4, frame),
        "orientation": dict(zip("xyzw", vals[:4], strict=True)),
        "orientation_covariance": vals[4:13],
        "angular_velocity": dict(zip("xyz", vals[13:16], strict=True)),
        "angular_velocity_covariance": vals[16:25],
        "linear_acceleration": dict(zip("xyz", vals[25:28], strict=True)),
        "linear_acceleration_covariance": vals[28:37],
    }
    data = _encode("sensor_msgs/msg/Imu", msg)
    f = cdr.decode_imu(data)
    g = _generic("sensor_msgs/msg/Imu", data)
    q = g.orientation
    assert f["orientation_xyzw"] == (q.x, q.y, q.z, q.w)
    assert list(f["orientation_covariance"]) == list(g.orientation_covariance)
    assert list(f["linear_acceleration_covariance"]) == list(g.linear_acceleration_covariance)
    assert f["linear_acceleration"][2] == g.linear_acceleration.z


@settings(max_examples=30, deadline=None)
@given(
    frame=frames,
    fmt=st.sampled_from(["jpeg", "png", "rgb8; jpeg compressed bgr8"]),
    payload=st.binary(max_size=64),
)
def test_image_fast_paths_equal_generic(frame, fmt, payload):
    data = _encode(
        "sensor_msgs/msg/CompressedImage", {"header": _hdr(5, 6, frame), "format": fmt, "data": payload}
    )
    f = cdr.decode_compressed_image(data)
    g = _generic("sensor_msgs/msg/CompressedImage", data)
    assert (f["frame_id"], f["format"], f["data"]) == (g.header.frame_id, g.format, bytes(g.data))
    raw = {
        "header": _hdr(5, 6, frame),
        "height": 2,
        "width": len(payload),
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": len(payload),
        "data": payload * 2,
    }
    data = _encode("sensor_msgs/msg/Image", raw)
    f = cdr.decode_image(data)
    g = _generic("sensor_msgs/msg/Image", data)
    assert (f["height"], f["width"], f["encoding"], f["step"], f["data"]) == (
        g.height,
        g.width,
        g.encoding,
        g.step,
        bytes(g.data),
    )


def test_big_endian_laser_scan_built_by_hand():
    # encapsulation 00 00 = CDR big endian; alignment counts from byte 4
    frame = b"laser\x00"
    body = struct.pack(">iI", 7, 8) + struct.pack(">I", len(frame)) + frame
    body += b"\x00" * ((-len(body)) % 4)
    body += struct.pack(">7f", -1.0, 1.0, 0.5, 0.0, 0.1, 0.05, 8.0)
    body += struct.pack(">I", 3) + struct.pack(">3f", 1.0, 2.5, math.inf) + struct.pack(">I", 0)
    msg = cdr.decode_laser_scan(b"\x00\x00\x00\x00" + body)
    assert msg["stamp_ns"] == 7 * 10**9 + 8 and msg["frame_id"] == "laser" and msg["range_max"] == 8.0
    np.testing.assert_array_equal(msg["ranges"], [1.0, 2.5, np.inf])
    assert msg["ranges"].dtype == np.dtype(np.float32)  # native order after the copy


def test_non_plain_cdr_falls_back():
    with pytest.raises(cdr.CdrFallback, match="0x07"):
        cdr.decode_laser_scan(b"\x00\x07\x00\x00" + b"\x00" * 40)
    with pytest.raises(cdr.CdrFallback):
        cdr.decode_laser_scan(b"\x00\x01\x00\x00" + struct.pack("<iII", 0, 0, 1000) + b"abc")


def test_generic_decoder_reports_bad_definitions():
    with pytest.raises(ValueError, match="does not parse|does not define"):
        cdr.generic_decoder("x_msgs/msg/Bad", "this is not a ros2msg line ###\n")


def test_decode_image_raw_and_compressed():
    import cv2

    bgr = np.zeros((4, 5, 3), np.uint8)
    bgr[..., 2] = 200  # red
    rgb = bgr[..., ::-1].tobytes()
    out = decode_pixels(Image(1, "cam", "rgb8", rgb, width=5, height=4, step=15))
    np.testing.assert_array_equal(out, bgr)
    padded = np.zeros((4, 8), np.uint8)
    padded[:, :5] = 7
    out = decode_pixels(Image(1, "cam", "mono8", padded.tobytes(), width=5, height=4, step=8))
    assert out.shape == (4, 5) and (out == 7).all()
    ok, png = cv2.imencode(".png", bgr)
    np.testing.assert_array_equal(Image(1, "cam", "png", png.tobytes()).decode(), bgr)
    with pytest.raises(ImageDecodeError, match="do not decode as jpeg"):
        decode_pixels(Image(2, "cam", "jpeg", b"\xff\xd8 definitely not a jpeg"))
    with pytest.raises(ImageDecodeError, match="truncated image"):
        decode_pixels(Image(3, "cam", "bgr8", b"\x00" * 10, width=5, height=4, step=15))
    with pytest.raises(ImageDecodeError, match="unknown encoding"):
        decode_pixels(Image(4, "cam", "yuv422_weird", b"\x00"))


@settings(max_examples=30, deadline=None)
@given(
    frame=frames,
    model=st.sampled_from(["plumb_bob", "rational_polynomial", ""]),
    nd=st.integers(0, 8),
    vals=st.lists(st.floats(-1e3, 1e3), min_size=38, max_size=38),
)
def test_camera_info_fast_path_equals_generic(frame, model, nd, vals):
    msg = {
        "header": _hdr(9, 10, frame),
        "height": 480,
        "width": 640,
        "distortion_model": model,
        "d": vals[:nd],
        "k": vals[8:17],
        "r": vals[17:26],
        "p": vals[26:38],
        "binning_x": 1,
        "binning_y": 2,
        "roi": {"x_offset": 1, "y_offset": 2, "height": 3, "width": 4, "do_rectify": True},
    }
    data = _encode("sensor_msgs/msg/CameraInfo", msg)
    f = cdr.decode_camera_info(data)
    g = _generic("sensor_msgs/msg/CameraInfo", data)
    assert (f["frame_id"], f["distortion_model"], f["width"], f["height"]) == (
        g.header.frame_id,
        g.distortion_model,
        g.width,
        g.height,
    )
    assert list(f["d"]) == list(g.d) and list(f["k"]) == list(g.k) and list(f["p"]) == list(g.p)


@settings(max_examples=30, deadline=None)
@given(
    names=st.lists(st.tuples(frames, frames), max_size=4),
    vals=st.lists(st.floats(-10, 10), min_size=7, max_size=7),
)
def test_tf_message_fast_path_equals_generic(names, vals):
    msg = {
        "transforms": [
            {
                "header": _hdr(i, 7 * i, p),
                "child_frame_id": c,
                "transform": {
                    "translation": dict(zip("xyz", vals[:3], strict=True)),
                    "rotation": dict(zip("xyzw", vals[3:], strict=True)),
                },
            }
            for i, (p, c) in enumerate(names)
        ]
    }
    data = _encode("tf2_msgs/msg/TFMessage", msg)
    f = cdr.decode_tf_message(data)["transforms"]
    g = _generic("tf2_msgs/msg/TFMessage", data).transforms
    assert len(f) == len(g) == len(names)
    for (stamp, parent, child, t, q), gt in zip(f, g, strict=True):
        assert stamp == gt.header.stamp.sec * 10**9 + gt.header.stamp.nanosec
        assert (parent, child) == (gt.header.frame_id, gt.child_frame_id)
        tr = gt.transform
        assert t == (tr.translation.x, tr.translation.y, tr.translation.z)
        assert q == (tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w)
