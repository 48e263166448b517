"""Compiled skeleton-to-graph kernels (numba, ``cache=True``) for :func:`holoslam.maps.topology.skeleton_to_graph`.

Imported lazily by :mod:`holoslam.maps.topology` (``_kernels``); without numba the numpy path there runs (same
graph). Every kernel works on the arrays of ``topology._Skeleton`` (sorted flat indices ``flat`` of the
zero-padded grid, 8-neighbour codes ``code``, the dense index map ``index``, offsets ``offs`` in ``_OFFS``
order) and returns exactly what the numpy path computes, in the same order:

* ``nodes``: junction clusters labelled by their smallest cell, node ids in order of that cell, kinds and
  representative cells (largest clearance, then most neighbours, then first in row-major order);
* ``node_pairs``: adjacent cells of different nodes in (cell, direction) order, kept when they join two
  components of the pairs kept so far (``_spanning_pairs``);
* ``trace``: one walk per chain from its first-found end, kept in the direction whose terminal
  (cell, direction) state is smaller than its reverse's, edges ordered by that state (``_trace``);
* ``lengths``: edge lengths from one running sum of step lengths over the concatenated cell sequences (as
  ``np.cumsum``), minimum clearance per edge (NaN if any cell's is NaN, as ``np.minimum.reduceat``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT_INNER)
def _nbr(flat, code, index, offs, i, k):
    """Index of neighbour k of cell i, or -1."""
    if (code[i] >> k) & 1:
        return np.int64(index[flat[i] + offs[k]])
    return np.int64(-1)


@nb.njit(**JIT)
def nodes(flat, code, index, offs, deg, is_node, tip2, clr):
    """(node_of (n,), kind code per node: 0 junction, 1 endpoint, 2 isolated, representative cell per node)."""
    n = flat.shape[0]
    lab = np.full(n, -1, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    for i in range(n):
        if deg[i] >= 3 and lab[i] < 0:  # smallest unlabelled junction cell: its cluster's minimum
            lab[i] = i
            top = 1
            stack[0] = i
            while top:
                top -= 1
                c = stack[top]
                for k in range(8):
                    j = _nbr(flat, code, index, offs, c, k)
                    if j >= 0 and deg[j] >= 3 and lab[j] < 0:
                        lab[j] = i
                        stack[top] = j
                        top += 1
    node_of = np.full(n, -1, dtype=np.int64)
    nn = 0
    for i in range(n):
        if is_node[i] and (lab[i] < 0 or lab[i] == i):
            node_of[i] = nn
            nn += 1
    kind = np.empty(nn, dtype=np.int8)
    rep = np.full(nn, -1, dtype=np.int64)
    best_key = np.empty(nn, dtype=np.float64)
    best_deg = np.empty(nn, dtype=np.int64)
    for i in range(n):
        if not is_node[i]:
            continue
        if lab[i] >= 0 and lab[i] != i:
            node_of[i] = node_of[lab[i]]
        v = node_of[i]
        key = clr[i]
        if np.isnan(key):
            key = 0.0
        if rep[v] < 0:  # the cluster's first cell: its root
            d = deg[i]
            kind[v] = 0 if d >= 3 else (1 if (d == 1 or tip2[i]) else 2)
            rep[v], best_key[v], best_deg[v] = i, key, deg[i]
        elif key > best_key[v] or (key == best_key[v] and deg[i] > best_deg[v]):
            rep[v], best_key[v], best_deg[v] = i, key, deg[i]
    return node_of, kind, rep


@nb.njit(**JIT_INNER)
def _find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@nb.njit(**JIT)
def node_pairs(flat, code, index, offs, is_node, node_of, n_nodes):
    """(di, dj): adjacent node cells of different nodes that join two components of the pairs kept so far."""
    parent = np.arange(n_nodes)
    n = flat.shape[0]
    di = np.empty(n_nodes, dtype=np.int64)  # a spanning forest has fewer than n_nodes edges
    dj = np.empty(n_nodes, dtype=np.int64)
    m = 0
    for i in range(n):
        if not is_node[i]:
            continue
        for k in range(8):
            j = _nbr(flat, code, index, offs, i, k)
            if j > i and is_node[j] and node_of[i] != node_of[j]:
                ra, rb = _find(parent, node_of[i]), _find(parent, node_of[j])
                if ra != rb:
                    parent[ra] = rb
                    di[m], dj[m] = i, j
                    m += 1
    return di[:m], dj[:m]


@nb.njit(**JIT)
def trace(flat, code, index, offs, bit0, bit1, is_node):
    """(u_cell, v_cell, cells, starts, complete): edges along chains as in ``topology._trace``; complete is
    False when chain cells remain that no walk from a node reached (closed loops without a node)."""
    cpos, n_chain, nb2 = _chain_neighbours(flat, code, index, offs, bit0, bit1, is_node)
    buf, wstart, wkey, nw, n_seen = _walk_chains(flat, code, index, offs, is_node, cpos, n_chain, nb2)
    u_cell, v_cell, cells, starts = _edges_in_key_order(buf, wstart, wkey, nw, n_chain)
    return u_cell, v_cell, cells, starts, n_seen == n_chain


@nb.njit(inline="always", **JIT)
def _chain_neighbours(flat, code, index, offs, bit0, bit1, is_node):
    """Each chain cell's position among the chain cells (-1 at nodes), their count, and both neighbours of
    every chain cell, sorted (n, 2)."""
    n = flat.shape[0]
    cpos = np.full(n, -1, dtype=np.int64)
    n_chain = 0
    for i in range(n):
        if not is_node[i]:
            cpos[i] = n_chain
            n_chain += 1
    # both neighbours of every chain cell, in cell order: the index map is read row by row (a walk reading it
    # would jump a grid row per vertical step)
    nb2 = np.empty((n, 2), dtype=np.int32)  # both in one cache line
    for i in range(n):
        if not is_node[i]:
            fc = flat[i]
            cc = code[i]
            a = np.int64(index[fc + offs[bit0[cc]]])
            b = np.int64(index[fc + offs[bit1[cc]]])
            nb2[i, 0], nb2[i, 1] = min(a, b), max(a, b)
    return cpos, n_chain, nb2


@nb.njit(inline="always", **JIT)
def _walk_chains(flat, code, index, offs, is_node, cpos, n_chain, nb2):
    """Walk every chain from each node it leaves (a chain already walked from its other end is skipped):
    the walks' cells (node, chain cells ..., node) in ``buf`` from ``wstart``, each in the direction whose last
    (cell, direction) state is smaller than its reverse's, that state its key; returns (buf, wstart, wkey,
    walks, chain cells seen)."""
    n = flat.shape[0]
    visited = np.zeros(n, dtype=np.bool_)
    buf = np.empty(3 * n_chain + 2, dtype=np.int64)  # every edge has a chain cell: edges <= chain cells
    wstart = np.empty(n_chain + 1, dtype=np.int64)
    wkey = np.empty(n_chain + 1, dtype=np.int64)
    nw = 0
    nb_ = 0
    n_seen = 0
    for i in range(n):
        if not is_node[i]:
            continue
        for k in range(8):
            c0 = _nbr(flat, code, index, offs, i, k)
            if c0 < 0 or is_node[c0] or visited[c0]:
                continue
            s0 = nb_
            buf[nb_] = i
            nb_ += 1
            prev, cur = np.int64(i), c0
            while True:  # only the walk's end cells are marked: a walk is skipped where another ended
                buf[nb_] = cur
                nb_ += 1
                nxt = np.int64(nb2[cur, 0]) + nb2[cur, 1] - prev
                if is_node[nxt]:
                    break
                prev, cur = cur, nxt
            buf[nb_] = nxt
            nb_ += 1
            # (cell, direction) states: 2 cpos + d at a chain cell arrived from its d-th (sorted) neighbour
            visited[c0] = True
            visited[cur] = True
            n_seen += nb_ - s0 - 2
            s = 2 * cpos[c0] + (nb2[c0, 0] != i)
            t = 2 * cpos[cur] + (nb2[cur, 0] != prev)
            if t < (s ^ 1):
                wkey[nw] = t
            else:  # keep the reverse walk
                wkey[nw] = s ^ 1
                _reverse(buf, s0, nb_ - 1)
            wstart[nw] = s0
            nw += 1
    wstart[nw] = nb_
    return buf, wstart, wkey, nw, n_seen


@nb.njit(inline="always", **JIT)
def _reverse(buf, lo, hi):
    while lo < hi:
        buf[lo], buf[hi] = buf[hi], buf[lo]
        lo += 1
        hi -= 1


@nb.njit(inline="always", **JIT)
def _edges_in_key_order(buf, wstart, wkey, nw, n_chain):
    """The walks as edges (u_cell, v_cell, cells, starts), ordered by key."""
    # order by key: the keys are distinct states < 2 n_chain, so a scan of a dense table sorts them
    slot = np.full(2 * n_chain + 2, -1, dtype=np.int64)
    for w in range(nw):
        slot[wkey[w]] = w
    order = np.empty(nw, dtype=np.int64)
    q = 0
    for x in range(slot.shape[0]):
        if slot[x] >= 0:
            order[q] = slot[x]
            q += 1
    nb_ = wstart[nw]
    cells = np.empty(nb_, dtype=np.int64)
    starts = np.empty(nw + 1, dtype=np.int64)
    u_cell = np.empty(nw, dtype=np.int64)
    v_cell = np.empty(nw, dtype=np.int64)
    p = 0
    for e in range(nw):
        w = order[e]
        a, b = wstart[w], wstart[w + 1]
        starts[e] = p
        for i in range(b - a):  # cells[p:p + b - a] = buf[a:b] (numba's slice-to-slice copy: 4 s to compile)
            cells[p + i] = buf[a + i]
        p += b - a
        u_cell[e] = buf[a]
        v_cell[e] = buf[b - 1]
    starts[nw] = p
    return u_cell, v_cell, cells, starts


@nb.njit(**JIT)
def lengths(rc, starts, clr_cells, resolution):
    """(length, min_clearance) per edge of the concatenated (sum K, 2) cell sequence rc."""
    m = starts.shape[0] - 1
    total = rc.shape[0]
    cum = np.empty(total + 1, dtype=np.float64)
    cum[0] = 0.0
    sqrt2 = np.sqrt(2.0)
    e = 0
    for j in range(total):
        while e < m and starts[e + 1] <= j:
            e += 1
        step = 0.0
        if j + 1 < total and j + 1 != starts[e + 1]:
            dd = abs(rc[j + 1, 0] - rc[j, 0]) + abs(rc[j + 1, 1] - rc[j, 1])
            step = sqrt2 if dd == 2 else 1.0
        cum[j + 1] = cum[j] + step
    length = np.empty(m, dtype=np.float64)
    min_clr = np.empty(m, dtype=np.float64)
    for e in range(m):
        a, b = starts[e], starts[e + 1]
        length[e] = (cum[b - 1] - cum[a]) * resolution
        mn = clr_cells[a]
        for j in range(a + 1, b):
            x = clr_cells[j]
            if np.isnan(x) or x < mn:
                if not np.isnan(mn):
                    mn = x
        min_clr[e] = mn
    return length, min_clr
