"""Compiled path smoothing of the planner: the shortest path through a corridor's portal boxes and its
grid-side string pull and validation (numba, :mod:`holoslam._jit` policy).

* :func:`corridor_path` -- :func:`funnel` (the funnel algorithm on the angular intervals the boxes subtend,
  :func:`_box_interval`), polished by :func:`refine` where the funnel path turns back; :func:`refine` (exact
  coordinate descent for the shortest polyline through boxes) is also the reference the tests compare the
  funnel with.
* :func:`string_pull` -- windowed shortcuts on the grid, checked with ``tiles.seg_free_tiles``;
  :func:`simplify_validate` drops collinear points and checks every segment the string pull did not.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._common_fast import clip_segment
from holoslam._jit import JIT
from holoslam.planning._fast.tiles import _point_free_bits, seg_free_tiles


@nb.njit(**JIT)
def _length(P):
    """Length of the polyline P (K, 2)."""
    s = 0.0
    for i in range(P.shape[0] - 1):
        s += math.hypot(P[i + 1, 0] - P[i, 0], P[i + 1, 1] - P[i, 1])
    return s


@nb.njit(**JIT)
def _best_on_segment(ax, ay, bx, by, px, py, qx, qy):
    """Point of segment p -> q minimising |x - a| + |x - b| (convex along the segment: ternary-free closed
    form through the reflection of b across the segment's line, clamped to the segment)."""
    dx = qx - px
    dy = qy - py
    L2 = dx * dx + dy * dy
    if L2 <= 0.0:
        return px, py
    # signed side of a and b w.r.t. the line
    sa = (ax - px) * dy - (ay - py) * dx
    sb = (bx - px) * dy - (by - py) * dx
    if sa * sb > 0.0:  # same side: reflect b
        t = ((bx - px) * dx + (by - py) * dy) / L2
        fx = px + t * dx
        fy = py + t * dy
        bx = 2.0 * fx - bx
        by = 2.0 * fy - by
        sb = -sb
    den = sa - sb
    if den == 0.0:  # a and b both on the line: the nearest point of the segment to a's projection
        t = ((ax - px) * dx + (ay - py) * dy) / L2
    else:
        # intersection of a -> b with the line, as a parameter along p -> q
        lam = sa / den
        ix = ax + lam * (bx - ax)
        iy = ay + lam * (by - ay)
        t = ((ix - px) * dx + (iy - py) * dy) / L2
    t = min(max(t, 0.0), 1.0)
    return px + t * dx, py + t * dy


@nb.njit(**JIT)
def _best_in_box(ax, ay, bx, by, u0, v0, u1, v1):
    """Point x of the closed box [u0, u1] x [v0, v1] minimising |x - a| + |x - b|."""
    # the segment a -> b meets the box: the middle of its clipped part
    dx = bx - ax
    dy = by - ay
    t0, t1 = clip_segment(ax, ay, dx, dy, u0, v0, u1, v1)
    if t0 <= t1:
        t = 0.5 * (t0 + t1)
        return min(max(ax + t * dx, u0), u1), min(max(ay + t * dy, v0), v1)
    best = np.inf
    rx, ry = u0, v0
    for k in range(4):
        if k == 0:
            px, py, qx, qy = u0, v0, u1, v0
        elif k == 1:
            px, py, qx, qy = u1, v0, u1, v1
        elif k == 2:
            px, py, qx, qy = u1, v1, u0, v1
        else:
            px, py, qx, qy = u0, v1, u0, v0
        x, y = _best_on_segment(ax, ay, bx, by, px, py, qx, qy)
        c = math.hypot(x - ax, y - ay) + math.hypot(x - bx, y - by)
        if c < best:
            best = c
            rx, ry = x, y
    return rx, ry


@nb.njit(**JIT)
def refine(su, sv, gu, gv, boxes, sweeps, tol):
    """Shortest polyline start -> p_1 -> ... -> p_m -> goal with each p_i in the closed box
    ``boxes[i] = (u0, v0, u1, v1)`` (a convex problem), by alternating forward and backward exact
    coordinate updates from the box centres until no point moves more than ``tol`` or ``sweeps`` sweeps.
    Returns the (m + 2, 2) points."""
    m = boxes.shape[0]
    P = np.empty((m + 2, 2), dtype=np.float64)
    P[0, 0], P[0, 1] = su, sv
    P[m + 1, 0], P[m + 1, 1] = gu, gv
    for i in range(m):
        P[i + 1, 0] = 0.5 * (boxes[i, 0] + boxes[i, 2])
        P[i + 1, 1] = 0.5 * (boxes[i, 1] + boxes[i, 3])
    for it in range(sweeps):
        moved = 0.0
        for s in range(m):
            i = s if it % 2 == 0 else m - 1 - s
            x, y = _best_in_box(
                P[i, 0], P[i, 1], P[i + 2, 0], P[i + 2, 1], boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3]
            )
            mv = abs(x - P[i + 1, 0]) + abs(y - P[i + 1, 1])
            if mv > moved:
                moved = mv
            P[i + 1, 0] = x
            P[i + 1, 1] = y
        if moved <= tol:
            break
    return P


