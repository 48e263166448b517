"""Compiled primitives shared by the kernel files of several packages (numba, :mod:`holoslam._jit` policy).

* :func:`clip_segment` -- Liang-Barsky: the part of a segment inside an axis-aligned box (the ray caster clips
  beams to the grid with it, the planner's corridor refinement finds where a segment meets a portal box).
* :func:`csr_group` -- items grouped by an integer key, CSR style (a stable counting sort): the point buckets
  of the front end's nearest-neighbour grid, the blocks of each planning region.
* :func:`argsort_stable` -- ``np.argsort(key, kind="mergesort")`` (numba's own took 2 s of a first run to
  compile in each kernel that used it): the branch and bound's top-level order, the line splitter's pieces.
* :func:`heap_push`, :func:`heap_pop` -- a binary min-heap of (distance, node) in two preallocated arrays, ties
  by the node as ``heapq``'s tuples order them: the Dijkstra searches of the anchor graph and of the rooms' cells
  (numba's ``heapq`` on a list of tuples compiles for ~0.4 s more in each kernel that uses it).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT)
def clip_segment(ox, oy, dx, dy, lo_x, lo_y, hi_x, hi_y):  # pragma: no cover - compiled
    """Liang-Barsky: the parameter interval [t0, t1] of o + t d, 0 <= t <= 1, inside the closed box
    [lo_x, hi_x] x [lo_y, hi_y]; t0 > t1 when the segment misses it."""
    t0 = 0.0
    t1 = 1.0
    for k in range(4):
        if k == 0:
            p, q = -dx, ox - lo_x
        elif k == 1:
            p, q = dx, hi_x - ox
        elif k == 2:
            p, q = -dy, oy - lo_y
        else:
            p, q = dy, hi_y - oy
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            r = q / p
            if p < 0.0:
                if r > t0:
                    t0 = r
            elif r < t1:
                t1 = r
    return t0, t1


@nb.njit(**JIT)
def csr_group(keys, n):  # pragma: no cover - compiled
    """Items 0 .. m-1 grouped by their key in [0, n): (start (n + 1,), order (m,)) int64, the items of key b
    being ``order[start[b]:start[b + 1]]`` in ascending item order (a stable counting sort)."""
    m = keys.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    for k in range(m):
        start[keys[k] + 1] += 1
    for b in range(n):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    for k in range(m):
        order[fill[keys[k]]] = k
        fill[keys[k]] += 1
    return start, order


@nb.njit(**JIT)
def argsort_stable(key):  # pragma: no cover - compiled
    """``np.argsort(key, kind="mergesort")`` of a 1-D array: the indices by increasing key, equal keys in index
    order (a bottom-up merge sort)."""
    n = key.size
    idx = np.arange(n)
    buf = np.empty(n, dtype=np.int64)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid, hi = min(lo + width, n), min(lo + 2 * width, n)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if key[idx[j]] < key[idx[i]]:  # strictly less: equal keys keep their order
                    buf[k] = idx[j]
                    j += 1
                else:
                    buf[k] = idx[i]
                    i += 1
                k += 1
            while i < mid:
                buf[k] = idx[i]
                i += 1
                k += 1
            while j < hi:
                buf[k] = idx[j]
                j += 1
                k += 1
        idx, buf = buf, idx
        width *= 2
    return idx


@nb.njit(**JIT_INNER)
def heap_push(hd, hv, n, d, v):  # pragma: no cover - compiled
    """Push (``d``, ``v``) onto the heap of the first ``n`` entries of ``hd`` (distances) and ``hv`` (nodes), whose
    capacity the caller sized; the new count."""
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


@nb.njit(**JIT, inline="always")  # a few lines at each call site: no kernel of its own to compile
def heap_pop(hd, hv, n):  # pragma: no cover - compiled
    """Pop the least (distance, node) of the heap of ``n`` entries: (distance, node, the new count); n > 0."""
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
