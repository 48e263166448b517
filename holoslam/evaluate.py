"""Accuracy of a SLAM result against ground truth (numpy only): alignment, trajectory and object errors,
relation errors (the Freiburg benchmark's metric) and ATE / RPE against a ground-truth trajectory.

The world frame of a SLAM run is arbitrary (its first anchor, or the compass's magnetic frame), so estimates are
compared after the rigid SE(2) transform ``T`` that best maps them onto the truth (:func:`align_se2`, closed-form
Kabsch/Umeyama without scale). ``T`` maps estimate world coordinates to truth coordinates: ``p_true ~ T * p_est``
and ``wTa_true ~ T ∘ wTa_est``.

Coverage (honest covariances): a true position is inside the 95 % ellipse of its estimate when the squared
Mahalanobis distance of the error under the 2x2 position marginal is below the chi-square(2) 95 % quantile,
5.991. An anchor covariance ``cov_wTa`` is in the pose's own (body) frame (GTSAM's right perturbation), so its
position block is rotated into the world frame by R(theta) of the aligned estimate first. Poses whose position
covariance is (numerically) zero are the gauge (the fixed first anchor) and are left out of the coverage.

Relation errors (Kümmerle et al. 2009, "On measuring the accuracy of SLAM algorithms"; :func:`relation_errors`)
need no alignment: for each relation (t1, t2, t_rel, yaw_rel) the estimated relative pose d = X(t1)^-1 X(t2) is
compared with it, translational error ||t(d) - t_rel|| (m), rotational error |wrap(yaw(d) - yaw_rel)| (deg),
summarised by mean and sample (N-1) standard deviation. X(t) is the estimated pose with the nearest stamp, when
it is within ``max_dt_ns`` of t (nothing is interpolated); otherwise the relation is unmatched and left out.

A trajectory made of two parts that a run had to join (a kidnap, two sessions) can be compared with a reference
run of the same log without trusting any ground truth: :func:`placement_difference` fits each part onto the
reference separately and says how far the two fits disagree, i.e. how wrongly the second part is placed relative
to the first.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from holoslam import geometry as g

if TYPE_CHECKING:
    from holoslam.io.relations import Relations

__all__ = [
    "CHI2_2D_95",
    "TrajectoryErrors",
    "ObjectErrors",
    "align_se2",
    "apply_se2",
    "trajectory_errors",
    "object_errors",
    "truth_at",
    "RelationErrors",
    "relation_errors",
    "PlacementDifference",
    "placement_difference",
    "GroundTruthErrors",
    "ground_truth_errors",
    "DEFAULT_MAX_DT_NS",
    "DEFAULT_RPE_DELTA_NS",
]

CHI2_2D_95 = 5.991464547107979  # chi-square quantile, 2 degrees of freedom, p = 0.95
_GAUGE_VAR = 1e-10  # m^2: a position variance below this is the fixed gauge, not an estimate
DEFAULT_MAX_DT_NS = 50_000_000  # 0.05 s: a relation stamp's pose must be this close (the benchmark scorer's)
DEFAULT_RPE_DELTA_NS = 1_000_000_000  # 1 s between the two poses of a relative pose error


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
    coverage. A moved object's earlier position (``holoslam.graph.keys.before_id``) is left out."""
    names = [str(k) for k in ids]
    P = np.asarray(est_w, dtype=np.float64)
    P = P.reshape(len(names), -1) if len(names) else np.zeros((0, 2))
    if P.shape[0] and P.shape[1] < 2:
        raise ValueError(f"object_errors: est_w must be (M, 2) or (M, 3), got {P.shape}")
    from holoslam.graph.keys import is_before  # here: `holoslam evaluate` stays clear of the graph layer

    keep = [k for k, n in enumerate(names) if not is_before(n)]
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
    return g.interpolate_poses(t, P, q)


# ------------------------------------------------------------------------------------------ relation errors


