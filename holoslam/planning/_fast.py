"""Compiled query kernels of the two-layer planner (numba, ``cache=True``).

Imported lazily by :func:`holoslam.planning.routes.build_planner` (importing numba costs about half a second
and the first call of each kernel compiles it, about 10 s once per machine, then loads it from numba's
on-disk cache next to this file). Every kernel is a plain function of numpy arrays.

* :func:`query` -- one whole planning query between two located points (see ``routes`` for the steps):
  :func:`corridor_astar` (A* over the port graph with Euclidean + ALT landmark heuristic), corridor trimming,
  :func:`corridor_path` (:func:`funnel`, polished by :func:`refine` where the funnel path turns back) on the
  corridor and on its greedy shortcut (:func:`shortcut_corridor`), :func:`string_pull` on the grid and
  :func:`simplify_validate` (collinear points dropped, every segment checked exactly by :func:`seg_free`).
* :func:`seg_free` -- the exact segment test of ``routes.segments_free`` (the same cut-at-grid-lines,
  midpoint-in-a-free-cell rule with the same ``eps``), without allocation.
* :func:`refine` -- exact coordinate descent for the shortest polyline through boxes; also the reference the
  tests compare the funnel with.
* Build kernels of :mod:`holoslam.planning.twolayer`: :func:`label_image`, :func:`block_edges` (layer-1
  adjacency from the label image) and :func:`grow_regions` (layer 2), each tested equal to the numpy
  reference it replaced (4000 x 4000 tiled household: both layers 2.4 s -> 1.0 s).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_JIT = {"cache": True, "nogil": True}


@nb.njit(**_JIT)
def _point_free(free, u, v, eps):
    h, w = free.shape
    ru = np.rint(u)
    rv = np.rint(v)
    on_u = abs(u - ru) <= eps
    on_v = abs(v - rv) <= eps
    fu = np.int64(ru) if on_u else np.int64(math.floor(u))
    fv = np.int64(rv) if on_v else np.int64(math.floor(v))
    for du in range(2):
        if du == 1 and not on_u:
            break
        cu = fu - du
        for dv in range(2):
            if dv == 1 and not on_v:
                break
            cv = fv - dv
            if cu >= 0 and cu < w and cv >= 0 and cv < h and free[cv, cu]:
                return True
    return False


@nb.njit(**_JIT)
def seg_free(free, au, av, bu, bv, eps):
    """True when every point of the segment a -> b lies in the closed union of free cells (the rule of
    ``routes.segments_free``): the segment is cut at every integer u and v line it crosses and the middle of
    each piece must be free. The crossings of each axis are already sorted along the segment, so the two
    sequences are merged on the fly (no allocation)."""
    if au == bu and av == bv:
        return _point_free(free, au, av, eps)
    lo = min(au, bu)
    hi = max(au, bu)
    f_u = np.int64(math.floor(lo + eps)) + 1
    n_u = max(np.int64(math.ceil(hi - eps)) - 1 - f_u + 1, 0)
    lo = min(av, bv)
    hi = max(av, bv)
    f_v = np.int64(math.floor(lo + eps)) + 1
    n_v = max(np.int64(math.ceil(hi - eps)) - 1 - f_v + 1, 0)
    du = bu - au
    dv = bv - av
    iu = 0
    iv = 0
    t_prev = 0.0
    while True:
        # next crossing of each axis in increasing t (lines visited upward or downward with the direction)
        tu = 2.0
        if iu < n_u:
            x = f_u + iu if du > 0 else f_u + n_u - 1 - iu
            tu = (x - au) / du
        tv = 2.0
        if iv < n_v:
            y = f_v + iv if dv > 0 else f_v + n_v - 1 - iv
            tv = (y - av) / dv
        if tu <= tv:
            t = tu
            iu += 1
        else:
            t = tv
            iv += 1
        if t > 1.0:
            t = 1.0
        tm = 0.5 * (t_prev + t)
        if not _point_free(free, au + du * tm, av + dv * tm, eps):
            return False
        if t >= 1.0:
            return True
        t_prev = t


@nb.njit(**_JIT)
def _h(D, dgoal, v, du, dv, hw):
    """Consistent A* heuristic of portal v: the largest of the Euclidean distance to the goal and the
    landmark (ALT) bounds |d(l, goal) - d(l, v)| (landmarks not reaching both are skipped)."""
    h = math.sqrt(du * du + dv * dv)
    for l in range(D.shape[1]):
        a = dgoal[l]
        b = D[v, l]
        if a < np.inf and b < np.inf:
            x = abs(a - b)
            if x > h:
                h = x
    return hw * h


@nb.njit(**_JIT)
def _touch(stamp, gen, gcost, hc, parent, closed, pos, j):
    """Reset node j's workspace entries the first time this query (generation ``gen``) meets it."""
    if stamp[j] != gen:
        stamp[j] = gen
        gcost[j] = np.inf
        hc[j] = -1.0  # heuristic cache: each node's bound is computed once per query
        parent[j] = -1
        closed[j] = False
        pos[j] = -1


