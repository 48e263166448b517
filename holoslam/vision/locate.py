"""Object positions from labels (seed 002, Eq. 6 and 16): single-view PnP on the label's four corners with
its known printed size, multi-view triangulation (DLT + Gauss-Newton), each with a first-order covariance
from pixel noise; then the label centre in the base frame and, with the robot's pose in a submap, in the
submap frame (Eq. 16: x, y by Eq. 12, z kept).

Pixel noise is isotropic with standard deviation ``sigma_px`` per coordinate. Both estimators are least
squares in the reprojection error, so their covariance to first order is ``sigma_px^2 (J^T J)^-1`` with J the
Jacobian of the predicted pixels with respect to the estimated parameters (for PnP the 6-vector
(rvec, tvec), whose tvec block is the label centre in the camera frame because the label frame's origin is
the code centre).

Label frame ``o`` (as in ``holoslam.sim.label_views``): origin at the code centre, x right along the printed top
edge, y up, z out of the printed face; corners TL, TR, BR, BL at (-s/2, s/2), (s/2, s/2), (s/2, -s/2),
(-s/2, -s/2): the order ``cv2.SOLVEPNP_IPPE_SQUARE`` expects.

The label's **normal** (its z axis, out of the printed face) comes with the PnP pose: the lifelong view tests use
it as the side the label can be read from. Its standard deviation ``normal_sigma_rad`` is first order in the
rotation's covariance; a square seen small is the planar pose's two-fold ambiguity (IPPE's two solutions, the
normal mirrored about the line of sight), and when the second solution's reprojection error is not worse by
``AMBIGUITY_CHI2`` (under ``sigma_px``) the sigma covers both normals (half the angle between them). The normal
does not depend on the printed size (scaling the square scales the translation only), so a label without one
gets it too (``label_normal``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from holoslam.errors import VisionError
from holoslam.types import ObjectObservation
from holoslam.vision.camera import PinholeCamera, invert_transform

__all__ = [
    "LabelPose",
    "Triangulation",
    "DEFAULT_SIGMA_PX",
    "AMBIGUITY_CHI2",
    "pnp_label",
    "label_normal",
    "triangulate",
    "transform_position",
    "base_to_submap",
    "observation_from_pnp",
    "observation_from_triangulation",
]

DEFAULT_SIGMA_PX = 0.5
# chi-square (1 dof, 0.95): the second IPPE solution's sum of squared corner residuals must exceed the best's by
# this many sigma_px^2 for the reading to tell the two normals apart (on the simulated days' readings of 5-15 cm
# labels at 5 px a module, the second solution's RMS was 0.36-12.6 px against 0.005-0.17 px for the best: all
# apart; in real images the corners' noise is larger and near-frontal small labels are not)
AMBIGUITY_CHI2 = 3.84


@dataclass(frozen=True, slots=True)
class LabelPose:
    """A label located in one view: ``cTo`` (4x4 pose of the label in the camera's optical frame), the centre
    ``c_position`` (3,) and its covariance ``cov_c_position`` (3x3), the reprojection RMS (px), and the
    standard deviation of its normal's direction (rad; the module docstring: the flip ambiguity included)."""

    cTo: np.ndarray
    c_position: np.ndarray
    cov_c_position: np.ndarray
    reprojection_rms: float
    normal_sigma_rad: float = math.nan

    @property
    def c_normal(self) -> np.ndarray:
        """The label's outward normal (3,), unit, in the camera's optical frame (towards the camera)."""
        return self.cTo[:3, 2].copy()


@dataclass(frozen=True, slots=True)
class Triangulation:
    """A point triangulated in a reference frame x: ``x_position`` (3,), ``cov_x_position`` (3x3), the
    reprojection RMS (px) and the largest angle (rad) between the viewing rays (small = poorly
    conditioned)."""

    x_position: np.ndarray
    cov_x_position: np.ndarray
    reprojection_rms: float
    parallax_rad: float


def _label_corners(side_m: float) -> np.ndarray:
    h = side_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def pnp_label(
    corners: np.ndarray, side_m: float, camera: PinholeCamera, sigma_px: float = DEFAULT_SIGMA_PX
) -> LabelPose:
    """Single-view position of a square label of printed side ``side_m`` from its corners (4, 2) in code
    order TL, TR, BR, BL, by ``cv2.solvePnPGeneric(SOLVEPNP_IPPE_SQUARE)`` (the lower-error of its two
    solutions) refined with Levenberg-Marquardt. Raises ``VisionError`` on bad input or a degenerate view."""
    import cv2

    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if c.shape != (4, 2) or not np.all(np.isfinite(c)):
        raise VisionError(f"PnP needs 4 finite corners (4, 2), got {np.asarray(corners).shape}")
    if not (np.isfinite(side_m) and side_m > 0):
        raise VisionError(
            f"PnP needs the printed label side in metres > 0 (label attribute 's'), got {side_m}"
        )
    obj = _label_corners(side_m)
    D = camera.D if camera.has_distortion else None
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(
        obj, c.reshape(4, 1, 2), camera.K, D, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    if n == 0:
        raise VisionError("PnP found no label pose for these corners (degenerate quadrilateral?)")
    order = np.argsort(np.asarray(errs).ravel()) if errs is not None else np.arange(n)
    k = int(order[0])
    rvec, tvec = rvecs[k].reshape(3, 1).copy(), tvecs[k].reshape(3, 1).copy()
    rvec, tvec = cv2.solvePnPRefineLM(obj, c.reshape(4, 1, 2), camera.K, D, rvec, tvec)
    proj, jac = cv2.projectPoints(obj, rvec, tvec, camera.K, D)
    resid = proj.reshape(4, 2) - c
    J = jac[:, :6]
    JtJ = J.T @ J
    if np.linalg.cond(JtJ) > 1e12:
        raise VisionError("PnP pose is not determined by these corners (degenerate view)")
    cov = sigma_px**2 * np.linalg.inv(JtJ)
    R, _ = cv2.Rodrigues(rvec)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = tvec.ravel()
    if T[2, 3] <= 0:
        raise VisionError("PnP put the label behind the camera; check the corner order (TL, TR, BR, BL)")
    cov_t = 0.5 * (cov[3:, 3:] + cov[3:, 3:].T)
    sigma_n = _normal_sigma(rvec, cov[:3, :3])
    if n > 1:  # the other IPPE solution: the normal mirrored about the line of sight
        alt = int(order[1])
        r_alt, _ = cv2.projectPoints(obj, rvecs[alt], tvecs[alt], camera.K, D)
        ssr_alt = float(np.sum((r_alt.reshape(4, 2) - c) ** 2))
        if ssr_alt - float(np.sum(resid**2)) < AMBIGUITY_CHI2 * sigma_px**2:
            n_alt = cv2.Rodrigues(rvecs[alt])[0][:, 2]
            sigma_n = max(sigma_n, 0.5 * math.acos(float(np.clip(n_alt @ R[:, 2], -1.0, 1.0))))
    return LabelPose(T, T[:3, 3].copy(), cov_t, float(np.sqrt(np.mean(resid**2))), sigma_n)


def _normal_sigma(rvec: np.ndarray, cov_rvec: np.ndarray) -> float:
    """The standard deviation (rad) of the direction of R(rvec)'s z axis under the rotation vector's covariance:
    first order, the Jacobian by central differences (the normal is a unit vector: its covariance's trace is the
    direction's variance)."""
    import cv2

    r = np.asarray(rvec, np.float64).reshape(3)
    Jn = np.zeros((3, 3))
    h = 1e-6
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        Jn[:, i] = (cv2.Rodrigues(r + d)[0][:, 2] - cv2.Rodrigues(r - d)[0][:, 2]) / (2 * h)
    return float(math.sqrt(max(float(np.trace(Jn @ cov_rvec @ Jn.T)), 0.0)))


def label_normal(corners: np.ndarray, camera: PinholeCamera, sigma_px: float = DEFAULT_SIGMA_PX
                 ) -> tuple[np.ndarray, float]:
    """The outward normal (3,) of a square label in the camera's optical frame from its corners (4, 2), and its
    standard deviation (rad), without its printed size: PnP's rotation does not depend on it (module docstring).
    Raises ``VisionError`` as ``pnp_label``."""
    est = pnp_label(corners, 1.0, camera, sigma_px)
    return est.c_normal, est.normal_sigma_rad


def triangulate(
    pixels: np.ndarray,
    cameras: Sequence[PinholeCamera],
    xTcs: Sequence[np.ndarray],
    sigma_px: float = DEFAULT_SIGMA_PX,
    iterations: int = 10,
) -> Triangulation:
    """Eq. 6 for two or more views: the point whose projections are ``pixels`` (V, 2) in cameras posed at
    ``xTcs`` (each the 4x4 pose of a camera's optical frame in the reference frame x: one robot's two cameras
    in its base frame, or one camera at two robot poses in the world). Linear DLT on undistorted normalised
    coordinates, then Gauss-Newton on the reprojection error in ideal pixels; covariance
    ``sigma_px^2 (J^T J)^-1``."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    V = px.shape[0]
    if V < 2 or len(cameras) != V or len(xTcs) != V:
        raise VisionError(
            f"triangulation needs >= 2 views with one camera and pose each (got {V} pixels, "
            f"{len(cameras)} cameras, {len(xTcs)} poses)"
        )
    cTx = [invert_transform(T) for T in xTcs]
    xn = np.vstack([cam.normalized(p[None, :]) for cam, p in zip(cameras, px, strict=True)])
    A = []
    for (u, v), T in zip(xn, cTx, strict=True):
        P = T[:3, :]
        A.append(u * P[2] - P[0])
        A.append(v * P[2] - P[1])
    _, s, vt = np.linalg.svd(np.asarray(A))
    Xh = vt[-1]
    if abs(Xh[3]) < 1e-12:
        raise VisionError(
            "triangulation: the viewing rays are parallel (point at infinity); move the robot or "
            "use a second camera with a baseline"
        )
    X = Xh[:3] / Xh[3]
    ideal = np.vstack([cam.K @ np.array([u, v, 1.0]) for cam, (u, v) in zip(cameras, xn, strict=True)])[:, :2]

    def predict(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, J = np.zeros(2 * V), np.zeros((2 * V, 3))
        for i, (cam, T) in enumerate(zip(cameras, cTx, strict=True)):
            pc = T[:3, :3] @ X + T[:3, 3]
            if pc[2] <= 0:
                raise VisionError(
                    f"triangulation: the point is behind camera {i} (z = {pc[2]:.3f} m); check the "
                    "camera poses and pixel correspondences"
                )
            fx, fy, sk = cam.K[0, 0], cam.K[1, 1], cam.K[0, 1]
            x, y, z = pc
            u = fx * x / z + sk * y / z + cam.K[0, 2]
            w = fy * y / z + cam.K[1, 2]
            r[2 * i : 2 * i + 2] = (u - ideal[i, 0], w - ideal[i, 1])
            dpc = np.array([[fx / z, sk / z, -(fx * x + sk * y) / z**2], [0.0, fy / z, -fy * y / z**2]])
            J[2 * i : 2 * i + 2] = dpc @ T[:3, :3]
        return r, J

    for _ in range(iterations):
        r, J = predict(X)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        X = X + step
        if np.linalg.norm(step) < 1e-10:
            break
    r, J = predict(X)
    JtJ = J.T @ J
    if np.linalg.cond(JtJ) > 1e14:
        raise VisionError("triangulation is degenerate (rays nearly parallel); the views need a baseline")
    cov = sigma_px**2 * np.linalg.inv(JtJ)
    centres = np.array([T[:3, 3] for T in xTcs])
    rays = X[None, :] - centres
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    parallax = float(np.arccos(np.clip(np.min(rays @ rays.T), -1.0, 1.0)))
    return Triangulation(X, 0.5 * (cov + cov.T), float(np.sqrt(np.mean(r**2))), parallax)


def transform_position(
    aTc: np.ndarray, c_position: np.ndarray, cov_c_position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A point and its covariance moved from frame c to frame a by the (exact) 4x4 ``aTc``."""
    R = np.asarray(aTc, np.float64)[:3, :3]
    p = R @ np.asarray(c_position, np.float64).reshape(3) + np.asarray(aTc, np.float64)[:3, 3]
    return p, R @ np.asarray(cov_c_position, np.float64) @ R.T


def base_to_submap(
    aTb: np.ndarray, b_position: np.ndarray, cov_b_position: np.ndarray, cov_aTb: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 16: the object at ``b_position`` (3,) in the base frame, with the robot at planar pose ``aTb``
    (x, y, theta) in the submap: x, y by Eq. 12 (``R(theta) p_xy + t``), z kept. Returns
    ``(a_position (3,), cov_a_position (3, 3))``; ``cov_aTb`` (3x3, the pose's own frame, GTSAM's right
    perturbation) adds the pose uncertainty to first order."""
    x, y, th = np.asarray(aTb, np.float64).reshape(3)
    p = np.asarray(b_position, np.float64).reshape(3)
    c, s = np.cos(th), np.sin(th)
    R3 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    a = np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1], p[2]])
    cov = R3 @ np.asarray(cov_b_position, np.float64).reshape(3, 3) @ R3.T
    if cov_aTb is not None:
        # p_a = t + R(theta) p_b with aTb <- aTb * Exp(delta): dt = R d_xy, d(R p) = R [0 -1; 1 0] p d_theta
        Jp = np.zeros((3, 3))
        Jp[:2, :2] = R3[:2, :2]
        Jp[:2, 2] = R3[:2, :2] @ np.array([-p[1], p[0]])
        cov = cov + Jp @ np.asarray(cov_aTb, np.float64).reshape(3, 3) @ Jp.T
    return a, 0.5 * (cov + cov.T)


def observation_from_pnp(
    stamp_ns: int,
    object_id: str,
    payload: str,
    corners: np.ndarray,
    side_m: float,
    camera: PinholeCamera,
    bTc: np.ndarray,
    sigma_px: float = DEFAULT_SIGMA_PX,
) -> ObjectObservation:
    """An ``ObjectObservation`` (label centre in the base frame at ``stamp_ns``, with the label's normal) from one
    view by PnP; ``bTc`` is the camera's optical frame in the base frame at the image stamp."""
    est = pnp_label(corners, side_m, camera, sigma_px)
    p, cov = transform_position(bTc, est.c_position, est.cov_c_position)
    b_normal = np.asarray(bTc, np.float64)[:3, :3] @ est.c_normal
    return ObjectObservation(int(stamp_ns), object_id, payload, p, cov, "pnp", b_normal=b_normal,
                             normal_sigma_rad=est.normal_sigma_rad)


def observation_from_triangulation(
    stamp_ns: int,
    object_id: str,
    payload: str,
    pixels: np.ndarray,
    cameras: Sequence[PinholeCamera],
    bTcs: Sequence[np.ndarray],
    sigma_px: float = DEFAULT_SIGMA_PX,
) -> ObjectObservation:
    """An ``ObjectObservation`` from two (or more) cameras of one robot at one stamp (Eq. 6a + 6b): each
    ``bTcs[i]`` is camera i's optical frame in the base frame, ``pixels[i]`` the label centre in its image."""
    tri = triangulate(pixels, cameras, bTcs, sigma_px)
    return ObjectObservation(
        int(stamp_ns), object_id, payload, tri.x_position, tri.cov_x_position, "triangulation"
    )
