"""Compiled query kernels of the two-layer planner (numba, ``cache=True``).

Imported lazily by :mod:`holoslam.planning.routes` (importing numba costs about half a second and the first
call of each kernel compiles it, or loads it from numba's on-disk cache). Every kernel is a plain function of
numpy arrays; the Python fallbacks in ``routes`` give the same answers when numba is missing.

* :func:`astar` -- A* over the portal-point graph in CSR form (Euclidean heuristic, admissible and
  consistent because edge weights are Euclidean lengths), several start nodes with initial costs, and a
  virtual goal reached from every node lying on the goal region.
* :func:`seg_free` / :func:`string_pull` -- the exact segment test of ``routes.segments_free`` (the same
  cut-at-grid-lines, midpoint-in-a-free-cell rule, with the same ``eps``) and the windowed string pulling of
  ``routes._string_pull``.
* :func:`path_regions` -- the lowest-numbered region shared by each pair of consecutive path nodes.
"""

from __future__ import annotations

import heapq
import math

import numba as nb
import numpy as np

_JIT = {"cache": True, "nogil": True}


@nb.njit(**_JIT)
def _on_region(nrp, nri, n, r):
    for k in range(nrp[n], nrp[n + 1]):
        if nri[k] == r:
            return True
    return False


@nb.njit(**_JIT)
def astar(aptr, adst, aw, U, V, nrp, nri, first, first_cost, rg, gx, gy):
    """Node sequence (int64 array) of a shortest start -> goal path over the portal-point graph; empty when
    the goal is unreachable. ``first`` are the start region's nodes with costs ``first_cost`` from the start
    point; the goal is reached from any node on region ``rg`` by a straight segment to (gx, gy)."""
    n = U.shape[0]
    INF = np.inf
    gcost = np.full(n, INF)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    heap = [(0.0, 0.0, np.int64(-3))]
    heap.pop()
    for i in range(first.shape[0]):
        j = first[i]
        d = first_cost[i]
        if d < gcost[j]:
            gcost[j] = d
            parent[j] = -1
            du = U[j] - gx
            dv = V[j] - gy
            heapq.heappush(heap, (d + math.sqrt(du * du + dv * dv), d, np.int64(j)))
    GOAL = np.int64(-2)
    best_goal = INF
    goal_parent = np.int64(-1)
    while len(heap) > 0:
        f, gc, u = heapq.heappop(heap)
        if u == GOAL:
            break
        if closed[u] or gc > gcost[u]:
            continue
        closed[u] = True
        if _on_region(nrp, nri, u, rg):
            du = U[u] - gx
            dv = V[u] - gy
            c = gc + math.sqrt(du * du + dv * dv)
            if c < best_goal:
                best_goal = c
                goal_parent = u
                heapq.heappush(heap, (c, c, GOAL))
        for k in range(aptr[u], aptr[u + 1]):
            j = adst[k]
            d = gc + aw[k]
            if d < gcost[j]:
                gcost[j] = d
                parent[j] = u
                du = U[j] - gx
                dv = V[j] - gy
                heapq.heappush(heap, (d + math.sqrt(du * du + dv * dv), d, j))
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
    each piece must be free."""
    if au == bu and av == bv:
        return _point_free(free, au, av, eps)
    lo = min(au, bu)
    hi = max(au, bu)
    f_u = np.int64(math.floor(lo + eps)) + 1
    l_u = np.int64(math.ceil(hi - eps)) - 1
    n_u = max(l_u - f_u + 1, 0)
    lo = min(av, bv)
    hi = max(av, bv)
    f_v = np.int64(math.floor(lo + eps)) + 1
    l_v = np.int64(math.ceil(hi - eps)) - 1
    n_v = max(l_v - f_v + 1, 0)
    t = np.empty(n_u + n_v + 2)
    t[0] = 0.0
    t[1] = 1.0
    for i in range(n_u):
        t[2 + i] = (f_u + i - au) / (bu - au)
    for i in range(n_v):
        t[2 + n_u + i] = (f_v + i - av) / (bv - av)
    t.sort()
    for i in range(t.shape[0] - 1):
        tm = 0.5 * (t[i] + t[i + 1])
        if not _point_free(free, au + (bu - au) * tm, av + (bv - av) * tm, eps):
            return False
    return True


@nb.njit(**_JIT)
def string_pull(free, pts, window, passes, eps):
    """Windowed string pulling (``routes._string_pull``): from each kept point jump to the farthest of the
    next ``window`` points in line of sight (all pairs when the path has at most ``window`` + 1 points),
    ``passes`` times. Returns (kept points, ok); ok is False when some point sees none of its successors."""
    cur = pts.copy()
    for _ in range(passes):
        k = cur.shape[0]
        if k <= 2:
            if k == 2 and not seg_free(free, cur[0, 0], cur[0, 1], cur[1, 0], cur[1, 1], eps):
                return cur, False
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
                if seg_free(free, cur[i, 0], cur[i, 1], cur[j, 0], cur[j, 1], eps):
                    nxt = j
                    break
            if nxt < 0:
                return cur, False
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
def path_regions(nodes, nrp, nri):
    """(len(nodes) - 1,) the smallest region id shared by consecutive nodes (-1 if none); node region lists
    are sorted ascending."""
    m = nodes.shape[0]
    out = np.full(max(m - 1, 0), -1, dtype=np.int64)
    for i in range(m - 1):
        a, b = nodes[i], nodes[i + 1]
        p, q = nrp[a], nrp[b]
        pe, qe = nrp[a + 1], nrp[b + 1]
        while p < pe and q < qe:
            if nri[p] == nri[q]:
                out[i] = nri[p]
                break
            if nri[p] < nri[q]:
                p += 1
            else:
                q += 1
    return out
