"""Accuracy of a SLAM result against ground truth (numpy only): alignment, trajectory and object errors.

The world frame of a SLAM run is arbitrary (its first anchor, or the compass's magnetic frame), so estimates are
compared after the rigid SE(2) transform ``T`` that best maps them onto the truth (:func:`align_se2`, closed-form
Kabsch/Umeyama without scale). ``T`` maps estimate world coordinates to truth coordinates: ``p_true ~ T * p_est``
and ``wTa_true ~ T ∘ wTa_est``.

Coverage (honest covariances): a true position is inside the 95 % ellipse of its estimate when the squared
Mahalanobis distance of the error under the 2x2 position marginal is below the chi-square(2) 95 % quantile,
5.991. An anchor covariance ``cov_wTa`` is in the pose's own (body) frame (GTSAM's right perturbation), so its
position block is rotated into the world frame by R(theta) of the aligned estimate first. Poses whose position
covariance is (numerically) zero are the gauge (the fixed first anchor) and are left out of the coverage.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from holoslam import geometry as g

__all__ = [
    "CHI2_2D_95",
    "TrajectoryErrors",
    "ObjectErrors",
    "align_se2",
    "apply_se2",
    "trajectory_errors",
    "object_errors",
    "truth_at",
]

CHI2_2D_95 = 5.991464547107979  # chi-square quantile, 2 degrees of freedom, p = 0.95
_GAUGE_VAR = 1e-10  # m^2: a position variance below this is the fixed gauge, not an estimate


def _xy(a: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(a, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] < 2:
        raise ValueError(f"{name} must be an (N, 2) or (N, 3) array, got shape {x.shape}")
    return x[:, :2]


def align_se2(est_xy: np.ndarray, true_xy: np.ndarray) -> np.ndarray:
    """The SE(2) transform T = (x, y, theta) minimising sum |T(est_i) - true_i|^2 (no scale).

    Closed form: centre both sets, theta = atan2(sum cross, sum dot), t = mean_true - R mean_est. One point gives
    a pure translation (theta = 0); no point raises ValueError.
    """
    p, q = _xy(est_xy, "est_xy"), _xy(true_xy, "true_xy")
    if p.shape[0] != q.shape[0]:
        raise ValueError(f"align_se2: {p.shape[0]} estimated points but {q.shape[0]} true points; pass pairs")
    ok = np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(q), axis=1)
    p, q = p[ok], q[ok]
    if p.shape[0] == 0:
        raise ValueError("align_se2: no finite point pair to align")
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    P, Q = p - pc, q - qc
    sdot = float(np.sum(P[:, 0] * Q[:, 0] + P[:, 1] * Q[:, 1]))
    scross = float(np.sum(P[:, 0] * Q[:, 1] - P[:, 1] * Q[:, 0]))
    th = float(np.arctan2(scross, sdot)) if p.shape[0] > 1 else 0.0
    t = qc - g.rot2(th) @ pc
    return np.array([t[0], t[1], float(g.wrap(th))])


def apply_se2(T: np.ndarray, wTa: np.ndarray) -> np.ndarray:
    """``T ∘ wTa`` for a batch of poses (N, 3)."""
    P = np.asarray(wTa, dtype=np.float64).reshape(-1, 3)
    return g.compose(np.broadcast_to(np.asarray(T, float).reshape(3), P.shape), P)


@dataclass(frozen=True, eq=False)
class TrajectoryErrors:
    """Position RMSE / max (m), heading RMSE (deg) over ``n`` poses after alignment ``T``; ``coverage95`` the
    fraction of true positions inside their 95 % ellipse (NaN without covariances; ``n_coverage`` poses
    counted); per-pose ``position_errors_m`` (N,) and ``heading_errors_deg`` (N,)."""

    rmse_m: float
    max_m: float
    heading_rmse_deg: float
    n: int
    coverage95: float
    position_errors_m: np.ndarray
    heading_errors_deg: np.ndarray
    T: np.ndarray
    n_coverage: int = 0


@dataclass(frozen=True, eq=False)
class ObjectErrors:
    """Object position RMSE / max (m) over the ``n_matched`` estimated ids that the truth knows; ``missing``
    true ids without an estimate, ``unexpected`` estimated ids the truth does not know; per-object errors (m);
    ``coverage95`` as for trajectories (NaN without covariances)."""

    rmse_m: float
    max_m: float
    n_matched: int
    missing: tuple[str, ...]
    unexpected: tuple[str, ...]
    errors_m: dict[str, float] = field(default_factory=dict)
    coverage95: float = float("nan")


def _inside95(err_w: np.ndarray, cov_w: np.ndarray) -> np.ndarray:
    """(N,) bool: error (N, 2) inside the 95 % ellipse of cov (N, 2, 2); False for a singular covariance."""
    det = cov_w[:, 0, 0] * cov_w[:, 1, 1] - cov_w[:, 0, 1] * cov_w[:, 1, 0]
    safe = np.where(det > 0, det, 1.0)
    ex, ey = err_w[:, 0], err_w[:, 1]
    m2 = (
        cov_w[:, 1, 1] * ex * ex - (cov_w[:, 0, 1] + cov_w[:, 1, 0]) * ex * ey + cov_w[:, 0, 0] * ey * ey
    ) / safe
    return (det > 0) & (m2 <= CHI2_2D_95)


def trajectory_errors(
    est_wTa: np.ndarray, true_wTa: np.ndarray, cov_wTa: np.ndarray | None = None, align: bool = True
) -> TrajectoryErrors:
    """Errors of estimated poses (N, 3) against true poses (N, 3), after :func:`align_se2` of the positions
    (``align=True``) or as given. ``cov_wTa`` (N, 3, 3) is in each pose's own frame (see module docstring)."""
    est = np.asarray(est_wTa, dtype=np.float64).reshape(-1, 3)
    tru = np.asarray(true_wTa, dtype=np.float64).reshape(-1, 3)
    if est.shape != tru.shape:
        raise ValueError(f"trajectory_errors: estimate has shape {est.shape}, truth {tru.shape}; pass pairs")
    if est.shape[0] == 0:
        raise ValueError("trajectory_errors: no pose to evaluate")
    T = align_se2(est[:, :2], tru[:, :2]) if align else np.zeros(3)
    e = apply_se2(T, est)
    d = tru[:, :2] - e[:, :2]
    pos = np.hypot(d[:, 0], d[:, 1])
    head = np.degrees(g.wrap(e[:, 2] - tru[:, 2]))
    cov95, ncov = float("nan"), 0
    if cov_wTa is not None:
        C = np.asarray(cov_wTa, dtype=np.float64).reshape(-1, 3, 3)
        if C.shape[0] != est.shape[0]:
            raise ValueError(f"trajectory_errors: {C.shape[0]} covariances for {est.shape[0]} poses")
        R = g.rot2(e[:, 2]).reshape(-1, 2, 2)
        Cw = R @ C[:, :2, :2] @ np.swapaxes(R, 1, 2)
        use = np.all(np.isfinite(C[:, :2, :2]), axis=(1, 2)) & (
            np.trace(C[:, :2, :2], axis1=1, axis2=2) > _GAUGE_VAR
        )
        ncov = int(use.sum())
        if ncov:
            cov95 = float(np.mean(_inside95(d[use], Cw[use])))
    return TrajectoryErrors(
        rmse_m=float(np.sqrt(np.mean(pos**2))),
        max_m=float(pos.max()),
        heading_rmse_deg=float(np.sqrt(np.mean(head**2))),
        n=int(est.shape[0]),
        coverage95=cov95,
        position_errors_m=pos,
        heading_errors_deg=head,
        T=T,
        n_coverage=ncov,
    )


