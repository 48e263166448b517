"""ROS 2 message definitions (``ros2msg`` schema texts) for the types holoslam writes and tests with.

``msgdef(name)`` returns the text an MCAP ``ros2msg`` schema carries: the type's own definition, then each
dependency (depth first, each once) after a line of 80 ``=`` and a ``MSG: pkg/Type`` line, exactly as
rosbag2 writes them. Field lists follow the ROS 2 Humble/Jazzy definitions (comments dropped, constants
and default values kept where the originals have them). This module is plain data: no ROS needed.
"""

from __future__ import annotations

import re

__all__ = ["msgdef", "MSG_TYPES", "dependencies"]

_BASE: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/PoseWithCovarianceStamped": "std_msgs/Header header\nPoseWithCovariance pose\n",
    "geometry_msgs/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n"
    ),
    "sensor_msgs/Imu": (
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n"
        "geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n"
        "geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n"
    ),
    "sensor_msgs/MagneticField": (
        "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\nfloat64[9] magnetic_field_covariance\n"
    ),
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n"
    ),
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data\n",
    "sensor_msgs/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
        "uint32 step\nuint8[] data\n"
    ),
    "sensor_msgs/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
        "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
        "RegionOfInterest roi\n"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "holoslam_msgs/TagDetection": "string payload\nfloat64[8] corners\n",
    "holoslam_msgs/TagDetectionArray": "std_msgs/Header header\nholoslam_msgs/TagDetection[] detections\n",
}

MSG_TYPES: tuple[str, ...] = tuple(
    f"{k.split('/')[0]}/msg/{k.split('/')[1]}" for k in _BASE if not k.startswith("builtin_interfaces")
)

_PRIMITIVES = {
    "bool",
    "byte",
    "char",
    "float32",
    "float64",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "string",
    "wstring",
}


def _short(name: str) -> str:
    """'sensor_msgs/msg/Imu' or 'sensor_msgs/Imu' -> 'sensor_msgs/Imu'."""
    parts = name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return f"{parts[0]}/{parts[2]}"
    if len(parts) == 2:
        return name
    raise KeyError(f"{name!r} is not a message type name like 'pkg/msg/Type'")


def _field_types(short: str) -> list[str]:
    pkg = short.split("/")[0]
    out = []
    for line in _BASE[short].splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        t = re.sub(r"\[.*\]$", "", line.split()[0])
        if t in _PRIMITIVES or re.fullmatch(r"string<=\d+", t):
            continue
        out.append(t if "/" in t else f"{pkg}/{t}")
    return out


def dependencies(name: str) -> list[str]:
    """The message types ``name`` depends on, depth first, each once ('pkg/Type' form)."""
    seen: list[str] = []

    def visit(s: str) -> None:
        for t in _field_types(s):
            if t not in seen:
                seen.append(t)
                visit(t)

    visit(_short(name))
    return seen


def msgdef(name: str) -> str:
    """The ros2msg schema text of ``name`` ('pkg/msg/Type' or 'pkg/Type') with its dependencies."""
    short = _short(name)
    if short not in _BASE:
        raise KeyError(f"no ROS 2 definition for {name!r}; known: {', '.join(sorted(MSG_TYPES))}")
    parts = [_BASE[short]]
    for dep in dependencies(short):
        parts.append("=" * 80 + "\n" + f"MSG: {dep}\n" + _BASE[dep])
    return "".join(parts)
