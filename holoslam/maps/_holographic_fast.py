"""Compiled kernels (numba, ``cache=True``) of the holographic graph's region merging and passages.

Imported lazily by :mod:`holoslam.maps.doorways` and :mod:`holoslam.maps.passages` (``kernels``); without numba
the numpy / scipy paths there run. Each kernel returns what its fallback computes:

* ``restore``: cells given back when a cut is dropped become one-cell regions joined to every labelled
  4-neighbour (union-find whose root is the smallest id of its set, so the partition, areas and largest
  clearances do not depend on the order of the unions: the same as ``doorways._Regions.restore``);
* ``grow_labels``: the room label image grown over the free cells (``rooms._grow``); ``label_max``,
  ``label_stats``: the largest value per label (``np.maximum.at``), where it is last and the label's size; ``cut_lines``: each gap's obstacle-to-obstacle line
  (``doorways.orient_cuts``); ``chords``: the free chords beside a wide opening (``rooms._widening``);
* ``dijkstra_to``: single-source Dijkstra over a CSR graph that stops once every target is settled (binary
  heap on (distance, cell)); returns distances and predecessors as ``scipy.sparse.csgraph.dijkstra`` does
  (inf / -9999 where not reached). Among equally short paths it may pick another than scipy's.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._common_fast import heap_pop, heap_push
from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT_INNER)
def _find(parent, x):
    root = x
    while parent[root] != root:
        root = parent[root]
    while parent[x] != root:
        nx_ = parent[x]
        parent[x] = root
        x = nx_
    return root


@nb.njit(**JIT_INNER)
def _union(parent, area, mx, a, b):
    ra = _find(parent, a)
    rb = _find(parent, np.int64(b))  # b is an int32 label: one _find to compile, not one per integer type
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
def dijkstra_to(indptr, indices, data, source, targets):
    """(dist, pred) from ``source``, searched until every cell of ``targets`` is settled (or none is left)."""
    n = indptr.shape[0] - 1
    dist = np.full(n, np.inf)
    pred = np.full(n, -9999, dtype=np.int32)
    done = np.zeros(n, dtype=np.bool_)
    want = np.zeros(n, dtype=np.bool_)
    left = 0
    for t in targets:
        if not want[t]:
            want[t] = True
            left += 1
    cap = indices.shape[0] + 1
    hd = np.empty(cap, dtype=np.float64)
    hv = np.empty(cap, dtype=np.int64)
    dist[source] = 0.0
    # np.int64 arguments: a literal 0 or an int32 node would compile heap_push once more for that type
    m = heap_push(hd, hv, np.int64(0), 0.0, source)
    while m > 0 and left > 0:
        d, u, m = heap_pop(hd, hv, m)
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
                m = heap_push(hd, hv, m, nd, np.int64(v))
    return dist, pred


@nb.njit(**JIT)
def grow_labels(lab, free, w):
    """Every free cell with label 0 gets the label of the nearest labelled cell along 4-connected free cells,
    the largest among equally near ones (the numpy fallback of ``rooms._grow``: one ring per round, each cell
    taking the largest label of its labelled 4-neighbours); in place."""
    size = lab.shape[0]
    dist = np.full(size, -1, dtype=np.int64)
    queue = np.empty(size, dtype=np.int64)
    head = 0
    tail = 0
    for c in range(size):
        if lab[c] > 0:
            dist[c] = 0
            queue[tail] = c
            tail += 1
    while head < tail:
        c = queue[head]
        head += 1
        col = c % w
        for k in range(4):
            if k == 0:
                if c < w:
                    continue
                nb = c - w
            elif k == 1:
                if c >= size - w:
                    continue
                nb = c + w
            elif k == 2:
                if col == 0:
                    continue
                nb = c - 1
            else:
                if col == w - 1:
                    continue
                nb = c + 1
            if dist[nb] < 0 and free[nb] and lab[nb] == 0:
                dist[nb] = dist[c] + 1
                queue[tail] = nb
                tail += 1
    # labels in order of distance: a cell takes the largest label of its 4-neighbours one step nearer
    for q in range(tail):
        c = queue[q]
        if dist[c] == 0:
            continue
        col = c % w
        best = 0
        d = dist[c] - 1
        if c >= w and dist[c - w] == d and lab[c - w] > best:
            best = lab[c - w]
        if c < size - w and dist[c + w] == d and lab[c + w] > best:
            best = lab[c + w]
        if col > 0 and dist[c - 1] == d and lab[c - 1] > best:
            best = lab[c - 1]
        if col < w - 1 and dist[c + 1] == d and lab[c + 1] > best:
            best = lab[c + 1]
        lab[c] = best


@nb.njit(**JIT)
def label_max(values, labels, n):
    """(n,) the largest of the ``values`` per label 0..n-1 (flat arrays; 0 where a label has none, values
    >= 0): ``np.maximum.at`` without its per-element dispatch."""
    out = np.zeros(n, dtype=np.float64)
    for i in range(values.shape[0]):
        k = labels[i]
        if values[i] > out[k]:
            out[k] = values[i]
    return out


@nb.njit(**JIT)
def cut_lines(free, cells, reach):
    """For each cell (N, 2) of a gap: its nearest non-free cell p1 within ``reach`` cells (a square window,
    the first in raster order among equally near ones) and the nearest non-free cell p2 on the other side
    ((p2 - cell) . (p1 - cell) < 0, first in raster order): ``doorways.orient_cuts``'s numpy loop. Returns
    p1, p2 (N, 2) int64 and whether each cell has both (no line when p1 is the cell itself)."""
    h, w = free.shape
    n = cells.shape[0]
    p1 = np.zeros((n, 2), dtype=np.int64)
    p2 = np.zeros((n, 2), dtype=np.int64)
    ok = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        r, c, k = cells[i, 0], cells[i, 1], reach[i]
        r0, r1 = max(r - k, 0), min(r + k + 1, h)
        c0, c1 = max(c - k, 0), min(c + k + 1, w)
        best = -1.0
        br, bc = 0, 0
        for rr in range(r0, r1):
            for cc in range(c0, c1):
                if not free[rr, cc]:
                    d2 = float((rr - r) * (rr - r) + (cc - c) * (cc - c))
                    if best < 0.0 or d2 < best:
                        best, br, bc = d2, rr, cc
        if best <= 0.0:
            continue
        vr, vc = br - r, bc - c
        best2 = -1.0
        sr, sc = 0, 0
        for rr in range(r0, r1):
            for cc in range(c0, c1):
                if not free[rr, cc] and (rr - r) * vr + (cc - c) * vc < 0:
                    d2 = float((rr - r) * (rr - r) + (cc - c) * (cc - c))
                    if best2 < 0.0 or d2 < best2:
                        best2, sr, sc = d2, rr, cc
        if best2 < 0.0:
            continue
        p1[i, 0], p1[i, 1], p2[i, 0], p2[i, 1] = br, bc, sr, sc
        ok[i] = True
    return p1, p2, ok


@nb.njit(**JIT_INNER)
def _free_at(free, r, c):
    h, w = free.shape
    ri = int(np.rint(r))
    ci = int(np.rint(c))
    if ri < 0 or ri >= h or ci < 0 or ci >= w:
        return False
    return free[ri, ci]


@nb.njit(**JIT)
def chords(free, mid, u, v, offsets, n):
    """For each cut (middle ``mid``, unit direction ``u`` along it, ``v`` across, (N, 2) row/col): the longest
    free chord along ``u`` through the points ``mid + o v`` for each offset o (cells; a point that is not free
    gives 0), each ray from the point stopping at the first non-free sample or after ``n`` steps of one cell
    (``rooms._widening``'s numpy sampling: points rounded to the nearest cell)."""
    m = mid.shape[0]
    out = np.zeros(m, dtype=np.float64)
    for i in range(m):
        for o in offsets:
            qr = mid[i, 0] + o * v[i, 0]
            qc = mid[i, 1] + o * v[i, 1]
            if not _free_at(free, qr, qc):
                continue
            total = 0.0
            for sgn in (1.0, -1.0):
                steps = n
                for s in range(1, n + 1):
                    if not _free_at(free, qr + sgn * s * u[i, 0], qc + sgn * s * u[i, 1]):
                        steps = s - 1
                        break
                total += steps
            if total > out[i]:
                out[i] = total
    return out


@nb.njit(**JIT)
def label_stats(labels, values, n):
    """Per label 0..n-1 of the flat ``labels``: the largest of the ``values`` (>= 0; 0 where none), the last
    flat index holding it (-1 where none) and the number of cells."""
    mx = np.zeros(n, dtype=np.float64)
    at = np.full(n, -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    for i in range(labels.shape[0]):
        k = labels[i]
        count[k] += 1
        if values[i] >= mx[k]:
            mx[k] = values[i]
            at[k] = i
    return mx, at, count
