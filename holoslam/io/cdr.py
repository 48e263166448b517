"""ROS 2 CDR decoding without ROS: a generic decoder built from the ``ros2msg`` definitions embedded in the
log (``mcap_ros2``), and fast paths for the messages holoslam reads most.

Measured (``benchmarks/bench_ingest.py``): the generic decoder walks every array element by element in
Python, so a 181-beam LaserScan costs tens of microseconds and a camera frame far more; the fast paths parse
the few header fields with ``struct`` and take arrays with ``np.frombuffer``. They handle plain CDR (XCDR1,
encapsulation kinds 0x0000 big endian and 0x0001 little endian), which is what ROS 2 writes; anything else
raises :class:`CdrFallback` and the caller uses the generic decoder instead.

CDR alignment: every primitive is aligned to its own size (8-byte types to 8 in XCDR1), measured from the end
of the 4-byte encapsulation header, i.e. from byte 4 of the message.

Every fast path returns plain Python / numpy values in a small dict whose keys follow the ROS field names;
``tests/test_ingest_cdr.py`` checks each one against the generic decoder.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "CdrFallback",
    "FAST_DECODERS",
    "decode_laser_scan",
    "decode_compressed_image",
    "decode_image",
    "decode_odometry",
    "decode_imu",
    "decode_camera_info",
    "decode_tf_message",
    "generic_decoder",
]


class CdrFallback(ValueError):
    """The message is not plain CDR (or is malformed for the fast path): use the generic decoder."""


_S_LE = {
    c: struct.Struct("<" + c) for c in ("I", "iI", "7f", "7d", "36d", "6d", "4d", "9d", "3d", "B", "12d")
}
_S_BE = {c: struct.Struct(">" + c) for c in _S_LE}


def _endian(data: bytes | memoryview) -> tuple[dict[str, struct.Struct], str]:
    if len(data) < 8 or data[0] != 0:
        raise CdrFallback("not a CDR encapsulation header")
    kind = data[1]
    if kind == 1:
        return _S_LE, "<"
    if kind == 0:
        return _S_BE, ">"
    raise CdrFallback(f"CDR encapsulation kind 0x{kind:02x} (only plain CDR 0x00/0x01 has a fast path)")


def _align(pos: int, n: int) -> int:
    r = (pos - 4) % n
    return pos if r == 0 else pos + n - r


_STRINGS: dict[bytes, str] = {}


def _string(s: dict[str, struct.Struct], data: bytes | memoryview, pos: int) -> tuple[str, int]:
    r = (pos - 4) & 3
    if r:
        pos += 4 - r
    (n,) = s["I"].unpack_from(data, pos)
    pos += 4
    end = pos + n
    if end > len(data):
        raise CdrFallback("string runs past the end of the message")
    # n counts the terminating NUL; frame ids repeat, so decoded strings are interned in a small cache
    raw = bytes(data[pos : end - 1 if n else end])
    text = _STRINGS.get(raw)
    if text is None:
        text = raw.decode("utf-8")
        if len(_STRINGS) < 4096:
            _STRINGS[raw] = text
    return text, end


def _header(s: dict[str, struct.Struct], data: bytes | memoryview) -> tuple[int, str, int]:
    sec, nsec = s["iI"].unpack_from(data, 4)
    frame_id, pos = _string(s, data, 12)
    return sec * 1_000_000_000 + nsec, frame_id, pos


def _f32_array(
    s: dict[str, struct.Struct], e: str, data: bytes | memoryview, pos: int
) -> tuple[np.ndarray, int]:
    pos = _align(pos, 4)
    (n,) = s["I"].unpack_from(data, pos)
    pos += 4
    end = pos + 4 * n
    if end > len(data):
        raise CdrFallback("float32 array runs past the end of the message")
    a = np.frombuffer(data, dtype=e + "f4", count=n, offset=pos).astype(np.float32)  # copy, native order
    return a, end


def _u8_array(s: dict[str, struct.Struct], data: bytes | memoryview, pos: int) -> tuple[bytes, int]:
    pos = _align(pos, 4)
    (n,) = s["I"].unpack_from(data, pos)
    pos += 4
    end = pos + n
    if end > len(data):
        raise CdrFallback("byte array runs past the end of the message")
    return bytes(data[pos:end]), end


def decode_laser_scan(data: bytes | memoryview) -> dict[str, Any]:
    """sensor_msgs/msg/LaserScan -> dict(stamp_ns, frame_id, angle_min, angle_max, angle_increment,
    time_increment, scan_time, range_min, range_max, ranges float32 (N,), intensities float32 (M,))."""
    s, e = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    pos = _align(pos, 4)
    f = s["7f"].unpack_from(data, pos)
    ranges, pos = _f32_array(s, e, data, pos + 28)
    intensities, pos = _f32_array(s, e, data, pos)
    return {
        "stamp_ns": stamp,
        "frame_id": frame_id,
        "angle_min": f[0],
        "angle_max": f[1],
        "angle_increment": f[2],
        "time_increment": f[3],
        "scan_time": f[4],
        "range_min": f[5],
        "range_max": f[6],
        "ranges": ranges,
        "intensities": intensities,
    }


def decode_compressed_image(data: bytes | memoryview) -> dict[str, Any]:
    """sensor_msgs/msg/CompressedImage -> dict(stamp_ns, frame_id, format, data bytes)."""
    s, _ = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    fmt, pos = _string(s, data, pos)
    payload, pos = _u8_array(s, data, pos)
    return {"stamp_ns": stamp, "frame_id": frame_id, "format": fmt, "data": payload}


def decode_image(data: bytes | memoryview) -> dict[str, Any]:
    """sensor_msgs/msg/Image -> dict(stamp_ns, frame_id, height, width, encoding, is_bigendian, step, data)."""
    s, _ = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    pos = _align(pos, 4)
    (height,) = s["I"].unpack_from(data, pos)
    (width,) = s["I"].unpack_from(data, pos + 4)
    encoding, pos = _string(s, data, pos + 8)
    (is_bigendian,) = s["B"].unpack_from(data, pos)
    pos = _align(pos + 1, 4)
    (step,) = s["I"].unpack_from(data, pos)
    payload, pos = _u8_array(s, data, pos + 4)
    return {
        "stamp_ns": stamp,
        "frame_id": frame_id,
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": is_bigendian,
        "step": step,
        "data": payload,
    }


def decode_odometry(data: bytes | memoryview) -> dict[str, Any]:
    """nav_msgs/msg/Odometry -> dict(stamp_ns, frame_id, child_frame_id, position (3,), orientation_xyzw (4,),
    pose_covariance (36,), linear (3,), angular (3,), twist_covariance (36,))."""
    s, _ = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    child, pos = _string(s, data, pos)
    pos = _align(pos, 8)
    pose = s["7d"].unpack_from(data, pos)
    pos += 56
    pcov = s["36d"].unpack_from(data, pos)
    pos += 288
    twist = s["6d"].unpack_from(data, pos)
    pos += 48
    tcov = s["36d"].unpack_from(data, pos)
    return {
        "stamp_ns": stamp,
        "frame_id": frame_id,
        "child_frame_id": child,
        "position": pose[:3],
        "orientation_xyzw": pose[3:],
        "pose_covariance": pcov,
        "linear": twist[:3],
        "angular": twist[3:],
        "twist_covariance": tcov,
    }


def decode_imu(data: bytes | memoryview) -> dict[str, Any]:
    """sensor_msgs/msg/Imu -> dict(stamp_ns, frame_id, orientation_xyzw, orientation_covariance (9,),
    angular_velocity, angular_velocity_covariance, linear_acceleration, linear_acceleration_covariance)."""
    s, _ = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    pos = _align(pos, 8)
    q = s["4d"].unpack_from(data, pos)
    qc = s["9d"].unpack_from(data, pos + 32)
    av = s["3d"].unpack_from(data, pos + 104)
    avc = s["9d"].unpack_from(data, pos + 128)
    la = s["3d"].unpack_from(data, pos + 200)
    lac = s["9d"].unpack_from(data, pos + 224)
    return {
        "stamp_ns": stamp,
        "frame_id": frame_id,
        "orientation_xyzw": q,
        "orientation_covariance": qc,
        "angular_velocity": av,
        "angular_velocity_covariance": avc,
        "linear_acceleration": la,
        "linear_acceleration_covariance": lac,
    }


def decode_camera_info(data: bytes | memoryview) -> dict[str, Any]:
    """sensor_msgs/msg/CameraInfo -> dict(stamp_ns, frame_id, height, width, distortion_model, d (N,), k (9,),
    r (9,), p (12,))."""
    s, e = _endian(data)
    stamp, frame_id, pos = _header(s, data)
    pos = _align(pos, 4)
    (height,) = s["I"].unpack_from(data, pos)
    (width,) = s["I"].unpack_from(data, pos + 4)
    model, pos = _string(s, data, pos + 8)
    pos = _align(pos, 4)
    (nd,) = s["I"].unpack_from(data, pos)
    pos = _align(pos + 4, 8)
    if pos + 8 * (nd + 30) > len(data):
        raise CdrFallback("CameraInfo runs past the end of the message")
    d = struct.unpack_from(f"{e}{nd}d", data, pos)
    pos += 8 * nd
    k = s["9d"].unpack_from(data, pos)
    r = s["9d"].unpack_from(data, pos + 72)
    p = struct.unpack_from(f"{e}12d", data, pos + 144)
    return {
        "stamp_ns": stamp,
        "frame_id": frame_id,
        "height": height,
        "width": width,
        "distortion_model": model,
        "d": d,
        "k": k,
        "r": r,
        "p": p,
    }


def decode_tf_message(data: bytes | memoryview) -> dict[str, Any]:
    """tf2_msgs/msg/TFMessage -> dict(transforms=[(stamp_ns, parent, child, (x, y, z), (qx, qy, qz, qw)), ...])."""
    s, _ = _endian(data)
    (n,) = s["I"].unpack_from(data, 4)
    pos = 8
    out = []
    for _ in range(n):
        pos = _align(pos, 4)
        sec, nsec = s["iI"].unpack_from(data, pos)
        parent, pos = _string(s, data, pos + 8)
        child, pos = _string(s, data, pos)
        pos = _align(pos, 8)
        v = s["7d"].unpack_from(data, pos)
        pos += 56
        out.append((sec * 1_000_000_000 + nsec, parent, child, v[:3], v[3:]))
    return {"transforms": out}


# keyed by the normalised schema name (package/Type)
FAST_DECODERS: dict[str, Callable[[bytes | memoryview], dict[str, Any]]] = {
    "sensor_msgs/LaserScan": decode_laser_scan,
    "sensor_msgs/CompressedImage": decode_compressed_image,
    "sensor_msgs/Image": decode_image,
    "nav_msgs/Odometry": decode_odometry,
    "sensor_msgs/Imu": decode_imu,
    "sensor_msgs/CameraInfo": decode_camera_info,
    "tf2_msgs/TFMessage": decode_tf_message,
}


def generic_decoder(schema_name: str, schema_text: str) -> Callable[[bytes], Any]:
    """The element-by-element decoder ``mcap_ros2`` builds from a ``ros2msg`` definition.

    Raises ValueError (with the parser's reason) when the definition does not parse.
    """
    from mcap_ros2._dynamic import generate_dynamic

    try:
        types = generate_dynamic(schema_name, schema_text)
    except Exception as exc:  # the vendored parser raises assorted exception types
        raise ValueError(f"the ros2msg definition of {schema_name} does not parse: {exc}") from exc
    if schema_name not in types:
        raise ValueError(f"the ros2msg definition embedded for {schema_name} does not define {schema_name}")
    return types[schema_name]
