"""Write a ``SimulatedRun`` as an MCAP log in the ROS 2 profile (CDR, ros2msg schemas embedded, zstd chunks,
CRCs), with the topics listed in ``holoslam.sim``'s docstring, messages in log-time order (log time =
publish time = header stamp), and the metadata record ``holoslam`` (seed, duration, noise settings)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from holoslam.errors import HoloslamError
from holoslam.frames import quaternion_from_matrix, quaternion_from_yaw
from holoslam.io.mcap_write import ros_quaternion
from holoslam.io.ros2defs import msgdef

__all__ = ["write_household_log", "TOPICS"]

TOPICS: dict[str, str] = {
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/ground_truth/world": "std_msgs/msg/String",
    "/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/pose": "geometry_msgs/msg/PoseStamped",
    "/compass": "sensor_msgs/msg/Imu",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/camera/camera_info": "sensor_msgs/msg/CameraInfo",
    "/camera/image/compressed": "sensor_msgs/msg/CompressedImage",
    "/tags": "holoslam_msgs/msg/TagDetectionArray",
    "/ground_truth/visible": "std_msgs/msg/String",
}
_ORDER = {t: i for i, t in enumerate(TOPICS)}


def _yaw_q(yaw: float) -> dict[str, float]:
    return ros_quaternion(quaternion_from_yaw(yaw))


def _matrix_q(R: np.ndarray) -> dict[str, float]:
    return ros_quaternion(quaternion_from_matrix(R))


def _header(stamp_ns: int, frame_id: str) -> dict:
    return {
        "stamp": {"sec": int(stamp_ns // 1_000_000_000), "nanosec": int(stamp_ns % 1_000_000_000)},
        "frame_id": frame_id,
    }


def _tf(stamp_ns: int, parent: str, child: str, t: tuple[float, float, float], q: dict) -> dict:
    return {
        "header": _header(stamp_ns, parent),
        "child_frame_id": child,
        "transform": {"translation": {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])}, "rotation": q},
    }


def _messages(run) -> list[tuple[int, str, dict]]:
    from holoslam.sim.camera import PTZ_MOUNT, optical_rotation
    from holoslam.sim.sensors import LASER_MOUNT
    from holoslam.sim.world import world_to_json

    out: list[tuple[int, str, dict]] = []
    t0 = int(run.stamps_ns[0])
    out.append(
        (
            t0,
            "/tf_static",
            {
                "transforms": [
                    _tf(t0, "base_link", "laser", LASER_MOUNT, _yaw_q(0.0)),
                    _tf(t0, "base_link", "ptz_base", PTZ_MOUNT, _yaw_q(0.0)),
                ]
            },
        )
    )
    out.append((t0, "/ground_truth/world", {"data": world_to_json(run.world)}))
    odo = run.odometry
    big = 1e6  # variance of the dimensions a planar odometer does not measure
    for k, st in enumerate(odo.stamps_ns.tolist()):
        x, y, th = odo.odomTb[k]
        C = odo.cov_odomTb[k]
        cov = [0.0] * 36
        for i, a in enumerate((0, 1, 5)):
            for j, b in enumerate((0, 1, 5)):
                cov[a * 6 + b] = float(f"{C[i, j]:.1e}")  # two significant digits, as drivers report
        cov[14] = cov[21] = cov[28] = big
        tcov = [0.0] * 36  # constant, as drivers publish it: 0.02 m/s and 2 deg/s
        tcov[0], tcov[7], tcov[14], tcov[21], tcov[28], tcov[35] = 4e-4, 1e-6, big, big, big, 1.2e-3
        out.append(
            (
                st,
                "/odom",
                {
                    "header": _header(st, "odom"),
                    "child_frame_id": "base_link",
                    "pose": {
                        "pose": {
                            "position": {"x": float(x), "y": float(y), "z": 0.0},
                            "orientation": _yaw_q(float(th)),
                        },
                        "covariance": cov,
                    },
                    "twist": {
                        "twist": {
                            "linear": {"x": float(odo.speed[k]), "y": 0.0, "z": 0.0},
                            "angular": {"x": 0.0, "y": 0.0, "z": float(odo.yaw_rate[k])},
                        },
                        "covariance": tcov,
                    },
                },
            )
        )
    for k, st in enumerate(run.stamps_ns.tolist()):
        x, y, th = run.wTb[k]
        out.append(
            (
                st,
                "/ground_truth/pose",
                {
                    "header": _header(st, "map"),
                    "pose": {
                        "position": {"x": float(x), "y": float(y), "z": 0.0},
                        "orientation": _yaw_q(float(th)),
                    },
                },
            )
        )
    com = run.compass
    var = float(com.sigma) ** 2
    for k, st in enumerate(com.stamps_ns.tolist()):
        out.append(
            (
                st,
                "/compass",
                {
                    "header": _header(st, "base_link"),
                    "orientation": _yaw_q(float(com.yaw[k])),
                    "orientation_covariance": [big, 0, 0, 0, big, 0, 0, 0, var],
                    "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
                    "angular_velocity_covariance": [-1.0] + [0.0] * 8,
                    "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 0.0},
                    "linear_acceleration_covariance": [-1.0] + [0.0] * 8,
                },
            )
        )
    sc = run.scans
    n_beams = sc.ranges.shape[1]
    for k, st in enumerate(sc.stamps_ns.tolist()):
        out.append(
            (
                st,
                "/scan",
                {
                    "header": _header(st, "laser"),
                    "angle_min": sc.angle_min,
                    "angle_max": sc.angle_min + (n_beams - 1) * sc.angle_increment,
                    "angle_increment": sc.angle_increment,
                    "time_increment": 0.0,
                    "scan_time": 1.0 / run.config.laser_rate_hz,
                    "range_min": sc.range_min,
                    "range_max": sc.range_max,
                    "ranges": sc.ranges[k].tolist(),
                    "intensities": [],
                },
            )
        )
    w, h = run.config.image_width, run.config.image_height
    for s in run.snapshots:
        st = int(s.stamp_ns)
        out.append(
            (
                st,
                "/tf",
                {
                    "transforms": [
                        _tf(
                            st,
                            "ptz_base",
                            "camera_optical",
                            (0.0, 0.0, 0.0),
                            _matrix_q(optical_rotation(s.pan, s.tilt)),
                        )
                    ]
                },
            )
        )
        K = s.K
        out.append(
            (
                st,
                "/camera/camera_info",
                {
                    "header": _header(st, "camera_optical"),
                    "height": h,
                    "width": w,
                    "distortion_model": "plumb_bob",
                    "d": [0.0] * 5,
                    "k": [float(v) for v in K.ravel()],
                    "r": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                    "p": [K[0, 0], 0.0, K[0, 2], 0.0, 0.0, K[1, 1], K[1, 2], 0.0, 0.0, 0.0, 1.0, 0.0],
                    "binning_x": 0,
                    "binning_y": 0,
                    "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
                },
            )
        )
        out.append(
            (
                st,
                "/camera/image/compressed",
                {"header": _header(st, "camera_optical"), "format": "jpeg", "data": s.jpeg},
            )
        )
        out.append(
            (
                st,
                "/tags",
                {
                    "header": _header(st, "camera_optical"),
                    "detections": [
                        {"payload": p, "corners": [float(v) for v in np.asarray(c).ravel()]}
                        for p, c in s.tags
                    ],
                },
            )
        )
        out.append(
            (st, "/ground_truth/visible", {"data": json.dumps({"stamp_ns": st, "ids": list(s.visible_ids)})})
        )
    out.sort(key=lambda m: (m[0], _ORDER[m[1]]))
    return out


def write_household_log(run, path: str | Path, chunk_size: int = 1024 * 1024) -> dict[str, int]:
    """Write ``run`` to ``path`` (MCAP, ROS 2 profile); returns the message count per topic."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    path = Path(path)
    msgs = _messages(run)
    counts: dict[str, int] = {}
    try:
        with open(path, "wb") as f:
            writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD, enable_crcs=True)
            schemas = {}
            for type_name in TOPICS.values():
                if type_name not in schemas:
                    schemas[type_name] = writer.register_msgdef(type_name, msgdef(type_name))
            seq: dict[str, int] = {}
            for stamp, topic, msg in msgs:
                seq[topic] = seq.get(topic, 0) + 1
                writer.write_message(
                    topic,
                    schemas[TOPICS[topic]],
                    msg,
                    log_time=stamp,
                    publish_time=stamp,
                    sequence=seq[topic],
                )
            meta = run.config.metadata()
            meta["duration_s"] = repr(round(float((run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9), 6))
            meta["t0_ns"] = str(int(run.stamps_ns[0]))
            writer.add_metadata("holoslam", meta)
            writer.finish()
            counts = dict(seq)
    except OSError as e:
        raise HoloslamError(
            f"cannot write the MCAP log {path}: {e.strerror}; check the folder exists and is writable"
        ) from e
    return counts
