"""Frozen records that cross holoslam's layer boundaries.

Every record carries its time as ``stamp_ns`` (int nanoseconds of the log's sensor time) and names the frame
its data live in. Poses follow GTSAM notation: ``aTb`` is the pose of frame b in frame a. Planar poses are
(x, y, theta) with theta in radians wrapped to [-pi, pi); batches of them are (N, 3) float64 arrays.
Covariances are named after their mean (``cov_aTb``) and are 3x3 in (x, y, theta) order, in the pose's own
frame (GTSAM's right-perturbation convention). Standard deviations are called sigmas.

This module depends on numpy alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

__all__ = [
    "Pose2",
    "Odometry",
    "Heading",
    "Scan",
    "Image",
    "CameraInfo",
    "Transform",
    "TagSighting",
    "GroundTruthPose",
    "GroundTruthWorld",
    "ObjectObservation",
    "LogData",
    "Record",
    "Role",
]


class Role(str, Enum):
    """What a channel of a log is used for. Ingestion assigns one role per channel."""

    ODOMETRY = "odometry"
    HEADING = "heading"  # digital compass / IMU orientation, absolute yaw
    SCAN = "scan"
    IMAGE = "image"
    CAMERA_INFO = "camera_info"
    TF = "tf"
    TF_STATIC = "tf_static"
    TAGS = "tags"  # QR sightings already decoded on the robot
    GROUND_TRUTH = "ground_truth"  # true robot pose
    GROUND_TRUTH_WORLD = "ground_truth_world"  # floor plan and object positions of a simulated world
    IGNORED = "ignored"


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True)
class Pose2:
    """A planar pose (x, y, theta); theta is wrapped to [-pi, pi) on construction."""

    x: float
    y: float
    theta: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", (self.theta + math.pi) % (2.0 * math.pi) - math.pi)

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    @classmethod
    def from_array(cls, a: np.ndarray) -> Pose2:
        return cls(float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True, slots=True)
class Odometry:
    """Wheel odometry: the base pose in the odometry frame (``odomTb``) at ``stamp_ns``.

    ``cov_odomTb`` is None when the log carried no usable covariance (all zeros); ``speed`` is the forward
    speed in m/s when the message had a twist, else NaN.
    """

    stamp_ns: int
    odomTb: Pose2
    cov_odomTb: np.ndarray | None = None
    speed: float = math.nan
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


@dataclass(frozen=True, slots=True)
class Heading:
    """An absolute heading (yaw of the base in the compass's world frame, radians) from a digital compass
    or an IMU orientation, with its sigma (radians; NaN when the log did not say)."""

    stamp_ns: int
    yaw: float
    sigma: float = math.nan
    frame_id: str = "base_link"


@dataclass(frozen=True, slots=True)
class Scan:
    """A planar laser scan in ``frame_id``. ``ranges`` is float32 (N,), ``valid`` marks usable beams
    (finite and within [range_min, range_max]). Beam i points at angle_min + i * angle_increment."""

    stamp_ns: int
    frame_id: str
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    valid: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "ranges", _readonly(np.asarray(self.ranges, dtype=np.float32)))
        object.__setattr__(self, "valid", _readonly(np.asarray(self.valid, dtype=bool)))

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[0], dtype=np.float64)

    def points(self) -> np.ndarray:
        """Valid beam end points in the sensor frame, (M, 2) float64."""
        a = self.angles[self.valid]
        r = self.ranges[self.valid].astype(np.float64)
        return np.column_stack([r * np.cos(a), r * np.sin(a)])


@dataclass(frozen=True, slots=True)
class Image:
    """A camera image, kept encoded until asked for. ``encoding`` is a CompressedImage format ('jpeg',
    'png') or a raw sensor_msgs/Image encoding ('mono8', 'bgr8', 'rgb8', ...)."""

    stamp_ns: int
    frame_id: str
    encoding: str
    data: bytes
    width: int = 0
    height: int = 0
    step: int = 0
    _decoder: Callable[[Image], np.ndarray] | None = field(default=None, repr=False, compare=False)

    def decode(self) -> np.ndarray:
        """The pixels as a numpy array (H, W) gray or (H, W, 3) BGR. Raises ``ImageDecodeError``."""
        if self._decoder is None:
            from holoslam.io.images import decode_image

            return decode_image(self)
        return self._decoder(self)


@dataclass(frozen=True, slots=True)
class CameraInfo:
    """Pinhole intrinsics ``K`` (3x3) and distortion ``D`` (plumb_bob / rational_polynomial coefficients)."""

    stamp_ns: int
    frame_id: str
    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    distortion_model: str = "plumb_bob"

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", _readonly(np.asarray(self.K, dtype=np.float64).reshape(3, 3)))
        object.__setattr__(self, "D", _readonly(np.asarray(self.D, dtype=np.float64).ravel()))


@dataclass(frozen=True, slots=True)
class Transform:
    """A 3D rigid transform ``parentTchild``: translation (x, y, z) and rotation quaternion (x, y, z, w)."""

    stamp_ns: int
    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]
    static: bool = False

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix of parentTchild."""
        x, y, z, w = self.rotation_xyzw
        n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
        x, y, z, w = x / n, y / n, z / n, w / n
        R = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = self.translation
        return T


@dataclass(frozen=True, slots=True)
class TagSighting:
    """One QR label seen in one image: its raw payload text and its four corners in pixels, (4, 2) float64,
    in the code's own order (top-left, top-right, bottom-right, bottom-left of the printed code)."""

    stamp_ns: int
    frame_id: str
    payload: str
    corners: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "corners", _readonly(np.asarray(self.corners, dtype=np.float64).reshape(4, 2))
        )


