"""Codes triangulated over the run's own poses, as landmark measurements of the SLAM problem.

After the first solve, each ``View`` (a label without a printed size, or a foreign code) gets its robot pose
from the front end and the solution: the anchor ``k`` of the submap active at the view's stamp (optimised
``wTa_k``), the nearest earlier keyframe of that submap (scan-matched ``aTb``; the scans localised between
nodes count) and the wheel odometry's motion from it to the stamp, bent to end at the next keyframe's matched
pose (the PTZ often fires while the robot turns, where the odometry's turn scale error shows). ``holoslam.vision.multiview`` triangulates
the views; every point becomes one landmark measurement in the anchor frame of its earliest view (Eq. 16 with
the point's height kept), so the second solve holds it like a PnP sighting: moved-object detection, outlier
rounds and marginal covariances apply.

A code on a wall or on the front of furniture also lies where the laser sees a surface: along each view's ray
(horizontal projection, in the view's own submap frame) the submap's laser points give the range
(``laser_ranges``). When at least two of a triangulated point's views have laser-ranged points that agree
(within ``inlier_m``) and agree with the triangulated point (within its covariance, chi-square 3 dof 0.999),
each such view becomes its own landmark measurement in its own anchor's frame, like a PnP sighting, and the
triangulated point is not used: a relative heading error between two views far apart
moves a triangulated point by about range x error / parallax, a laser-ranged one by range x error sideways
only. A code above furniture that stands in front of the wall gets laser ranges to the furniture, which its
triangulation (or the disagreement between views from different sides) rejects.

The views' pose covariances: the keyframe's scan-match covariance in its submap; a view in another submap than
the point's reference view adds both anchors' marginal covariances (no cross-covariance is computed: the sum
over-states the relative uncertainty of neighbouring anchors, which is the safe side).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.types import ObjectObservation
from holoslam.vision.multiview import (
    DEFAULT_INLIER_M,
    DEFAULT_MIN_PARALLAX_DEG,
    MultiViewPoint,
    MultiViewReport,
    View,
    locate_from_views,
    point_covariance,
)

__all__ = ["TriangulatedLandmarks", "view_poses", "triangulated_landmarks", "with_landmarks"]

_MAX_BRIDGE_NS = 1_000_000_000  # interpolate between matched scans at most this far apart


@dataclass(frozen=True)
class TriangulatedLandmarks:
    """The located points, one ``ObjectObservation`` per point (in the base frame at its reference view's
    stamp, method "triangulation"), the landmark measurements (anchor index ``i``, id, anchor-frame xy, 2x2
    covariance, height z) and each id's initial world position, and the report."""

    points: tuple[MultiViewPoint, ...]
    observations: tuple[ObjectObservation, ...]
    i: np.ndarray
    ids: tuple[str, ...]
    a_xy: np.ndarray
    cov_a_xy: np.ndarray
    z: np.ndarray
    initial: dict[str, np.ndarray]
    report: MultiViewReport
    laser_ranged: int = 0  # views located by their ray and the laser's range instead of the triangulation


