"""Compiled kernels of the front end's anchor graph (numba, ``cache=True``): Dijkstra's shortest paths.

A module of its own, apart from the kernels local SLAM needs from its first scan (``warmup.FRONT_END``): a first
run's pool compiles it while local SLAM runs (the loop search needs it once a submap is finished).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._common_fast import heap_pop, heap_push
from holoslam._jit import JIT


@nb.njit(**JIT)
def dijkstra(indptr, indices, weights, source):  # pragma: no cover - compiled
    """Shortest paths from ``source`` over the arcs of a graph in CSR form (node u's arcs go to
    ``indices[indptr[u]:indptr[u + 1]]`` with ``weights``, non-negative): (dist (N,), inf where unreached, and
    pred (N,), the node before each on its path, -1 for the source and the unreached). Dijkstra's algorithm with a
    binary heap (``_common_fast.heap_push``: ties by the node, as ``heapq``'s tuples); a node's distance is its
    predecessor's plus the arc's weight, scipy's ``csgraph.dijkstra`` arithmetic (the anchor graph's tens to
    thousands of nodes: that call's sparse-matrix set-up cost ~10x the search)."""
    n = indptr.size - 1
    dist = np.full(n, np.inf)
    pred = np.full(n, -1, dtype=np.int64)
    done = np.zeros(n, dtype=np.bool_)
    hd = np.empty(indices.size + 1, dtype=np.float64)  # a push per improving arc at most, and the source's
    hv = np.empty(indices.size + 1, dtype=np.int64)
    dist[source] = 0.0
    m = heap_push(hd, hv, np.int64(0), 0.0, np.int64(source))
    while m > 0:
        d, u, m = heap_pop(hd, hv, m)
        if done[u]:
            continue
        done[u] = True
        for k in range(indptr[u], indptr[u + 1]):
            v = indices[k]
            nd = d + weights[k]
            if not done[v] and nd < dist[v]:
                dist[v] = nd
                pred[v] = u
                m = heap_push(hd, hv, m, nd, np.int64(v))
    return dist, pred
