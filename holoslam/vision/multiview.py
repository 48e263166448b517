"""Codes located from several robot poses: labels without a printed size (no ``s=``, so no single-view PnP)
and foreign codes (any QR code that is not a holoslam label) are triangulated over their sightings from
different places, the baseline the robot's own motion gives (Eq. 6 for V views).

A ``View`` is one sighting: the code's centre in the image (the intersection of its diagonals, exact under
perspective), the camera and its optical frame in the base frame at the image's stamp. Given the base poses
``wTb`` (V, 3) of the views (the optimised trajectory) and their covariances, ``locate_from_views``:

1. groups the views by code (object id);
2. for every pair of views whose rays meet at ``min_parallax_deg`` or more, triangulates the pair, and keeps
   the pair whose point the most views agree with (a view agrees when its ray passes within ``inlier_m`` of
   the point, in front of the camera): a consensus, so a misread or a code seen after it was moved does not
   pull the estimate;
3. triangulates the agreeing views jointly (DLT + Gauss-Newton, ``holoslam.vision.locate.triangulate``); the
   covariance is the pixel noise's ``sigma_px^2 (J^T J)^-1`` plus the views' pose uncertainty carried through
   to first order (numerical derivatives of the solution in each view's pose, GTSAM's right perturbation);
4. repeats on the views left over: a code moved to a new place gives a second point (the solver's moved-object
   logic then sees two inconsistent measurements of one id, as for labels located by PnP).

Views that share no pair with enough parallax locate nothing; ``MultiViewReport`` says how many and why.

Geometry of the accuracy (one camera at two places a baseline b apart, range r, focal length f px): the
range error is about ``r^2 sigma_px sqrt(2) / (f b)`` from the pixels and ``r^2 sigma_theta / b`` from a
relative heading error sigma_theta between the two poses, so scan-matched poses (a few tenths of a degree)
and a zoomed camera are what make 5 cm at 3 m possible with a 0.3 m baseline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from holoslam import geometry as g
from holoslam.errors import VisionError
from holoslam.vision.camera import PinholeCamera
from holoslam.vision.locate import DEFAULT_SIGMA_PX, triangulate

__all__ = [
    "View",
    "MultiViewPoint",
    "MultiViewReport",
    "locate_from_views",
    "point_covariance",
    "planar_to_matrix",
    "DEFAULT_MIN_PARALLAX_DEG",
    "DEFAULT_INLIER_M",
]

DEFAULT_MIN_PARALLAX_DEG = 2.0
DEFAULT_INLIER_M = 0.10


@dataclass(frozen=True, slots=True)
class View:
    """One sighting of a code to be triangulated: ``centre_px`` (2,) the code centre in the image,
    ``camera`` its camera, ``bTc`` (4, 4) the camera's optical frame in the base frame at ``stamp_ns``;
    ``source`` is where the sighting came from ("images": decoded here, "tags": the robot's tag topic);
    ``foreign`` whether the code is not a holoslam label (then ``object_id`` is derived from the payload);
    ``side_px`` the mean side of the code in the image (for a size estimate, 0 if unknown); ``b_normal`` the
    code's outward normal in the base frame from its corners (``locate.label_normal``; None if unknown) with the
    standard deviation of its direction ``normal_sigma_rad``."""

    stamp_ns: int
    object_id: str
    payload: str
    centre_px: np.ndarray
    camera: PinholeCamera
    bTc: np.ndarray
    source: str = "images"
    foreign: bool = False
    side_px: float = 0.0
    b_normal: np.ndarray | None = None
    normal_sigma_rad: float = math.nan

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre_px", np.asarray(self.centre_px, np.float64).reshape(2))
        object.__setattr__(self, "bTc", np.asarray(self.bTc, np.float64).reshape(4, 4))


@dataclass(frozen=True, slots=True)
class MultiViewPoint:
    """A code located from several views: ``w_position`` (3,) in the frame of the base poses (the world),
    ``cov_w_position`` (3, 3), the indices of the views that agreed (into the input sequence), the largest
    angle between their rays (rad), the reprojection RMS (px), the earliest agreeing view's stamp and its
    index (the reference view), and ``size_m``: the code's side estimated from its size in the images and its
    range (NaN when unknown)."""

    object_id: str
    payload: str
    w_position: np.ndarray
    cov_w_position: np.ndarray
    views: tuple[int, ...]
    parallax_rad: float
    reprojection_rms: float
    stamp_ns: int
    reference: int
    foreign: bool = False
    size_m: float = math.nan


@dataclass(frozen=True, slots=True)
class MultiViewReport:
    """Counts of what triangulation made of the views: codes (ids) seen, points located, views used, views
    left without a partner (too little parallax or no agreement), and one line per code that gave nothing."""

    codes: int = 0
    points: int = 0
    views: int = 0
    views_used: int = 0
    views_unused: int = 0
    problems: tuple[str, ...] = field(default=())


def planar_to_matrix(wTb: np.ndarray) -> np.ndarray:
    """The 4x4 transform of a planar pose (x, y, theta): the base frame on the floor, z up."""
    x, y, t = (float(v) for v in np.asarray(wTb, np.float64).reshape(3))
    c, s = math.cos(t), math.sin(t)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = (x, y)
    return T


def _rays(views: Sequence[View], wTcs: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (V, 3) and unit ray directions (V, 3) in the world."""
    c = np.array([T[:3, 3] for T in wTcs])
    d = np.array([T[:3, :3] @ v.camera.unproject(v.centre_px[None, :])[0] for v, T in zip(views, wTcs, strict=True)])
    return c, d


def _ray_distance(c: np.ndarray, d: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Perpendicular distance of X from each ray (V,) and its depth along it (V,)."""
    v = X[None, :] - c
    depth = np.einsum("ij,ij->i", v, d)
    perp = np.linalg.norm(v - depth[:, None] * d, axis=1)
    return perp, depth


def _solve(views: Sequence[View], wTcs: Sequence[np.ndarray], sigma_px: float) -> tuple[np.ndarray, np.ndarray, float]:
    tri = triangulate(
        np.array([v.centre_px for v in views]), [v.camera for v in views], list(wTcs), sigma_px
    )
    return tri.x_position, tri.cov_x_position, tri.reprojection_rms


def _pose_covariance_term(
    views: Sequence[View], wTb: np.ndarray, cov_wTb: np.ndarray, sigma_px: float
) -> np.ndarray:
    """First-order covariance of the joint triangulation from the views' pose uncertainty (right
    perturbations of each planar pose, independent between views), by central differences."""
    cov = np.zeros((3, 3))
    eps = 1e-5
    for i in range(len(views)):
        C = cov_wTb[i]
        if not np.any(C):
            continue
        J = np.zeros((3, 3))
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            pts = []
            for sgn in (1.0, -1.0):
                P = wTb.copy()
                P[i] = g.compose(wTb[i], sgn * d)
                Ts = [planar_to_matrix(p) @ v.bTc for p, v in zip(P, views, strict=True)]
                pts.append(_solve(views, Ts, sigma_px)[0])
            J[:, k] = (pts[0] - pts[1]) / (2 * eps)
        cov += J @ C @ J.T
    return cov


def point_covariance(
    views: Sequence[View], wTb: np.ndarray, cov_wTb: np.ndarray | None, sigma_px: float = DEFAULT_SIGMA_PX
) -> tuple[np.ndarray, np.ndarray, float]:
    """The joint triangulation of ``views`` at base poses ``wTb`` (V, 3): the point (3,), its covariance from
    the pixels and from the poses' covariances ``cov_wTb`` (V, 3, 3, body frame; None: exact poses), and the
    reprojection RMS (px). Raises ``VisionError`` when the views do not determine a point."""
    P = np.asarray(wTb, np.float64).reshape(-1, 3)
    Ts = [planar_to_matrix(p) @ v.bTc for p, v in zip(P, views, strict=True)]
    X, cov, rms = _solve(views, Ts, sigma_px)
    if cov_wTb is not None:
        cov = cov + _pose_covariance_term(views, P, np.asarray(cov_wTb, np.float64).reshape(-1, 3, 3), sigma_px)
    return X, 0.5 * (cov + cov.T), rms


def locate_from_views(
    views: Sequence[View],
    wTb: np.ndarray,
    cov_wTb: np.ndarray | None = None,
    sigma_px: float = DEFAULT_SIGMA_PX,
    min_parallax_deg: float = DEFAULT_MIN_PARALLAX_DEG,
    inlier_m: float = DEFAULT_INLIER_M,
) -> tuple[list[MultiViewPoint], MultiViewReport]:
    """Triangulate every code of ``views`` (see the module docstring). ``wTb`` (V, 3) are the base poses at
    the views' stamps, ``cov_wTb`` (V, 3, 3) their covariances (body frame; None: exact poses). Returns the
    located points, sorted by reference stamp, and a report."""
    V = len(views)
    P = np.asarray(wTb, np.float64).reshape(V, 3)
    C = np.zeros((V, 3, 3)) if cov_wTb is None else np.asarray(cov_wTb, np.float64).reshape(V, 3, 3)
    if not (math.isfinite(min_parallax_deg) and min_parallax_deg > 0 and inlier_m > 0):
        raise VisionError(f"min_parallax_deg ({min_parallax_deg}) and inlier_m ({inlier_m}) must be > 0")
    wTcs = [planar_to_matrix(p) @ v.bTc for p, v in zip(P, views, strict=True)]
    by_id: dict[str, list[int]] = {}
    for k, v in enumerate(views):
        by_id.setdefault(v.object_id, []).append(k)
    min_par = math.radians(min_parallax_deg)
    points: list[MultiViewPoint] = []
    problems: list[str] = []
    used = 0
    for oid, idx in by_id.items():
        left = list(idx)
        found_any = False
        while len(left) >= 2:
            sub = [views[k] for k in left]
            Ts = [wTcs[k] for k in left]
            c, d = _rays(sub, Ts)
            best: tuple[int, float, list[int]] | None = None
            for a in range(len(left)):
                for b in range(a + 1, len(left)):
                    if math.acos(float(np.clip(d[a] @ d[b], -1.0, 1.0))) < min_par:
                        continue
                    try:
                        X, _, _ = _solve([sub[a], sub[b]], [Ts[a], Ts[b]], sigma_px)
                    except VisionError:
                        continue
                    perp, depth = _ray_distance(c, d, X)
                    inl = [j for j in range(len(left)) if perp[j] <= inlier_m and depth[j] > 0]
                    if a not in inl or b not in inl:
                        continue
                    score = float(np.sum(perp[inl]))
                    if best is None or len(inl) > best[0] or (len(inl) == best[0] and score < best[1]):
                        best = (len(inl), score, inl)
            if best is None:
                break
            members = [left[j] for j in best[2]]
            mv = [views[k] for k in members]
            mT = [wTcs[k] for k in members]
            try:
                X, cov, rms = point_covariance(mv, P[members], C[members], sigma_px)
            except VisionError as e:
                problems.append(f"{oid}: {e}")
                break
            mc, md = _rays(mv, mT)
            cosines = np.clip(md @ md.T, -1.0, 1.0)
            parallax = float(np.arccos(cosines.min()))
            ref = min(members, key=lambda k: views[k].stamp_ns)
            size = math.nan
            sides = [(views[k].side_px, float(np.linalg.norm(X - wTcs[k][:3, 3])), views[k].camera.K[0, 0])
                     for k in members if views[k].side_px > 0]
            if sides:
                size = float(np.median([s * r / f for s, r, f in sides]))
            points.append(
                MultiViewPoint(oid, views[ref].payload, X, cov, tuple(sorted(members)), parallax,
                               rms, int(views[ref].stamp_ns), ref, views[ref].foreign, size)
            )
            found_any = True
            used += len(members)
            left = [k for k in left if k not in members]
        if not found_any:
            problems.append(
                f"{oid}: {len(idx)} view(s), no two from places whose rays meet at >= {min_parallax_deg:g} deg "
                "and agree; not located"
            )
    points.sort(key=lambda p: (p.stamp_ns, p.object_id))
    report = MultiViewReport(len(by_id), len(points), V, used, V - used, tuple(problems))
    return points, report