@nb.njit(**_JIT)
def _heap_set(hn, hk, pos, size, v, key):
    """Insert node v with ``key`` into the indexed binary min-heap (hn nodes, hk keys, pos[v] = slot or -1),
    or lower its key; returns the new size."""
    i = pos[v]
    if i < 0:
        i = size
        size += 1
    elif hk[i] <= key:
        return size
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= key:
            break
        hn[i] = hn[p]
        hk[i] = hk[p]
        pos[hn[i]] = i
        i = p
    hn[i] = v
    hk[i] = key
    pos[v] = i
    return size


@nb.njit(**_JIT)
def _heap_pop(hn, hk, pos, size):
    """Remove the minimum of the indexed heap: (node, new size)."""
    v = hn[0]
    pos[v] = -1
    size -= 1
    if size > 0:
        lv = hn[size]
        lk = hk[size]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= size:
                break
            if c + 1 < size and hk[c + 1] < hk[c]:
                c += 1
            if hk[c] >= lk:
                break
            hn[i] = hn[c]
            hk[i] = hk[c]
            pos[hn[i]] = i
            i = c
        hn[i] = lv
        hk[i] = lk
        pos[lv] = i
    return v, size


@nb.njit(**_JIT)
def corridor_astar(
    pptr,
    pdst,
    pw,
    cu,
    cv,
    ea,
    eb,
    D,
    first,
    first_cost,
    last,
    goal_regs,
    gx,
    gy,
    hw,
    stamp,
    gcost,
    hc,
    parent,
    closed,
    hn,
    hk,
    pos,
):
    """Port sequence (int64 array) of a shortest start -> goal route over the port graph (nodes = ports at
    (cu, cv), each on portal edge (ea, eb); edges = two ports of one region, weighted by their distance).
    ``first`` are the start regions' ports with costs ``first_cost``; the goal is reached from every port
    (``last``) of the regions ``goal_regs`` holding it by a straight segment. Heuristic: Euclidean and ALT
    landmark bounds from ``D`` (n, L) landmark distances, times ``hw`` (1 = exact: both bounds are
    consistent, so a popped node is final). Empty when unreachable.

    The rest is a reusable workspace, nothing of it cleared per query: ``stamp`` (n + 2,) int64 (a node's
    entries are valid only when ``stamp[node] == stamp[n + 1]``, the query's generation, bumped here);
    ``gcost``, ``hc`` (n + 1,) float64; ``parent`` (n + 1,) int64; ``closed`` (n + 1,) bool; the indexed
    binary heap ``hn`` (n + 1,) int64, ``hk`` (n + 1,) float64, ``pos`` (n + 1,) int64 (decrease-key, so
    at most one entry per node; node n is the goal)."""
    n = cu.shape[0]
    INF = np.inf
    nl = D.shape[1]
    dgoal = np.full(nl, INF)
    for i in range(last.shape[0]):
        p = last[i]
        du = cu[p] - gx
        dv = cv[p] - gy
        e = math.sqrt(du * du + dv * dv)
        for l in range(nl):
            x = D[p, l] + e
            if x < dgoal[l]:
                dgoal[l] = x
    stamp[n + 1] += 1
    gen = stamp[n + 1]
    GOAL = n
    _touch(stamp, gen, gcost, hc, parent, closed, pos, GOAL)
    size = 0
    for i in range(first.shape[0]):
        j = first[i]
        d = first_cost[i]
        _touch(stamp, gen, gcost, hc, parent, closed, pos, j)
        if d < gcost[j]:
            gcost[j] = d
            if hc[j] < 0.0:
                hc[j] = _h(D, dgoal, j, cu[j] - gx, cv[j] - gy, hw)
            size = _heap_set(hn, hk, pos, size, j, d + hc[j])
    best_goal = INF
    goal_parent = np.int64(-1)
    while size > 0:
        u, size = _heap_pop(hn, hk, pos, size)
        if u == GOAL:
            break
        closed[u] = True
        gc = gcost[u]
        on_goal = False
        for q in range(goal_regs.shape[0]):
            if ea[u] == goal_regs[q] or eb[u] == goal_regs[q]:
                on_goal = True
        if on_goal:
            du = cu[u] - gx
            dv = cv[u] - gy
            c = gc + math.sqrt(du * du + dv * dv)
            if c < best_goal:
                best_goal = c
                goal_parent = u
                size = _heap_set(hn, hk, pos, size, GOAL, c)
        for k in range(pptr[u], pptr[u + 1]):
            j = pdst[k]
            d = gc + pw[k]
            if d >= best_goal:
                continue
            _touch(stamp, gen, gcost, hc, parent, closed, pos, j)
            if d < gcost[j] and not closed[j]:
                gcost[j] = d
                parent[j] = u
                if hc[j] < 0.0:
                    hc[j] = _h(D, dgoal, j, cu[j] - gx, cv[j] - gy, hw)
                size = _heap_set(hn, hk, pos, size, j, d + hc[j])
    if goal_parent < 0:
        return np.zeros(0, dtype=np.int64)
    m = 0
    x = goal_parent
    while x != -1:
        m += 1
        x = parent[x]
    out = np.empty(m, dtype=np.int64)
    x = goal_parent
    for i in range(m - 1, -1, -1):
        out[i] = x
        x = parent[x]
    return out


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
def _best_in_box(ax, ay, bx, by, u0, v0, u1, v1):
    """Point x of the closed box [u0, u1] x [v0, v1] minimising |x - a| + |x - b|."""
    # the segment a -> b meets the box: the middle of its clipped part (Liang-Barsky)
    t0 = 0.0
    t1 = 1.0
    dx = bx - ax
    dy = by - ay
    ok = True
    for k in range(4):
        if k == 0:
            p, q = -dx, ax - u0
        elif k == 1:
            p, q = dx, u1 - ax
        elif k == 2:
            p, q = -dy, ay - v0
        else:
            p, q = dy, v1 - ay
        if p == 0.0:
            if q < 0.0:
                ok = False
                break
        else:
            r = q / p
            if p < 0.0:
                if r > t0:
                    t0 = r
            else:
                if r < t1:
                    t1 = r
            if t0 > t1:
                ok = False
                break
    if ok:
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


