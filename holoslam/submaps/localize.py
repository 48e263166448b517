"""Self-localisation in a local map (seed 002 Eq. 12): from matched feature pairs and by scan registration.

Eq. 12 maps a point seen at p_R in the robot frame into the local frame: p_L = R(theta_RL) p_R + t_RL. Given
matched pairs (p_R, p_L):

* :func:`align_pairs` solves for aTb = (x_RL, y_RL, theta_RL) in closed form (weighted 2-D Procrustes /
  Umeyama without scale) and gives its covariance sigma^2 (J^T W J)^-1 in the pose's own frame, sigma from the
  residuals (or given);
* :func:`ransac_align` makes it robust to wrong matches: every hypothesis from two pairs is scored at once
  (vectorised), the largest consensus set is refined by :func:`align_pairs`.

Scan registration (:func:`register_points`) is point-to-line ICP of the scan's points (robot frame) against a
local map's points and normals (anchor frame), seeded by dead reckoning. Nearest neighbours within the gate come
from a :class:`NearestIndex` (a bucket grid searched by a compiled kernel, exactly cKDTree's answer), built once
per map and reusable across registrations into it; the matched points' residuals, Jacobian rows and Huber weights
are computed by the same kernel (``_fast.icp_terms``, numpy's arithmetic point by point). Each iteration solves the
linearised 3x3 normal equations with Huber weights; correspondences farther than a distance that shrinks over
the iterations are dropped. The covariance is sigma^2 (J^T W J)^-1 at convergence (sigma^2 from the residuals,
never below ``sigma_floor``^2), multiplied by ``cov_inflation`` because ICP's residuals are correlated
(neighbouring beams hit the same wall) and the textbook formula is overconfident; a degenerate geometry
(a long corridor) shows up as a large variance along the corridor. The quality record says whether to trust
the match: enough inliers, small RMS, a well-conditioned information matrix.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = [
    "Alignment",
    "align_pairs",
    "ransac_align",
    "IcpConfig",
    "Registration",
    "register_points",
    "scan_normals",
]


@dataclass(frozen=True, slots=True)
class Alignment:
    """``aTb`` (3,) with ``cov_aTb`` (3x3, own frame), the RMS residual (m) and the inlier mask of the pairs."""

    aTb: np.ndarray
    cov_aTb: np.ndarray
    rms: float
    inliers: np.ndarray


def _pose_jacobian(aTb: np.ndarray, b_pts: np.ndarray) -> np.ndarray:
    """d(aTb * p)/d(xi) for a right perturbation xi of aTb: (N, 2, 3) = [R, R (-p_y, p_x)]."""
    R = g.rot2(aTb[2])
    J = np.zeros((b_pts.shape[0], 2, 3))
    J[:, :, :2] = R
    perp = np.column_stack([-b_pts[:, 1], b_pts[:, 0]])
    J[:, :, 2] = perp @ R.T
    return J


def align_pairs(
    b_points: np.ndarray, a_points: np.ndarray, weights: np.ndarray | None = None, sigma: float | None = None,
    sigma_floor: float = 1e-3,
) -> Alignment:
    """Closed-form weighted least squares for aTb with a_points ~ aTb * b_points (Eq. 12), >= 2 pairs.

    ``sigma`` is the per-coordinate standard deviation of the points (m); when None it is estimated from the
    residuals with 2N - 3 degrees of freedom (and never below ``sigma_floor``).
    """
    p = np.asarray(b_points, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(a_points, dtype=np.float64).reshape(-1, 2)
    n = p.shape[0]
    if n < 2 or q.shape[0] != n:
        raise ValueError(f"align_pairs needs >= 2 matched pairs of equal count, got {n} and {q.shape[0]}")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64).reshape(n)
    ws = w.sum()
    pc, qc = (w @ p) / ws, (w @ q) / ws
    P, Q = p - pc, q - qc
    sxx = np.sum(w * (P[:, 0] * Q[:, 0] + P[:, 1] * Q[:, 1]))
    sxy = np.sum(w * (P[:, 0] * Q[:, 1] - P[:, 1] * Q[:, 0]))
    th = np.arctan2(sxy, sxx)
    R = g.rot2(th)
    t = qc - R @ pc
    aTb = np.array([t[0], t[1], g.wrap(th)])
    r = g.transform_points(aTb, p) - q
    rss = float(np.sum(w * np.sum(r * r, axis=1)))
    if sigma is None:
        dof = max(2 * n - 3, 1)
        s2 = max(rss / ws * n / dof, sigma_floor**2)
    else:
        s2 = float(sigma) ** 2
    J = _pose_jacobian(aTb, p)
    H = np.einsum("n,nki,nkj->ij", w, J, J)
    cov = s2 * np.linalg.pinv(H)
    return Alignment(aTb, 0.5 * (cov + cov.T), float(np.sqrt(rss / ws)), np.ones(n, dtype=bool))


def ransac_align(
    b_points: np.ndarray, a_points: np.ndarray, threshold: float = 0.05, max_hypotheses: int = 2000,
    sigma: float | None = None, seed: int = 0, min_inliers: int = 2,
) -> Alignment | None:
    """Eq. 12 robust to wrong matches: all (or ``max_hypotheses`` random) two-pair hypotheses scored at once.

    A pair is an inlier when its residual is below ``threshold`` (m). Returns None when no hypothesis has
    ``min_inliers`` inliers. The two pairs of a hypothesis must be at least 2 * threshold apart.
    """
    p = np.asarray(b_points, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(a_points, dtype=np.float64).reshape(-1, 2)
    n = p.shape[0]
    if n < 2:
        return None
    iu, ju = np.triu_indices(n, 1)
    if iu.size > max_hypotheses:
        rng = np.random.default_rng(seed)
        pick = rng.choice(iu.size, max_hypotheses, replace=False)
        iu, ju = iu[pick], ju[pick]
    dp, dq = p[ju] - p[iu], q[ju] - q[iu]
    ok = (np.hypot(*dp.T) > 2 * threshold) & (np.abs(np.hypot(*dp.T) - np.hypot(*dq.T)) < 2 * threshold)
    if not ok.any():
        return None
    iu, ju, dp, dq = iu[ok], ju[ok], dp[ok], dq[ok]
    th = np.arctan2(dq[:, 1], dq[:, 0]) - np.arctan2(dp[:, 1], dp[:, 0])
    c, s = np.cos(th), np.sin(th)
    mid_p, mid_q = 0.5 * (p[iu] + p[ju]), 0.5 * (q[iu] + q[ju])
    tx = mid_q[:, 0] - (c * mid_p[:, 0] - s * mid_p[:, 1])
    ty = mid_q[:, 1] - (s * mid_p[:, 0] + c * mid_p[:, 1])
    # residuals of every pair under every hypothesis: (H, N)
    ex = tx[:, None] + c[:, None] * p[None, :, 0] - s[:, None] * p[None, :, 1] - q[None, :, 0]
    ey = ty[:, None] + s[:, None] * p[None, :, 0] + c[:, None] * p[None, :, 1] - q[None, :, 1]
    inl = ex * ex + ey * ey < threshold**2
    best = int(np.argmax(inl.sum(axis=1)))
    mask = inl[best]
    if mask.sum() < max(min_inliers, 2):
        return None
    for _ in range(3):  # refine, re-select inliers under the refined pose
        a = align_pairs(p[mask], q[mask], sigma=sigma)
        r = g.transform_points(a.aTb, p) - q
        new = np.sum(r * r, axis=1) < threshold**2
        if new.sum() < 2 or np.array_equal(new, mask):
            break
        mask = new
    a = align_pairs(p[mask], q[mask], sigma=sigma)
    return Alignment(a.aTb, a.cov_aTb, a.rms, mask)


def scan_normals(points: np.ndarray, max_gap: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of ordered scan points from their neighbours (central differences); ``valid`` is False where
    a neighbour is missing or farther than ``max_gap`` (m)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    if n < 3:
        return np.zeros((n, 2)), np.zeros(n, dtype=bool)
    prev = np.vstack([pts[:1], pts[:-1]])
    nxt = np.vstack([pts[1:], pts[-1:]])
    d_prev = np.hypot(*(pts - prev).T)
    d_next = np.hypot(*(nxt - pts).T)
    ok_p = (d_prev < max_gap) & (np.arange(n) > 0)
    ok_n = (d_next < max_gap) & (np.arange(n) < n - 1)
    a = np.where(ok_p[:, None], prev, pts)
    b = np.where(ok_n[:, None], nxt, pts)
    tan = b - a
    norm = np.hypot(*tan.T)
    valid = (ok_p | ok_n) & (norm > 1e-9)
    tan = tan / np.where(norm > 1e-9, norm, 1.0)[:, None]
    return np.column_stack([-tan[:, 1], tan[:, 0]]), valid


@dataclass(frozen=True, slots=True)
class IcpConfig:
    max_iterations: int = 30
    max_distance: float = 0.5  # m, first iterations
    min_distance: float = 0.1  # m, final correspondence gate
    huber: float = 0.03  # m
    sigma_floor: float = 0.01  # m, laser noise floor for the covariance
    cov_inflation: float = 4.0
    min_inlier_fraction: float = 0.6
    max_rms: float = 0.05  # m
    min_points: int = 20
    max_condition: float = 1e5
    block: int = 256


@dataclass(frozen=True, slots=True)
class Registration:
    """ICP result: ``aTb`` and ``cov_aTb`` (own frame), the inlier RMS (m), inlier fraction, iterations, the
    information matrix's condition number, and ``ok`` = passed the quality gate."""

    aTb: np.ndarray
    cov_aTb: np.ndarray
    rms: float
    inlier_fraction: float
    iterations: int
    condition: float
    ok: bool