def object_errors(
    ids: Sequence[str],
    est_w: np.ndarray,
    truth: Mapping[str, np.ndarray],
    T: np.ndarray,
    cov_w: np.ndarray | None = None,
) -> ObjectErrors:
    """Errors of estimated object positions ``est_w`` (M, 2 or 3, world frame of the estimate) named by ``ids``
    against ``truth`` (id -> true position (2,) or (3,)), after mapping by ``T`` (from :func:`align_se2` on the
    anchors). Compared in x, y. ``cov_w`` (M, 2, 2) world-frame position covariances (optional) give the
    coverage. Ids with an ``@`` (a moved object's earlier position, ``"<id>@before"``) are left out."""
    names = [str(k) for k in ids]
    P = np.asarray(est_w, dtype=np.float64)
    P = P.reshape(len(names), -1) if len(names) else np.zeros((0, 2))
    if P.shape[0] and P.shape[1] < 2:
        raise ValueError(f"object_errors: est_w must be (M, 2) or (M, 3), got {P.shape}")
    keep = [k for k, n in enumerate(names) if "@" not in n]
    Tm = np.asarray(T, dtype=np.float64).reshape(3)
    Pw = g.transform_points(Tm, P[keep, :2]) if keep else np.zeros((0, 2))
    errs: dict[str, float] = {}
    inside: list[bool] = []
    R = g.rot2(Tm[2])
    for row, k in enumerate(keep):
        n = names[k]
        if n not in truth:
            continue
        d = np.asarray(truth[n], dtype=np.float64).reshape(-1)[:2] - Pw[row]
        errs[n] = float(np.hypot(d[0], d[1]))
        if cov_w is not None:
            c = R @ np.asarray(cov_w, dtype=np.float64)[k][:2, :2] @ R.T
            if np.all(np.isfinite(c)):
                inside.append(bool(_inside95(d[None], c[None])[0]))
    est_names = {names[k] for k in keep}
    missing = tuple(sorted(set(truth) - est_names))
    unexpected = tuple(sorted(est_names - set(truth)))
    v = np.array(list(errs.values()))
    return ObjectErrors(
        rmse_m=float(np.sqrt(np.mean(v**2))) if v.size else float("nan"),
        max_m=float(v.max()) if v.size else float("nan"),
        n_matched=int(v.size),
        missing=missing,
        unexpected=unexpected,
        errors_m=errs,
        coverage95=float(np.mean(inside)) if inside else float("nan"),
    )


def truth_at(stamps_ns: np.ndarray, gt_stamps_ns: np.ndarray, gt_wTb: np.ndarray) -> np.ndarray:
    """Ground-truth poses (N, 3) at ``stamps_ns`` by linear interpolation (heading unwrapped, then wrapped);
    stamps outside the ground truth's span take its first / last pose."""
    q = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    t = np.asarray(gt_stamps_ns, dtype=np.int64).reshape(-1)
    P = np.asarray(gt_wTb, dtype=np.float64).reshape(-1, 3)
    if t.size == 0 or t.size != P.shape[0]:
        raise ValueError(
            f"truth_at: {t.size} ground-truth stamps for {P.shape[0]} poses; need >= 1 of each, paired"
        )
    if np.any(np.diff(t) < 0):
        raise ValueError("truth_at: ground-truth stamps must be sorted in time")
    tf = (t - t[0]).astype(np.float64)
    qf = (q - t[0]).astype(np.float64)
    return np.column_stack(
        [
            np.interp(qf, tf, P[:, 0]),
            np.interp(qf, tf, P[:, 1]),
            g.wrap(np.interp(qf, tf, np.unwrap(P[:, 2]))),
        ]
    )
