"""The ROS 2 messages holoslam writes, built from plain values, and the one function that writes them to MCAP.

Each ``*_message`` function returns the message as the dict ``mcap_ros2`` serialises (field names of the
``ros2msg`` definitions in :mod:`holoslam.io.ros2defs`). Both writers use them: ``holoslam.io.mcap_write``
(holoslam records -> a log that ingests back to them) and the simulator's (``holoslam.sim.writer``, which adds
what simulated drivers publish: rounded covariances, twists, visibility ground truth). ``write_ros2_messages``
writes (stamp, topic, type, message) tuples: schemas, sequence numbers, CRCs, metadata.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.io.ros2defs import msgdef

__all__ = [
    "header",
    "quaternion_message",
    "transform_stamped",
    "tf_message",
    "odometry_message",
    "imu_orientation_message",
    "scan_message",
    "camera_info_message",
    "compressed_image_message",
    "pose_stamped_message",
    "tags_message",
    "string_message",
    "write_ros2_messages",
]


def header(stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """std_msgs/Header."""
    return {"stamp": {"sec": int(stamp_ns // 1_000_000_000), "nanosec": int(stamp_ns % 1_000_000_000)},
            "frame_id": frame_id}


def quaternion_message(q_xyzw: Sequence[float]) -> dict[str, float]:
    """geometry_msgs/Quaternion of (x, y, z, w)."""
    return {"x": float(q_xyzw[0]), "y": float(q_xyzw[1]), "z": float(q_xyzw[2]), "w": float(q_xyzw[3])}


def transform_stamped(stamp_ns: int, parent: str, child: str, t: Sequence[float], q_xyzw: Sequence[float]) -> dict:
    """geometry_msgs/TransformStamped: ``child``'s pose in ``parent`` (translation t, rotation q)."""
    return {
        "header": header(stamp_ns, parent),
        "child_frame_id": child,
        "transform": {"translation": {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])},
                      "rotation": quaternion_message(q_xyzw)},
    }


def tf_message(transforms: Sequence[dict]) -> dict:
    """tf2_msgs/TFMessage of ``transform_stamped`` dicts."""
    return {"transforms": list(transforms)}