def view_poses(
    stamps_ns: np.ndarray, submaps: Sequence[Any], wTa: np.ndarray, odom_stamps_ns: np.ndarray, odomTb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each stamp: the anchor index k of the submap active then, the base pose ``aTb`` in that anchor's
    frame (nearest earlier keyframe, scan-matched, composed with the odometry's motion since it) and the
    keyframe's covariance (3, 3). Returns ``(k (V,), aTb (V, 3), cov_aTb (V, 3, 3))``."""
    from holoslam.geometry import interpolate_poses

    stamps = np.asarray(stamps_ns, np.int64).reshape(-1)
    anchors = np.array([int(sm.anchor_stamp_ns) for sm in submaps], np.int64)
    ks = np.clip(np.searchsorted(anchors, stamps, side="right") - 1, 0, len(submaps) - 1)
    aTb = np.zeros((len(stamps), 3))
    cov = np.zeros((len(stamps), 3, 3))
    for n, (t, k) in enumerate(zip(stamps, ks, strict=True)):
        sm = submaps[k]
        key_t = np.concatenate([np.asarray(sm.scan_stamps_ns, np.int64), np.asarray(sm.track_stamps_ns, np.int64)])
        key_p = np.vstack([np.reshape(sm.aTb, (-1, 3)), np.reshape(sm.track_aTb, (-1, 3))])
        order = np.argsort(key_t, kind="stable")
        key_t, key_p = key_t[order], key_p[order]
        q = max(int(np.searchsorted(key_t, t, side="right")) - 1, 0)
        odo = interpolate_poses(odom_stamps_ns, odomTb, np.array([key_t[q], t], np.int64))
        aTb[n] = g.compose(key_p[q], g.between(odo[0], odo[1]))
        if key_t[q] < t and q + 1 < len(key_t) and key_t[q + 1] - key_t[q] <= _MAX_BRIDGE_NS:
            # between two matched scans: the odometry's motion, bent to end at the next scan's matched pose
            # (odometry over- or under-reports a turn by a few per cent; the scans do not)
            o_next = interpolate_poses(odom_stamps_ns, odomTb, np.array([key_t[q + 1]], np.int64))[0]
            miss = g.between(g.compose(key_p[q], g.between(odo[0], o_next)), key_p[q + 1])
            frac = float(t - key_t[q]) / float(key_t[q + 1] - key_t[q])
            aTb[n] = g.compose(aTb[n], frac * miss)
        node = int(np.clip(np.searchsorted(sm.scan_stamps_ns, t, side="right") - 1, 0, len(sm.scan_stamps_ns) - 1))
        cov[n] = np.asarray(sm.cov_aTb)[node]
    return ks, aTb, cov


_CHI2_3_999 = 16.27
LASER_RANGE_SIGMA_M = 0.03  # along the ray: laser noise, the 5 cm decimation of the submap's points, paint
LASER_GATE_SIGMAS = 3.0  # laser points searched within 3 sd of the triangulated point along each ray


def laser_ranges(
    views: Sequence[View], ks: np.ndarray, aTb: np.ndarray, cov_aTb: np.ndarray, submaps: Sequence[Any],
    sigma_px: float, lateral_m: float = 0.04, near_a: np.ndarray | None = None, gate_m: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """For each view: the point (3,) in its anchor's frame where its ray meets the first laser point of its
    submap within ``lateral_m`` (+1 % of the range) of the ray's horizontal projection, and its 2x2 covariance
    (range ``LASER_RANGE_SIGMA_M`` along the ray; pixels and the pose's heading across it); None when the ray
    meets no laser point (a code above the laser's plane with nothing below it, or beyond the submap).

    With an expected point ``near_a[n]`` (xy in the view's anchor frame, NaN for none) and ``gate_m[n]``, only
    laser points whose range along the ray is within ``gate_m`` of the expected point's count: a code on a wall
    above a table or a sideboard is ranged on the wall behind it, which the laser sees past the furniture's
    legs or from the side, not on the furniture's front: of the laser points in the gate, the surface nearest the
    expected point is taken."""
    out: list[tuple[np.ndarray, np.ndarray] | None] = []
    V = len(views)
    near = np.full((V, 2), np.nan) if near_a is None else np.asarray(near_a, np.float64).reshape(V, 2)
    gate = np.full(V, np.inf) if gate_m is None else np.asarray(gate_m, np.float64).reshape(V)
    for v, k, T, C, xy, gm in zip(views, ks, aTb, cov_aTb, near, gate, strict=True):
        pts = np.asarray(submaps[int(k)].points, np.float64).reshape(-1, 2)
        aTb4 = np.eye(4)
        aTb4[:2, :2] = g.rot2(T[2])
        aTb4[:2, 3] = T[:2]
        aTc = aTb4 @ v.bTc
        c = aTc[:3, 3]
        d = aTc[:3, :3] @ v.camera.unproject(v.centre_px[None, :])[0]
        h = float(np.hypot(d[0], d[1]))
        if h < 1e-3 or not len(pts):
            out.append(None)
            continue
        u = d[:2] / h
        rel = pts - c[:2]
        along = rel @ u
        perp = np.abs(rel[:, 0] * u[1] - rel[:, 1] * u[0])
        hit = (along > 0.2) & (perp <= lateral_m + 0.01 * along)
        expected = float((xy - c[:2]) @ u) if np.isfinite(xy).all() else None
        if expected is not None:
            hit &= np.abs(along - expected) <= gm
        if not hit.any():
            out.append(None)
            continue
        if expected is None:  # the first surface along the ray
            first = float(along[hit].min())
            rho = float(np.median(along[hit & (along <= first + 0.05)]))
        else:  # the surface nearest the expected point (furniture in front of a wall is a surface too)
            near_hit = float(along[hit][np.argmin(np.abs(along[hit] - expected))])
            rho = float(np.median(along[hit & (np.abs(along - near_hit) <= 0.05)]))
        X = c + d * (rho / h)
        f = float(v.camera.K[0, 0])
        lat2 = (rho * sigma_px / f) ** 2 + rho**2 * C[2, 2] + max(C[0, 0], C[1, 1])
        along2 = LASER_RANGE_SIGMA_M**2 + max(C[0, 0], C[1, 1])
        R = np.column_stack([u, [-u[1], u[0]]])
        out.append((X, R @ np.diag([along2, lat2]) @ R.T))
    return out


def _gated_laser_ranges(
    views: Sequence[View], points: Sequence[MultiViewPoint], ks: np.ndarray, aTb: np.ndarray, cov_aTb: np.ndarray,
    wTa: np.ndarray, submaps: Sequence[Any], sigma_px: float,
) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """``laser_ranges`` of each view, searched along its ray within ``LASER_GATE_SIGMAS`` standard deviations (of
    its triangulated point's horizontal position, + ``LASER_RANGE_SIGMA_M``) of that point."""
    near = np.full((len(views), 2), np.nan)
    gate = np.full(len(views), np.inf)
    for p in points:
        sd = float(np.sqrt(max(np.linalg.eigvalsh(p.cov_w_position[:2, :2]).max(), 0.0)))
        for n in p.views:
            near[n] = g.transform_points(g.inverse(wTa[ks[n]]), p.w_position[None, :2])[0]
            gate[n] = LASER_GATE_SIGMAS * sd + LASER_RANGE_SIGMA_M
    return laser_ranges(views, ks, aTb, cov_aTb, submaps, sigma_px, near_a=near, gate_m=gate)


def _with_anchor_uncertainty(
    points: Sequence[MultiViewPoint], views: Sequence[View], ks: np.ndarray, aTb: np.ndarray,
    cov_local: np.ndarray, wTb: np.ndarray, cov_wTa: np.ndarray, sigma_px: float,
) -> list[MultiViewPoint]:
    """The points' covariances again, each view in another submap than its point's reference view holding
    both anchors' marginal covariances besides its own (module docstring)."""
    C_anchor = np.asarray(cov_wTa, np.float64).reshape(-1, 3, 3)
    redone = []
    for p in points:
        idx = list(p.views)
        ref_k = int(ks[p.reference])
        C = cov_local[idx].copy()
        for m, n in enumerate(idx):
            if ks[n] != ref_k:
                A = g.adjoint(g.inverse(aTb[n]))
                C[m] += A @ (C_anchor[ks[n]] + C_anchor[ref_k]) @ A.T
        _, cov, _ = point_covariance([views[n] for n in idx], wTb[idx], C, sigma_px)
        redone.append(replace(p, cov_w_position=cov))
    return redone


def _laser_ranged(
    points: Sequence[MultiViewPoint], laser: Sequence[tuple[np.ndarray, np.ndarray] | None], ks: np.ndarray,
    wTa: np.ndarray, inlier_m: float,
) -> tuple[set[int], list[int]]:
    """The points replaced by their views' laser ranges (indices into ``points``) and those views: at least
    two views whose laser-ranged points agree within ``inlier_m`` and, together, with the triangulated point
    (chi-square 3 dof 0.999)."""
    drop: set[int] = set()
    ranged: list[int] = []
    for j, p in enumerate(points):
        a_X = {n: hit[0] for n in p.views if (hit := laser[n]) is not None}
        Lw = {n: np.r_[g.transform_points(wTa[ks[n]], X[None, :2])[0], X[2]] for n, X in a_X.items()}
        idx = list(Lw)
        support = [[m for m in idx if np.linalg.norm(Lw[m] - Lw[n]) <= inlier_m] for n in idx]
        group = max(support, key=len, default=[])
        if len(group) < 2:
            continue
        d = np.mean([Lw[n] for n in group], axis=0) - p.w_position
        if d @ np.linalg.solve(p.cov_w_position + np.eye(3) * LASER_RANGE_SIGMA_M**2, d) > _CHI2_3_999:
            continue  # the laser saw something else along these rays (furniture before the wall)
        drop.add(j)
        ranged.extend(group)
    return drop, ranged


def _base_normal(v: View) -> np.ndarray | None:
    return None if v.b_normal is None else np.asarray(v.b_normal, np.float64)


def _point_normal(p: MultiViewPoint, views: Sequence[View], wTb: np.ndarray) -> tuple[np.ndarray | None, float]:
    """The label's normal of a triangulated point in the world: the robust weighted mean of its views' normals
    (``holoslam.vision.normals.mean_direction``), each turned by its view's base heading; (None, NaN) when no view
    has one."""
    from holoslam.vision.normals import mean_direction

    rows = [(n, views[n]) for n in p.views if views[n].b_normal is not None]
    if not rows:
        return None, float("nan")
    w = []
    for n, v in rows:
        R3 = np.eye(3)
        R3[:2, :2] = g.rot2(float(wTb[n, 2]))
        w.append(R3 @ np.asarray(v.b_normal, np.float64))
    m, sigma, _ = mean_direction(np.array(w), np.array([v.normal_sigma_rad for _n, v in rows]))
    return m, sigma


class _LandmarkRows:
    """The landmark measurements and observations as they are collected (``TriangulatedLandmarks``' fields)."""

    def __init__(self) -> None:
        self.obs: list[ObjectObservation] = []
        self.i: list[int] = []
        self.ids: list[str] = []
        self.axy: list[np.ndarray] = []
        self.acov: list[np.ndarray] = []
        self.z: list[float] = []
        self.initial: dict[str, np.ndarray] = {}

    def _add(self, k: int, oid: str, a_xy: np.ndarray, cov_a_xy: np.ndarray, z: float,
             w_xy: np.ndarray) -> None:
        self.i.append(k)
        self.ids.append(oid)
        self.axy.append(a_xy)
        self.acov.append(cov_a_xy)
        self.z.append(z)
        self.initial.setdefault(oid, w_xy)

    def add_laser_view(self, v: View, k: int, X: np.ndarray, C2: np.ndarray, wTa_k: np.ndarray,
                       aTb_n: np.ndarray) -> None:
        """View ``v``'s laser-ranged point ``X`` (anchor ``k``'s frame, covariance ``C2`` of its xy)."""
        self._add(k, v.object_id, X[:2], C2, float(X[2]), g.transform_points(wTa_k, X[None, :2])[0])
        b = np.r_[g.transform_points(g.inverse(aTb_n), X[None, :2])[0], X[2]]
        Rb = np.eye(3)
        Rb[:2, :2] = g.rot2(aTb_n[2])
        C3 = np.diag([0.0, 0.0, LASER_RANGE_SIGMA_M**2])
        C3[:2, :2] = C2
        self.obs.append(ObjectObservation(v.stamp_ns, v.object_id, v.payload, b, Rb.T @ C3 @ Rb,
                                          "laser_range", v.source, _base_normal(v), v.normal_sigma_rad))

    def add_point(self, p: MultiViewPoint, k: int, a: np.ndarray, R: np.ndarray, wTb_r: np.ndarray,
                  source: Any, w_normal: tuple[np.ndarray | None, float] = (None, float("nan"))) -> None:
        """Point ``p`` in anchor ``k``'s frame (``a``; ``R`` the anchor's rotation), observed from its
        reference view's pose ``wTb_r``; ``w_normal`` its label's normal in the world and its sigma (rad)."""
        self._add(k, p.object_id, a, R.T @ p.cov_w_position[:2, :2] @ R, float(p.w_position[2]),
                  p.w_position[:2].copy())
        Rb = g.rot2(wTb_r[2])
        b = np.r_[Rb.T @ (p.w_position[:2] - wTb_r[:2]), p.w_position[2]]
        Rb3 = np.eye(3)
        Rb3[:2, :2] = Rb
        b_normal = None if w_normal[0] is None else Rb3.T @ w_normal[0]
        self.obs.append(ObjectObservation(p.stamp_ns, p.object_id, p.payload, b, Rb3.T @ p.cov_w_position @ Rb3,
                                          "triangulation", source, b_normal, w_normal[1]))

    def result(self, points: Sequence[MultiViewPoint], report: MultiViewReport,
               n_ranged: int) -> TriangulatedLandmarks:
        return TriangulatedLandmarks(
            tuple(points), tuple(self.obs), np.array(self.i, np.int64), tuple(self.ids),
            np.array(self.axy).reshape(-1, 2), np.array(self.acov).reshape(-1, 2, 2), np.array(self.z),
            self.initial, report, n_ranged,
        )


def triangulated_landmarks(
    views: Sequence[View],
    submaps: Sequence[Any],
    wTa: np.ndarray,
    cov_wTa: np.ndarray | None,
    odom_stamps_ns: np.ndarray,
    odomTb: np.ndarray,
    sigma_px: float,
    min_parallax_deg: float = DEFAULT_MIN_PARALLAX_DEG,
    inlier_m: float = DEFAULT_INLIER_M,
    laser_range: bool = True,
) -> TriangulatedLandmarks:
    """Triangulate ``views`` over the solved poses (module docstring) and express every point as a landmark
    measurement of the anchor of its earliest view."""
    V = len(views)
    wTa = np.asarray(wTa, np.float64).reshape(-1, 3)
    stamps = np.array([v.stamp_ns for v in views], np.int64)
    ks, aTb, cov_local = view_poses(stamps, submaps, wTa, odom_stamps_ns, odomTb)
    wTb = g.compose(wTa[ks], aTb) if V else np.zeros((0, 3))

    points, report = locate_from_views(views, wTb, cov_local, sigma_px, min_parallax_deg, inlier_m)
    if cov_wTa is not None:  # views in other submaps than the reference view's: add both anchors' uncertainty
        points = _with_anchor_uncertainty(points, views, ks, aTb, cov_local, wTb, cov_wTa, sigma_px)
    laser: list[tuple[np.ndarray, np.ndarray] | None] = (
        _gated_laser_ranges(views, points, ks, aTb, cov_local, wTa, submaps, sigma_px) if laser_range else [None] * V
    )
    drop, ranged = _laser_ranged(points, laser, ks, wTa, inlier_m)
    rows = _LandmarkRows()
    for n in sorted(ranged, key=lambda n: views[n].stamp_ns):
        hit = laser[n]
        assert hit is not None  # a ranged view has a laser range
        X, C2 = hit
        if np.hypot(*X[:2]) < 1e-3:
            continue
        rows.add_laser_view(views[n], int(ks[n]), X, C2, wTa[int(ks[n])], aTb[n])
    points = [p for j, p in enumerate(points) if j not in drop]
    for p in points:
        r = p.reference
        k = int(ks[r])
        R = g.rot2(wTa[k, 2])
        a = R.T @ (p.w_position[:2] - wTa[k, :2])
        if np.hypot(*a) < 1e-3:  # at the anchor's origin: no bearing (never for a code seen from a robot)
            continue
        rows.add_point(p, k, a, R, wTb[r], views[r].source, _point_normal(p, views, wTb))
    return rows.result(points, report, len(ranged))


def with_landmarks(problem: Any, tl: TriangulatedLandmarks, initial_wTa: np.ndarray | None = None) -> Any:
    """The SLAM problem with the triangulated landmark measurements added (ids already located by PnP keep
    their initial position); ``initial_wTa`` replaces the initial anchors (the first solve's, to start close)."""
    from holoslam.graph.problem import LandmarkMeasurements

    old = problem.landmarks
    lm = LandmarkMeasurements(
        np.concatenate([old.i, tl.i]),
        tuple(old.landmark) + tl.ids,
        np.vstack([old.a_position, tl.a_xy]),
        np.concatenate([old.cov_a_position, tl.cov_a_xy]),
        np.concatenate([old.z, tl.z]),
    )
    init = dict(tl.initial)
    init.update(problem.initial_landmarks)
    kw: dict[str, Any] = {"landmarks": lm, "initial_landmarks": init}
    if initial_wTa is not None:
        kw["initial_wTa"] = np.asarray(initial_wTa, np.float64)
    return replace(problem, **kw)