@nb.njit(**_JIT)
def refine(su, sv, gu, gv, boxes, sweeps, tol):
    """Shortest polyline start -> p_1 -> ... -> p_m -> goal with each p_i in the closed box
    ``boxes[i] = (u0, v0, u1, v1)`` (a convex problem), by alternating forward and backward exact
    coordinate updates from the box centres until no point moves more than ``tol`` or ``sweeps`` sweeps.
    Returns the (m + 2, 2) points."""
    m = boxes.shape[0]
    P = np.empty((m + 2, 2))
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


@nb.njit(**_JIT)
def string_pull(free, pts, window, passes, eps):
    """Windowed string pulling on the grid: from each kept point jump to the farthest of the next ``window``
    points in line of sight (exact ``seg_free``; all pairs when the path has at most ``window`` + 1 points),
    ``passes`` times. Shortcuts leave the corridor where the grid allows it (through regions the corridor
    does not list). Returns (kept points, ok); ok is False when some point sees none of its successors."""
    cur = pts.copy()
    for _ in range(passes):
        k = cur.shape[0]
        if k <= 2:
            return cur, True
        keep = np.empty(k, dtype=np.int64)
        nk = 1
        keep[0] = 0
        i = 0
        allpairs = k <= window + 1
        while i < k - 1:
            last = k - 1 if allpairs else min(i + window, k - 1)
            nxt = -1
            for j in range(last, i, -1):
                if j == i + 1 or seg_free(free, cur[i, 0], cur[i, 1], cur[j, 0], cur[j, 1], eps):
                    nxt = j
                    break
            i = nxt
            keep[nk] = i
            nk += 1
        out = np.empty((nk, 2))
        for q in range(nk):
            out[q, 0] = cur[keep[q], 0]
            out[q, 1] = cur[keep[q], 1]
        if nk == k or allpairs:
            return out, True
        cur = out
    return cur, True