@nb.njit(**JIT)
def _box_interval_exact(ax, ay, b, i):
    """Absolute angular interval (lo, hi, lo corner u, v, hi corner u, v, inside) of box ``b[i]`` seen from
    (ax, ay); ``inside`` when the point lies in the closed box (no constraint). Five atan2 calls: the
    reference of :func:`_box_interval`."""
    u0, v0, u1, v1 = b[i, 0], b[i, 1], b[i, 2], b[i, 3]
    if u0 <= ax <= u1 and v0 <= ay <= v1:
        return 0.0, 0.0, ax, ay, ax, ay, True
    cx = 0.5 * (u0 + u1) - ax
    cy = 0.5 * (v0 + v1) - ay
    tc = math.atan2(cy, cx)
    lo = np.inf
    hi = -np.inf
    lu = lv = hu = hv = 0.0
    ld = hd = np.inf
    for k in range(4):
        x = u0 if (k == 0 or k == 3) else u1
        y = v0 if k < 2 else v1
        dx = x - ax
        dy = y - ay
        r = math.atan2(cx * dy - cy * dx, cx * dx + cy * dy)
        d2 = dx * dx + dy * dy
        # ties (corners on one ray from the point): the nearer corner is where a path touching the box
        # bends
        if r < lo - 1e-12 or (r <= lo + 1e-12 and d2 < ld):
            lo, lu, lv, ld = min(r, lo), x, y, d2
        if r > hi + 1e-12 or (r >= hi - 1e-12 and d2 < hd):
            hi, hu, hv, hd = max(r, hi), x, y, d2
    return tc + lo, tc + hi, lu, lv, hu, hv, False


@nb.njit(**JIT)
def _box_interval(ax, ay, b, i):
    """:func:`_box_interval_exact` (the same result) with fewer atan2 calls, the funnel's main cost: when
    every corner lies within 90 degrees of the direction to the box centre, a corner's angle from that
    direction, atan2(cross, dot), is monotone in cross / dot, so only the corners whose ratio is within a
    tolerance of the smallest (largest), far wider than the exact rule's 1e-12 rad tie band, can give the
    low (high) end and only they pay for atan2; other cases go to the exact function."""
    u0, v0, u1, v1 = b[i, 0], b[i, 1], b[i, 2], b[i, 3]
    if u0 <= ax <= u1 and v0 <= ay <= v1:
        return 0.0, 0.0, ax, ay, ax, ay, True
    cx = 0.5 * (u0 + u1) - ax
    cy = 0.5 * (v0 + v1) - ay
    xs = (u0, u1, u1, u0)
    ys = (v0, v0, v1, v1)
    tmin = np.inf
    tmax = -np.inf
    for k in range(4):
        dx = xs[k] - ax
        dy = ys[k] - ay
        d = cx * dx + cy * dy
        if d <= 0.0:
            return _box_interval_exact(ax, ay, b, i)
        t = (cx * dy - cy * dx) / d
        tmin = min(tmin, t)
        tmax = max(tmax, t)
    # a ratio gap dt is an angle gap >= dt / (1 + t^2): 8e-12 rad here, plus float rounding
    band_lo = tmin + 8e-12 * (1.0 + tmin * tmin) + 1e-13 * (1.0 + abs(tmin))
    band_hi = tmax - 8e-12 * (1.0 + tmax * tmax) - 1e-13 * (1.0 + abs(tmax))
    tc = math.atan2(cy, cx)
    lo = np.inf
    hi = -np.inf
    lu = lv = hu = hv = 0.0
    ld = hd = np.inf
    for k in range(4):
        x = xs[k]
        y = ys[k]
        dx = x - ax
        dy = y - ay
        d = cx * dx + cy * dy
        c = cx * dy - cy * dx
        t = c / d
        near_lo = t <= band_lo
        near_hi = t >= band_hi
        if not (near_lo or near_hi):
            continue
        r = math.atan2(c, d)
        d2 = dx * dx + dy * dy
        if near_lo and (r < lo - 1e-12 or (r <= lo + 1e-12 and d2 < ld)):
            lo, lu, lv, ld = min(r, lo), x, y, d2
        if near_hi and (r > hi + 1e-12 or (r >= hi - 1e-12 and d2 < hd)):
            hi, hu, hv, hd = max(r, hi), x, y, d2
    return tc + lo, tc + hi, lu, lv, hu, hv, False


