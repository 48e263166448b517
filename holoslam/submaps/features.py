"""Scan features H = {point, line, corner, crossing} (seed 002 Eq. 10) from ordered 2-D scan points.

* Lines: the ordered beam end points are cut into runs where consecutive points are farther apart than
  ``gap`` (plus a range-proportional allowance for the beam spacing); each run is split recursively at the
  point farthest from the chord (split-and-merge) until every piece is within ``split_tol`` of its chord; pieces
  with at least ``min_points`` points and ``min_length`` metres get a total-least-squares line (PCA), and
  adjacent collinear pieces are merged. A segment is stored as its end points projected onto the fitted line.
* Corners: two segments with an end of each within ``corner_gap`` (+ ``gap_per_m`` per metre of range, as
  beams spread) of the other meeting at an angle
  between ``corner_min_angle`` and 180 - that angle: the intersection of their lines.
* Crossings: intersections of the extended lines of two non-adjacent segments at an angle of at least
  ``corner_min_angle`` that lie within ``extend`` metres beyond the ends of both segments (a doorway edge, the
  hidden corner behind furniture), excluding points that already are corners.
* Points: small isolated clusters (runs shorter than ``point_max_extent``, e.g. table and chair legs), by their
  centroid.

Per-point work is vectorised with numpy; the split of all runs of a scan is one compiled call
(``_fast.split_pieces``, the arithmetic of :func:`_split`), and each piece's line is fitted once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["FeatureConfig", "ScanFeatures", "extract_features", "split_runs", "fit_line", "transform_features"]


@dataclass(frozen=True, slots=True)
class FeatureConfig:
    gap: float = 0.15  # m between consecutive beams of one run
    gap_per_m: float = 0.05  # extra allowance per metre of range (beam spacing)
    split_tol: float = 0.03  # m
    min_points: int = 6
    min_length: float = 0.3  # m
    merge_angle_deg: float = 5.0
    corner_gap: float = 0.2  # m
    corner_min_angle_deg: float = 45.0
    extend: float = 1.0  # m
    point_max_extent: float = 0.12  # m
    point_min_points: int = 2


@dataclass(frozen=True, slots=True)
class ScanFeatures:
    """Features in one frame: ``segments`` (S, 4) x0 y0 x1 y1, ``lines`` (S, 3) unit normal (nx, ny) and
    offset d with n . p = d, ``corners`` (C, 2), ``crossings`` (X, 2), ``points`` (P, 2)."""

    segments: np.ndarray
    lines: np.ndarray
    corners: np.ndarray
    crossings: np.ndarray
    points: np.ndarray


def split_runs(points: np.ndarray, gap: float = 0.15, gap_per_m: float = 0.05) -> list[tuple[int, int]]:
    """[start, end) index ranges of runs of ordered points whose neighbours are close."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return []
    d = np.hypot(*np.diff(pts, axis=0).T)
    rng = np.hypot(pts[:, 0], pts[:, 1])
    lim = gap + gap_per_m * np.maximum(rng[:-1], rng[1:])
    cuts = np.nonzero(d > lim)[0] + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [pts.shape[0]]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def fit_line(pts: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Total least squares line of (N, 2) points: unit normal n, offset d (n . p = d), and the segment (4,)
    between the projections of the first and last point."""
    c = pts.mean(axis=0)
    q = pts - c
    sxx, syy, sxy = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
    # the scatter's principal axis in closed form (what the SVD's first right singular vector spans)
    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    direction = np.array([math.cos(phi), math.sin(phi)])
    n = np.array([-direction[1], direction[0]])
    d = float(n @ c)
    t = (pts[[0, -1]] - c) @ direction
    seg = np.concatenate([c + t[0] * direction, c + t[1] * direction])
    return n, d, seg


def _split(pts: np.ndarray, tol: float, min_points: int) -> list[tuple[int, int]]:
    """Split-and-merge's split step: pieces [start, end) of one run, each within tol of its chord."""
    out: list[tuple[int, int]] = []
    stack = [(0, pts.shape[0])]
    x, y = pts[:, 0], pts[:, 1]
    while stack:
        a, b = stack.pop()
        if b - a < 3:
            out.append((a, b))
            continue
        x0, y0 = x[a], y[a]
        chx, chy = x[b - 1] - x0, y[b - 1] - y0
        L = np.hypot(chx, chy)
        sx, sy = x[a:b] - x0, y[a:b] - y0
        dist = np.abs(sx * chy - sy * chx) / L if L > 1e-9 else np.hypot(sx, sy)
        k = int(np.argmax(dist))
        if dist[k] > tol and 0 < k < b - a - 1:
            stack.append((a + k, b))
            stack.append((a, a + k + 1))
        else:
            out.append((a, b))
    return sorted(out)


def _split_all(
    pts: np.ndarray, runs: list[tuple[int, int]], lines: list[bool], tol: float
) -> dict[int, list[tuple[int, int]]]:
    """:func:`_split` of every run marked in ``lines``, keyed by the run's start, pieces relative to it: one
    compiled call for the scan (``_fast.split_pieces``, the same arithmetic), or run by run without numba."""
    todo = [ab for ab, keep in zip(runs, lines, strict=True) if keep]
    try:
        from holoslam.submaps._fast import split_pieces
    except ImportError:  # pragma: no cover - numba is a declared dependency
        return {a: _split(pts[a:b], tol, 0) for a, b in todo}
    out: dict[int, list[tuple[int, int]]] = {a: [] for a, _ in todo}
    if not todo:
        return out
    ra = np.array([a for a, _ in todo], dtype=np.int64)
    ps, pe = split_pieces(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), ra,
                          np.array([b for _, b in todo], dtype=np.int64), float(tol))
    owner = ra[np.searchsorted(ra, ps, side="right") - 1].tolist()
    for a, p0, p1 in zip(owner, ps.tolist(), pe.tolist(), strict=True):
        out[a].append((p0 - a, p1 - a))
    return out