@nb.njit(**_JIT)
def simplify_validate(free, pts, eps, tol):
    """Drop the points where the polyline does not turn (|cross| <= tol * |a| * |b|, same direction), then
    check every remaining segment exactly on the grid. Returns (points, ok)."""
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
    out = np.empty((nk, 2))
    for q in range(nk):
        out[q, 0] = pts[keep[q], 0]
        out[q, 1] = pts[keep[q], 1]
    for q in range(nk - 1):
        if not seg_free(free, out[q, 0], out[q, 1], out[q + 1, 0], out[q + 1, 1], eps):
            return out, False
    if nk == 1 and not _point_free(free, out[0, 0], out[0, 1], eps):
        return out, False
    return out, True


@nb.njit(**_JIT)
def _box_interval(ax, ay, b, i):
    """Absolute angular interval (lo, hi, lo corner u, v, hi corner u, v, inside) of box ``b[i]`` seen from
    (ax, ay); ``inside`` when the point lies in the closed box (no constraint)."""
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


@nb.njit(**_JIT)
def funnel(su, sv, gu, gv, boxes):
    """Shortest polyline start -> goal passing through the closed boxes ``boxes[i] = (u0, v0, u1, v1)`` in
    order, where consecutive boxes (and the start / goal with the first / last box) lie in one convex region:
    the funnel algorithm on angular intervals seen from the current apex. A straight piece from the apex that
    meets boxes i..j is covered by the regions between them, so it is collision-free. Returns (K, 2)."""
    m = boxes.shape[0]
    # boxes plus the goal as a degenerate last box
    B = np.empty((m + 1, 4))
    B[:m] = boxes
    B[m, 0] = gu
    B[m, 2] = gu
    B[m, 1] = gv
    B[m, 3] = gv
    out = np.empty((m + 2, 2))
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


@nb.njit(**_JIT)
def shortcut_corridor(regs, ekeys, nr):
    """Greedy corridor shortcut: from each kept region jump to the last later region of ``regs`` adjacent
    to it (``ekeys`` = sorted ``lo * nr + hi`` keys of the region edges); returns the portal (region edge)
    ids of the shortened corridor."""
    m = regs.shape[0]
    out = np.empty(max(m - 1, 0), dtype=np.int64)
    n = 0
    i = 0
    while i < m - 1:
        best = -1
        bk = -1
        for j in range(m - 1, i, -1):
            a = regs[i]
            b = regs[j]
            if a == b:
                continue
            key = min(a, b) * nr + max(a, b)
            k = np.searchsorted(ekeys, key)
            if k < ekeys.shape[0] and ekeys[k] == key:
                best = j
                bk = k
                break
        if best < 0:  # consecutive regions of a corridor are always adjacent; keep the rest as it is
            return out[:0]
        out[n] = bk
        n += 1
        i = best
    return out[:n].copy()


@nb.njit(**_JIT)
def shortcut_corridor_adj(regs, rptr, rids, E, nr):
    """:func:`shortcut_corridor` (same result) through the region adjacency (CSR ``rptr`` / ``rids`` of each
    region's edges ``E``) instead of a search over all later regions: O(m * degree), not O(m^2 log F). The
    region edges are sorted by key, so an edge's index is its index in the sorted keys."""
    m = regs.shape[0]
    last = np.full(nr, -1, dtype=np.int64)
    for i in range(m):
        last[regs[i]] = i
    out = np.empty(max(m - 1, 0), dtype=np.int64)
    n = 0
    i = 0
    while i < m - 1:
        a = regs[i]
        best = -1
        bk = -1
        for k in range(rptr[a], rptr[a + 1]):
            f = rids[k]
            o = E[f, 0] + E[f, 1] - a
            j = last[o]
            if j > i and j > best:
                best = j
                bk = f
        if best < 0:  # consecutive regions of a corridor are always adjacent; keep the rest as it is
            return out[:0]
        out[n] = bk
        n += 1
        i = best
    return out[:n].copy()


