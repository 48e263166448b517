"""The exact collision check of planned segments on a free mask, in cell-boundary coordinates (u = column
axis, v = row axis; cell (r, c) is the closed square [c, c + 1] x [r, r + 1]), and polyline lengths.

A segment is collision-free when every point of it lies in the closed union of free cells (exact up to
``EPS_CELLS`` = 1e-9 cells for float rounding): it may touch an obstacle's edge and pass diagonally between
two obstacle cells meeting at a corner, as an 8-connected grid planner does. :func:`segments_free` is the
vectorised reference; the compiled queries check with ``holoslam.planning._fast.tiles.seg_free_tiles``,
tested equal to it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["EPS_CELLS", "path_length", "segments_free"]

EPS_CELLS = 1e-9  # geometric tolerance of the collision check, in cells


def segments_free(free: np.ndarray, a_uv: np.ndarray, b_uv: np.ndarray, eps: float = EPS_CELLS) -> np.ndarray:
    """Exact collision check of segments a -> b (N, 2) in cell-boundary coordinates (u = col, v = row) on a
    free mask: True where every point of the segment lies in the closed union of free cells.

    Vectorised over all segments: each segment is cut at every integer u and v line it crosses; the middle of
    each piece lies inside one cell (or on a grid line, when the segment runs along it, where either side will
    do) and that cell must be free. Points outside the grid are not free. Coordinates within ``eps`` cells of
    a grid line count as on it, so round trips through world metres (float rounding) do not change the answer.
    """
    a = np.asarray(a_uv, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(b_uv, dtype=np.float64).reshape(-1, 2)
    n = a.shape[0]
    if n == 0:
        return np.zeros(0, dtype=bool)
    ts = [np.zeros(n), np.ones(n)]
    seg = [np.arange(n), np.arange(n)]
    for k in (0, 1):
        lo = np.minimum(a[:, k], b[:, k])
        hi = np.maximum(a[:, k], b[:, k])
        first = np.floor(lo + eps).astype(np.int64) + 1
        last = np.ceil(hi - eps).astype(np.int64) - 1
        cnt = np.maximum(last - first + 1, 0)
        if cnt.sum() == 0:
            continue
        s = np.repeat(np.arange(n), cnt)
        off = np.arange(s.shape[0]) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        val = (first[s] + off).astype(np.float64)
        ts.append((val - a[s, k]) / (b[s, k] - a[s, k]))
        seg.append(s)
    t = np.concatenate(ts)
    sg = np.concatenate(seg)
    order = np.lexsort((t, sg))
    t, sg = t[order], sg[order]
    same = sg[1:] == sg[:-1]
    tm = ((t[1:] + t[:-1]) / 2)[same]
    sm = sg[1:][same]
    p = a[sm] + (b[sm] - a[sm]) * tm[:, None]
    bad = np.zeros(n, dtype=bool)
    np.logical_or.at(bad, sm, ~_point_free(free, p, eps))
    # zero-length segments: the point itself must be in a free cell's closure
    zero = np.all(a == b, axis=1)
    if zero.any():
        bad[zero] = ~_point_free(free, a[zero], eps)
    return ~bad


def _point_free(free: np.ndarray, uv: np.ndarray, eps: float = EPS_CELLS) -> np.ndarray:
    """Points (N, 2) in the closed union of free cells; within ``eps`` of a grid line counts as on it."""
    h, w = free.shape
    ru, rv = np.rint(uv[:, 0]), np.rint(uv[:, 1])
    on_u = np.abs(uv[:, 0] - ru) <= eps
    on_v = np.abs(uv[:, 1] - rv) <= eps
    fu = np.where(on_u, ru, np.floor(uv[:, 0])).astype(np.int64)
    fv = np.where(on_v, rv, np.floor(uv[:, 1])).astype(np.int64)
    ok = np.zeros(uv.shape[0], dtype=bool)
    for du in (0, 1):
        cu = fu - du * on_u
        for dv in (0, 1):
            cv = fv - dv * on_v
            inside = (cu >= 0) & (cu < w) & (cv >= 0) & (cv < h)
            o = np.zeros(uv.shape[0], dtype=bool)
            o[inside] = free[cv[inside], cu[inside]]
            ok |= o
    return ok


def path_length(waypoints: np.ndarray) -> float:
    """Length of a polyline (K, 2) in its own units."""
    w = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
    if w.shape[0] < 2:
        return 0.0
    return float(np.hypot(*np.diff(w, axis=0).T).sum())