def _line_intersections(lines_a: np.ndarray, lines_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intersections (K, 2) of pairs of lines (n, d) and |sin| of their angle (K,)."""
    n1, d1 = lines_a[:, :2], lines_a[:, 2]
    n2, d2 = lines_b[:, :2], lines_b[:, 2]
    det = n1[:, 0] * n2[:, 1] - n1[:, 1] * n2[:, 0]
    safe = np.where(np.abs(det) > 1e-9, det, 1.0)
    x = (d1 * n2[:, 1] - n1[:, 1] * d2) / safe
    y = (n1[:, 0] * d2 - d1 * n2[:, 0]) / safe
    return np.column_stack([x, y]), np.abs(det)


def _beyond(seg: np.ndarray, p: np.ndarray) -> np.ndarray:
    """How far p lies outside each segment along its direction (0 when its projection falls on it)."""
    a, b = seg[:, :2], seg[:, 2:]
    d = b - a
    L = np.hypot(*d.T)
    u = np.sum((p - a) * d, axis=1) / np.maximum(L, 1e-12)
    return np.maximum(np.maximum(-u, u - L), 0.0)


def extract_features(points: np.ndarray, config: FeatureConfig | None = None) -> ScanFeatures:
    """Features of one scan's ordered points (M, 2) (beam order, in any frame)."""
    cfg = config or FeatureConfig()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] > 2 and len(split_runs(pts[[-1, 0]], cfg.gap, cfg.gap_per_m)) == 1:
        # a full-circle scan whose last beam continues its first: start at the widest gap instead
        d = np.hypot(*np.diff(np.vstack([pts, pts[:1]]), axis=0).T)
        pts = np.roll(pts, -(int(np.argmax(d)) + 1), axis=0)
    segs: list[np.ndarray] = []
    lines: list[np.ndarray] = []
    blobs = []
    fits: dict[tuple[int, int], tuple[np.ndarray, float, np.ndarray]] = {}  # each piece is fitted once

    def fit(i0: int, i1: int) -> tuple[np.ndarray, float, np.ndarray]:
        if (i0, i1) not in fits:
            fits[i0, i1] = fit_line(pts[i0:i1])
        return fits[i0, i1]

    runs = split_runs(pts, cfg.gap, cfg.gap_per_m)
    pieces_of: dict[int, list[tuple[int, int]]] = {}
    if runs:  # the extent of every run at once, and the pieces of those that are not point features
        starts = np.array([a for a, _ in runs])
        span = np.maximum.reduceat(pts, starts, axis=0) - np.minimum.reduceat(pts, starts, axis=0)
        extents = np.hypot(span[:, 0], span[:, 1]).tolist()
        pieces_of = _split_all(pts, runs, [e > cfg.point_max_extent for e in extents], cfg.split_tol)
    for r, (a, b) in enumerate(runs):
        if extents[r] <= cfg.point_max_extent:
            if b - a >= cfg.point_min_points:
                blobs.append(pts[a:b].mean(axis=0))
            continue
        for pa, pb in _merged_pieces(pts[a:b], a, pieces_of[a], fit, cfg):
            n, d, seg = fit(a + pa, a + pb)
            if np.hypot(seg[2] - seg[0], seg[3] - seg[1]) < cfg.min_length:
                continue
            segs.append(seg)
            lines.append(np.array([n[0], n[1], d]))
    S = np.array(segs).reshape(-1, 4)
    Ln = np.array(lines).reshape(-1, 3)
    corners, crossings = _corners_and_crossings(S, Ln, cfg)
    return ScanFeatures(S, Ln, corners, crossings, np.array(blobs).reshape(-1, 2))