@nb.njit(**_JIT)
def _ports_of(rs, rptr, rids, pp):
    """The ports of the portals of the regions ``rs``."""
    n = 0
    for r in rs:
        for k in range(rptr[r], rptr[r + 1]):
            f = rids[k]
            n += pp[f + 1] - pp[f]
    out = np.empty(n, dtype=np.int64)
    n = 0
    for r in rs:
        for k in range(rptr[r], rptr[r + 1]):
            f = rids[k]
            for q in range(pp[f], pp[f + 1]):
                out[n] = q
                n += 1
    return out


@nb.njit(**_JIT)
def _regions_of(rs, portals, E, rg):
    m = portals.shape[0]
    regs = np.empty(m + 1, dtype=np.int64)
    regs[0] = rs
    for i in range(m - 1):
        a0, a1 = E[portals[i], 0], E[portals[i], 1]
        b0, b1 = E[portals[i + 1], 0], E[portals[i + 1], 1]
        regs[i + 1] = a0 if (a0 == b0 or a0 == b1) else a1
    regs[m] = rg
    return regs


@nb.njit(**_JIT)
def _length(P):
    s = 0.0
    for i in range(P.shape[0] - 1):
        s += math.hypot(P[i + 1, 0] - P[i, 0], P[i + 1, 1] - P[i, 1])
    return s


@nb.njit(**_JIT)
def _contains(rect, u, v):
    return rect[1] <= u <= rect[3] and rect[0] <= v <= rect[2]


@nb.njit(**_JIT)
def _contains_at(regions, r, u, v):
    """``_contains(regions[r], u, v)`` by scalar reads (no row view: the scan over all regions of a query
    is 20-30x faster)."""
    return regions[r, 1] <= u and u <= regions[r, 3] and regions[r, 0] <= v and v <= regions[r, 2]


