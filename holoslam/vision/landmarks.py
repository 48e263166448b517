"""Codes triangulated over the run's own poses, as landmark measurements of the SLAM problem.

After the first solve, each ``View`` (a label without a printed size, or a foreign code) gets its robot pose
from the front end and the solution: the anchor ``k`` of the submap active at the view's stamp (optimised
``wTa_k``), the nearest earlier keyframe of that submap (scan-matched ``aTb``; the scans localised between
nodes count) and the wheel odometry's motion from it to the stamp. ``holoslam.vision.multiview`` triangulates
the views; every point becomes one landmark measurement in the anchor frame of its earliest view (Eq. 16 with
the point's height kept), so the second solve holds it like a PnP sighting: moved-object detection, outlier
rounds and marginal covariances apply.

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


def view_poses(
    stamps_ns: np.ndarray, submaps: Sequence[Any], wTa: np.ndarray, odom_stamps_ns: np.ndarray, odomTb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each stamp: the anchor index k of the submap active then, the base pose ``aTb`` in that anchor's
    frame (nearest earlier keyframe, scan-matched, composed with the odometry's motion since it) and the
    keyframe's covariance (3, 3). Returns ``(k (V,), aTb (V, 3), cov_aTb (V, 3, 3))``."""
    from holoslam.submaps.deadreckon import interpolate_poses

    stamps = np.asarray(stamps_ns, np.int64).reshape(-1)
    anchors = np.array([int(sm.anchor_stamp_ns) for sm in submaps], np.int64)
    ks = np.clip(np.searchsorted(anchors, stamps, side="right") - 1, 0, len(submaps) - 1)
    aTb = np.zeros((len(stamps), 3))
    cov = np.zeros((len(stamps), 3, 3))
    for n, (t, k) in enumerate(zip(stamps, ks, strict=True)):
        sm = submaps[k]
        key_t = np.concatenate([np.asarray(sm.scan_stamps_ns, np.int64), np.asarray(sm.track_stamps_ns, np.int64)])
        key_p = np.vstack([np.reshape(sm.aTb, (-1, 3)), np.reshape(sm.track_aTb, (-1, 3))])
        before = np.flatnonzero(key_t <= t)
        q = int(before[np.argmax(key_t[before])]) if before.size else int(np.argmin(key_t))
        odo = interpolate_poses(odom_stamps_ns, odomTb, np.array([key_t[q], t], np.int64))
        aTb[n] = g.compose(key_p[q], g.between(odo[0], odo[1]))
        node = int(np.clip(np.searchsorted(sm.scan_stamps_ns, t, side="right") - 1, 0, len(sm.scan_stamps_ns) - 1))
        cov[n] = np.asarray(sm.cov_aTb)[node]
    return ks, aTb, cov


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
            X, cov, _ = point_covariance([views[n] for n in idx], wTb[idx], C, sigma_px)
            redone.append(replace(p, cov_w_position=cov))
        points = redone
    obs, i, ids, axy, acov, z = [], [], [], [], [], []
    initial: dict[str, np.ndarray] = {}
    for p in points:
        r = p.reference
        k = int(ks[r])
        R = g.rot2(wTa[k, 2])
        a = R.T @ (p.w_position[:2] - wTa[k, :2])
        if np.hypot(*a) < 1e-3:  # at the anchor's origin: no bearing (never for a code seen from a robot)
            continue
        i.append(k)
        ids.append(p.object_id)
        axy.append(a)
        acov.append(R.T @ p.cov_w_position[:2, :2] @ R)
        z.append(float(p.w_position[2]))
        initial.setdefault(p.object_id, p.w_position[:2].copy())
        Rb = g.rot2(wTb[r, 2])
        b = np.r_[Rb.T @ (p.w_position[:2] - wTb[r, :2]), p.w_position[2]]
        Rb3 = np.eye(3)
        Rb3[:2, :2] = Rb
        obs.append(ObjectObservation(p.stamp_ns, p.object_id, p.payload, b, Rb3.T @ p.cov_w_position @ Rb3,
                                     "triangulation", views[r].source))
    return TriangulatedLandmarks(
        tuple(points), tuple(obs), np.array(i, np.int64), tuple(ids), np.array(axy).reshape(-1, 2),
        np.array(acov).reshape(-1, 2, 2), np.array(z), initial, report,
    )


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