def _sorted_unique(stamps_ns: np.ndarray, wTb: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (N,) int64 and poses (N, 3) sorted in time; of poses sharing a stamp the last one given is kept."""
    t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    P = np.asarray(wTb, dtype=np.float64).reshape(-1, 3)
    if t.shape[0] != P.shape[0]:
        raise ValueError(f"{name}: {t.shape[0]} stamps for {P.shape[0]} poses; pass one stamp per pose")
    if t.shape[0] == 0:
        raise ValueError(f"{name}: no pose to evaluate")
    order = np.argsort(t, kind="stable")
    t, P = t[order], P[order]
    keep = np.append(np.diff(t) != 0, True)
    return t[keep], P[keep]


def _nearest(stamps: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest of sorted unique ``stamps`` to each of ``q`` (the earlier on a tie), and |dt|."""
    i = np.searchsorted(stamps, q)
    left = np.clip(i - 1, 0, stamps.shape[0] - 1)
    right = np.clip(i, 0, stamps.shape[0] - 1)
    dl, dr = np.abs(q - stamps[left]), np.abs(stamps[right] - q)
    idx = np.where(dl <= dr, left, right)
    return idx, np.minimum(dl, dr)


def _mean_std_max(v: np.ndarray) -> tuple[float, float, float]:
    """Mean, sample standard deviation (N-1; 0 for one value) and max; NaN for none."""
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    return float(np.mean(v)), float(np.std(v, ddof=1)) if v.size > 1 else 0.0, float(np.max(v))


def _finite_or_none(v: float) -> float | None:
    """A float for JSON: full precision, None for NaN (nothing to measure)."""
    return float(v) if np.isfinite(v) else None


@dataclass(frozen=True, eq=False)
class RelationErrors:
    """Relation errors of a trajectory (see the module docstring). Per relation (N,): ``matched`` (both stamps
    had a pose within ``max_dt_ns``), ``translation_m`` and ``rotation_deg`` (NaN when unmatched). Statistics
    over the matched relations: mean, sample standard deviation (N-1) and max."""

    n_relations: int
    n_matched: int
    matched: np.ndarray
    translation_m: np.ndarray
    rotation_deg: np.ndarray
    translation_mean_m: float
    translation_std_m: float
    translation_max_m: float
    rotation_mean_deg: float
    rotation_std_deg: float
    rotation_max_deg: float
    max_dt_ns: int

    @property
    def n_unmatched(self) -> int:
        return self.n_relations - self.n_matched

    def to_dict(self) -> dict[str, Any]:
        """The summary as JSON-able scalars (no per-relation arrays); NaN (nothing matched) becomes None."""
        return {
            "relations": self.n_relations,
            "matched": self.n_matched,
            "unmatched": self.n_unmatched,
            "max_dt_s": self.max_dt_ns / 1e9,
            "translation_m": {
                "mean": _finite_or_none(self.translation_mean_m),
                "std": _finite_or_none(self.translation_std_m),
                "max": _finite_or_none(self.translation_max_m),
            },
            "rotation_deg": {
                "mean": _finite_or_none(self.rotation_mean_deg),
                "std": _finite_or_none(self.rotation_std_deg),
                "max": _finite_or_none(self.rotation_max_deg),
            },
        }

    def to_text(self) -> str:
        return "\n".join(
            [
                f"relations {self.n_relations}: matched {self.n_matched}, unmatched {self.n_unmatched} "
                f"(a pose within {self.max_dt_ns / 1e9:g} s of both stamps)",
                f"  translational error {self.translation_mean_m:.4f} ± {self.translation_std_m:.4f} m "
                f"(max {self.translation_max_m:.4f})",
                f"  rotational error    {self.rotation_mean_deg:.3f} ± {self.rotation_std_deg:.3f} deg "
                f"(max {self.rotation_max_deg:.3f})",
            ]
        )


def relation_errors(
    stamps_ns: np.ndarray, wTb: np.ndarray, relations: Relations, max_dt_ns: int = DEFAULT_MAX_DT_NS
) -> RelationErrors:
    """Relation errors of the trajectory ``wTb`` (N, 3) at ``stamps_ns`` (N,) against ``relations``
    (:class:`holoslam.io.relations.Relations`): the Freiburg benchmark's metric (module docstring). The
    trajectory's stamps need not be sorted; of poses sharing a stamp the last one given is used."""
    t, P = _sorted_unique(stamps_ns, wTb, "relation_errors")
    if max_dt_ns < 0:
        raise ValueError(f"relation_errors: max_dt_ns must be >= 0, got {max_dt_ns}")
    t1 = np.asarray(relations.t1_ns, dtype=np.int64).reshape(-1)
    t2 = np.asarray(relations.t2_ns, dtype=np.int64).reshape(-1)
    R = np.asarray(relations.T, dtype=np.float64).reshape(-1, 3)
    i1, d1 = _nearest(t, t1)
    i2, d2 = _nearest(t, t2)
    ok = (d1 <= max_dt_ns) & (d2 <= max_dt_ns)
    d = g.between(P[i1[ok]], P[i2[ok]])
    trans = np.full(t1.shape[0], np.nan)
    rot = np.full(t1.shape[0], np.nan)
    trans[ok] = np.hypot(d[:, 0] - R[ok, 0], d[:, 1] - R[ok, 1])
    rot[ok] = np.degrees(np.abs(g.wrap(d[:, 2] - R[ok, 2])))
    tm, ts, tx = _mean_std_max(trans[ok])
    rm, rs, rx = _mean_std_max(rot[ok])
    for a in (ok, trans, rot):
        a.setflags(write=False)
    return RelationErrors(
        n_relations=int(t1.shape[0]),
        n_matched=int(ok.sum()),
        matched=ok,
        translation_m=trans,
        rotation_deg=rot,
        translation_mean_m=tm,
        translation_std_m=ts,
        translation_max_m=tx,
        rotation_mean_deg=rm,
        rotation_std_deg=rs,
        rotation_max_deg=rx,
        max_dt_ns=int(max_dt_ns),
    )


# ------------------------------------------------------------------------ placement of parts of a trajectory


@dataclass(frozen=True, eq=False)
class PlacementDifference:
    """How differently two parts of a trajectory sit in a reference trajectory (:func:`placement_difference`).

    ``T_first`` / ``T_second``: the SE(2) transforms (x, y, theta) mapping the trajectory's world to the
    reference's, each fit (:func:`align_se2`, positions) on one part's poses against the reference's poses at
    the same stamps; ``rms_first_m`` / ``rms_second_m`` the position residuals of those fits over
    ``n_first`` / ``n_second`` pose pairs. ``translation_m``: |T_second(c) - T_first(c)| at the centroid c of the
    second part's positions, which is the mean displacement of the second part between its placement by the
    first part's fit and by its own (the displacement is affine in the position); ``rotation_deg``:
    |wrap(theta_second - theta_first)|. Both are independent of the trajectory's and the reference's world frames
    (the translation of ``between(T_first, T_second)`` is not: it carries the rotation difference times the
    distance from the trajectory's origin)."""

    T_first: np.ndarray
    T_second: np.ndarray
    translation_m: float
    rotation_deg: float
    n_first: int
    n_second: int
    rms_first_m: float
    rms_second_m: float


def placement_difference(
    stamps_ns: np.ndarray,
    wTb: np.ndarray,
    ref_stamps_ns: np.ndarray,
    ref_wTb: np.ndarray,
    first: np.ndarray,
    second: np.ndarray,
    max_dt_ns: int = 0,
) -> PlacementDifference:
    """The placement of the ``second`` part of a trajectory relative to its ``first`` part, against a reference
    trajectory (see :class:`PlacementDifference`): zero when the two parts are joined exactly as the reference
    joins them, whatever either trajectory's world frame.

    ``first`` / ``second``: boolean masks (N,) over the trajectory's poses ``wTb`` (N, 3) at ``stamps_ns`` (N,);
    poses in neither part are ignored. A pose is paired with the reference pose of the nearest stamp when it is
    within ``max_dt_ns`` (default 0: the same stamp); unpaired poses are left out. Raises ValueError when a part
    has no paired pose."""
    t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    P = np.asarray(wTb, dtype=np.float64).reshape(-1, 3)
    if t.shape[0] != P.shape[0]:
        raise ValueError(f"placement_difference: {t.shape[0]} stamps for {P.shape[0]} poses")
    if max_dt_ns < 0:
        raise ValueError(f"placement_difference: max_dt_ns must be >= 0, got {max_dt_ns}")
    rt, R = _sorted_unique(ref_stamps_ns, ref_wTb, "placement_difference (reference)")
    idx, dt = _nearest(rt, t)
    paired = dt <= max_dt_ns
    fits = []
    for name, part in (("first", first), ("second", second)):
        m = np.asarray(part, dtype=bool).reshape(-1)
        if m.shape[0] != t.shape[0]:
            raise ValueError(f"placement_difference: the {name} mask has {m.shape[0]} entries for {t.shape[0]} poses")
        m = m & paired
        if not m.any():
            raise ValueError(f"placement_difference: no pose of the {name} part has a reference pose within "
                             f"{max_dt_ns / 1e9:g} s")
        T = align_se2(P[m, :2], R[idx[m], :2])
        r = g.transform_points(T, P[m, :2]) - R[idx[m], :2]
        fits.append((T, int(m.sum()), float(np.sqrt(np.mean(np.sum(r**2, axis=1)))), P[m, :2]))
    (T1, n1, rms1, _), (T2, n2, rms2, p2) = fits
    c = p2.mean(axis=0, keepdims=True)
    d = g.transform_points(T2, c)[0] - g.transform_points(T1, c)[0]
    return PlacementDifference(
        T_first=T1,
        T_second=T2,
        translation_m=float(np.hypot(d[0], d[1])),
        rotation_deg=float(np.degrees(abs(g.wrap(T2[2] - T1[2])))),
        n_first=n1,
        n_second=n2,
        rms_first_m=rms1,
        rms_second_m=rms2,
    )


# -------------------------------------------------------------------------- ATE / RPE against a trajectory


@dataclass(frozen=True, eq=False)
class GroundTruthErrors:
    """Errors against a ground-truth trajectory. ``ate``: absolute trajectory error after SE(2) alignment
    (:func:`trajectory_errors`) of the ``ate.n`` estimated poses inside the truth's time span, the truth
    interpolated at their stamps. RPE: for each compared pose i, the first pose j at least ``rpe_delta_ns``
    later (kept when it is less than twice that later), E = (truth_i^-1 truth_j)^-1 (est_i^-1 est_j);
    ``rpe_translation_m`` = ||t(E)|| and ``rpe_rotation_deg`` = |yaw(E)| per pair (independent of alignment)."""

    n_estimate: int
    ate: TrajectoryErrors
    rpe_delta_ns: int
    rpe_translation_m: np.ndarray
    rpe_rotation_deg: np.ndarray

    @property
    def ate_mean_m(self) -> float:
        return float(np.mean(self.ate.position_errors_m))

    def _rpe_stats(self) -> dict[str, dict[str, float | None]]:
        out: dict[str, dict[str, float | None]] = {}
        for key, v in (("translation_m", self.rpe_translation_m), ("rotation_deg", self.rpe_rotation_deg)):
            m, s, x = _mean_std_max(v)
            rmse = float(np.sqrt(np.mean(v**2))) if v.size else float("nan")
            out[key] = {
                "rmse": _finite_or_none(rmse),
                "mean": _finite_or_none(m),
                "std": _finite_or_none(s),
                "max": _finite_or_none(x),
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "poses": self.n_estimate,
            "ate": {
                "poses_compared": self.ate.n,
                "rmse_m": _finite_or_none(self.ate.rmse_m),
                "mean_m": _finite_or_none(self.ate_mean_m),
                "max_m": _finite_or_none(self.ate.max_m),
                "heading_rmse_deg": _finite_or_none(self.ate.heading_rmse_deg),
                "alignment_xytheta": [_finite_or_none(v) for v in self.ate.T],
            },
            "rpe": {"delta_s": self.rpe_delta_ns / 1e9, "pairs": int(self.rpe_translation_m.size)}
            | self._rpe_stats(),
        }

    def to_text(self) -> str:
        r = self._rpe_stats()
        tr, ro = r["translation_m"], r["rotation_deg"]
        return "\n".join(
            [
                f"ATE over {self.ate.n} of {self.n_estimate} poses (after SE(2) alignment): "
                f"RMSE {self.ate.rmse_m:.4f} m, mean {self.ate_mean_m:.4f} m, max {self.ate.max_m:.4f} m, "
                f"heading RMSE {self.ate.heading_rmse_deg:.3f} deg",
                f"RPE over {self.rpe_delta_ns / 1e9:g} s ({self.rpe_translation_m.size} pairs): "
                f"translation RMSE {_fmt(tr['rmse'], 4)} m (mean {_fmt(tr['mean'], 4)}, max {_fmt(tr['max'], 4)}), "
                f"rotation RMSE {_fmt(ro['rmse'], 3)} deg (mean {_fmt(ro['mean'], 3)}, max {_fmt(ro['max'], 3)})",
            ]
        )


def _fmt(v: float | None, digits: int) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def ground_truth_errors(
    stamps_ns: np.ndarray,
    wTb: np.ndarray,
    gt_stamps_ns: np.ndarray,
    gt_wTb: np.ndarray,
    rpe_delta_ns: int = DEFAULT_RPE_DELTA_NS,
) -> GroundTruthErrors:
    """ATE (after :func:`align_se2`) and RPE over ``rpe_delta_ns`` of an estimate against a ground-truth
    trajectory (see :class:`GroundTruthErrors`). Raises ValueError when no estimated pose lies in the truth's
    time span."""
    if rpe_delta_ns <= 0:
        raise ValueError(f"ground_truth_errors: rpe_delta_ns must be > 0, got {rpe_delta_ns}")
    t, P = _sorted_unique(stamps_ns, wTb, "ground_truth_errors (estimate)")
    gt, G = _sorted_unique(gt_stamps_ns, gt_wTb, "ground_truth_errors (truth)")
    inside = (t >= gt[0]) & (t <= gt[-1])
    if not inside.any():
        raise ValueError(
            f"ground_truth_errors: no estimated pose in the truth's span [{gt[0] / 1e9:.6f}, {gt[-1] / 1e9:.6f}] s "
            f"(the estimate spans [{t[0] / 1e9:.6f}, {t[-1] / 1e9:.6f}] s)"
        )
    t, P = t[inside], P[inside]
    truth = truth_at(t, gt, G)
    ate = trajectory_errors(P, truth, None)
    j = np.searchsorted(t, t + rpe_delta_ns, side="left")
    ok = j < t.shape[0]
    i, j = np.nonzero(ok)[0], j[ok]
    near = (t[j] - t[i]) < 2 * rpe_delta_ns
    i, j = i[near], j[near]
    E = g.between(g.between(truth[i], truth[j]), g.between(P[i], P[j]))
    rpe_t = np.hypot(E[:, 0], E[:, 1])
    rpe_r = np.degrees(np.abs(g.wrap(E[:, 2])))
    return GroundTruthErrors(
        n_estimate=int(np.asarray(stamps_ns).size),
        ate=ate,
        rpe_delta_ns=int(rpe_delta_ns),
        rpe_translation_m=rpe_t,
        rpe_rotation_deg=rpe_r,
    )
