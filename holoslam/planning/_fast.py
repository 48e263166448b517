"""Compiled query kernels of the two-layer planner (numba, ``cache=True``).

Imported lazily by :func:`holoslam.planning.routes.build_planner` (importing numba costs about half a second
and the first call of each kernel compiles it, about 10 s once per machine, then loads it from numba's
on-disk cache next to this file). Every kernel is a plain function of numpy arrays.

* :func:`query` -- one whole planning query between two located points (see ``routes`` for the steps):
  the regions holding them (:func:`_regions_at`, bucket index), :func:`corridor_astar` (A* over the port
  graph with Euclidean + ALT landmark heuristic), corridor trimming, :func:`corridor_path` (:func:`funnel`,
  polished by :func:`refine` where the funnel path turns back) on the corridor and on its greedy shortcut
  (:func:`shortcut_corridor_adj`), :func:`string_pull` on the grid and :func:`simplify_validate` (collinear
  points dropped, every segment not checked by the string pull checked exactly by :func:`seg_free_tiles`).
* :func:`seg_free_tiles` -- the exact segment test of ``routes.segments_free`` (the same cut-at-grid-lines,
  midpoint-in-a-free-cell rule with the same ``eps``, tested equal) without allocation, on the 64-bit tiles
  of :func:`tile_bits`, jumping over squares of free tiles (:func:`chessboard_clearance`).
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

# the corridor search's per-node workspace record (see ``corridor_astar``)
WORKSPACE_DTYPE = np.dtype(
    [("g", "f8"), ("h", "f8"), ("stamp", "i4"), ("parent", "i4"), ("pos", "i4"), ("pad", "i4")], align=True
)


@nb.njit(**_JIT)
def chessboard_clearance(free):
    """(h, w) uint8: for each free cell, its chessboard (L-infinity) distance in cells to the nearest cell that
    is not free, the outside of the grid counting as not free (so every cell within distance k - 1 of a cell
    of value k is free), saturated at 255; 0 on cells that are not free. Two raster passes (exact for this
    metric)."""
    h, w = free.shape
    d = np.empty((h, w), dtype=np.uint8)
    for r in range(h):
        for c in range(w):
            if not free[r, c]:
                d[r, c] = 0
            elif r == 0 or c == 0 or c == w - 1:
                d[r, c] = 1
            else:
                m = min(np.int64(d[r, c - 1]), np.int64(d[r - 1, c - 1]))
                m = min(m, np.int64(d[r - 1, c]), np.int64(d[r - 1, c + 1]))
                d[r, c] = min(m + 1, 255)
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            if d[r, c] <= 1:
                continue
            if r == h - 1:
                d[r, c] = 1
                continue
            m = min(np.int64(d[r, c + 1]), np.int64(d[r + 1, c + 1]))
            m = min(m, np.int64(d[r + 1, c]), np.int64(d[r + 1, c - 1]))
            d[r, c] = min(np.int64(d[r, c]), m + 1)
    return d


@nb.njit(**_JIT)
def tile_bits(free):
    """The (h, w) free mask as 8 x 8 tiles of one uint64 each (row-major tiles; bit (r % 8) * 8 + c % 8 of
    tile (r // 8, c // 8) is cell (r, c)), cells outside the grid blocked: 1/8 of the bool mask's memory, so
    the grid checks of a query read few cache lines. Returns (bits (th * tw,), full (th, tw) bool: tiles
    with every cell free)."""
    h, w = free.shape
    th = (h + 7) >> 3
    tw = (w + 7) >> 3
    bits = np.zeros(th * tw, dtype=np.uint64)
    for r in range(h):
        base = (r >> 3) * tw
        sh = (r & 7) << 3
        for c in range(w):
            if free[r, c]:
                bits[base + (c >> 3)] |= np.uint64(1) << np.uint64(sh | (c & 7))
    full = np.empty((th, tw), dtype=np.bool_)
    for t in range(th * tw):
        full[t // tw, t % tw] = bits[t] == np.uint64(0xFFFFFFFFFFFFFFFF)
    return bits, full


def block_clearance(free):
    """(ceil(h / 4), ceil(w / 4)) uint8: the chessboard clearance (:func:`chessboard_clearance`), in blocks
    of 4 x 4 cells, of the blocks whose cells are all free (cells outside the grid blocked): the jumps of
    :func:`seg_free_tiles`."""
    h, w = free.shape
    f = np.zeros((-(-h // 4) * 4, -(-w // 4) * 4), dtype=bool)
    f[:h, :w] = free
    return chessboard_clearance(f.reshape(f.shape[0] // 4, 4, f.shape[1] // 4, 4).all(axis=(1, 3)))


@nb.njit(**_JIT)
def _cell_free(bits, w, r, c):
    """Cell (r, c) (inside the grid) is free in the tiled mask."""
    t = bits[(r >> 3) * ((w + 7) >> 3) + (c >> 3)]
    return (t >> np.uint64(((r & 7) << 3) | (c & 7))) & np.uint64(1) != np.uint64(0)


@nb.njit(**_JIT)
def _point_free_bits(bits, h, w, u, v, eps):
    """Is the point (u, v) in the closed union of free cells of the tiled mask (a point within ``eps`` of a
    grid line touches the cells on both sides; ``routes._point_free``'s rule)?"""
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
            if cu >= 0 and cu < w and cv >= 0 and cv < h and _cell_free(bits, w, cv, cu):
                return True
    return False


@nb.njit(**_JIT)
def _crossings_upto(f, n, a, d, t):
    """How many of the n grid lines f .. f + n - 1 a segment crosses (visited in the direction of d, the
    line x crossed at parameter (x - a) / d) it crosses at a parameter <= t."""
    if n == 0:
        return np.int64(0)
    x = a + d * t
    if d > 0:
        c = np.int64(math.floor(x)) - f + 1
    else:
        c = f + n - np.int64(math.ceil(x))
    c = min(max(c, np.int64(0)), n)
    while c > 0:  # float rounding: never count a line crossed after t
        xl = f + c - 1 if d > 0 else f + n - c
        if (xl - a) / d <= t:
            break
        c -= 1
    return c


@nb.njit(**_JIT)
def seg_free_tiles(bits, tclear, h, w, au, av, bu, bv, eps):
    """``routes.segments_free`` (the same answer) on the tiled mask ``bits`` of an (h, w) grid (:func:`tile_bits`),
    jumping through free space: ``tclear`` (ceil(h / 4), ceil(w / 4)) uint8 is the chessboard clearance, in
    blocks of 4 x 4 cells, of the fully free blocks (:func:`block_clearance`), so after checking a piece of
    the segment inside a block of clearance K >= 1 (the (2K - 1)-block square around it is free) every piece
    up to where the segment leaves that square is free and skipped. The cost is the number of pieces in
    blocks with blocked cells plus the number of jumps, not the segment's length in cells, and the pieces it
    checks are pieces of ``segments_free``'s own cut (between consecutive grid-line crossings)."""
    if au == bu and av == bv:
        return _point_free_bits(bits, h, w, au, av, eps)
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
    iu = np.int64(0)
    iv = np.int64(0)
    t_prev = 0.0
    # the next crossing of each axis in increasing t, recomputed only when passed
    tu = 2.0
    if n_u > 0:
        tu = ((f_u if du > 0 else f_u + n_u - 1) - au) / du
    tv = 2.0
    if n_v > 0:
        tv = ((f_v if dv > 0 else f_v + n_v - 1) - av) / dv
    while True:
        if tu <= tv:
            t = tu
            iu += 1
            tu = 2.0
            if iu < n_u:
                x = f_u + iu if du > 0 else f_u + n_u - 1 - iu
                tu = (x - au) / du
        else:
            t = tv
            iv += 1
            tv = 2.0
            if iv < n_v:
                y = f_v + iv if dv > 0 else f_v + n_v - 1 - iv
                tv = (y - av) / dv
        if t > 1.0:
            t = 1.0
        tm = 0.5 * (t_prev + t)
        mu = au + du * tm
        mv = av + dv * tm
        if not _point_free_bits(bits, h, w, mu, mv, eps):
            return False
        if t >= 1.0:
            return True
        t_prev = t
        # the piece lies in cell (cu, cv) of block (tr, tc); with block clearance K >= 1 skip to where the
        # segment leaves the free square of blocks around it
        cu = np.int64(math.floor(mu))
        cv = np.int64(math.floor(mv))
        if cu < 0 or cu >= w or cv < 0 or cv >= h:
            continue
        k = np.int64(tclear[cv >> 2, cu >> 2])
        if k < 1 or mu - cu <= eps or cu + 1 - mu <= eps or mv - cv <= eps or cv + 1 - mv <= eps:
            continue
        tc = cu >> 2
        tr = cv >> 2
        te = 1.0
        if du > 0.0:
            te = min(te, ((tc + k) * 4 - au) / du)
        elif du < 0.0:
            te = min(te, ((tc - k + 1) * 4 - au) / du)
        if dv > 0.0:
            te = min(te, ((tr + k) * 4 - av) / dv)
        elif dv < 0.0:
            te = min(te, ((tr - k + 1) * 4 - av) / dv)
        if te >= 1.0:
            return True
        ju = max(_crossings_upto(f_u, n_u, au, du, te), iu)
        jv = max(_crossings_upto(f_v, n_v, av, dv, te), iv)
        if ju > iu or jv > iv:
            iu = ju
            iv = jv
            # the next piece starts at the last crossing skipped
            if iu > 0:
                x = f_u + iu - 1 if du > 0 else f_u + n_u - iu
                t_prev = max(t_prev, (x - au) / du)
            if iv > 0:
                y = f_v + iv - 1 if dv > 0 else f_v + n_v - iv
                t_prev = max(t_prev, (y - av) / dv)
            tu = 2.0
            if iu < n_u:
                x = f_u + iu if du > 0 else f_u + n_u - 1 - iu
                tu = (x - au) / du
            tv = 2.0
            if iv < n_v:
                y = f_v + iv if dv > 0 else f_v + n_v - 1 - iv
                tv = (y - av) / dv


@nb.njit(**_JIT)
def _alt(node, dgoal, v, h):
    """The largest of ``h`` and the landmark (ALT) bounds |d(l, goal) - d(l, v)| (``node[v, 2 + l]`` =
    d(l, v)); a landmark of another component (both distances infinite: NaN) is skipped."""
    for l in range(dgoal.shape[0]):
        x = abs(dgoal[l] - node[v, 2 + l])
        if x > h and x < np.inf:
            h = x
    return h


@nb.njit(cache=True, nogil=True, fastmath=True)
def _alt_finite(node, dgoal, v, h):
    """:func:`_alt` when every landmark distance involved is finite (the landmarks all reach the goal's
    component, so they reach every node the search meets): a branch-free max that vectorises."""
    for l in range(dgoal.shape[0]):
        h = max(h, abs(dgoal[l] - node[v, 2 + l]))
    return h


@nb.njit(**_JIT)
def _touch(ws, gen, j):
    """Reset node j's workspace record the first time this query (generation ``gen``) meets it."""
    r = ws[j]
    if r.stamp != gen:
        r.stamp = gen
        r.parent = -1
        r.pos = -1
        r.g = np.inf
        r.h = -1.0


@nb.njit(**_JIT)
def _heap_set(hn, hk, ws, size, v, key):
    """Insert node v with ``key`` into the indexed binary min-heap (hn nodes, hk keys, ``ws[v].pos`` = slot
    or -1), or lower its key; returns the new size."""
    i = ws[v].pos
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
        ws[hn[i]].pos = i
        i = p
    hn[i] = v
    hk[i] = key
    ws[v].pos = i
    return size


@nb.njit(**_JIT)
def _heap_pop(hn, hk, ws, size):
    """Remove the minimum of the indexed heap: (node, its key, new size); the node's slot becomes -1."""
    v = hn[0]
    key = hk[0]
    ws[v].pos = -1
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
            ws[hn[i]].pos = i
            i = c
        hn[i] = lv
        hk[i] = lk
        ws[lv].pos = i
    return v, key, size


@nb.njit(**_JIT)
def corridor_astar(
    rp_ptr, rp_id, rp_uv, node, ea, eb, first, first_cost, last, goal_regs, gx, gy, hw, ws, hn, hk
):
    """Port sequence (int64 array) of a shortest start -> goal route over the port graph (nodes = ports, each
    on portal edge (ea, eb); edges = two ports of one region, weighted by their distance). The edges are not
    stored: a port's neighbours are the ports of its two regions, listed per region with their coordinates
    (CSR ``rp_ptr``, ``rp_id`` int32, ``rp_uv`` (M, 2) float32), read in sequence, so only the records of
    the ports the search meets are read at random (an eighth of the memory of the edge list). ``node`` (n, >= 2
    + L) float32 rows: the port's (u, v), then its distances from the L landmarks (the rest padding), one
    64-byte row a port for L = 14. ``first`` are the start regions' ports with costs ``first_cost``; the goal
    is reached from every port (``last``) of the regions ``goal_regs`` holding it by a straight segment.
    Heuristic: the larger of the Euclidean distance and the ALT landmark bounds, times ``hw`` (1 = exact:
    both bounds are consistent, so a popped node is final), computed once per node when first reached (a
    lazy variant, keyed by the Euclidean bound until the node reaches the top of the heap, computes it for
    two thirds of the nodes anyway and was 1.6x slower: the heap work of the re-insertions costs more).
    Nodes are not put in the heap when their key is no less than the best goal cost found: the goal, keyed
    by that cost, would leave the heap first. Empty when unreachable.

    The rest is a reusable workspace, nothing of it cleared per query: ``ws`` (n + 2,) records of
    ``WORKSPACE_DTYPE`` (g, h, stamp, parent, pos: 32 bytes, so meeting a node touches one cache line; a
    record is valid only when its stamp equals ``ws[n + 1].stamp``, the query's generation, bumped here;
    node n is the goal; pos is the heap slot, -1 out of the heap, -2 closed) and the indexed binary heap
    ``hn`` (n + 1,) int64, ``hk`` (n + 1,) float64 (decrease-key: at most one entry per node)."""
    n = node.shape[0]
    INF = np.inf
    nl = min(node.shape[1] - 2, 64)
    dgoal = np.full(nl, INF)
    for i in range(last.shape[0]):
        p = last[i]
        du = node[p, 0] - gx
        dv = node[p, 1] - gy
        e = math.sqrt(du * du + dv * dv)
        for l in range(nl):
            x = node[p, 2 + l] + e
            if x < dgoal[l]:
                dgoal[l] = x
    finite = True
    for l in range(nl):
        finite = finite and dgoal[l] < INF
    if ws[n + 1].stamp >= 2**31 - 2:  # generation about to wrap: forget every stamp
        for j in range(n + 2):
            ws[j].stamp = 0
    ws[n + 1].stamp += 1
    gen = ws[n + 1].stamp
    GOAL = n
    _touch(ws, gen, GOAL)
    size = 0
    for i in range(first.shape[0]):
        j = first[i]
        d = first_cost[i]
        _touch(ws, gen, j)
        r = ws[j]
        if d < r.g:
            r.g = d
            if r.h < 0.0:
                du = node[j, 0] - gx
                dv = node[j, 1] - gy
                e = math.sqrt(du * du + dv * dv)
                r.h = hw * (_alt_finite(node, dgoal, j, e) if finite else _alt(node, dgoal, j, e))
            size = _heap_set(hn, hk, ws, size, j, d + r.h)
    best_goal = INF
    goal_parent = np.int64(-1)
    while size > 0:
        u, key, size = _heap_pop(hn, hk, ws, size)
        if u == GOAL:
            break
        ru = ws[u]
        gc = ru.g
        ru.pos = -2  # closed
        on_goal = False
        for q in range(goal_regs.shape[0]):
            if ea[u] == goal_regs[q] or eb[u] == goal_regs[q]:
                on_goal = True
        if on_goal:
            du = node[u, 0] - gx
            dv = node[u, 1] - gy
            c = gc + math.sqrt(du * du + dv * dv)
            if c < best_goal:
                best_goal = c
                goal_parent = u
                size = _heap_set(hn, hk, ws, size, GOAL, c)
        uu = node[u, 0]
        uv = node[u, 1]
        pr = ru.parent
        for side in range(2):
            reg = ea[u] if side == 0 else eb[u]
            if pr >= 0 and (reg == ea[pr] or reg == eb[pr]):
                # u was reached through this region (convex, so |p j| <= |p u| + |u j|): relaxing its ports
                # from u cannot beat the relaxation from u's parent p, already done
                continue
            for k in range(rp_ptr[reg], rp_ptr[reg + 1]):
                j = rp_id[k]
                if j == u:
                    continue
                ju = rp_uv[k, 0]
                jv = rp_uv[k, 1]
                d = gc + math.sqrt((ju - uu) * (ju - uu) + (jv - uv) * (jv - uv))
                e = -1.0
                if best_goal < INF:
                    e = math.sqrt((ju - gx) * (ju - gx) + (jv - gy) * (jv - gy))
                    if d + e >= best_goal:  # no shorter route to the goal through j (e: a lower bound)
                        continue
                _touch(ws, gen, j)
                r = ws[j]
                if d < r.g and r.pos != -2:
                    r.g = d
                    r.parent = u
                    if r.h < 0.0:
                        if e < 0.0:
                            e = math.sqrt((ju - gx) * (ju - gx) + (jv - gy) * (jv - gy))
                        r.h = hw * (_alt_finite(node, dgoal, j, e) if finite else _alt(node, dgoal, j, e))
                    if d + r.h < best_goal:
                        size = _heap_set(hn, hk, ws, size, j, d + r.h)
    if goal_parent < 0:
        return np.zeros(0, dtype=np.int64)
    m = 0
    x = goal_parent
    while x != -1:
        m += 1
        x = ws[x].parent
    out = np.empty(m, dtype=np.int64)
    x = goal_parent
    for i in range(m - 1, -1, -1):
        out[i] = x
        x = ws[x].parent
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
        out = np.empty((nk, 2))
        for q in range(nk):
            out[q, 0] = cur[keep[q], 0]
            out[q, 1] = cur[keep[q], 1]
        chk = kc[: nk - 1].copy()
        if nk == k or allpairs:
            return out, chk
        cur = out
    return cur, chk


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
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
    out = np.empty((nk, 2))
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


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
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
def shortcut_corridor_adj(regs, rptr, rids, E, nr):
    """Greedy corridor shortcut: from each kept region of ``regs`` jump to the last later region adjacent to it;
    returns the portal (region edge) ids of the shortened corridor (empty when two consecutive regions are not
    adjacent). Read through the region adjacency (CSR ``rptr`` / ``rids`` of each region's edges ``E``), not a
    search over all later regions: O(m * degree), not O(m^2 log F); the tests compare it with that search."""
    return _shortcut_adj(regs, rptr, rids, E, np.full(nr, -1, dtype=np.int64))


@nb.njit(**_JIT)
def _shortcut_adj(regs, rptr, rids, E, last):
    """:func:`shortcut_corridor_adj` with the (nr,) scratch ``last``, all -1 on entry and on return (the
    query reuses one, so it costs O(m), not O(nr))."""
    m = regs.shape[0]
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
            n = 0
            break
        out[n] = bk
        n += 1
        i = best
    for i in range(m):
        last[regs[i]] = -1
    return out[:n].copy()


@nb.njit(**_JIT)
def _ports_of(rs, rptr, rids, pp, pslot):
    """The ports of the portals of the regions ``rs`` (portal f's ports: ``pslot[pp[f]:pp[f + 1]]``)."""
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
                out[n] = pslot[q]
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
def _regions_at(regions, bptr, bids, shift, nbx, u, v, out):
    """The regions whose closed rectangle holds the point (u, v), ascending, written to ``out``; returns their
    number. Candidates come from the point's bucket (``bptr`` / ``bids`` CSR over square buckets of
    2**shift cells, ``nbx`` buckets a row, listing every region whose closed rectangle meets the bucket)."""
    bu = np.int64(math.floor(u)) >> shift
    bv = np.int64(math.floor(v)) >> shift
    n = 0
    if bu < 0 or bu >= nbx or bv < 0 or (bv + 1) * nbx >= bptr.shape[0]:
        return n
    b = bv * nbx + bu
    for k in range(bptr[b], bptr[b + 1]):
        r = bids[k]
        if _contains_at(regions, r, u, v):
            out[n] = r
            n += 1
    return n


@nb.njit(**_JIT)
def query(
    rp_ptr,
    rp_id,
    rp_uv,
    cuv,
    node,
    ea,
    eb,
    port_portal,
    pp,
    pslot,
    rptr,
    rids,
    E,
    regions,
    bptr,
    bids,
    bgrid,
    boxes,
    bits,
    tclear,
    gh,
    gw,
    world,
    su,
    sv,
    rs,
    gu,
    gv,
    rg,
    hw,
    eps,
    ws,
    hn,
    hk,
    rlast,
):
    """One whole query between two located points (start in region ``rs``, goal in ``rg``, same component):
    corridor A* over the ports, corridor trimmed to the last region holding the start and the first holding
    the goal, the funnel path through it and through its greedy shortcut (the shorter wins), collinear
    points dropped and every segment checked on the grid. Returns (waypoints (K, 2) in world metres,
    regions crossed, length in metres, status): status 0 ok, 1 no corridor, 2 a segment failed the grid
    check; ``world`` = (origin_x, origin_y, resolution) maps cells to metres.

    ``bptr`` / ``bids`` / ``bgrid`` (shift, buckets a row, most regions in a bucket) are the bucket index of :func:`_regions_at`;
    ``bits``, ``tclear`` the (gh, gw) free mask's tiles and their clearance (``seg_free_tiles``); ``node`` the port rows and ``ws``, ``hn``, ``hk`` the search workspace of :func:`corridor_astar` and ``rlast`` (R,) int64,
    all -1, the scratch of :func:`_shortcut_adj`."""
    # every region holding the start (the goal): regions overlap, any of them may start the best corridor
    sr = np.empty(max(bgrid[2], 1), dtype=np.int64)
    gr = np.empty(max(bgrid[2], 1), dtype=np.int64)
    shift, nbx = bgrid[0], bgrid[1]
    ns = _regions_at(regions, bptr, bids, shift, nbx, su, sv, sr)
    ng = _regions_at(regions, bptr, bids, shift, nbx, gu, gv, gr)
    both = -1
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
        first = _ports_of(sr[:ns], rptr, rids, pp, pslot)
        last = _ports_of(gr[:ng], rptr, rids, pp, pslot)
        d0 = np.empty(first.shape[0])
        for i in range(first.shape[0]):
            d0[i] = math.hypot(cuv[first[i], 0] - su, cuv[first[i], 1] - sv)
        seq = corridor_astar(
            rp_ptr, rp_id, rp_uv, node, ea, eb, first, d0, last, gr[:ng], gu, gv, hw, ws, hn, hk
        )
        if seq.shape[0] == 0:
            return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), 0.0, 1
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
            short = _shortcut_adj(regs, rptr, rids, E, rlast)
            if 0 < short.shape[0] < portals.shape[0]:
                alt = corridor_path(su, sv, gu, gv, boxes[short], 200)
                if _length(alt) < _length(raw):
                    raw = alt
                    regs = _regions_of(regs[0], short, E, regs[regs.shape[0] - 1])
    # string pull on the grid: all pairs on short paths (where a shortcut through regions off the corridor
    # matters most), only the next-but-one point on long ones (each check costs the segment's length); the
    # shortcuts it checked are not checked again
    if 2 < raw.shape[0] <= 9:
        raw, chk = string_pull(bits, tclear, gh, gw, raw, 8, 1, eps)
    elif raw.shape[0] > 9:
        raw, chk = string_pull(bits, tclear, gh, gw, raw, 2, 1, eps)
    else:
        chk = np.zeros(max(raw.shape[0] - 1, 0), dtype=np.bool_)
    pts, ok = simplify_validate(bits, tclear, gh, gw, raw, chk, eps, 1e-9)
    # consecutive repeats dropped from the region list
    out = np.empty(regs.shape[0], dtype=np.int64)
    n = 0
    for i in range(regs.shape[0]):
        if n == 0 or out[n - 1] != regs[i]:
            out[n] = regs[i]
            n += 1
    # world coordinates: x = origin_x + u * resolution, y = origin_y + v * resolution
    ox, oy, res = world[0], world[1], world[2]
    wp = np.empty_like(pts)
    for i in range(pts.shape[0]):
        wp[i, 0] = ox + pts[i, 0] * res
        wp[i, 1] = oy + pts[i, 1] * res
    return wp, out[:n].copy(), _length(wp), 0 if ok else 2


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