@dataclass(frozen=True, slots=True)
class GroundTruthPose:
    """The true pose of the base in the world frame (``wTb``) at ``stamp_ns``; z is kept for 3D logs."""

    stamp_ns: int
    wTb: Pose2
    z: float = 0.0
    frame_id: str = "map"


@dataclass(frozen=True, slots=True)
class GroundTruthWorld:
    """A simulated world's description as carried in its log (JSON text, see ``holoslam.sim.world``)."""

    stamp_ns: int
    json_text: str


@dataclass(frozen=True, slots=True)
class ObjectObservation:
    """A QR-tagged object located from one image (or a pair): the label centre in the base frame at
    ``stamp_ns`` (``b_position`` (3,) metres) with its covariance ``cov_b_position`` (3x3), produced by the
    vision layer for the backend's landmark factors (Eq. 16). ``payload`` is the decoded label text.
    ``b_normal`` (3,) is the label's outward normal (unit, out of its printed face) in the base frame, from the
    pose of its corners (None when unknown), with the standard deviation of its direction ``normal_sigma_rad``."""

    stamp_ns: int
    object_id: str
    payload: str
    b_position: np.ndarray
    cov_b_position: np.ndarray
    method: str = "pnp"  # "pnp" (single view, known label size) or "triangulation" (two views)
    source: str = ""  # where the sighting came from: "images" (decoded here), "tags" (the robot's topic)
    b_normal: np.ndarray | None = None
    normal_sigma_rad: float = float("nan")

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "b_position", _readonly(np.asarray(self.b_position, dtype=np.float64).reshape(3))
        )
        object.__setattr__(
            self, "cov_b_position", _readonly(np.asarray(self.cov_b_position, dtype=np.float64).reshape(3, 3))
        )
        if self.b_normal is not None:
            n = np.asarray(self.b_normal, dtype=np.float64).reshape(3)
            object.__setattr__(self, "b_normal", _readonly(n / max(float(np.linalg.norm(n)), 1e-12)))


Record = (
    Odometry
    | Heading
    | Scan
    | Image
    | CameraInfo
    | Transform
    | TagSighting
    | GroundTruthPose
    | GroundTruthWorld
)


@dataclass(frozen=True, slots=True)
class LogData:
    """Every record of one log, grouped by kind and sorted by ``stamp_ns`` (what ingestion returns).

    The ``*_arrays`` helpers give the numeric streams as numpy arrays for the algorithms.
    """

    source: str
    odometry: tuple[Odometry, ...] = ()
    headings: tuple[Heading, ...] = ()
    scans: tuple[Scan, ...] = ()
    images: tuple[Image, ...] = ()
    camera_infos: tuple[CameraInfo, ...] = ()
    transforms: tuple[Transform, ...] = ()
    tags: tuple[TagSighting, ...] = ()
    ground_truth: tuple[GroundTruthPose, ...] = ()
    world_json: str | None = None
    # the robot's base frame: the mapping's frames.base, else the odometry's child frame (set by ingestion)
    base_frame: str = "base_link"

    def odometry_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(stamps_ns (N,) int64, odomTb (N, 3) float64)."""
        stamps = np.fromiter((o.stamp_ns for o in self.odometry), dtype=np.int64, count=len(self.odometry))
        poses = np.array([(o.odomTb.x, o.odomTb.y, o.odomTb.theta) for o in self.odometry], dtype=np.float64)
        return stamps, poses.reshape(-1, 3)

    def heading_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(stamps_ns (N,) int64, yaw (N,) float64, sigma (N,) float64, NaN where unknown)."""
        h = self.headings
        return (
            np.fromiter((r.stamp_ns for r in h), dtype=np.int64, count=len(h)),
            np.fromiter((r.yaw for r in h), dtype=np.float64, count=len(h)),
            np.fromiter((r.sigma for r in h), dtype=np.float64, count=len(h)),
        )

    def ground_truth_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(stamps_ns (N,) int64, wTb (N, 3) float64); empty arrays when the log has no ground truth."""
        g = self.ground_truth
        stamps = np.fromiter((r.stamp_ns for r in g), dtype=np.int64, count=len(g))
        poses = np.array([(r.wTb.x, r.wTb.y, r.wTb.theta) for r in g], dtype=np.float64)
        return stamps, poses.reshape(-1, 3)
