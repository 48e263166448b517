"""Compiled corridor search of the planner: A* over the port graph (numba, :mod:`holoslam._jit` policy).

:func:`corridor_astar` searches the ports (the distinct corners and the centre of each portal) with edges
between the ports of one region, read from each region's port list instead of stored; the heuristic is the
larger of the Euclidean distance and the ALT landmark bounds (:func:`_alt`), weighted; the per-node state
lives in a reusable workspace of ``WORKSPACE_DTYPE`` records and an indexed binary heap with decrease-key
(:func:`_heap_set`, :func:`_heap_pop`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_FASTMATH

# the corridor search's per-node workspace record (see ``corridor_astar``)
WORKSPACE_DTYPE = np.dtype(
    [("g", "f8"), ("h", "f8"), ("stamp", "i4"), ("parent", "i4"), ("pos", "i4"), ("pad", "i4")], align=True
)


@nb.njit(**JIT)
def _alt(node, dgoal, v, h):
    """The landmark (ALT) heuristic of node v: for each region q holding the goal, the largest of ``h`` and
    the bounds |d(l, goal via q) - d(l, v)| (``dgoal[q, l]``, ``node[v, 2 + l]`` = d(l, v)), and the
    smallest of these over q (:func:`_goal_distances`); a landmark of another component (both distances
    infinite: NaN) is skipped."""
    best = h
    for q in range(dgoal.shape[0]):
        x = h
        for l in range(dgoal.shape[1]):
            y = abs(dgoal[q, l] - node[v, 2 + l])
            if y > x and y < np.inf:
                x = y
        best = x if q == 0 else min(best, x)
    return best


@nb.njit(**JIT_FASTMATH)
def _alt_finite(node, dgoal, v, h):
    """:func:`_alt` when every landmark distance involved is finite (the landmarks all reach the goal's
    component, so they reach every node the search meets): a branch-free max that vectorises."""
    best = h
    for q in range(dgoal.shape[0]):
        x = h
        for l in range(dgoal.shape[1]):
            x = max(x, abs(dgoal[q, l] - node[v, 2 + l]))
        best = x if q == 0 else min(best, x)
    return best


@nb.njit(**JIT)
def _heuristic(heur, j, e):
    """The search's weighted heuristic of node j, ``e`` its Euclidean distance to the goal; ``heur`` =
    (node rows, the landmarks' distances to the goal by goal region (:func:`_goal_distances`), all of them
    finite, weight)."""
    node, dgoal, finite, hw = heur
    return hw * (_alt_finite(node, dgoal, j, e) if finite else _alt(node, dgoal, j, e))


@nb.njit(**JIT)
def _touch(ws, gen, j):
    """Reset node j's workspace record the first time this query (generation ``gen``) meets it."""
    r = ws[j]
    if r.stamp != gen:
        r.stamp = gen
        r.parent = -1
        r.pos = -1
        r.g = np.inf
        r.h = -1.0


@nb.njit(**JIT)
def _heap_put(hn, hk, ws, i, v, key):
    """Slot i of the indexed heap holds node v with ``key``."""
    hn[i] = v
    hk[i] = key
    ws[v].pos = i


@nb.njit(**JIT)
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
        _heap_put(hn, hk, ws, i, hn[p], hk[p])
        i = p
    _heap_put(hn, hk, ws, i, v, key)
    return size


@nb.njit(**JIT)
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
            _heap_put(hn, hk, ws, i, hn[c], hk[c])
            i = c
        _heap_put(hn, hk, ws, i, lv, lk)
    return v, key, size


@nb.njit(**JIT)
def _goal_distances(node, last, ea, eb, goal_regs, gx, gy, nl):
    """(Q, nl): row q holds each landmark's distance to the goal through the best port of the region
    ``goal_regs[q]`` holding it (among ``last``, the ports of all of them), then straight to the goal.

    Kept apart by region, not as one distance through any of them: the goal joins the ports of every region
    holding it, so with several such regions it also joins ports that the port graph joins only around
    (overlapping regions need not be adjacent: adjacency comes from their blocks), and the landmark
    distances d(l, v), measured on the port graph, need not obey the triangle inequality through the goal:
    |d(l, goal) - d(l, v)| was then no lower bound of d(v, goal) (a route 1.6x the A* optimum, test_routes).
    Through one region q it is: the goal joins only q's ports, which the port graph joins to each other by
    straight edges, no longer than through the goal. So v's bound through each goal region bounds its
    distance through that region, and the smallest of them its distance to the goal (:func:`_alt`)."""
    Q = goal_regs.shape[0]
    dist = np.full((Q, nl), np.inf)
    for i in range(last.shape[0]):
        p = last[i]
        du = node[p, 0] - gx
        dv = node[p, 1] - gy
        e = math.sqrt(du * du + dv * dv)
        for q in range(Q):
            if Q > 1 and ea[p] != goal_regs[q] and eb[p] != goal_regs[q]:
                continue
            for l in range(nl):
                x = node[p, 2 + l] + e
                if x < dist[q, l]:
                    dist[q, l] = x
    return dist


@nb.njit(**JIT)
def _next_generation(ws, n):
    """Start a query on the workspace of n nodes: bump the generation kept in ``ws[n + 1]`` (forgetting every
    stamp when it is about to wrap) and return it."""
    if ws[n + 1].stamp >= 2**31 - 2:
        for j in range(n + 2):
            ws[j].stamp = 0
    ws[n + 1].stamp += 1
    return ws[n + 1].stamp