@nb.njit(**_JIT)
def query(
    pptr,
    pdst,
    pw,
    cu,
    cv,
    ea,
    eb,
    D,
    port_portal,
    pp,
    rptr,
    rids,
    E,
    regions,
    ekeys,
    boxes,
    free,
    su,
    sv,
    rs,
    gu,
    gv,
    rg,
    hw,
    eps,
    ws_stamp,
    ws_g,
    ws_h,
    ws_parent,
    ws_closed,
    ws_hn,
    ws_hk,
    ws_pos,
    rcols,
):
    """One whole query between two located points (start in region ``rs``, goal in ``rg``, same component):
    corridor A* over the ports, corridor trimmed to the last region holding the start and the first holding
    the goal, the funnel path through it and through its greedy shortcut (the shorter wins), collinear
    points dropped and every segment checked on the grid. Returns (points (K, 2), regions crossed, status):
    status 0 ok, 1 no corridor, 2 a segment failed the grid check."""
    # every region holding the start (the goal): regions overlap, any of them may start the best corridor
    sr = np.empty(regions.shape[0], dtype=np.int64)
    gr = np.empty(regions.shape[0], dtype=np.int64)
    ns = 0
    ng = 0
    both = -1
    # branchless over the region columns (rcols rows: row0, col0, row1, col1 as float64) so it vectorises
    R0, C0, R1, C1 = rcols[0], rcols[1], rcols[2], rcols[3]
    for r in range(regions.shape[0]):
        a = (C0[r] <= su) & (su <= C1[r]) & (R0[r] <= sv) & (sv <= R1[r])
        b = (C0[r] <= gu) & (gu <= C1[r]) & (R0[r] <= gv) & (gv <= R1[r])
        sr[ns] = r
        ns += a
        gr[ng] = r
        ng += b
    for i in range(ns):  # the first region holding both (sr is ascending)
        r = sr[i]
        if _contains_at(regions, r, gu, gv):
            both = r
            break
    if ns == 0:
        sr[0] = rs
        ns = 1
    if ng == 0:
        gr[0] = rg
        ng = 1
    if rs == rg or both >= 0:
        raw = np.empty((2, 2))
        raw[0, 0], raw[0, 1], raw[1, 0], raw[1, 1] = su, sv, gu, gv
        regs = np.full(1, rs if rs == rg else both, dtype=np.int64)
    else:
        first = _ports_of(sr[:ns], rptr, rids, pp)
        last = _ports_of(gr[:ng], rptr, rids, pp)
        d0 = np.empty(first.shape[0])
        for i in range(first.shape[0]):
            d0[i] = math.hypot(cu[first[i]] - su, cv[first[i]] - sv)
        seq = corridor_astar(
            pptr,
            pdst,
            pw,
            cu,
            cv,
            ea,
            eb,
            D,
            first,
            d0,
            last,
            gr[:ng],
            gu,
            gv,
            hw,
            ws_stamp,
            ws_g,
            ws_h,
            ws_parent,
            ws_closed,
            ws_hn,
            ws_hk,
            ws_pos,
        )
        if seq.shape[0] == 0:
            return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), 1
        portals = np.empty(seq.shape[0], dtype=np.int64)
        m = 0
        for i in range(seq.shape[0]):
            f = port_portal[seq[i]]
            if m == 0 or portals[m - 1] != f:
                portals[m] = f
                m += 1
        portals = portals[:m]
        # the corridor's end regions: those of the first (last) portal holding the start (goal)
        f0, f1 = E[portals[0], 0], E[portals[0], 1]
        rs = f0 if _contains_at(regions, f0, su, sv) else f1
        l0, l1 = E[portals[m - 1], 0], E[portals[m - 1], 1]
        rg = l0 if _contains_at(regions, l0, gu, gv) else l1
        regs = _regions_of(rs, portals, E, rg)
        i0 = 0
        for i in range(regs.shape[0]):
            if _contains_at(regions, regs[i], su, sv):
                i0 = i
        i1 = regs.shape[0] - 1
        for i in range(i0, regs.shape[0]):
            if _contains_at(regions, regs[i], gu, gv):
                i1 = i
                break
        portals = portals[i0:i1].copy()
        regs = regs[i0 : i1 + 1].copy()
        if portals.shape[0] == 0:
            raw = np.empty((2, 2))
            raw[0, 0], raw[0, 1], raw[1, 0], raw[1, 1] = su, sv, gu, gv
        else:
            raw = corridor_path(su, sv, gu, gv, boxes[portals], 200)
            short = shortcut_corridor_adj(regs, rptr, rids, E, regions.shape[0])
            if 0 < short.shape[0] < portals.shape[0]:
                alt = corridor_path(su, sv, gu, gv, boxes[short], 200)
                if _length(alt) < _length(raw):
                    raw = alt
                    regs = _regions_of(regs[0], short, E, regs[regs.shape[0] - 1])
    # string pull on the grid: all pairs on short paths (where a shortcut through regions off the corridor
    # matters most), only the next-but-one point on long ones (each check costs the segment's length)
    if 2 < raw.shape[0] <= 9:
        raw, _ = string_pull(free, raw, 8, 1, eps)
    elif raw.shape[0] > 9:
        raw, _ = string_pull(free, raw, 2, 1, eps)
    pts, ok = simplify_validate(free, raw, eps, 1e-9)
    # consecutive repeats dropped from the region list
    out = np.empty(regs.shape[0], dtype=np.int64)
    n = 0
    for i in range(regs.shape[0]):
        if n == 0 or out[n - 1] != regs[i]:
            out[n] = regs[i]
            n += 1
    return pts, out[:n].copy(), 0 if ok else 2


@nb.njit(**_JIT)
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


# ---- build kernels of the two-layer graph (holoslam.planning.twolayer) ----


@nb.njit(**_JIT)
def label_image(blocks, h, w):
    """(h, w) int32 block id of each cell (-1 outside every block): each (disjoint) block fills its cells."""
    L = np.full((h, w), -1, dtype=np.int32)
    for b in range(blocks.shape[0]):
        for r in range(blocks[b, 0], blocks[b, 2]):
            for c in range(blocks[b, 1], blocks[b, 3]):
                L[r, c] = b
    return L


@nb.njit(**_JIT)
def block_edges(blocks, labels):
    """Adjacent block pairs (E, 2) (i < j in a row, each pair once) by the one-cell dilation rule, read off
    the label image along each block's boundary: its right column line (rows r0-1 .. r1, keeping blocks that
    start on that line: side and corner contacts) and its top row line (columns c0 .. c1-1: side contacts
    with a shared horizontal line). Each pair is seen from exactly one block; a block met on several
    consecutive cells of a line (blocks are rectangles: one run) is kept once."""
    h, w = labels.shape
    n = blocks.shape[0]
    cap = 0
    for b in range(n):
        cap += (blocks[b, 2] - blocks[b, 0]) + 2 + (blocks[b, 3] - blocks[b, 1])
    out = np.empty((cap, 2), dtype=np.int64)
    m = 0
    for b in range(n):
        r0, c0, r1, c1 = blocks[b, 0], blocks[b, 1], blocks[b, 2], blocks[b, 3]
        if c1 < w:
            prev = -1
            for r in range(max(r0 - 1, 0), min(r1 + 1, h)):
                y = labels[r, c1]
                if y >= 0 and y != prev:
                    prev = y
                    if blocks[y, 1] == c1:
                        out[m, 0] = min(b, y)
                        out[m, 1] = max(b, y)
                        m += 1
        if r1 < h:
            prev = -1
            for c in range(c0, c1):
                y = labels[r1, c]
                if y >= 0 and y != prev:
                    prev = y
                    out[m, 0] = min(b, y)
                    out[m, 1] = max(b, y)
                    m += 1
    return out[:m].copy()


