"""Write a ``SimulatedRun`` as an MCAP log in the ROS 2 profile (CDR, ros2msg schemas embedded, zstd chunks,
CRCs), with the topics listed in ``holoslam.sim``'s docstring, messages in log-time order (log time =
publish time = header stamp), and the metadata record ``holoslam`` (seed, duration, noise settings)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from holoslam.errors import HoloslamError
from holoslam.frames import quaternion_from_matrix, quaternion_from_yaw
from holoslam.io import ros2_messages as m

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
_BIG = 1e6  # variance of the dimensions a sensor does not measure


def _odometry(run) -> list[tuple[int, str, str, dict]]:
    """/odom as the simulated driver publishes it: the pose covariance in the odom frame with two significant
    digits, 1e6 on the dimensions a planar odometer does not measure, and a constant twist covariance."""
    odo = run.odometry
    out = []
    for k, st in enumerate(odo.stamps_ns.tolist()):
        x, y, th = odo.odomTb[k]
        C = odo.cov_odomTb[k]
        cov = [0.0] * 36
        for i, a in enumerate((0, 1, 5)):
            for j, b in enumerate((0, 1, 5)):
                cov[a * 6 + b] = float(f"{C[i, j]:.1e}")  # two significant digits, as drivers report
        cov[14] = cov[21] = cov[28] = _BIG
        tcov = [0.0] * 36  # constant, as drivers publish it: 0.02 m/s and 2 deg/s
        tcov[0], tcov[7], tcov[14], tcov[21], tcov[28], tcov[35] = 4e-4, 1e-6, _BIG, _BIG, _BIG, 1.2e-3
        msg = m.odometry_message(st, "odom", "base_link", float(x), float(y), quaternion_from_yaw(float(th)), cov,
                                 speed=float(odo.speed[k]), yaw_rate=float(odo.yaw_rate[k]), twist_covariance=tcov)
        out.append((st, "/odom", TOPICS["/odom"], msg))
    return out


def _camera(run) -> list[tuple[int, str, str, dict]]:
    """Per snapshot: the head's /tf, the intrinsics, the JPEG, the driver's tag detections, the visible ids."""
    from holoslam.sim.camera import optical_rotation

    w, h = run.config.image_width, run.config.image_height
    out = []
    for s in run.snapshots:
        st = int(s.stamp_ns)
        q = quaternion_from_matrix(optical_rotation(s.pan, s.tilt))
        out += [
            (st, "/tf", TOPICS["/tf"], m.tf_message([m.transform_stamped(st, "ptz_base", "camera_optical",
                                                                         (0.0, 0.0, 0.0), q)])),
            (st, "/camera/camera_info", TOPICS["/camera/camera_info"],
             m.camera_info_message(st, "camera_optical", w, h, s.K, np.zeros(5))),
            (st, "/camera/image/compressed", TOPICS["/camera/image/compressed"],
             m.compressed_image_message(st, "camera_optical", "jpeg", s.jpeg)),
            (st, "/tags", TOPICS["/tags"], m.tags_message(st, "camera_optical", s.tags)),
            (st, "/ground_truth/visible", TOPICS["/ground_truth/visible"],
             m.string_message(json.dumps({"stamp_ns": st, "ids": list(s.visible_ids)}))),
        ]
    return out


def _messages(run) -> list[tuple[int, str, str, dict]]:
    """Every message of ``run``: (stamp, topic, type, message), in log-time order (topics in ``TOPICS`` order
    at one stamp)."""
    from holoslam.sim.camera import PTZ_MOUNT
    from holoslam.sim.sensors import LASER_MOUNT
    from holoslam.sim.world import world_to_json

    t0 = int(run.stamps_ns[0])
    level = quaternion_from_yaw(0.0)
    out: list[tuple[int, str, str, dict]] = [
        (t0, "/tf_static", TOPICS["/tf_static"], m.tf_message([
            m.transform_stamped(t0, "base_link", "laser", LASER_MOUNT, level),
            m.transform_stamped(t0, "base_link", "ptz_base", PTZ_MOUNT, level)])),
        (t0, "/ground_truth/world", TOPICS["/ground_truth/world"], m.string_message(world_to_json(run.world))),
    ]
    out += _odometry(run)
    out += [(st, "/ground_truth/pose", TOPICS["/ground_truth/pose"],
             m.pose_stamped_message(st, "map", float(x), float(y), 0.0, quaternion_from_yaw(float(th))))
            for st, (x, y, th) in zip(run.stamps_ns.tolist(), run.wTb, strict=True)]
    com = run.compass
    var = float(com.sigma) ** 2
    out += [(st, "/compass", TOPICS["/compass"],
             m.imu_orientation_message(st, "base_link", quaternion_from_yaw(float(yaw)),
                                       [_BIG, 0, 0, 0, _BIG, 0, 0, 0, var]))
            for st, yaw in zip(com.stamps_ns.tolist(), com.yaw, strict=True)]
    sc = run.scans
    out += [(st, "/scan", TOPICS["/scan"],
             m.scan_message(st, "laser", sc.angle_min, sc.angle_increment, sc.range_min, sc.range_max, sc.ranges[k],
                            scan_time=1.0 / run.config.laser_rate_hz))
            for k, st in enumerate(sc.stamps_ns.tolist())]
    out += _camera(run)
    out.sort(key=lambda msg: (msg[0], _ORDER[msg[1]]))
    return out


def write_household_log(run, path: str | Path, chunk_size: int = 1024 * 1024,
                        metadata: dict[str, str] | None = None) -> dict[str, int]:
    """Write ``run`` to ``path`` (MCAP, ROS 2 profile) through ``holoslam.io.ros2_messages``; returns the message
    count per topic. ``metadata`` replaces entries of the ``holoslam`` record (another generator and world)."""
    path = Path(path)
    meta = run.config.metadata()
    meta.update(metadata or {})
    meta["duration_s"] = repr(round(float((run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9), 6))
    meta["t0_ns"] = str(int(run.stamps_ns[0]))
    try:
        return m.write_ros2_messages(path, _messages(run), schemas=list(TOPICS.values()), sequence=True,
                                     metadata={"holoslam": meta}, chunk_size=chunk_size)
    except OSError as e:
        raise HoloslamError(
            f"cannot write the MCAP log {path}: {e.strerror}; check the folder exists and is writable"
        ) from e
