"""A ``SimulatedRun`` as holoslam records (``holoslam.types.LogData``), without writing an MCAP file.

``to_log_data(run)`` gives the same information the log carries, already in the records ingestion
returns, so that later stages can be tested on a simulated household in memory. Values follow the log's
conventions: odometry covariances in the ROS convention as written on ``/odom`` (numbers x, y, yaw in the
odom frame) converted to holoslam's body-frame ``cov_odomTb``; compass sigma from the configured white
noise; scans with ``valid`` = finite and within range; images as JPEG bytes.
"""

from __future__ import annotations

import numpy as np

from holoslam.types import (
    CameraInfo,
    GroundTruthPose,
    Heading,
    Image,
    LogData,
    Odometry,
    Pose2,
    Scan,
    TagSighting,
    Transform,
)

__all__ = ["to_log_data"]


def to_log_data(run, source: str = "simulated household") -> LogData:
    """The records of ``run`` (a ``holoslam.sim.SimulatedRun``), sorted by stamp within each kind."""
    from holoslam.frames import quaternion_from_matrix, quaternion_from_yaw
    from holoslam.sim.camera import PTZ_MOUNT, optical_rotation
    from holoslam.sim.sensors import LASER_MOUNT
    from holoslam.sim.world import world_to_json

    odo = run.odometry
    c, s = np.cos(odo.odomTb[:, 2]), np.sin(odo.odomTb[:, 2])
    odometry = []
    for k, st in enumerate(odo.stamps_ns.tolist()):
        # back from the ROS convention (covariance of x, y, yaw in odom) to the body frame
        J = np.array([[c[k], s[k], 0.0], [-s[k], c[k], 0.0], [0.0, 0.0, 1.0]])
        cov = J @ odo.cov_odomTb[k] @ J.T
        odometry.append(  # all zeros: unknown, as the log reader gives it
            Odometry(int(st), Pose2.from_array(odo.odomTb[k]), 0.5 * (cov + cov.T) if cov.any() else None,
                     float(odo.speed[k]))
        )
    com = run.compass
    headings = [
        Heading(int(t), float(y), float(com.sigma))
        for t, y in zip(com.stamps_ns.tolist(), com.yaw, strict=True)
    ]
    sc = run.scans
    scans = []
    for k, st in enumerate(sc.stamps_ns.tolist()):
        r = sc.ranges[k]
        valid = np.isfinite(r) & (r >= sc.range_min) & (r <= sc.range_max)
        scans.append(
            Scan(int(st), "laser", sc.angle_min, sc.angle_increment, sc.range_min, sc.range_max, r, valid)
        )
    cfg = run.config
    t0 = int(run.stamps_ns[0])
    transforms = [
        Transform(t0, "base_link", "laser", LASER_MOUNT, quaternion_from_yaw(0.0), static=True),
        Transform(t0, "base_link", "ptz_base", PTZ_MOUNT, quaternion_from_yaw(0.0), static=True),
    ]
    images: list[Image] = []
    infos: list[CameraInfo] = []
    tags: list[TagSighting] = []
    for snap in run.snapshots:
        st = int(snap.stamp_ns)
        transforms.append(
            Transform(
                st,
                "ptz_base",
                "camera_optical",
                (0.0, 0.0, 0.0),
                quaternion_from_matrix(optical_rotation(snap.pan, snap.tilt)),
            )
        )
        images.append(Image(st, "camera_optical", "jpeg", snap.jpeg, cfg.image_width, cfg.image_height))
        infos.append(CameraInfo(st, "camera_optical", cfg.image_width, cfg.image_height, snap.K, np.zeros(5)))
        tags.extend(TagSighting(st, "camera_optical", p, corners) for p, corners in snap.tags)
    ground_truth = [
        GroundTruthPose(int(t), Pose2.from_array(p))
        for t, p in zip(run.stamps_ns.tolist(), run.wTb, strict=True)
    ]
    transforms.sort(key=lambda t: t.stamp_ns)
    return LogData(
        source=source,
        odometry=tuple(odometry),
        headings=tuple(headings),
        scans=tuple(scans),
        images=tuple(images),
        camera_infos=tuple(infos),
        transforms=tuple(transforms),
        tags=tuple(tags),
        ground_truth=tuple(ground_truth),
        world_json=world_to_json(run.world),
    )
