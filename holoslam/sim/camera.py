"""The simulated robot's pan-tilt-zoom camera and its labels: the mount, the pinhole model, the optical frame's
rotation (Eq. 8-9 of seed 002), a label's corners and its QR modules. Shared by the snapshot logic
(``holoslam.sim.sensors``) and the renderers (``holoslam.sim.render``, ``holoslam.sim.stream_render``)."""

from __future__ import annotations

import math

import numpy as np

from holoslam.vision.camera import OPTICAL_IN_BODY, pinhole_pixels, ptz_rotation

__all__ = ["PTZ_MOUNT", "F0", "IMAGE_SIZE", "LABEL_MARGIN_MODULES", "qr_modules", "optical_rotation",
           "camera_pose_world", "intrinsics", "label_corners_world", "project"]

PTZ_MOUNT = (0.05, 0.0, 1.10)  # bTptz: x, y, z (axes of the base)
F0 = 525.0  # px, focal length at zoom 1 for a 640 px wide image
IMAGE_SIZE = (640, 480)
LABEL_MARGIN_MODULES = 2  # white quiet zone printed around the code, in modules


def qr_modules(payload: str, error: str = "m", boost_error: bool = False) -> np.ndarray:
    """The QR code's dark modules (n, n) bool for ``payload`` (segno, a full-size code at error level
    ``error``, raised when the version has room for more with ``boost_error``; no quiet zone)."""
    import segno

    q = segno.make_qr(payload, error=error, boost_error=boost_error)
    return np.asarray(q.matrix, dtype=bool)


def optical_rotation(pan: float, tilt_up: float) -> np.ndarray:
    """ptzRc: the camera_optical frame (z forward, x right, y down) in the ptz_base frame (x forward, y left,
    z up) of the simulated head, whose tilt is positive *up*: ``holoslam.vision.camera.ptz_rotation`` (the
    head's body rotation, tilt about +y, i.e. positive down) at -tilt_up, then the optical axes (Eq. 8-9,
    seed 002, t_b = 0)."""
    return ptz_rotation(pan, -tilt_up) @ OPTICAL_IN_BODY


def camera_pose_world(wTb: np.ndarray, pan: float, tilt: float) -> tuple[np.ndarray, np.ndarray]:
    """(wRc (3, 3), wtc (3,)) of the camera_optical frame for a base pose (3,)."""
    x, y, th = wTb
    c, s = math.cos(th), math.sin(th)
    wRb = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    wtc = np.array(
        [x + c * PTZ_MOUNT[0] - s * PTZ_MOUNT[1], y + s * PTZ_MOUNT[0] + c * PTZ_MOUNT[1], PTZ_MOUNT[2]]
    )
    return wRb @ optical_rotation(pan, tilt), wtc


def intrinsics(zoom: float, size: tuple[int, int] = IMAGE_SIZE) -> np.ndarray:
    """K at a zoom factor: f = F0 * zoom * width / 640, principal point near the image centre."""
    w, h = size
    f = F0 * zoom * w / 640.0
    return np.array([[f, 0, w / 2 - 0.5 + 1.3], [0, f, h / 2 - 0.5 - 0.8], [0, 0, 1.0]])


def label_corners_world(obj, margin_modules: float = 0.0, n_modules: int = 29) -> np.ndarray:
    """The four corners (TL, TR, BR, BL as seen facing the label) of the code (plus a margin in modules),
    (4, 3) in map."""
    n = np.array([math.cos(obj.label_yaw), math.sin(obj.label_yaw), 0.0])
    u = np.cross(-n, [0.0, 0.0, 1.0])  # right, for a viewer facing the label
    v = np.array([0.0, 0.0, -1.0])  # down
    h = obj.label_size / 2 * (1 + 2 * margin_modules / n_modules)
    c = np.asarray(obj.position, dtype=np.float64)
    return np.stack([c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v])


def project(K: np.ndarray, wRc: np.ndarray, wtc: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (M, 2) and depths (M,) of world points X (M, 3) seen by a camera at (wRc, wtc): the vision
    layer's pinhole (``holoslam.vision.camera.pinhole_pixels``)."""
    return pinhole_pixels(K, (X - wtc) @ wRc)  # (X - t) @ wRc = wRc^T (X - t), the points in the optical frame
