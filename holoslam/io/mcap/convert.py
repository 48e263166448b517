"""Decoded messages -> holoslam records, one converter per role (``CONVERTERS``), and the per-topic
conversion state (``_Conv``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from holoslam.frames import yaw_from_quaternion
from holoslam.io.mcap.mapping import _UNIT_KIND, TopicRule
from holoslam.types import (
    CameraInfo,
    GroundTruthPose,
    GroundTruthWorld,
    Heading,
    Image,
    Odometry,
    Pose2,
    Record,
    Role,
    Scan,
    TagSighting,
    Transform,
)

MOSTLY_INVALID = 0.5  # a scan with fewer valid beams than this fraction is "mostly invalid"


def _get(obj: Any, name: str, default: Any = None) -> Any:
    if isinstance(obj, dict):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _path(obj: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        nxt = _get(obj, part, _MISSING)
        if nxt is _MISSING:
            raise KeyError(f"field '{dotted}' not in the message (no '{part}')")
        obj = nxt
    return obj


_MISSING = object()


def _time_ns(t: Any) -> int:
    """int ns from a ROS Time (sec/nanosec, ROS 1 secs/nsecs), a Foxglove timestamp (sec/nsec JSON,
    seconds/nanos protobuf), an int (ns) or a float (s)."""
    if t is None:
        return 0
    if isinstance(t, bool):
        raise TypeError("a boolean is not a time")
    if isinstance(t, int):
        return t
    if isinstance(t, float):
        return int(round(t * 1e9))
    for s, n in (("sec", "nanosec"), ("sec", "nsec"), ("seconds", "nanos"), ("secs", "nsecs")):
        sv = _get(t, s, _MISSING)
        nv = _get(t, n, _MISSING)
        if sv is not _MISSING and nv is not _MISSING:
            return int(sv) * 1_000_000_000 + int(nv or 0)
    for s in ("sec", "seconds", "secs"):
        sv = _get(t, s, _MISSING)
        if sv is not _MISSING:
            return int(sv) * 1_000_000_000
    raise TypeError(f"cannot read a time from {type(t).__name__}")


def _header_stamp(msg: Any) -> tuple[int, str]:
    h = _get(msg, "header")
    if h is not None:
        return _time_ns(_get(h, "stamp")), str(_get(h, "frame_id", "") or "")
    return _time_ns(_get(msg, "timestamp")), str(_get(msg, "frame_id", "") or "")


def _yaw(q: Any) -> float:
    return yaw_from_quaternion(
        float(_get(q, "x", 0.0)), float(_get(q, "y", 0.0)), float(_get(q, "z", 0.0)), float(_get(q, "w", 1.0))
    )


def rotate_cov_xy(cov3: np.ndarray, phi: float) -> np.ndarray:
    """``J cov3 J^T`` with J = blockdiag(R(phi), 1): the (x, y, yaw) covariance with its x/y axes rotated by
    phi. The 2x2 block uses the double-angle form, so an isotropic block stays exactly isotropic."""
    cov = np.asarray(cov3, dtype=np.float64)
    a, b, d = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[1, 1]
    m, h = 0.5 * (a + d), 0.5 * (a - d)
    c2, s2 = math.cos(2.0 * phi), math.sin(2.0 * phi)
    out = np.empty((3, 3))
    out[0, 0] = m + h * c2 - b * s2
    out[1, 1] = m - h * c2 + b * s2
    out[0, 1] = out[1, 0] = h * s2 + b * c2
    c, s = math.cos(phi), math.sin(phi)
    xt = 0.5 * (cov[:2, 2] + cov[2, :2])
    out[0, 2] = out[2, 0] = c * xt[0] - s * xt[1]
    out[1, 2] = out[2, 1] = s * xt[0] + c * xt[1]
    out[2, 2] = cov[2, 2]
    return out


def _cov36_to_body(c: Any, theta: float) -> np.ndarray | None:
    """nav_msgs/Odometry's 6x6 row-major pose covariance ``c`` is in the parent (odom) frame;
    ``Odometry.cov_odomTb`` is the (x, y, yaw) block in the body frame (GTSAM's right perturbation), i.e.
    ``rotate_cov_xy(block, -theta)``, computed here in scalar arithmetic with the same operations in the same
    order (bit-identical, without numpy indexing per message). None when all zero or not 36 numbers (unknown)."""
    if not isinstance(c, tuple):  # the generic decoders give lists or arrays; the fast CDR path a float tuple
        c = tuple(float(v) for v in c)
    if len(c) != 36 or not any(c):
        return None
    phi = -theta
    a, b, d = c[0], 0.5 * (c[1] + c[6]), c[7]
    m, h = 0.5 * (a + d), 0.5 * (a - d)
    c2, s2 = math.cos(2.0 * phi), math.sin(2.0 * phi)
    o00 = m + h * c2 - b * s2
    o11 = m - h * c2 + b * s2
    o01 = h * s2 + b * c2
    co, si = math.cos(phi), math.sin(phi)
    x0, x1 = 0.5 * (c[5] + c[30]), 0.5 * (c[11] + c[31])
    o02 = co * x0 - si * x1
    o12 = si * x0 + co * x1
    return np.array([[o00, o01, o02], [o01, o11, o12], [o02, o12, float(c[35])]], dtype=np.float64)


def _readonly_f64(values: Any, shape: tuple[int, ...]) -> np.ndarray:
    a = np.array(values, dtype=np.float64).reshape(shape)
    a.setflags(write=False)
    return a


class _Conv:
    """Per-topic conversion state and counters (shared by the report)."""

    def __init__(self, topic: str, role: Role, rule: TopicRule | None) -> None:
        self.topic = topic
        self.role = role
        self.rule = rule
        self.zero_cov = 0
        self.mostly_invalid = 0
        self.skipped = 0
        self.skip_reason = ""
        self.fields = dict(rule.fields) if rule else {}
        self.units = dict(rule.units) if rule else {}
        self.last_kd: tuple[Any, Any, np.ndarray, np.ndarray] | None = None  # CameraInfo K, D -> arrays

    def skip(self, why: str) -> None:
        self.skipped += 1
        self.skip_reason = self.skip_reason or why

    def unit(self, name: str) -> float:
        u = self.units.get(name)
        if u is None:
            return 1.0
        return _UNIT_KIND[name][u]


def _pose_from(msg: Any, kind: str) -> tuple[float, float, float, float, Any]:
    """(x, y, z, yaw, covariance36 or None) from Odometry / PoseStamped / PoseWithCovarianceStamped /
    PoseInFrame / foxglove.Odometry messages."""
    cov = None
    if kind in ("nav_msgs/Odometry", "geometry_msgs/PoseWithCovarianceStamped"):
        pwc = _get(msg, "pose")
        pose, cov = _get(pwc, "pose"), _get(pwc, "covariance")
    elif kind == "foxglove.Odometry":
        pose, cov = _get(msg, "pose"), _get(msg, "pose_covariance")
    else:
        pose = _get(msg, "pose")
    p, q = _get(pose, "position"), _get(pose, "orientation")
    return float(_get(p, "x", 0.0)), float(_get(p, "y", 0.0)), float(_get(p, "z", 0.0)), _yaw(q), cov


def _fields_pose(c: _Conv, msg: Any) -> tuple[float, float, float]:
    f = c.fields
    return (
        float(_path(msg, f["x"])) * c.unit("x"),
        float(_path(msg, f["y"])) * c.unit("y"),
        float(_path(msg, f["yaw"])) * c.unit("yaw"),
    )


def _custom_stamp(c: _Conv, msg: Any) -> tuple[int, str]:
    stamp = _time_ns(_path(msg, c.fields["stamp"])) if "stamp" in c.fields else None
    frame = str(_path(msg, c.fields["frame_id"])) if "frame_id" in c.fields else None
    try:
        s0, f0 = _header_stamp(msg)
    except (TypeError, KeyError):
        s0, f0 = 0, ""
    return (s0 if stamp is None else stamp), (f0 if frame is None else frame)


Converted = tuple[int, list[Record]]  # (message stamp ns, records)


def _speed(msg: Any) -> float:
    tw = _get(msg, "twist")
    if tw is not None:
        return float(_get(_get(_get(tw, "twist"), "linear"), "x", math.nan))
    if _get(msg, "linear_velocity") is not None:
        return float(_get(_get(msg, "linear_velocity"), "x", math.nan))
    return math.nan


def _pose_fields(
    c: _Conv, kind: str, msg: Any
) -> tuple[int, str, float, float, float, float, Any, float, str]:
    """(stamp, frame, x, y, z, yaw, covariance36 or None, speed, child frame) of an odometry or pose message:
    custom fields, the fast CDR Odometry dict, or a generic message."""
    if c.fields:
        stamp, frame = _custom_stamp(c, msg)
        x, y, th = _fields_pose(c, msg)
        return stamp, frame, x, y, 0.0, th, None, math.nan, "base_link"
    if isinstance(msg, dict) and "pose_covariance" in msg and "position" in msg:  # fast Odometry
        stamp, frame, child = msg["stamp_ns"], msg["frame_id"], msg["child_frame_id"]
        x, y, z = msg["position"]
        th = yaw_from_quaternion(*msg["orientation_xyzw"])
        return stamp, frame, x, y, z, th, msg["pose_covariance"], float(msg["linear"][0]), child
    stamp, frame = _header_stamp(msg)
    x, y, z, th, cov = _pose_from(msg, kind)
    child = str(_get(msg, "child_frame_id", "") or _get(msg, "body_frame_id", "") or "base_link")
    return stamp, frame, x, y, z, th, cov, _speed(msg), child


def _convert_pose(c: _Conv, kind: str, msg: Any) -> Converted:
    """Odometry (covariance to the body frame; all-zero counted) or ground truth."""
    stamp, frame, x, y, z, th, cov, speed, child = _pose_fields(c, kind, msg)
    if c.role is Role.GROUND_TRUTH:
        return stamp, [GroundTruthPose(stamp, Pose2(x, y, th), z=z, frame_id=frame or "map")]
    cov3 = _cov36_to_body(cov, th) if cov is not None else None
    if cov3 is None and cov is not None:
        c.zero_cov += 1
    return stamp, [Odometry(stamp, Pose2(x, y, th), cov3, speed, frame or "odom", child or "base_link")]


def _scan_fields(c: _Conv, kind: str, msg: Any) -> tuple[int, str, Any, float, float, float, float]:
    """(stamp, frame, ranges, angle_min, angle_increment, range_min, range_max) of a scan message."""
    if c.fields:
        stamp, frame = _custom_stamp(c, msg)
        f = c.fields
        ranges = np.asarray(_path(msg, f["ranges"]), dtype=np.float32) * np.float32(c.unit("ranges"))
        a0 = float(_path(msg, f["angle_min"])) * c.unit("angle_min")
        da = float(_path(msg, f["angle_increment"])) * c.unit("angle_increment")
        rmin = float(_path(msg, f["range_min"])) * c.unit("range_min") if "range_min" in f else 0.0
        rmax = float(_path(msg, f["range_max"])) * c.unit("range_max") if "range_max" in f else math.inf
        return stamp, frame, ranges, a0, da, rmin, rmax
    if kind == "foxglove.LaserScan":
        stamp, frame = _header_stamp(msg)
        ranges = np.asarray(_get(msg, "ranges"), dtype=np.float32)
        a0 = float(_get(msg, "start_angle", 0.0))
        a1 = float(_get(msg, "end_angle", 0.0))
        da = (a1 - a0) / (ranges.size - 1) if ranges.size > 1 else 0.0
        return stamp, frame, ranges, a0, da, 0.0, math.inf
    if isinstance(msg, dict) and "stamp_ns" in msg:
        stamp, frame = msg["stamp_ns"], msg["frame_id"]
        ranges = msg["ranges"]
    else:
        stamp, frame = _header_stamp(msg)
        ranges = np.asarray(_get(msg, "ranges"), dtype=np.float32)
    a0, da = float(_get(msg, "angle_min")), float(_get(msg, "angle_increment"))
    rmin, rmax = float(_get(msg, "range_min")), float(_get(msg, "range_max"))
    return stamp, frame, ranges, a0, da, rmin, rmax


def _convert_scan(c: _Conv, kind: str, msg: Any) -> Converted:
    stamp, frame, ranges, a0, da, rmin, rmax = _scan_fields(c, kind, msg)
    valid = np.isfinite(ranges) & (ranges >= rmin) & (ranges <= rmax) & (ranges > 0)
    if ranges.size and np.count_nonzero(valid) < MOSTLY_INVALID * ranges.size:
        c.mostly_invalid += 1
    return stamp, [Scan(stamp, frame, a0, da, rmin, rmax, ranges, valid)]


def _wrap(yaw: float) -> float:
    return (yaw + math.pi) % (2 * math.pi) - math.pi


def _convert_heading(c: _Conv, kind: str, msg: Any) -> Converted:
    """Custom fields, a magnetometer (level, REP-103 axes) or an IMU's orientation."""
    if c.fields:
        stamp, frame = _custom_stamp(c, msg)
        yaw = float(_path(msg, c.fields["yaw"])) * c.unit("yaw")
        sigma = float(_path(msg, c.fields["sigma"])) * c.unit("sigma") if "sigma" in c.fields else math.nan
        return stamp, [Heading(stamp, _wrap(yaw), sigma, frame or "base_link")]
    if kind == "sensor_msgs/MagneticField":
        stamp, frame = _header_stamp(msg)
        m = _get(msg, "magnetic_field")
        mx, my = float(_get(m, "x")), float(_get(m, "y"))
        if mx == 0.0 and my == 0.0:
            c.skip("magnetic field without a horizontal component")
            return stamp, []
        return stamp, [Heading(stamp, _wrap(-math.atan2(my, mx)), math.nan, frame or "base_link")]
    if isinstance(msg, dict) and "orientation_xyzw" in msg:
        stamp, frame = msg["stamp_ns"], msg["frame_id"]
        q = msg["orientation_xyzw"]
        qc = msg["orientation_covariance"]
    else:
        stamp, frame = _header_stamp(msg)
        q, qc = _get(msg, "orientation"), list(_get(msg, "orientation_covariance"))
    if qc[0] == -1.0:
        c.skip("IMU message without orientation (orientation_covariance[0] = -1)")
        return stamp, []
    var = float(qc[8])
    if var <= 0.0:
        c.zero_cov += 1
    sigma = math.sqrt(var) if var > 0.0 else math.nan
    yaw = yaw_from_quaternion(*q) if isinstance(q, tuple) else _yaw(q)
    return stamp, [Heading(stamp, yaw, sigma, frame or "base_link")]


def _convert_image(c: _Conv, kind: str, msg: Any) -> Converted:
    if isinstance(msg, dict) and "stamp_ns" in msg:
        stamp, frame = msg["stamp_ns"], msg["frame_id"]
        get: Callable[..., Any] = msg.get
    else:
        stamp, frame = _header_stamp(msg)
        get = lambda k, d=None: _get(msg, k, d)  # noqa: E731
    data = get("data")
    if isinstance(data, str):  # JSON bytes are base64
        import base64

        data = base64.b64decode(data)
    data = bytes(data)
    if kind in ("sensor_msgs/Image", "foxglove.RawImage"):
        w, h = int(get("width")), int(get("height"))
        return stamp, [
            Image(stamp, frame, str(get("encoding")), data, width=w, height=h, step=int(get("step") or 0))
        ]
    return stamp, [Image(stamp, frame, str(get("format")), data)]


def _convert_camera_info(c: _Conv, kind: str, msg: Any) -> Converted:
    if isinstance(msg, dict) and "stamp_ns" in msg:  # fast CDR path
        stamp = msg["stamp_ns"]
        k, d = msg["k"], msg["d"]
        kd = c.last_kd
        if kd is None or kd[0] != k or kd[1] != d:  # intrinsics rarely change: share read-only arrays
            kd = c.last_kd = (k, d, _readonly_f64(k, (3, 3)), _readonly_f64(d, (len(d),)))
        return stamp, [
            CameraInfo(
                stamp,
                msg["frame_id"],
                msg["width"],
                msg["height"],
                kd[2],
                kd[3],
                msg["distortion_model"] or "plumb_bob",
            )
        ]
    stamp, frame = _header_stamp(msg)
    K = _get(msg, "k", None)
    if K is None:
        K = _get(msg, "K")
    D = _get(msg, "d", None)
    if D is None:
        D = _get(msg, "D", ())
    return stamp, [
        CameraInfo(
            stamp,
            frame,
            int(_get(msg, "width")),
            int(_get(msg, "height")),
            np.asarray(K, dtype=np.float64),
            np.asarray(D, dtype=np.float64),
            str(_get(msg, "distortion_model", "") or "plumb_bob"),
        )
    ]


def _foxglove_transforms(kind: str, msg: Any, static: bool) -> list[Record]:
    items = [msg] if kind == "foxglove.FrameTransform" else list(_get(msg, "transforms"))
    out: list[Record] = []
    for tr in items:
        t, q = _get(tr, "translation"), _get(tr, "rotation")
        out.append(
            Transform(
                _time_ns(_get(tr, "timestamp")),
                str(_get(tr, "parent_frame_id")),
                str(_get(tr, "child_frame_id")),
                (float(_get(t, "x", 0.0)), float(_get(t, "y", 0.0)), float(_get(t, "z", 0.0))),
                (
                    float(_get(q, "x", 0.0)),
                    float(_get(q, "y", 0.0)),
                    float(_get(q, "z", 0.0)),
                    float(_get(q, "w", 1.0)),
                ),
                static,
            )
        )
    return out


def _ros_transforms(msg: Any, static: bool) -> list[Record]:
    out: list[Record] = []
    for ts in _get(msg, "transforms"):
        stamp, parent = _header_stamp(ts)
        tr = _get(ts, "transform")
        t, q = _get(tr, "translation"), _get(tr, "rotation")
        out.append(
            Transform(
                stamp,
                parent.lstrip("/"),
                str(_get(ts, "child_frame_id")).lstrip("/"),
                (float(_get(t, "x")), float(_get(t, "y")), float(_get(t, "z"))),
                (float(_get(q, "x")), float(_get(q, "y")), float(_get(q, "z")), float(_get(q, "w"))),
                static,
            )
        )
    return out


def _convert_tf(c: _Conv, kind: str, msg: Any) -> Converted:
    static = c.role is Role.TF_STATIC
    out: list[Record]
    if isinstance(msg, dict) and msg.get("transforms") and isinstance(msg["transforms"][0], tuple):
        out = [
            Transform(st_, p_.lstrip("/"), c_.lstrip("/"), t_, q_, static)
            for st_, p_, c_, t_, q_ in msg["transforms"]
        ]
    elif kind.startswith("foxglove."):
        out = _foxglove_transforms(kind, msg, static)
    else:
        out = _ros_transforms(msg, static)
    return (out[0].stamp_ns if out else 0), out


def _convert_tags(c: _Conv, kind: str, msg: Any) -> Converted:
    stamp, frame = _header_stamp(msg)
    return stamp, [
        TagSighting(
            stamp, frame, str(_get(d, "payload")), np.asarray(list(_get(d, "corners")), dtype=np.float64)
        )
        for d in _get(msg, "detections")
    ]


def _convert_world(c: _Conv, kind: str, msg: Any) -> Converted:
    return 0, [GroundTruthWorld(0, str(_get(msg, "data")))]


# Role -> converter: (conversion state, normalised schema name, decoded message) -> (stamp, records)
CONVERTERS: dict[Role, Callable[[_Conv, str, Any], Converted]] = {
    Role.ODOMETRY: _convert_pose,
    Role.GROUND_TRUTH: _convert_pose,
    Role.SCAN: _convert_scan,
    Role.HEADING: _convert_heading,
    Role.IMAGE: _convert_image,
    Role.CAMERA_INFO: _convert_camera_info,
    Role.TF: _convert_tf,
    Role.TF_STATIC: _convert_tf,
    Role.TAGS: _convert_tags,
    Role.GROUND_TRUTH_WORLD: _convert_world,
}


def _convert(c: _Conv, kind: str, msg: Any) -> Converted:
    """One decoded message -> (message stamp ns, records). ``msg`` is a fast-path dict, a generic ROS object,
    a protobuf message or a JSON dict."""
    convert = CONVERTERS.get(c.role)
    if convert is None:
        raise ValueError(f"role {c.role.value} has no converter for {kind}")
    return convert(c, kind, msg)