@nb.njit(**JIT)
def _seed_start(heur, first, first_cost, gx, gy, ws, hn, hk, gen):
    """Put the start's ports ``first`` with their costs in the emptied heap; returns its size."""
    node = heur[0]
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
                r.h = _heuristic(heur, j, math.sqrt(du * du + dv * dv))
            size = _heap_set(hn, hk, ws, size, j, d + r.h)
    return size


@nb.njit(**JIT)
def _relax_region(graph, heur, gx, gy, ws, hn, hk, gen, size, reg, u, gc, uu, uv, best_goal):
    """Relax the ports of region ``reg`` from node u (cost ``gc``, at (uu, uv)); returns the heap's size.
    A port is skipped when even the straight line from it to the goal cannot beat ``best_goal``, and not put
    in the heap when its key cannot."""
    rp_ptr, rp_id, rp_uv = graph[0], graph[1], graph[2]
    for k in range(rp_ptr[reg], rp_ptr[reg + 1]):
        j = rp_id[k]
        if j == u:
            continue
        ju = rp_uv[k, 0]
        jv = rp_uv[k, 1]
        d = gc + math.sqrt((ju - uu) * (ju - uu) + (jv - uv) * (jv - uv))
        e = -1.0
        if best_goal < np.inf:
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
                r.h = _heuristic(heur, j, e)
            if d + r.h < best_goal:
                size = _heap_set(hn, hk, ws, size, j, d + r.h)
    return size


@nb.njit(**JIT)
def _on_goal(ea, eb, goal_regs, u):
    """Port u lies on a region holding the goal."""
    for q in range(goal_regs.shape[0]):
        if ea[u] == goal_regs[q] or eb[u] == goal_regs[q]:
            return True
    return False


@nb.njit(**JIT)
def _trace(ws, last):
    """The port sequence (int64) from the start to ``last`` along the parents; empty when ``last`` < 0."""
    if last < 0:
        return np.zeros(0, dtype=np.int64)
    m = 0
    x = last
    while x != -1:
        m += 1
        x = ws[x].parent
    out = np.empty(m, dtype=np.int64)
    x = last
    for i in range(m - 1, -1, -1):
        out[i] = x
        x = ws[x].parent
    return out


@nb.njit(**JIT)
def corridor_astar(graph, first, first_cost, last, goal_regs, gx, gy, hw, ws, hn, hk):
    """Port sequence (int64 array) of a shortest start -> goal route over the port graph ``graph`` = (rp_ptr,
    rp_id, rp_uv, node, ea, eb): nodes = ports, each on portal edge (ea, eb); edges = two ports of one region,
    weighted by their distance. The edges are not stored: a port's neighbours are the ports of its two
    regions, listed per region with their coordinates (CSR ``rp_ptr``, ``rp_id`` int32, ``rp_uv`` (M, 2)
    float32), read in sequence, so only the records of
    the ports the search meets are read at random (an eighth of the memory of the edge list). ``node`` (n, >= 2
    + L) float32 rows: the port's (u, v), then its distances from the L landmarks (the rest padding), one
    64-byte row a port for L = 14. ``first`` are the start regions' ports with costs ``first_cost``; the goal
    is reached from every port (``last``) of the regions ``goal_regs`` holding it by a straight segment.
    Heuristic: the larger of the Euclidean distance and the ALT landmark bounds (by goal region,
    :func:`_goal_distances`: a lower bound also when several regions hold the goal), times ``hw`` (1 = exact: both bounds are
    consistent, so a popped node is final), computed once per node when first reached (a
    lazy variant, keyed by the Euclidean bound until the node reaches the top of the heap, computes it for
    two thirds of the nodes anyway and was 1.6x slower: the heap work of the re-insertions costs more).
    Nodes are not put in the heap when their key is no less than the best goal cost found: the goal, keyed
    by that cost, would leave the heap first. Empty when unreachable.

    The rest is a reusable workspace, nothing of it cleared per query: ``ws`` (n + 2,) records of
    ``WORKSPACE_DTYPE`` (g, h, stamp, parent, pos: 32 bytes, so meeting a node touches one cache line; a
    record is valid only when its stamp equals ``ws[n + 1].stamp``, the query's generation, bumped here;
    node n is the goal; pos is the heap slot, -1 out of the heap, -2 closed) and the indexed binary heap
    ``hn`` (n + 1,) int64, ``hk`` (n + 1,) float64 (decrease-key: at most one entry per node)."""
    node, ea, eb = graph[3], graph[4], graph[5]
    n = node.shape[0]
    dgoal = _goal_distances(node, last, ea, eb, goal_regs, gx, gy, min(node.shape[1] - 2, 64))
    finite = True
    for q in range(dgoal.shape[0]):
        for l in range(dgoal.shape[1]):
            finite = finite and dgoal[q, l] < np.inf
    heur = (node, dgoal, finite, hw)
    gen = _next_generation(ws, n)
    GOAL = n
    _touch(ws, gen, GOAL)
    size = _seed_start(heur, first, first_cost, gx, gy, ws, hn, hk, gen)
    best_goal = np.inf
    goal_parent = np.int64(-1)
    while size > 0:
        u, key, size = _heap_pop(hn, hk, ws, size)
        if u == GOAL:
            break
        ru = ws[u]
        gc = ru.g
        ru.pos = -2  # closed
        if _on_goal(ea, eb, goal_regs, u):
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
            size = _relax_region(graph, heur, gx, gy, ws, hn, hk, gen, size, reg, u, gc, uu, uv, best_goal)
    return _trace(ws, goal_parent)
