"""Write holoslam records as a ROS 2 MCAP log (the inverse of :mod:`holoslam.io.mcap` ingestion).

Used by the ingestion tests and benchmark to build logs with ``mcap_ros2.writer.Writer``; the message
definitions are the standard ROS 2 ``ros2msg`` texts (as ``ros2 bag record`` embeds them: the type, then each
dependency after a ``MSG:`` line) plus holoslam's own ``holoslam_msgs/msg/TagDetectionArray``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.frames import quaternion_from_yaw
from holoslam.io import ros2_messages as m
from holoslam.io.ros2defs import MSG_TYPES, msgdef
from holoslam.types import (
    CameraInfo,
    GroundTruthPose,
    GroundTruthWorld,
    Heading,
    Image,
    Odometry,
    Pose2,
    Record,
    Scan,
    TagSighting,
    Transform,
)

__all__ = ["MSGDEFS", "msgdef", "ros2_message", "write_ros2_log", "DEFAULT_TOPICS", "example_records"]

# the full ros2msg text of every type holoslam writes, keyed pkg/msg/Type
MSGDEFS: dict[str, str] = {name: msgdef(name) for name in MSG_TYPES}

DEFAULT_TOPICS: dict[type, tuple[str, str]] = {
    Odometry: ("/odom", "nav_msgs/msg/Odometry"),
    Heading: ("/compass", "sensor_msgs/msg/Imu"),
    Scan: ("/scan", "sensor_msgs/msg/LaserScan"),
    Image: ("/camera/image/compressed", "sensor_msgs/msg/CompressedImage"),
    CameraInfo: ("/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
    TagSighting: ("/tags", "holoslam_msgs/msg/TagDetectionArray"),
    GroundTruthPose: ("/ground_truth/pose", "geometry_msgs/msg/PoseStamped"),
    GroundTruthWorld: ("/ground_truth/world", "std_msgs/msg/String"),
}


def _cov6(cov3: np.ndarray | None, theta: float = 0.0) -> list[float]:
    """The ROS 6x6 pose covariance (parent frame) of a body-frame (x, y, yaw) covariance at heading theta."""
    c = np.zeros((6, 6))
    if cov3 is not None:
        from holoslam.io.mcap import rotate_cov_xy

        idx = [0, 1, 5]
        c[np.ix_(idx, idx)] = rotate_cov_xy(cov3, theta)
    return c.ravel().tolist()


def ros2_message(rec: Record) -> dict[str, Any]:
    """The ROS 2 message (as a dict for ``mcap_ros2``) that ingests back to ``rec``.

    Transforms give a one-element TFMessage; tag sightings a one-element TagDetectionArray.
    """
    if isinstance(rec, Odometry):
        p = rec.odomTb
        return m.odometry_message(rec.stamp_ns, rec.frame_id, rec.child_frame_id, p.x, p.y,
                                  quaternion_from_yaw(p.theta), _cov6(rec.cov_odomTb, p.theta),
                                  speed=0.0 if math.isnan(rec.speed) else rec.speed)
    if isinstance(rec, Heading):
        var = 0.0 if math.isnan(rec.sigma) else rec.sigma**2
        return m.imu_orientation_message(rec.stamp_ns, rec.frame_id, quaternion_from_yaw(rec.yaw), [0.0] * 8 + [var])
    if isinstance(rec, Scan):
        return m.scan_message(rec.stamp_ns, rec.frame_id, rec.angle_min, rec.angle_increment, rec.range_min,
                              rec.range_max, rec.ranges)
    if isinstance(rec, Image):
        if rec.width and rec.height:
            return {
                "header": m.header(rec.stamp_ns, rec.frame_id),
                "height": rec.height,
                "width": rec.width,
                "encoding": rec.encoding,
                "is_bigendian": 0,
                "step": rec.step,
                "data": rec.data,
            }
        return m.compressed_image_message(rec.stamp_ns, rec.frame_id, rec.encoding, rec.data)
    if isinstance(rec, CameraInfo):
        return m.camera_info_message(rec.stamp_ns, rec.frame_id, rec.width, rec.height, rec.K, rec.D,
                                     rec.distortion_model)
    if isinstance(rec, Transform):
        return m.tf_message([m.transform_stamped(rec.stamp_ns, rec.parent, rec.child, rec.translation,
                                                 rec.rotation_xyzw)])
    if isinstance(rec, TagSighting):
        return m.tags_message(rec.stamp_ns, rec.frame_id, [(rec.payload, rec.corners)])
    if isinstance(rec, GroundTruthPose):
        p = rec.wTb
        return m.pose_stamped_message(rec.stamp_ns, rec.frame_id, p.x, p.y, rec.z, quaternion_from_yaw(p.theta))
    if isinstance(rec, GroundTruthWorld):
        return m.string_message(rec.json_text)
    raise TypeError(f"no ROS 2 message for {type(rec).__name__}")


def write_ros2_log(
    path: str | Path,
    records: Iterable[Record | tuple[str, Record]],
    *,
    topics: dict[type, tuple[str, str]] | None = None,
    log_time_offset_ns: int = 0,
    chunk_size: int = 1024 * 1024,
    compression: str = "zstd",
) -> Path:
    """Write ``records`` (in the order given) into a ROS 2 MCAP file (``ros2_messages.write_ros2_messages``).

    Each record type goes to its topic in ``topics`` (``DEFAULT_TOPICS`` otherwise; transforms go to
    ``/tf_static`` or ``/tf`` by their ``static`` flag); a ``(topic, record)`` pair goes to that topic (two
    topics of one type, a rewritten real log's own names). Log time = stamp + ``log_time_offset_ns``.
    """
    table = dict(DEFAULT_TOPICS)
    if topics:
        table.update(topics)

    def messages() -> Iterable[tuple[int, str, str, dict]]:
        for item in records:
            named, rec = item if isinstance(item, tuple) else (None, item)
            if isinstance(rec, Transform):
                topic, typ = ("/tf_static" if rec.static else "/tf"), "tf2_msgs/msg/TFMessage"
            elif isinstance(rec, Image) and rec.width and rec.height and type(rec) not in (topics or {}):
                topic, typ = "/camera/image_raw", "sensor_msgs/msg/Image"
            else:
                topic, typ = table[type(rec)]
            yield getattr(rec, "stamp_ns", 0), named or topic, typ, ros2_message(rec)

    path = Path(path)
    m.write_ros2_messages(path, messages(), log_time_offset_ns=log_time_offset_ns, chunk_size=chunk_size,
                          compression=compression)
    return path


def example_records(
    seconds: float = 4.0,
    t0_ns: int = 1_700_000_000_000_000_000,
    seed: int = 0,
    image_bytes: bytes | None = None,
) -> list[Record]:
    """A small synthetic household drive at the reference log's rates (odometry 20 Hz, compass 10 Hz,
    scans 5 Hz, camera 2 Hz with intrinsics, /tf at each image, one static laser transform, ground truth),
    in time order. Used by the ingestion tests and the benchmark; ``image_bytes`` replaces the default JPEG."""
    rng = np.random.default_rng(seed)
    if image_bytes is None:
        import cv2

        img = (rng.random((48, 64)) * 255).astype(np.uint8)
        ok, enc = cv2.imencode(".jpg", img)
        image_bytes = enc.tobytes()
    K = np.array([[300.0, 0, 32], [0, 300.0, 24], [0, 0, 1]])
    out: list[Record] = [
        GroundTruthWorld(t0_ns, '{"walls": [], "objects": []}'),
        Transform(t0_ns, "base_link", "laser", (0.15, 0.0, 0.3), (0.0, 0.0, 0.0, 1.0), static=True),
        Transform(t0_ns, "base_link", "ptz_base", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0), static=True),
    ]
    step = 50_000_000
    for i in range(int(seconds * 20)):
        t = t0_ns + i * step
        th = 0.05 * i
        pose = Pose2(0.02 * i * math.cos(0.01 * i), 0.02 * i * math.sin(0.01 * i), th)
        out.append(Odometry(t, pose, np.diag([1e-4, 1e-4, 4e-4]), 0.4))
        out.append(GroundTruthPose(t, Pose2(pose.x + 0.01, pose.y, th)))
        if i % 2 == 0:
            out.append(Heading(t, th + 0.01 * rng.standard_normal(), 0.02))
        if i % 4 == 0:
            r = (1.0 + 5.0 * rng.random(181)).astype(np.float32)
            r[rng.random(181) < 0.1] = np.inf
            out.append(Scan(t, "laser", -math.pi / 2, math.pi / 180, 0.05, 8.0, r, np.isfinite(r)))
        if i % 10 == 0:
            pan = 0.1 * i
            q = (0.0, 0.0, math.sin(pan / 2), math.cos(pan / 2))
            out.append(Transform(t, "ptz_base", "camera_optical", (0.0, 0.0, 0.1), q, static=False))
            out.append(Image(t, "camera_optical", "jpeg", image_bytes))
            out.append(CameraInfo(t, "camera_optical", 64, 48, K, np.zeros(5)))
            out.append(TagSighting(t, "camera_optical", f"HL1;cup{i};cup", np.arange(8.0) + i))
    return out