@nb.njit(**JIT)
def funnel(su, sv, gu, gv, boxes):
    """Shortest polyline start -> goal passing through the closed boxes ``boxes[i] = (u0, v0, u1, v1)`` in
    order, where consecutive boxes (and the start / goal with the first / last box) lie in one convex region:
    the funnel algorithm on angular intervals seen from the current apex. A straight piece from the apex that
    meets boxes i..j is covered by the regions between them, so it is collision-free. Returns (K, 2)."""
    m = boxes.shape[0]
    # boxes plus the goal as a degenerate last box
    B = np.empty((m + 1, 4), dtype=np.float64)
    B[:m] = boxes
    B[m, 0] = gu
    B[m, 2] = gu
    B[m, 1] = gv
    B[m, 3] = gv
    out = np.empty((m + 2, 2), dtype=np.float64)
    out[0, 0], out[0, 1] = su, sv
    n_out = 1
    ax, ay = su, sv
    i = 0
    guard = 0
    while True:
        guard += 1
        if guard > 4 * (m + 2) * (m + 2):  # cannot happen: every restart moves the apex forward
            break
        has = False
        L = H = 0.0
        lu = lv = hu = hv = 0.0
        li = hi_i = -1
        bent = False
        j = i
        while j <= m:
            bl, bh, blu, blv, bhu, bhv, inside = _box_interval(ax, ay, B, j)
            if not inside:
                if not has:
                    L, H, lu, lv, hu, hv, li, hi_i = bl, bh, blu, blv, bhu, bhv, j, j
                    has = True
                else:
                    # bring the box interval next to the funnel (angles mod 2 pi)
                    k = np.rint(((bl + bh) - (L + H)) / (4.0 * math.pi))
                    bl -= 2.0 * math.pi * k
                    bh -= 2.0 * math.pi * k
                    if bh < L:  # wholly on the low side: bend at the low corner
                        ax, ay = lu, lv
                        i = li + 1 if li < m else m
                        bent = True
                        break
                    if bl > H:
                        ax, ay = hu, hv
                        i = hi_i + 1 if hi_i < m else m
                        bent = True
                        break
                    if bl >= L:
                        L, lu, lv, li = bl, blu, blv, j
                    if bh <= H:
                        H, hu, hv, hi_i = bh, bhu, bhv, j
            j += 1
        if bent:
            out[n_out, 0], out[n_out, 1] = ax, ay
            n_out += 1
            if n_out >= m + 1:
                break
            continue
        break
    out[n_out, 0], out[n_out, 1] = gu, gv
    n_out += 1
    return out[:n_out].copy()


@nb.njit(**JIT)
def corridor_path(su, sv, gu, gv, boxes, sweeps):
    """The path through a corridor's portal boxes: the funnel path; where it turns back on itself (two
    consecutive pieces at more than 90 degrees: the funnel bends at box corners only, while the optimum may
    touch a box edge and turn back there) also ``refine`` from the box centres for ``sweeps`` sweeps, and
    the shorter wins (so never longer than the polyline through the box centres in that case)."""
    f = funnel(su, sv, gu, gv, boxes)
    back = False
    for i in range(1, f.shape[0] - 1):
        if (f[i, 0] - f[i - 1, 0]) * (f[i + 1, 0] - f[i, 0]) + (f[i, 1] - f[i - 1, 1]) * (
            f[i + 1, 1] - f[i, 1]
        ) < 0:
            back = True
            break
    if not back:
        return f
    r = refine(su, sv, gu, gv, boxes, sweeps, 1e-9)
    return r if _length(r) < _length(f) else f


