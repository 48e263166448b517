"""The outlier tests of ``holoslam.solve``: Mahalanobis residuals of measurements at a solution, chi-square
quantiles, the two-sighting rule and moved-object detection (numpy only)."""

from __future__ import annotations

import math

import numpy as np

from holoslam import geometry as geo
from holoslam.graph.keys import is_before
from holoslam.graph.options import HEAD, LMK, REL, SolveOptions
from holoslam.graph.problem import SlamProblem

__all__ = ["residuals", "chi2_quantile", "in_pairs", "detect_moved"]


def residuals(
    problem: SlamProblem,
    wTa: np.ndarray,
    w_lm: np.ndarray,
    names: tuple[str, ...],
    theta_m: float | None,
    labels: tuple[str, ...],
    rows_by_family: dict[int, np.ndarray],
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Mahalanobis squared residual of the given measurement rows at a solution: {family: (rows, d2)}.
    A sighting whose landmark variable is not in ``names`` gets an infinite residual."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    rel = problem.relative
    rows = rows_by_family.get(REL, np.zeros(0, np.int64))
    if rows.size:
        pred = geo.between(wTa[rel.i[rows]], wTa[rel.j[rows]])
        r = geo.between(rel.iTj[rows], pred)
        out[REL] = (rows, np.einsum("ki,kij,kj->k", r, np.linalg.inv(rel.cov_iTj[rows]), r))
    hd = problem.headings
    rows = rows_by_family.get(HEAD, np.zeros(0, np.int64))
    if rows.size and theta_m is not None:
        r = geo.wrap(wTa[hd.i[rows], 2] - theta_m - hd.yaw[rows])
        out[HEAD] = (rows, np.square(r / hd.sigma[rows]))
    lm = problem.landmarks
    rows = rows_by_family.get(LMK, np.zeros(0, np.int64))
    if rows.size:
        var_of = {n: k for k, n in enumerate(names)}
        v = np.array([var_of.get(labels[k], -1) for k in rows.tolist()])
        wl = np.where((v >= 0)[:, None], w_lm[np.maximum(v, 0)] if len(names) else 0.0, 0.0)
        pred = geo.transform_points(geo.inverse(wTa[lm.i[rows]]), wl)
        r = pred - lm.a_position[rows]
        d2 = np.einsum("ki,kij,kj->k", r, np.linalg.inv(lm.cov_a_position[rows]), r)
        out[LMK] = (rows, np.where(v >= 0, d2, np.inf))
    return out


def chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square quantile for 1, 2 or 3 degrees of freedom (closed-form CDFs, bisection)."""
    if dof == 2:
        return -2.0 * math.log1p(-probability)

    def cdf(x: float) -> float:
        e = math.erf(math.sqrt(x / 2.0))
        return e if dof == 1 else e - math.sqrt(2.0 * x / math.pi) * math.exp(-x / 2.0)

    if dof not in (1, 3):
        raise ValueError(f"chi2_quantile supports 1-3 degrees of freedom, not {dof}")
    lo, hi = 0.0, 200.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < probability else (lo, mid)
    return 0.5 * (lo + hi)


def _world_sightings(
    problem: SlamProblem, wTa: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    lm = problem.landmarks
    T = wTa[lm.i[rows]]
    p = np.stack([geo.transform_points(T[k], lm.a_position[rows[k]][None])[0] for k in range(rows.size)])
    R = geo.rot2(T[:, 2])
    cov = R @ lm.cov_a_position[rows] @ np.swapaxes(R, 1, 2)
    return p, cov


def _cluster(p: np.ndarray, cov: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of points and the per-point chi2 inlier mask (one refit without outliers)."""
    info = np.linalg.inv(cov)
    mask = np.ones(p.shape[0], bool)
    mean = np.zeros(2)
    for _ in range(2):
        I = info[mask].sum(0)
        mean = np.linalg.solve(I, np.einsum("kij,kj->i", info[mask], p[mask]))
        r = p - mean
        mask_new = np.einsum("ki,kij,kj->k", r, info, r) <= thr
        if mask_new.sum() < 1 or np.array_equal(mask_new, mask):
            break
        mask = mask_new
    return mean, mask


def in_pairs(labels: tuple[str, ...], active: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Which of the sighting ``rows`` belong to a landmark with exactly two active sightings. Such a pair that
    disagrees has no majority: rejecting either one is a coin toss (on sim/s11/x2 it kept the sighting 9 cm off
    and dropped the one 2 cm off), so both stay and the landmark sits at their information-weighted mean. Pairs
    far apart do not get here: the front end leaves out objects whose sightings all disagree."""
    lab = np.asarray(labels)
    names, counts = np.unique(lab[active], return_counts=True)
    return np.isin(lab[rows], names[counts == 2])


def detect_moved(
    problem: SlamProblem,
    wTa: np.ndarray,
    w_lm: np.ndarray,
    names: tuple[str, ...],
    labels: tuple[str, ...],
    active: np.ndarray,
    options: SolveOptions,
    thr: float,
) -> list[tuple[str, np.ndarray, bool, np.ndarray]]:
    """Objects whose rejected sightings form their own place: at least ``min_moved_sightings`` rejected sightings
    of one id that agree with each other (chi2), lie ``min_move_distance`` or more from the id's estimate, and
    are all later (or all earlier) than every accepted sighting of that id. Returns (object id, the cluster's
    rows, whether the cluster is the later one, its mean world position)."""
    lm = problem.landmarks
    var_of = {n: k for k, n in enumerate(names)}
    found = []
    out_rows: dict[str, list[int]] = {}
    for k in np.flatnonzero(~active).tolist():
        out_rows.setdefault(labels[k], []).append(k)
    m = max(1, options.min_moved_sightings)
    for name, rows_l in out_rows.items():
        if len(rows_l) < m or is_before(name) or name not in var_of:
            continue
        rows_in = np.array([k for k in range(len(lm)) if active[k] and labels[k] == name])
        if rows_in.size == 0:
            continue
        rows = np.array(rows_l)
        p, cov = _world_sightings(problem, wTa, rows)
        mean, inl = _cluster(p, cov, thr)
        cluster = rows[inl]
        if cluster.size < m or np.hypot(*(mean - w_lm[var_of[name]])) < options.min_move_distance:
            continue
        a_c, a_in = lm.i[cluster], lm.i[rows_in]
        if a_c.min() > a_in.max():
            found.append((name, cluster, True, mean))
        elif a_c.max() < a_in.min():
            found.append((name, cluster, False, mean))
    return found
