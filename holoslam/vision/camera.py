"""Camera geometry (seed 002, Eq. 6-9): pinhole intrinsics with distortion, and the camera chains from the
robot base frame as composable 4x4 homogeneous transforms.

Conventions. A 4x4 ``aTb`` is the pose of frame b in frame a (maps b coordinates to a coordinates:
``p_a = aTb @ p_b``), so chains compose left to right: ``bTc = bTe @ eTc``. Camera frames are ROS *optical*
frames: z forward (along the optical axis), x right, y down in the image. Body-style frames (base, PTZ mount,
arm links) are x forward, y left, z up. Eq. 6's extrinsic matrix ``[R t]`` maps robot points into the camera,
i.e. it is ``cTb = inv(bTc)``: ``lambda m = K [I 0] cTb X_b``.

Eq. 7 (hand-eye camera): ``bTc = bTe @ eTc`` with ``bTe`` the arm base -> end-effector transform read from the
arm controller and ``eTc`` the hand-eye calibration (``hand_eye_chain``).

Eq. 8-9 (PTZ camera): ``bTc = bTm @ mTh(pan, tilt) @ hTc`` with ``bTm`` the fixed base -> pan-tilt mount
transform (calibrated), ``mTh`` a rotation by pan about the mount's vertical axis (z) followed by tilt about
the rotated horizontal axis (y), both through the optical centre (t_b = 0), and ``hTc`` the fixed body ->
optical rotation (``ptz_chain``). Positive pan turns left, positive tilt looks down.

The printed Eq. 8a is garbled by the scan (its (3, 1) entry reads ``-sin p cos p``; that matrix is not
orthonormal). Written for a mount frame with a vertical y axis, as the paper does, the matrix is the product
of the two axis rotations ``Rx(-tilt) @ Ry(pan)``, whose (3, 1) entry is ``-sin p cos T``: ``eq8_rotation``
builds it that way and ``check_rotation`` rejects the printed one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam.errors import VisionError
from holoslam.types import CameraInfo

__all__ = [
    "PinholeCamera",
    "OPTICAL_IN_BODY",
    "rot_x",
    "rot_y",
    "rot_z",
    "check_rotation",
    "make_transform",
    "invert_transform",
    "compose_transforms",
    "hand_eye_chain",
    "ptz_rotation",
    "ptz_chain",
    "eq8_rotation",
    "projection_matrix",
    "pinhole_pixels",
]

# The optical frame's axes written in its body-style frame: x_opt = -y_body, y_opt = -z_body, z_opt = x_body.
OPTICAL_IN_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def check_rotation(R: np.ndarray, what: str = "rotation", tol: float = 1e-6) -> np.ndarray:
    """Return ``R`` as a (3, 3) float64 array if it is a proper rotation (``R^T R = I`` and det +1 within
    ``tol``), else raise ``VisionError`` saying how far off it is."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise VisionError(f"{what}: expected a finite 3x3 rotation matrix, got shape {R.shape}")
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if err > tol or abs(det - 1.0) > tol:
        raise VisionError(
            f"{what} is not orthonormal (max |R^T R - I| = {err:.3g}, det = {det:.6f}); "
            "rebuild it from axis rotations or re-orthonormalise the calibration"
        )
    return R


def make_transform(
    R: np.ndarray, t: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0), what: str = "transform"
) -> np.ndarray:
    """The 4x4 ``[R t; 0 1]`` after checking that ``R`` is a rotation."""
    T = np.eye(4)
    T[:3, :3] = check_rotation(R, what)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def _check_T(T: np.ndarray, what: str) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.allclose(T[3], (0, 0, 0, 1)):
        raise VisionError(f"{what}: expected a 4x4 homogeneous transform with last row (0 0 0 1)")
    check_rotation(T[:3, :3], what)
    return T


def invert_transform(aTb: np.ndarray) -> np.ndarray:
    """``bTa`` from ``aTb``."""
    T = _check_T(aTb, "transform to invert")
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def compose_transforms(*Ts: np.ndarray) -> np.ndarray:
    """``T1 @ T2 @ ...`` after checking each is a rigid transform (``aTb @ bTc = aTc``)."""
    out = np.eye(4)
    for i, T in enumerate(Ts):
        out = out @ _check_T(T, f"transform {i} of the chain")
    return out


def hand_eye_chain(bTe: np.ndarray, eTc: np.ndarray) -> np.ndarray:
    """Eq. 7: the hand-eye camera's pose in the base frame, ``bTc = bTe @ eTc`` (arm base -> end effector read
    from the arm, end effector -> camera from hand-eye calibration). Both are checked for orthonormality."""
    return compose_transforms(
        _check_T(bTe, "arm base -> end effector (Eq. 7 [R1 t1])"),
        _check_T(eTc, "hand-eye calibration (Eq. 7 [Ra ta])"),
    )


def ptz_rotation(pan: float, tilt: float) -> np.ndarray:
    """The head rotation in the mount frame (body-style, z up): pan about z, then tilt about the rotated y
    axis: ``Rz(pan) @ Ry(tilt)``."""
    return rot_z(pan) @ rot_y(tilt)