@nb.njit(**JIT)
def string_pull(bits, tclear, h, w, pts, window, passes, eps):
    """Windowed string pulling on the grid: from each kept point jump to the farthest of the next ``window``
    points in line of sight (exact ``seg_free_tiles`` on the tiled mask of the (h, w) grid; all pairs when
    the path has at most ``window`` + 1 points), ``passes`` times. Shortcuts leave the corridor where the
    grid allows it (through regions the corridor does not list). The funnel path is taut, so most shortcuts
    fail, near the corner they cut: the few cells of the shortcut nearest to the first skipped point are
    checked first (:func:`_near_corner_blocked`) and a failure there rejects it without walking the rest;
    an accepted shortcut is always checked whole. Returns (kept points (K, 2), checked (K - 1,)):
    ``checked[q]`` when segment q -> q + 1 passed ``seg_free_tiles`` here (a shortcut), False for a segment
    of the input kept as it was."""
    cur = pts.copy()
    chk = np.zeros(max(cur.shape[0] - 1, 0), dtype=np.bool_)
    for _ in range(passes):
        k = cur.shape[0]
        if k <= 2:
            return cur, chk
        keep = np.empty(k, dtype=np.int64)
        kc = np.empty(k, dtype=np.bool_)
        nk = 1
        keep[0] = 0
        i = 0
        allpairs = k <= window + 1
        while i < k - 1:
            last = k - 1 if allpairs else min(i + window, k - 1)
            nxt = i + 1
            for j in range(last, i + 1, -1):
                if _near_corner_blocked(bits, tclear, h, w, cur, i, j, eps):
                    continue
                if seg_free_tiles(bits, tclear, h, w, cur[i, 0], cur[i, 1], cur[j, 0], cur[j, 1], eps):
                    nxt = j
                    break
            kc[nk - 1] = True if nxt > i + 1 else chk[i]
            i = nxt
            keep[nk] = i
            nk += 1
        out = np.empty((nk, 2), dtype=np.float64)
        for q in range(nk):
            out[q, 0] = cur[keep[q], 0]
            out[q, 1] = cur[keep[q], 1]
        chk = kc[: nk - 1].copy()
        if nk == k or allpairs:
            return out, chk
        cur = out
    return cur, chk


@nb.njit(**JIT)
def _near_corner_blocked(bits, tclear, h, w, pts, i, j, eps):
    """True when the part of segment pts[i] -> pts[j] within 2 cells (along it) of its point nearest to
    pts[i + 1] fails ``seg_free_tiles``: then so does the whole segment, except in float-degenerate cases
    (pieces on grid lines, judged within ``eps`` differently once cut), where a shortcut is merely missed."""
    au, av = pts[i, 0], pts[i, 1]
    du, dv = pts[j, 0] - au, pts[j, 1] - av
    L2 = du * du + dv * dv
    if L2 <= 0.0:
        return False
    t = ((pts[i + 1, 0] - au) * du + (pts[i + 1, 1] - av) * dv) / L2
    r = 2.0 / math.sqrt(L2)
    t0 = min(max(t - r, 0.0), 1.0)
    t1 = min(max(t + r, 0.0), 1.0)
    if t1 <= t0:
        return False
    return not seg_free_tiles(bits, tclear, h, w, au + du * t0, av + dv * t0, au + du * t1, av + dv * t1, eps)


@nb.njit(**JIT)
def simplify_validate(bits, tclear, h, w, pts, checked, eps, tol):
    """Drop the points where the polyline does not turn (|cross| <= tol * |a| * |b|, same direction), then
    check every remaining segment exactly on the grid (``seg_free_tiles``) but those ``checked`` already (segment
    q -> q + 1 of ``pts`` passed ``seg_free_tiles`` and both ends are kept). Returns (points, ok)."""
    k = pts.shape[0]
    keep = np.empty(k, dtype=np.int64)
    nk = 1
    keep[0] = 0
    for i in range(1, k - 1):
        p = keep[nk - 1]
        ax = pts[i, 0] - pts[p, 0]
        ay = pts[i, 1] - pts[p, 1]
        bx = pts[i + 1, 0] - pts[i, 0]
        by = pts[i + 1, 1] - pts[i, 1]
        la = math.hypot(ax, ay)
        lb = math.hypot(bx, by)
        if la <= 1e-12:
            continue
        if lb > 1e-12 and (abs(ax * by - ay * bx) > tol * la * lb or ax * bx + ay * by < 0.0):
            keep[nk] = i
            nk += 1
    if k > 1:
        keep[nk] = k - 1
        nk += 1
    out = np.empty((nk, 2), dtype=np.float64)
    for q in range(nk):
        out[q, 0] = pts[keep[q], 0]
        out[q, 1] = pts[keep[q], 1]
    for q in range(nk - 1):
        if keep[q + 1] == keep[q] + 1 and checked[keep[q]]:
            continue
        if not seg_free_tiles(bits, tclear, h, w, out[q, 0], out[q, 1], out[q + 1, 0], out[q + 1, 1], eps):
            return out, False
    if nk == 1 and not _point_free_bits(bits, h, w, out[0, 0], out[0, 1], eps):
        return out, False
    return out, True
