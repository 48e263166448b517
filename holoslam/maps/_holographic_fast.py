"""Compiled kernels (numba, ``cache=True``) of the holographic graph's region merging and passages.

Imported lazily by :mod:`holoslam.maps.doorways` and :mod:`holoslam.maps.passages` (``kernels``); without numba
the numpy / scipy paths there run. Each kernel returns what its fallback computes:

* ``restore``: cells given back when a cut is dropped become one-cell regions joined to every labelled
  4-neighbour (union-find whose root is the smallest id of its set, so the partition, areas and largest
  clearances do not depend on the order of the unions: the same as ``doorways._Regions.restore``);
* ``dijkstra_to``: single-source Dijkstra over a CSR graph that stops once every target is settled (binary
  heap on (distance, cell)); returns distances and predecessors as ``scipy.sparse.csgraph.dijkstra`` does
  (inf / -9999 where not reached). Among equally short paths it may pick another than scipy's.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._jit import JIT


@nb.njit(**JIT)
def _find(parent, x):
    root = x
    while parent[root] != root:
        root = parent[root]
    while parent[x] != root:
        nx_ = parent[x]
        parent[x] = root
        x = nx_
    return root


@nb.njit(**JIT)
def _union(parent, area, mx, a, b):
    ra = _find(parent, a)
    rb = _find(parent, b)
    if ra == rb:
        return
    if ra > rb:
        ra, rb = rb, ra
    parent[rb] = ra
    area[ra] += area[rb]
    if mx[rb] > mx[ra]:
        mx[ra] = mx[rb]


@nb.njit(**JIT)
def restore(cells, lab, parent, area, mx, clr, next_id, w):
    """Label ``cells`` (flat indices) next_id, next_id + 1, ... and join each to its labelled 4-neighbours;
    returns the next free id."""
    k = cells.shape[0]
    size = lab.shape[0]
    for q in range(k):
        c = cells[q]
        i = next_id + q
        lab[c] = i
        area[i] = 1.0
        mx[i] = clr[c]
    for q in range(k):
        c = cells[q]
        i = next_id + q
        col = c % w
        if c >= w and lab[c - w] > 0:
            _union(parent, area, mx, i, lab[c - w])
        if c < size - w and lab[c + w] > 0:
            _union(parent, area, mx, i, lab[c + w])
        if col > 0 and lab[c - 1] > 0:
            _union(parent, area, mx, i, lab[c - 1])
        if col < w - 1 and lab[c + 1] > 0:
            _union(parent, area, mx, i, lab[c + 1])
    return next_id + k


@nb.njit(**JIT)
def _push(hd, hv, n, d, v):
    i = n
    hd[i] = d
    hv[i] = v
    while i > 0:
        p = (i - 1) >> 1
        if hd[p] < hd[i] or (hd[p] == hd[i] and hv[p] <= hv[i]):
            break
        hd[p], hd[i] = hd[i], hd[p]
        hv[p], hv[i] = hv[i], hv[p]
        i = p
    return n + 1


@nb.njit(**JIT)
def _pop(hd, hv, n):
    d, v = hd[0], hv[0]
    n -= 1
    hd[0] = hd[n]
    hv[0] = hv[n]
    i = 0
    while True:
        a = 2 * i + 1
        if a >= n:
            break
        b = a + 1
        s = a
        if b < n and (hd[b] < hd[a] or (hd[b] == hd[a] and hv[b] < hv[a])):
            s = b
        if hd[i] < hd[s] or (hd[i] == hd[s] and hv[i] <= hv[s]):
            break
        hd[s], hd[i] = hd[i], hd[s]
        hv[s], hv[i] = hv[i], hv[s]
        i = s
    return d, v, n


@nb.njit(**JIT)
def dijkstra_to(indptr, indices, data, source, targets):
    """(dist, pred) from ``source``, searched until every cell of ``targets`` is settled (or none is left)."""
    n = indptr.shape[0] - 1
    dist = np.full(n, np.inf)
    pred = np.full(n, -9999, np.int32)
    done = np.zeros(n, np.bool_)
    want = np.zeros(n, np.bool_)
    left = 0
    for t in targets:
        if not want[t]:
            want[t] = True
            left += 1
    cap = indices.shape[0] + 1
    hd = np.empty(cap)
    hv = np.empty(cap, np.int64)
    dist[source] = 0.0
    m = _push(hd, hv, 0, 0.0, source)
    while m > 0 and left > 0:
        d, u, m = _pop(hd, hv, m)
        if done[u]:
            continue
        done[u] = True
        if want[u]:
            left -= 1
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + data[e]
            if nd < dist[v]:
                dist[v] = nd
                pred[v] = u
                m = _push(hd, hv, m, nd, v)
    return dist, pred