@nb.njit(**_JIT)
def grow_regions(S, blocks, labels, seeds):
    """Layer 2 (see ``twolayer.grow_regions``): for each seed block in order that no earlier region covers,
    grow its rectangle round robin up (row1), right (col1), down (row0), left (col0), a direction's step
    doubling while the strip it adds is free (O(1) from the integral image ``S``) and halving when it is not,
    stopping when a one-cell strip fails; then mark every still-uncovered block wholly inside it (read off
    the label image row by row, jumping over each block met). Returns (regions (R, 4), region_of_block,
    ptr (R+1,), ids) with ids the blocks grouped by region in ascending block order."""
    h, w = labels.shape
    n = blocks.shape[0]
    rob = np.full(n, -1, dtype=np.int64)
    regs = np.empty((n, 4), dtype=np.int64)
    nr = 0
    step = np.empty(4, dtype=np.int64)
    active = np.empty(4, dtype=np.bool_)
    for s in seeds:
        if rob[s] >= 0:
            continue
        r0, c0, r1, c1 = blocks[s, 0], blocks[s, 1], blocks[s, 2], blocks[s, 3]
        step[:] = 1
        active[:] = True
        n_act = 4
        while n_act > 0:
            for d in range(4):
                if not active[d]:
                    continue
                k = step[d]
                if d == 0:
                    k = min(k, h - r1)
                    a0, b0, a1, b1 = r1, c0, r1 + k, c1
                elif d == 1:
                    k = min(k, w - c1)
                    a0, b0, a1, b1 = r0, c1, r1, c1 + k
                elif d == 2:
                    k = min(k, r0)
                    a0, b0, a1, b1 = r0 - k, c0, r0, c1
                else:
                    k = min(k, c0)
                    a0, b0, a1, b1 = r0, c0 - k, r1, c0
                ok = False
                if k > 0:
                    cnt = (
                        np.int64(S[a1, b1]) - np.int64(S[a0, b1]) - np.int64(S[a1, b0]) + np.int64(S[a0, b0])
                    )
                    ok = cnt == (a1 - a0) * (b1 - b0)
                if ok:
                    if d == 0:
                        r1 += k
                    elif d == 1:
                        c1 += k
                    elif d == 2:
                        r0 -= k
                    else:
                        c0 -= k
                    step[d] = k * 2
                elif k <= 1:
                    active[d] = False
                    n_act -= 1
                else:
                    step[d] = k // 2
        regs[nr, 0], regs[nr, 1], regs[nr, 2], regs[nr, 3] = r0, c0, r1, c1
        for r in range(r0, r1):
            c = c0
            while c < c1:
                y = labels[r, c]
                if y < 0:
                    c += 1
                    continue
                if (
                    rob[y] < 0
                    and blocks[y, 0] >= r0
                    and blocks[y, 1] >= c0
                    and blocks[y, 2] <= r1
                    and blocks[y, 3] <= c1
                ):
                    rob[y] = nr
                c = blocks[y, 3]
        nr += 1
    # blocks grouped by region, ascending within a region (a stable counting sort); seeds cover every block
    ptr = np.zeros(nr + 1, dtype=np.int64)
    for b in range(n):
        ptr[rob[b] + 1] += 1
    for k in range(nr):
        ptr[k + 1] += ptr[k]
    fill = ptr[:-1].copy()
    ids = np.empty(n, dtype=np.int64)
    for b in range(n):
        ids[fill[rob[b]]] = b
        fill[rob[b]] += 1
    return regs[:nr].copy(), rob, ptr, ids