def _merged_pieces(run: np.ndarray, a: int, pieces: list[tuple[int, int]], fit, cfg: FeatureConfig
                   ) -> list[tuple[int, int]]:
    """The pieces (offsets in ``run``, which starts at point ``a``) with at least ``min_points`` points, adjacent
    collinear ones merged (normals within ``merge_angle_deg``, the next piece's points within 2 ``split_tol`` of
    the line so far)."""
    fitted: list[tuple[int, int, np.ndarray, float, np.ndarray] | None] = []
    for pa, pb in pieces:
        if pb - pa < cfg.min_points:
            fitted.append(None)
            continue
        n, d, seg = fit(a + pa, a + pb)
        fitted.append((pa, pb, n, d, seg))
    merged: list[tuple[int, int]] = []
    cos_tol = np.cos(np.radians(cfg.merge_angle_deg))
    for f in fitted:
        if f is None:
            merged.append((-1, -1))
            continue
        if merged and merged[-1][0] >= 0:
            pa0, pb0 = merged[-1]
            n0, d0, _ = fit(a + pa0, a + pb0)
            if abs(n0 @ f[2]) > cos_tol and np.max(np.abs(run[f[0]:f[1]] @ n0 - d0)) < 2 * cfg.split_tol:
                merged[-1] = (pa0, f[1])
                continue
        merged.append((f[0], f[1]))
    return [m for m in merged if m[0] >= 0]


def _corners_and_crossings(S: np.ndarray, Ln: np.ndarray, cfg: FeatureConfig) -> tuple[np.ndarray, np.ndarray]:
    """Corners: pairs of segments with two ends close together (adjacent along the scan or across the wrap of a
    full-circle scan) whose lines meet near both; crossings: the extended lines of non-adjacent segments, away
    from the corners."""
    corners = np.zeros((0, 2))
    crossings = np.zeros((0, 2))
    if S.shape[0] < 2:
        return corners, crossings
    sin_min = np.sin(np.radians(cfg.corner_min_angle_deg))
    i, j = np.triu_indices(S.shape[0], 1)
    ends_i = S[i].reshape(-1, 2, 2)
    ends_j = S[j].reshape(-1, 2, 2)
    dd = np.hypot(ends_i[:, :, None, 0] - ends_j[:, None, :, 0], ends_i[:, :, None, 1] - ends_j[:, None, :, 1])
    X, sn = _line_intersections(Ln[i], Ln[j])
    tol = cfg.corner_gap + cfg.gap_per_m * np.hypot(X[:, 0], X[:, 1])  # beams spread with range
    adjacent = dd.reshape(-1, 4).min(axis=1) < tol
    bi, bj = _beyond(S[i], X), _beyond(S[j], X)
    corner = adjacent & (sn >= sin_min) & (bi < tol) & (bj < tol)
    corners = X[corner]
    ok = ~adjacent & (sn >= sin_min) & (bi <= cfg.extend) & (bj <= cfg.extend)
    X = X[ok]
    if corners.shape[0] and X.shape[0]:
        dmin = np.min(np.hypot(X[:, None, 0] - corners[None, :, 0], X[:, None, 1] - corners[None, :, 1]), axis=1)
        X = X[dmin > cfg.corner_gap]
    return corners, X


def transform_features(aTb: np.ndarray, f: ScanFeatures) -> ScanFeatures:
    """The same features expressed in frame a (for putting a scan's features into its submap's anchor frame)."""
    from holoslam import geometry as g

    T = np.asarray(aTb, dtype=np.float64)
    seg = np.column_stack([g.transform_points(T, f.segments[:, :2]), g.transform_points(T, f.segments[:, 2:])])
    R = g.rot2(T[2])
    n = f.lines[:, :2] @ R.T
    d = f.lines[:, 2] + n @ T[:2]
    return ScanFeatures(seg.reshape(-1, 4), np.column_stack([n, d]).reshape(-1, 3),
                        g.transform_points(T, f.corners).reshape(-1, 2),
                        g.transform_points(T, f.crossings).reshape(-1, 2),
                        g.transform_points(T, f.points).reshape(-1, 2))