def odometry_message(stamp_ns: int, frame_id: str, child_frame_id: str, x: float, y: float,
                     q_xyzw: Sequence[float], pose_covariance: Sequence[float], speed: float = 0.0,
                     yaw_rate: float = 0.0, twist_covariance: Sequence[float] | None = None) -> dict:
    """nav_msgs/Odometry of a planar pose (row-major 6x6 covariances, parent frame)."""
    return {
        "header": header(stamp_ns, frame_id),
        "child_frame_id": child_frame_id,
        "pose": {
            "pose": {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": quaternion_message(q_xyzw)},
            "covariance": [float(v) for v in pose_covariance],
        },
        "twist": {
            "twist": {"linear": {"x": float(speed), "y": 0.0, "z": 0.0},
                      "angular": {"x": 0.0, "y": 0.0, "z": float(yaw_rate)}},
            "covariance": [0.0] * 36 if twist_covariance is None else [float(v) for v in twist_covariance],
        },
    }


def imu_orientation_message(stamp_ns: int, frame_id: str, q_xyzw: Sequence[float],
                            orientation_covariance: Sequence[float]) -> dict:
    """sensor_msgs/Imu carrying an orientation only (angular velocity and acceleration marked absent, -1)."""
    return {
        "header": header(stamp_ns, frame_id),
        "orientation": quaternion_message(q_xyzw),
        "orientation_covariance": [float(v) for v in orientation_covariance],
        "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular_velocity_covariance": [-1.0] + [0.0] * 8,
        "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 0.0},
        "linear_acceleration_covariance": [-1.0] + [0.0] * 8,
    }


def scan_message(stamp_ns: int, frame_id: str, angle_min: float, angle_increment: float, range_min: float,
                 range_max: float, ranges: np.ndarray, scan_time: float = 0.0) -> dict:
    """sensor_msgs/LaserScan (no intensities)."""
    n = len(ranges)
    return {
        "header": header(stamp_ns, frame_id),
        "angle_min": angle_min,
        "angle_max": angle_min + (n - 1) * angle_increment,
        "angle_increment": angle_increment,
        "time_increment": 0.0,
        "scan_time": scan_time,
        "range_min": range_min,
        "range_max": range_max,
        "ranges": np.asarray(ranges).tolist(),
        "intensities": [],
    }


def camera_info_message(stamp_ns: int, frame_id: str, width: int, height: int, K: np.ndarray, D: np.ndarray,
                        distortion_model: str = "plumb_bob") -> dict:
    """sensor_msgs/CameraInfo of a pinhole camera (R identity, P = [K | 0])."""
    K = np.asarray(K, dtype=np.float64)
    P = np.zeros((3, 4))
    P[:, :3] = K
    return {
        "header": header(stamp_ns, frame_id),
        "height": height,
        "width": width,
        "distortion_model": distortion_model,
        "d": np.asarray(D, dtype=np.float64).tolist(),
        "k": K.ravel().tolist(),
        "r": np.eye(3).ravel().tolist(),
        "p": P.ravel().tolist(),
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def compressed_image_message(stamp_ns: int, frame_id: str, fmt: str, data: bytes) -> dict:
    """sensor_msgs/CompressedImage."""
    return {"header": header(stamp_ns, frame_id), "format": fmt, "data": data}


def pose_stamped_message(stamp_ns: int, frame_id: str, x: float, y: float, z: float,
                         q_xyzw: Sequence[float]) -> dict:
    """geometry_msgs/PoseStamped."""
    return {"header": header(stamp_ns, frame_id),
            "pose": {"position": {"x": float(x), "y": float(y), "z": float(z)}, "orientation": quaternion_message(q_xyzw)}}


def tags_message(stamp_ns: int, frame_id: str, detections: Iterable[tuple[str, np.ndarray]]) -> dict:
    """holoslam_msgs/TagDetectionArray: (payload, corners (4, 2) px) per detection."""
    return {"header": header(stamp_ns, frame_id),
            "detections": [{"payload": p, "corners": [float(v) for v in np.asarray(c).ravel()]} for p, c in detections]}


def string_message(text: str) -> dict:
    """std_msgs/String."""
    return {"data": text}


def write_ros2_messages(
    path: str | Path,
    messages: Iterable[tuple[int, str, str, dict]],
    *,
    schemas: Sequence[str] = (),
    sequence: bool = False,
    metadata: dict[str, dict[str, str]] | None = None,
    log_time_offset_ns: int = 0,
    chunk_size: int = 1024 * 1024,
    compression: str = "zstd",
) -> dict[str, int]:
    """Write ``(stamp_ns, topic, type, message)`` in the order given into a ROS 2 MCAP file (CRCs on); log time =
    publish time = stamp + ``log_time_offset_ns``. ``schemas``: types registered first, in this order (the rest
    as met); ``sequence``: number each topic's messages 1, 2, ...; ``metadata``: named metadata records.
    Returns the message count per topic. Raises OSError when the file cannot be written."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    counts: dict[str, int] = {}
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size, compression=comp, enable_crcs=True)
        ids: dict[str, Any] = {}
        for typ in schemas:
            if typ not in ids:
                ids[typ] = w.register_msgdef(typ, msgdef(typ))
        for stamp, topic, typ, msg in messages:
            if typ not in ids:
                ids[typ] = w.register_msgdef(typ, msgdef(typ))
            counts[topic] = counts.get(topic, 0) + 1
            t = int(stamp) + log_time_offset_ns
            w.write_message(topic, ids[typ], msg, log_time=t, publish_time=t,
                            sequence=counts[topic] if sequence else 0)
        for name, record in (metadata or {}).items():
            w.add_metadata(name, record)
        w.finish()
    return counts