def ptz_chain(bTm: np.ndarray, pan: float, tilt: float, optical: bool = True) -> np.ndarray:
    """Eq. 8-9: the PTZ camera's pose in the base frame, ``bTc = bTm @ [Rz(pan) Ry(tilt), 0] @ hTc``, the pan
    and tilt turning about the optical centre (t_b = 0). With ``optical`` the result is the ROS optical frame
    (z forward, x right, y down), else the body-style head frame."""
    T = compose_transforms(
        _check_T(bTm, "base -> PTZ mount (Eq. 9 [R2 t2])"), make_transform(ptz_rotation(pan, tilt))
    )
    if optical:
        T = T @ make_transform(OPTICAL_IN_BODY)
    return T


def eq8_rotation(pan: float, tilt: float) -> np.ndarray:
    """Eq. 8a as printed, corrected: in a mount frame with y vertical, ``Rx(-tilt) @ Ry(pan)``::

    [ cos p          0        sin p        ]
    [ -sin p sin T   cos T    cos p sin T  ]
    [ -sin p cos T   -sin T   cos p cos T  ]
    """
    return check_rotation(rot_x(-tilt) @ rot_y(pan), "Eq. 8a rotation")


def pinhole_pixels(K: np.ndarray, c_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) and depths z (N,) of points (N, 3) in the optical frame through the undistorted pinhole
    ``K`` (skew included). No checks: a point at or behind the camera (z <= 0) gets a meaningless pixel, which
    the caller masks by z (a renderer clips with it; ``PinholeCamera.project`` refuses such points)."""
    p = np.asarray(c_points, dtype=np.float64).reshape(-1, 3)
    K = np.asarray(K, dtype=np.float64)
    z = p[:, 2]
    x, y = p[:, 0] / z, p[:, 1] / z
    return np.column_stack([x * K[0, 0] + y * K[0, 1] + K[0, 2], y * K[1, 1] + K[1, 2]]), z


def projection_matrix(K: np.ndarray, cTx: np.ndarray) -> np.ndarray:
    """Eq. 6: the 3x4 ``[K 0] cTx`` that maps homogeneous points of frame x to homogeneous pixels."""
    return np.asarray(K, np.float64) @ _check_T(cTx, "camera extrinsics (Eq. 6 [R t])")[:3, :]


@dataclass(frozen=True, slots=True)
class PinholeCamera:
    """A pinhole camera: ``K`` (3x3), distortion ``D`` (OpenCV order k1 k2 p1 p2 [k3 ...]; plumb_bob and
    rational_polynomial), image size. Pixel centres are at integer coordinates (OpenCV)."""

    K: np.ndarray
    D: np.ndarray
    width: int = 0
    height: int = 0
    frame_id: str = "camera_optical"

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        if not (K[0, 0] > 0 and K[1, 1] > 0 and np.isfinite(K).all()):
            raise VisionError(
                f"camera {self.frame_id!r}: intrinsics K must have positive fx, fy (got {K.ravel()})"
            )
        D = np.asarray(self.D, dtype=np.float64).ravel()
        if D.size not in (0, 4, 5, 8, 12, 14):
            raise VisionError(
                f"camera {self.frame_id!r}: {D.size} distortion coefficients; OpenCV takes 4, 5, 8, 12 or 14"
            )
        for name, a in (("K", K), ("D", D)):
            a = np.ascontiguousarray(a)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @classmethod
    def from_camera_info(cls, info: CameraInfo) -> PinholeCamera:
        model = (info.distortion_model or "plumb_bob").lower()
        if model not in ("plumb_bob", "rational_polynomial", "", "none"):
            raise VisionError(
                f"camera {info.frame_id!r}: distortion model {info.distortion_model!r} is not "
                "supported (plumb_bob, rational_polynomial)"
            )
        D = info.D if np.any(info.D) else np.zeros(0)
        return cls(info.K, D, info.width, info.height, info.frame_id)

    @property
    def has_distortion(self) -> bool:
        return bool(self.D.size and np.any(self.D))

    def project(self, c_points: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of points (N, 3) in the optical frame; raises ``VisionError`` for points at or behind
        the camera (z <= 0)."""
        import cv2

        p = np.asarray(c_points, dtype=np.float64).reshape(-1, 3)
        if np.any(p[:, 2] <= 0):
            raise VisionError(
                f"camera {self.frame_id!r}: {int(np.sum(p[:, 2] <= 0))} point(s) at or behind the camera"
            )
        if not self.has_distortion:
            return pinhole_pixels(self.K, p)[0]
        out, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), self.K, self.D)
        return out.reshape(-1, 2)

    def normalized(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalised image coordinates (N, 2) (x/z, y/z) of pixels (N, 2)."""
        import cv2

        px = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if not self.has_distortion:
            x = (px.reshape(-1, 2) - self.K[:2, 2]) / np.array([self.K[0, 0], self.K[1, 1]])
            x[:, 0] -= self.K[0, 1] / self.K[0, 0] * x[:, 1]
            return x
        return cv2.undistortPoints(px, self.K, self.D).reshape(-1, 2)

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """Unit rays (N, 3) in the optical frame through pixels (N, 2)."""
        x = self.normalized(pixels)
        r = np.column_stack([x, np.ones(len(x))])
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    def undistort_points(self, pixels: np.ndarray) -> np.ndarray:
        """The pixels (N, 2) an ideal (distortion-free) camera with the same K would see."""
        x = self.normalized(pixels)
        uv = np.column_stack([x, np.ones(len(x))]) @ self.K.T
        return uv[:, :2]
