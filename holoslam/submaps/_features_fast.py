"""Compiled scan features H (numba, ``cache=True``): :func:`holoslam.submaps.features.extract_features`'s rules
in one compiled pass per scan, and every scan of a submap in one call (:func:`scans_features`).

Runs of close beams, their split (``_fast.split_pieces``), total-least-squares lines of the pieces, the merge of
adjacent collinear pieces, small runs as point features, then the corners and crossings of every pair of
segments: the rules and their order are :mod:`holoslam.submaps.features`' (its docstring describes them). A
submap's features were a sixth of the household run's time under the GIL in Python; compiled, the front end's
worker no longer holds back the local SLAM beside it. Sums run in index order (numpy's dot products may add
in another order: segment ends agree to ~1e-15 m).

Imported lazily by :mod:`holoslam.submaps.features`; the first call compiles, later processes load the kernels
from numba's on-disk cache next to this file.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_INNER
from holoslam.submaps._fast import split_pieces


@nb.njit(**JIT)
def _fit(x, y, a, b):  # pragma: no cover - compiled
    """``features.fit_line`` of the points [a, b): normal (nx, ny), offset d, segment (x0, y0, x1, y1)."""
    k = b - a
    cx = cy = 0.0
    for i in range(a, b):
        cx += x[i]
        cy += y[i]
    cx /= k
    cy /= k
    sxx = syy = sxy = 0.0
    for i in range(a, b):
        qx, qy = x[i] - cx, y[i] - cy
        sxx += qx * qx
        syy += qy * qy
        sxy += qx * qy
    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux, uy = math.cos(phi), math.sin(phi)
    nx, ny = -uy, ux
    d = nx * cx + ny * cy
    t0 = (x[a] - cx) * ux + (y[a] - cy) * uy
    t1 = (x[b - 1] - cx) * ux + (y[b - 1] - cy) * uy
    return nx, ny, d, cx + t0 * ux, cy + t0 * uy, cx + t1 * ux, cy + t1 * uy


@nb.njit(**JIT_INNER)
def _ordered(px, py, gap, gap_per_m):  # pragma: no cover - compiled
    """The points, a full-circle scan whose last beam continues its first started at its widest gap instead."""
    n = px.size
    if n > 2:
        lim = gap + gap_per_m * max(math.hypot(px[n - 1], py[n - 1]), math.hypot(px[0], py[0]))
        if not math.hypot(px[0] - px[n - 1], py[0] - py[n - 1]) > lim:
            k, best = 0, -1.0
            for i in range(n):
                j = (i + 1) % n
                d = math.hypot(px[j] - px[i], py[j] - py[i])
                if d > best:
                    k, best = i, d
            x, y = np.empty(n, dtype=np.float64), np.empty(n, dtype=np.float64)
            for i in range(n):
                x[i], y[i] = px[(i + k + 1) % n], py[(i + k + 1) % n]
            return x, y
    return px.copy(), py.copy()


@nb.njit(**JIT)
def _runs(x, y, gap, gap_per_m):  # pragma: no cover - compiled
    """``features.split_runs``: [start, end) of the runs of close consecutive points."""
    n = x.size
    starts = np.empty(n, dtype=np.int64)
    ends = np.empty(n, dtype=np.int64)
    m = 0
    if n == 0:
        return starts[:0], ends[:0]
    starts[0] = 0
    for i in range(n - 1):
        lim = gap + gap_per_m * max(math.hypot(x[i], y[i]), math.hypot(x[i + 1], y[i + 1]))
        if math.hypot(x[i + 1] - x[i], y[i + 1] - y[i]) > lim:
            ends[m] = i + 1
            m += 1
            starts[m] = i + 1
    ends[m] = n
    return starts[:m + 1], ends[:m + 1]


@nb.njit(**JIT)
def _extent(x, y, a, b):  # pragma: no cover - compiled
    x0 = x1 = x[a]
    y0 = y1 = y[a]
    for i in range(a + 1, b):
        x0, x1 = min(x0, x[i]), max(x1, x[i])
        y0, y1 = min(y0, y[i]), max(y1, y[i])
    return math.hypot(x1 - x0, y1 - y0)


@nb.njit(**JIT_INNER)
def _segments(x, y, starts, ends, is_line, split_tol, min_points, min_length, cos_merge):  # pragma: no cover
    """Segments (S, 4) and lines (S, 3) of the runs marked ``is_line``: their split pieces of ``min_points`` or
    more, adjacent collinear ones merged (``features._merged_pieces``), those ``min_length`` long or more."""
    nr = 0
    for r in range(starts.size):  # the marked runs (a loop: numba compiles a boolean mask's indexing slowly)
        nr += is_line[r]
    ra, rb = np.empty(nr, dtype=np.int64), np.empty(nr, dtype=np.int64)
    q = 0
    for r in range(starts.size):
        if is_line[r]:
            ra[q], rb[q] = starts[r], ends[r]
            q += 1
    ps, pe = split_pieces(x, y, ra, rb, split_tol)
    segs = np.empty((ps.size, 4), dtype=np.float64)
    lines = np.empty((ps.size, 3), dtype=np.float64)
    ns, q, big = 0, 0, 2.0 * split_tol
    ma = np.empty(ps.size, dtype=np.int64)  # the merged pieces of one run; -1: a short piece, which ends a merge
    mb = np.empty(ps.size, dtype=np.int64)
    for r in range(ra.size):
        nm = 0
        while q < ps.size and ps[q] < rb[r]:
            a, b = ps[q], pe[q]
            q += 1
            if b - a < min_points:
                ma[nm], mb[nm] = -1, -1
                nm += 1
                continue
            if nm and ma[nm - 1] >= 0:
                n0x, n0y, d0, _s0, _s1, _s2, _s3 = _fit(x, y, ma[nm - 1], mb[nm - 1])
                n1x, n1y, _d, _t0, _t1, _t2, _t3 = _fit(x, y, a, b)
                if abs(n0x * n1x + n0y * n1y) > cos_merge:
                    worst = 0.0
                    for i in range(a, b):
                        worst = max(worst, abs(x[i] * n0x + y[i] * n0y - d0))
                    if worst < big:
                        mb[nm - 1] = b
                        continue
            ma[nm], mb[nm] = a, b
            nm += 1
        for k in range(nm):
            if ma[k] < 0:
                continue
            nx, ny, d, s0, s1, s2, s3 = _fit(x, y, ma[k], mb[k])
            if math.hypot(s2 - s0, s3 - s1) < min_length:
                continue
            segs[ns, 0], segs[ns, 1], segs[ns, 2], segs[ns, 3] = s0, s1, s2, s3
            lines[ns, 0], lines[ns, 1], lines[ns, 2] = nx, ny, d
            ns += 1
    return segs[:ns], lines[:ns]


@nb.njit(**JIT_INNER)
def _beyond(s, px, py):  # pragma: no cover - compiled
    """How far (px, py) lies outside segment s along its direction (``features._beyond``)."""
    dx, dy = s[2] - s[0], s[3] - s[1]
    L = math.hypot(dx, dy)
    u = ((px - s[0]) * dx + (py - s[1]) * dy) / max(L, 1e-12)
    return max(max(-u, u - L), 0.0)


@nb.njit(**JIT_INNER)
def _corners_and_crossings(S, Ln, corner_gap, gap_per_m, sin_min, extend):  # pragma: no cover - compiled
    """``features._corners_and_crossings``: corners (C, 2) and crossings (X, 2) of the pairs i < j in order."""
    ns = S.shape[0]
    npair = ns * (ns - 1) // 2
    corners = np.empty((npair, 2), dtype=np.float64)
    cross = np.empty((npair, 2), dtype=np.float64)
    nc = nx = 0
    for i in range(ns):
        for j in range(i + 1, ns):
            det = Ln[i, 0] * Ln[j, 1] - Ln[i, 1] * Ln[j, 0]
            safe = det if abs(det) > 1e-9 else 1.0
            px = (Ln[i, 2] * Ln[j, 1] - Ln[i, 1] * Ln[j, 2]) / safe
            py = (Ln[i, 0] * Ln[j, 2] - Ln[i, 2] * Ln[j, 0]) / safe
            if not abs(det) >= sin_min:
                continue
            tol = corner_gap + gap_per_m * math.hypot(px, py)
            dd = np.inf
            for e in range(2):
                for f in range(2):
                    dd = min(dd, math.hypot(S[i, 2 * e] - S[j, 2 * f], S[i, 2 * e + 1] - S[j, 2 * f + 1]))
            bi, bj = _beyond(S[i], px, py), _beyond(S[j], px, py)
            if dd < tol:
                if bi < tol and bj < tol:
                    corners[nc, 0], corners[nc, 1] = px, py
                    nc += 1
            elif bi <= extend and bj <= extend:
                cross[nx, 0], cross[nx, 1] = px, py
                nx += 1
    keep = 0
    for k in range(nx):  # crossings away from every corner
        dmin = np.inf
        for c in range(nc):
            dmin = min(dmin, math.hypot(cross[k, 0] - corners[c, 0], cross[k, 1] - corners[c, 1]))
        if nc == 0 or dmin > corner_gap:
            cross[keep, 0], cross[keep, 1] = cross[k, 0], cross[k, 1]
            keep += 1
    return corners[:nc], cross[:keep]


@nb.njit(**JIT, inline="always")  # one caller in a run (scans_features): not compiled a second time on its own
def scan_features(px, py, gap, gap_per_m, split_tol, min_points, min_length, cos_merge, corner_gap, sin_min,
                  extend, point_max_extent, point_min_points):  # pragma: no cover - compiled
    """Features of one scan's ordered points (px, py): segments (S, 4), lines (S, 3), corners (C, 2),
    crossings (X, 2), points (P, 2), in the points' frame (``features.FeatureConfig``'s settings)."""
    x, y = _ordered(px, py, gap, gap_per_m)
    starts, ends = _runs(x, y, gap, gap_per_m)
    is_line = np.zeros(starts.size, dtype=np.bool_)
    blobs = np.empty((starts.size, 2), dtype=np.float64)
    nb_ = 0
    for r in range(starts.size):
        a, b = starts[r], ends[r]
        if _extent(x, y, a, b) > point_max_extent:
            is_line[r] = True
        elif b - a >= point_min_points:
            sx = sy = 0.0
            for i in range(a, b):
                sx += x[i]
                sy += y[i]
            blobs[nb_, 0], blobs[nb_, 1] = sx / (b - a), sy / (b - a)
            nb_ += 1
    segs, lines = _segments(x, y, starts, ends, is_line, split_tol, min_points, min_length, cos_merge)
    if segs.shape[0] < 2:
        return segs, lines, np.zeros((0, 2), dtype=np.float64), np.zeros((0, 2), dtype=np.float64), blobs[:nb_]
    corners, cross = _corners_and_crossings(segs, lines, corner_gap, gap_per_m, sin_min, extend)
    return segs, lines, corners, cross, blobs[:nb_]


@nb.njit(**JIT_INNER)
def _moved(P, c, s, tx, ty):  # pragma: no cover - compiled
    """Points (N, 2) in place: R(theta) p + t (``geometry.transform_points``'s arithmetic)."""
    for i in range(P.shape[0]):
        x, y = P[i, 0], P[i, 1]
        P[i, 0] = tx + c * x - s * y
        P[i, 1] = ty + s * x + c * y


@nb.njit(**JIT_INNER)
def _put(buf, n, rows):  # pragma: no cover - compiled
    """``rows`` appended to the first ``n`` rows of ``buf`` (a new buffer of twice the size when full)."""
    k, w = rows.shape[0], buf.shape[1]
    if n + k > buf.shape[0]:  # element loops: numba's compile of 2-D slice assignment costs seconds
        grown = np.empty((max(2 * buf.shape[0], n + k), w), dtype=np.float64)
        for i in range(n):
            for c in range(w):
                grown[i, c] = buf[i, c]
        buf = grown
    for i in range(k):
        for c in range(w):
            buf[n + i, c] = rows[i, c]
    return buf, n + k


@nb.njit(**JIT)
def scans_features(x, y, start, poses, gap, gap_per_m, split_tol, min_points, min_length, cos_merge, corner_gap,
                   sin_min, extend, point_max_extent, point_min_points):  # pragma: no cover - compiled
    """:func:`scan_features` of every scan k (points [start[k], start[k + 1]) of x, y) moved into one frame by
    its pose ``poses[k]`` (``features.transform_features``), stacked in scan order."""
    segs_all, lines_all = np.empty((64, 4), dtype=np.float64), np.empty((64, 3), dtype=np.float64)
    corners_all, cross_all, blobs_all = np.empty((64, 2), dtype=np.float64), np.empty((64, 2), dtype=np.float64), np.empty((64, 2), dtype=np.float64)
    ns = nl = nc = nx = nb_ = np.int64(0)  # not the literal 0: numba would compile _put once more for its type
    for k in range(poses.shape[0]):
        a, b = start[k], start[k + 1]
        segs, lines, corners, cross, blobs = scan_features(
            x[a:b].copy(), y[a:b].copy(), gap, gap_per_m, split_tol, min_points, min_length, cos_merge, corner_gap,
            sin_min, extend, point_max_extent, point_min_points)
        tx, ty, th = poses[k, 0], poses[k, 1], poses[k, 2]
        c, s = math.cos(th), math.sin(th)
        for i in range(segs.shape[0]):
            for e in range(2):
                sx, sy = segs[i, 2 * e], segs[i, 2 * e + 1]
                segs[i, 2 * e], segs[i, 2 * e + 1] = tx + c * sx - s * sy, ty + s * sx + c * sy
            nx_, ny_ = lines[i, 0], lines[i, 1]
            lines[i, 0], lines[i, 1] = c * nx_ - s * ny_, s * nx_ + c * ny_
            lines[i, 2] = lines[i, 2] + (lines[i, 0] * tx + lines[i, 1] * ty)
        _moved(corners, c, s, tx, ty)
        _moved(cross, c, s, tx, ty)
        _moved(blobs, c, s, tx, ty)
        segs_all, ns = _put(segs_all, ns, segs)
        lines_all, nl = _put(lines_all, nl, lines)
        corners_all, nc = _put(corners_all, nc, corners)
        cross_all, nx = _put(cross_all, nx, cross)
        blobs_all, nb_ = _put(blobs_all, nb_, blobs)
    return segs_all[:ns], lines_all[:nl], corners_all[:nc], cross_all[:nx], blobs_all[:nb_]