def _nearest(src: np.ndarray, dst: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Index and squared distance of the nearest dst point to every src point (brute force in blocks)."""
    idx = np.empty(src.shape[0], dtype=np.int64)
    d2 = np.empty(src.shape[0])
    dn = np.sum(dst * dst, axis=1)
    for k in range(0, src.shape[0], block):
        s = src[k:k + block]
        D = np.sum(s * s, axis=1)[:, None] - 2.0 * s @ dst.T + dn[None, :]
        j = np.argmin(D, axis=1)
        idx[k:k + block] = j
        d2[k:k + block] = np.maximum(D[np.arange(s.shape[0]), j], 0.0)
    return idx, d2


class NearestIndex:
    """Nearest neighbours in a fixed point set, built once per map and passed to :func:`register_points` to
    reuse it across registrations into the same map (a submap's revisits). Bounded queries (ICP's gates) run on
    a bucket grid of ``cell`` metres by a compiled kernel (``holoslam.submaps._fast``, numba), which returns what
    scipy's cKDTree returns; unbounded ones, and every query when numba is unavailable, use the cKDTree
    (O(log M) per query), or brute force on numpy blocks without scipy."""

    def __init__(self, dst: np.ndarray, block: int = 256, cell: float = 0.1) -> None:
        self.dst, self.block = np.asarray(dst, dtype=np.float64).reshape(-1, 2), block
        self._x, self._y = np.ascontiguousarray(self.dst[:, 0]), np.ascontiguousarray(self.dst[:, 1])
        self._tree: object = False  # built on first need
        try:
            from holoslam.submaps import _fast

            self._kernel: Any = _fast
            self._grid: Any = _fast.bucket_grid(self._x, self._y, float(cell), 4_000_000)
        except ImportError:  # pragma: no cover - numba is a declared dependency
            self._kernel, self._grid = None, None

    @property
    def tree(self):
        """scipy's cKDTree over the points, or None without scipy."""
        if self._tree is False:
            try:
                from scipy.spatial import cKDTree

                self._tree = cKDTree(self.dst)
            except ImportError:  # pragma: no cover - scipy ships with the environment
                self._tree = None
        return self._tree

    def nearest(self, x: np.ndarray, y: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """(index, distance) of the nearest point of each (x[i], y[i]) nearer than ``max_distance``; index M and
        distance inf for none (cKDTree's convention)."""
        if self._kernel is not None and np.isfinite(max_distance):
            j = np.empty(x.shape[0], dtype=np.int64)
            d = np.empty(x.shape[0])
            self._kernel.grid_nearest(np.ascontiguousarray(x, dtype=np.float64),
                                      np.ascontiguousarray(y, dtype=np.float64), self._x, self._y, *self._grid,
                                      float(max_distance), j, d)
            return j, d
        if self.tree is not None:
            d, j = self.tree.query(np.column_stack([x, y]), k=1, distance_upper_bound=max_distance)
            return j.astype(np.int64, copy=False), d
        j, d2 = _nearest(np.column_stack([x, y]), self.dst, self.block)
        far = d2 >= max_distance**2
        return np.where(far, self.dst.shape[0], j), np.where(far, np.inf, np.sqrt(d2))

    def query(self, src: np.ndarray, max_distance: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """(index, squared distance) of the nearest point; beyond ``max_distance`` the distance is inf."""
        src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
        if self._kernel is None and self.tree is None:
            return _nearest(src, self.dst, self.block)
        j, d = self.nearest(src[:, 0], src[:, 1], max_distance)
        return np.minimum(j, self.dst.shape[0] - 1), d * d


def _icp_terms(px, py, c0, s0, tx, ty, qx, qy, nqx, nqy, index: NearestIndex, gate: float, huber: float):
    """numpy version of ``_fast.icp_terms``: (J (m, 3), w (m,), r (m,)) of the matched points."""
    pax, pay = tx + c0 * px - s0 * py, ty + s0 * px + c0 * py
    j, d = index.nearest(pax, pay, gate)
    sel = d * d < gate * gate
    js = j[sel]
    sx, sy = pax[sel], pay[sel]
    nx, ny = nqx[js], nqy[js]
    r = nx * (sx - qx[js]) + ny * (sy - qy[js])
    J = np.empty((r.shape[0], 3))  # left perturbation (world-frame increment)
    J[:, 0], J[:, 1], J[:, 2] = nx, ny, nx * -sy + ny * sx
    ar = np.abs(r)
    return J, np.where(ar <= huber, 1.0, huber / np.maximum(ar, 1e-12)), r


def register_points(
    b_points: np.ndarray, a_points: np.ndarray, a_normals: np.ndarray, aTb_init: np.ndarray,
    config: IcpConfig | None = None, index: NearestIndex | None = None,
) -> Registration:
    """Point-to-line ICP of ``b_points`` (robot/scan frame) into a map (``a_points`` with unit ``a_normals``),
    starting from ``aTb_init``. Returns the registration with covariance and quality. ``index`` is an optional
    prebuilt :class:`NearestIndex` over ``a_points`` (it must be built on exactly those points)."""
    cfg = config or IcpConfig()
    p = np.asarray(b_points, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(a_points, dtype=np.float64).reshape(-1, 2)
    nq = np.asarray(a_normals, dtype=np.float64).reshape(-1, 2)
    T = np.asarray(aTb_init, dtype=np.float64).reshape(3).copy()
    bad = Registration(T, np.eye(3), np.inf, 0.0, 0, np.inf, False)
    if p.shape[0] < cfg.min_points or q.shape[0] < cfg.min_points:
        return bad
    if index is None:
        index = NearestIndex(q, cfg.block)
    elif index.dst.shape != q.shape or not np.array_equal(index.dst, q):
        raise ValueError(f"register_points: the index was built on other points ({index.dst.shape[0]}) than the "
                         f"map's ({q.shape[0]}); build NearestIndex(a_points) on the map passed")
    it = 0
    gate = cfg.max_distance
    px, py = p[:, 0].copy(), p[:, 1].copy()
    qx, qy = q[:, 0].copy(), q[:, 1].copy()
    nqx, nqy = nq[:, 0].copy(), nq[:, 1].copy()
    damp = 1e-9 * np.eye(3)
    tx, ty, th = (float(v) for v in T)
    fast = index._kernel  # the compiled terms of an iteration (the same arithmetic), or numpy below
    if fast is not None:
        jb, db = np.empty(p.shape[0], dtype=np.int64), np.empty(p.shape[0])
        Jb, wb, rb = np.empty((p.shape[0], 3)), np.empty(p.shape[0]), np.empty(p.shape[0])
    for it in range(1, cfg.max_iterations + 1):  # noqa: B007 - the count is reported
        c0, s0 = np.cos(th), np.sin(th)
        if fast is not None:
            m = fast.icp_terms(px, py, c0, s0, tx, ty, qx, qy, nqx, nqy, *index._grid, gate, cfg.huber,
                               jb, db, Jb, wb, rb)
            if m < cfg.min_points:
                return bad
            J, w, r = Jb[:m], wb[:m], rb[:m]
        else:
            J, w, r = _icp_terms(px, py, c0, s0, tx, ty, qx, qy, nqx, nqy, index, gate, cfg.huber)
            if r.shape[0] < cfg.min_points:
                return bad
        H = J.T @ (w[:, None] * J)
        bvec = -J.T @ (w * r)
        try:
            dx = np.linalg.solve(H + damp, bvec)
        except np.linalg.LinAlgError:
            return bad
        # left update: T <- Exp(dx) * T (small-angle first-order on translation about the origin)
        c, s = np.cos(dx[2]), np.sin(dx[2])
        tx, ty, th = c * tx - s * ty + dx[0], s * tx + c * ty + dx[1], g.wrap(float(th + dx[2]))
        gate = max(cfg.min_distance, 0.7 * gate)
        if np.hypot(dx[0], dx[1]) < 1e-5 and abs(dx[2]) < 1e-5 and gate <= cfg.min_distance:
            break
    T = np.array([tx, ty, th])
    # final statistics at the converged pose with the tight gate
    pa = g.transform_points(T, p)
    j, d2 = index.query(pa, cfg.min_distance)
    sel = d2 < cfg.min_distance**2
    m = int(sel.sum())
    if m < cfg.min_points:
        return bad
    n = nq[j[sel]]
    r = np.sum(n * (pa[sel] - q[j[sel]]), axis=1)
    # right-perturbation Jacobian (own frame) of the point-to-line residual
    Jp = _pose_jacobian(T, p[sel])
    J = np.einsum("nk,nkj->nj", n, Jp)
    H = J.T @ J
    rms = float(np.sqrt(np.mean(r * r)))
    s2 = max(float(np.sum(r * r)) / max(m - 3, 1), cfg.sigma_floor**2)
    ev = np.linalg.eigvalsh(H)
    cond = float(ev[-1] / max(ev[0], 1e-300))
    cov = cfg.cov_inflation * s2 * np.linalg.pinv(H)
    frac = m / p.shape[0]
    ok = frac >= cfg.min_inlier_fraction and rms <= cfg.max_rms and cond <= cfg.max_condition
    return Registration(T, 0.5 * (cov + cov.T), rms, frac, it, cond, bool(ok))
