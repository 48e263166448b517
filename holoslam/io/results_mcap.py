"""A run's results as an MCAP of Foxglove protobuf schemas, to open beside the input log in Foxglove.

Topics (all in frame ``map``, the optimised world frame):
- ``/holoslam/trajectory``  foxglove.PosesInFrame: the optimised base trajectory (one message at the end time)
- ``/holoslam/dead_reckoning`` foxglove.PosesInFrame: dead reckoning, for comparison
- ``/holoslam/anchors``  foxglove.PosesInFrame: submap anchors
- ``/holoslam/pose``  foxglove.PoseInFrame: the optimised pose over time (one per trajectory stamp, decimated)
- ``/holoslam/map``  foxglove.Grid: the occupancy grid (uint8 cells: 0 free, 100 occupied, 255 unknown)
- ``/holoslam/objects``  foxglove.SceneUpdate: a cube and a text per object
- ``/holoslam/graph``  foxglove.SceneUpdate: line lists for topology and holographic edges
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from holoslam.frames import quaternion_from_yaw

__all__ = ["ResultsScene", "write_results_mcap"]


@dataclass(frozen=True)
class ResultsScene:
    """What the results log shows; every array is in the world frame."""

    stamps_ns: np.ndarray  # (N,) trajectory stamps
    wTb: np.ndarray  # (N, 3) optimised trajectory
    dead_reckoning_wTb: np.ndarray | None = None  # (N, 3)
    wTa: np.ndarray | None = None  # (K, 3) anchors
    grid: object | None = None  # holoslam.maps.grid.OccupancyGrid
    object_ids: Sequence[str] = ()
    w_objects: np.ndarray | None = None  # (M, 3) xyz
    edges: Sequence[tuple[str, np.ndarray]] = field(default_factory=tuple)  # (layer name, (E, 2, 2) segments)


def _timestamp(msg_ts, stamp_ns: int) -> None:
    msg_ts.seconds = int(stamp_ns // 1_000_000_000)
    msg_ts.nanos = int(stamp_ns % 1_000_000_000)


def _poses_msg(poses: np.ndarray, stamp_ns: int):
    from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame

    msg = PosesInFrame(frame_id="map")
    _timestamp(msg.timestamp, stamp_ns)
    for x, y, t in np.asarray(poses, dtype=np.float64).reshape(-1, 3):
        p = msg.poses.add()
        p.position.x, p.position.y, p.position.z = float(x), float(y), 0.0
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = quaternion_from_yaw(float(t))
    return msg


def _grid_msg(grid, stamp_ns: int):
    from foxglove_schemas_protobuf.Grid_pb2 import Grid
    from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField

    occ = np.asarray(grid.occupancy)
    cells = np.where(occ < 0, 255, np.clip(occ, 0, 100).astype(np.int16)).astype(np.uint8)  # 255: not int8
    h, w = cells.shape
    msg = Grid(frame_id="map", column_count=w, row_stride=w, cell_stride=1, data=cells.tobytes())
    _timestamp(msg.timestamp, stamp_ns)
    msg.pose.position.x, msg.pose.position.y = float(grid.origin_x), float(grid.origin_y)
    msg.pose.orientation.w = 1.0
    msg.cell_size.x = msg.cell_size.y = float(grid.resolution)
    msg.fields.append(PackedElementField(name="occupancy", offset=0, type=PackedElementField.UINT8))
    return msg


def _objects_msg(ids: Sequence[str], xyz: np.ndarray, stamp_ns: int):
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    msg = SceneUpdate()
    for oid, (x, y, z) in zip(ids, np.asarray(xyz, dtype=np.float64).reshape(-1, 3), strict=True):
        e = msg.entities.add(frame_id="map", id=f"object/{oid}")
        _timestamp(e.timestamp, stamp_ns)
        c = e.cubes.add()
        c.pose.position.x, c.pose.position.y, c.pose.position.z = x, y, z
        c.pose.orientation.w = 1.0
        c.size.x = c.size.y = c.size.z = 0.12
        c.color.r, c.color.g, c.color.b, c.color.a = 0.95, 0.45, 0.1, 0.9
        t = e.texts.add(text=str(oid), billboard=True, font_size=14.0, scale_invariant=True)
        t.pose.position.x, t.pose.position.y, t.pose.position.z = x, y, z + 0.15
        t.pose.orientation.w = 1.0
        t.color.r = t.color.g = t.color.b = t.color.a = 1.0
    return msg


def _edges_msg(edges: Sequence[tuple[str, np.ndarray]], stamp_ns: int):
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    palette = [(0.2, 0.6, 1.0), (0.2, 0.9, 0.3), (1.0, 0.3, 0.6), (0.9, 0.9, 0.2)]
    msg = SceneUpdate()
    for k, (name, segs) in enumerate(edges):
        e = msg.entities.add(frame_id="map", id=f"graph/{name}")
        _timestamp(e.timestamp, stamp_ns)
        line = e.lines.add(type=LinePrimitive.LINE_LIST, thickness=2.0, scale_invariant=True)
        line.pose.orientation.w = 1.0
        r, g, b = palette[k % len(palette)]
        line.color.r, line.color.g, line.color.b, line.color.a = r, g, b, 1.0
        for (x0, y0), (x1, y1) in np.asarray(segs, dtype=np.float64).reshape(-1, 2, 2):
            line.points.add(x=x0, y=y0, z=0.05)
            line.points.add(x=x1, y=y1, z=0.05)
    return msg


def write_results_mcap(scene: ResultsScene, path: str | Path, max_pose_messages: int = 2000) -> Path:
    """Write the scene as an MCAP of Foxglove protobuf messages; returns the path written."""
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from mcap_protobuf.writer import Writer

    path = Path(path)
    stamps = np.asarray(scene.stamps_ns, dtype=np.int64)
    t0 = int(stamps[0]) if stamps.size else 0
    t1 = int(stamps[-1]) if stamps.size else 0
    with path.open("wb") as f:
        w = Writer(f)
        step = max(1, int(math.ceil(stamps.size / max_pose_messages)))
        for s, (x, y, t) in zip(stamps[::step], np.asarray(scene.wTb)[::step], strict=True):
            msg = PoseInFrame(frame_id="map")
            _timestamp(msg.timestamp, int(s))
            msg.pose.position.x, msg.pose.position.y = float(x), float(y)
            (
                msg.pose.orientation.x,
                msg.pose.orientation.y,
                msg.pose.orientation.z,
                msg.pose.orientation.w,
            ) = quaternion_from_yaw(float(t))
            w.write_message("/holoslam/pose", msg, log_time=int(s), publish_time=int(s))
        w.write_message("/holoslam/trajectory", _poses_msg(scene.wTb, t1), log_time=t1, publish_time=t1)
        if scene.dead_reckoning_wTb is not None:
            msg = _poses_msg(scene.dead_reckoning_wTb, t1)
            w.write_message("/holoslam/dead_reckoning", msg, log_time=t1, publish_time=t1)
        if scene.wTa is not None:
            w.write_message("/holoslam/anchors", _poses_msg(scene.wTa, t1), log_time=t1, publish_time=t1)
        if scene.grid is not None:
            w.write_message("/holoslam/map", _grid_msg(scene.grid, t0), log_time=t0, publish_time=t0)
        if scene.w_objects is not None and len(scene.object_ids):
            msg = _objects_msg(scene.object_ids, scene.w_objects, t1)
            w.write_message("/holoslam/objects", msg, log_time=t1, publish_time=t1)
        if scene.edges:
            w.write_message("/holoslam/graph", _edges_msg(scene.edges, t1), log_time=t1, publish_time=t1)
        w.finish()
    return path
