"""The skeleton's cells and the numpy path of :func:`holoslam.maps.topology.skeleton_to_graph` (classification
tables, node labelling, chain tracing by lockstep walks or pointer jumping, junction-cluster holes): the fallback
without numba and the reference the compiled kernels (:mod:`holoslam.maps._topology_fast`) are tested against.
The module docstring of :mod:`holoslam.maps.topology` describes the method."""

from __future__ import annotations

import numpy as np


def _pointer_jump(
    nxt: np.ndarray, val: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Successor array nxt (-1 = terminal). Returns (rank = steps to the terminal, root = terminal state,
    done = whether a terminal was reached); with val, also folds min(val) along the way (returned as root for
    states that never terminate, i.e. lie on a cycle)."""
    n = nxt.shape[0]
    rank = (nxt >= 0).astype(np.int64)
    root = np.where(nxt >= 0, nxt, np.arange(n))
    ptr = nxt.copy()
    mn = val.copy() if val is not None else None
    rounds = max(1, int(np.ceil(np.log2(max(n, 2)))) + 1)
    act = np.flatnonzero(ptr >= 0)  # live states only: the set shrinks as chains are resolved
    for _ in range(rounds):
        if act.size == 0:
            break
        p = ptr[act]
        rank[act] += rank[p]
        root[act] = root[p]
        if mn is not None:
            mn[act] = np.minimum(mn[act], mn[p])
        nptr = ptr[p]
        ptr[act] = nptr
        act = act[nptr >= 0]
    done = ptr < 0
    return rank, (root if mn is None else np.where(done, root, mn)), done


_OFFS = np.array([(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)], dtype=np.int64)


def _code_tables() -> tuple[np.ndarray, np.ndarray]:
    """Per 8-neighbour code (bit k = neighbour _OFFS[k]): number of neighbours, and whether the code has
    exactly two neighbours that touch each other (8-adjacent: a line tip)."""
    bits = (np.arange(256)[:, None] >> np.arange(8)[None, :]) & 1
    deg = bits.sum(axis=1).astype(np.int64)
    tip2 = np.zeros(256, dtype=bool)
    for code in np.flatnonzero(deg == 2):
        a, b = np.flatnonzero(bits[code])
        tip2[code] = np.abs(_OFFS[a] - _OFFS[b]).max() == 1
    return deg, tip2


_DEG, _TIP2 = _code_tables()
# lowest and second-lowest set bit of each code (0 where there are fewer)
_BIT0 = np.array([([k for k in range(8) if c >> k & 1] + [0, 0])[0] for c in range(256)], dtype=np.int64)
_BIT1 = np.array([([k for k in range(8) if c >> k & 1] + [0, 0])[1] for c in range(256)], dtype=np.int64)


class _Skeleton:
    """Skeleton cells as sorted flat indices of the zero-padded grid: their (row, col), neighbour codes,
    neighbour table (index of the neighbour cell or -1) and degrees, all from whole-array gathers."""

    def __init__(self, skel: np.ndarray) -> None:
        import cv2

        h, w = skel.shape
        self.h, self.w, self.w2 = h, w, w + 2
        pad = cv2.copyMakeBorder(
            np.ascontiguousarray(skel).view(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0
        )
        self.pad = pad.ravel()
        # intp positions (numpy gathers convert int32 indices first, several times slower)
        self.flat = np.flatnonzero(self.pad.view(bool))  # sorted (row-major)
        n = self.flat.shape[0]
        itype = np.int32 if n < 2**31 - 1 else np.int64  # cell numbers in the index map
        r = self.flat // self.w2
        self.rc = np.column_stack([r - 1, self.flat - r * self.w2 - 1]).astype(np.int64)
        self.offs = (_OFFS[:, 0] * self.w2 + _OFFS[:, 1]).astype(np.intp)
        code = np.zeros(n, dtype=np.uint8)
        for k in range(8):
            code |= np.take(self.pad, self.flat + self.offs[k]) << np.uint8(k)
        self.code = code
        self.deg = _DEG[code]
        # dense index map: only read at set cells, so it needs no initialisation
        self.index = np.empty(self.pad.shape[0], dtype=itype)
        self.index[self.flat] = np.arange(n, dtype=itype)

    def neighbours(self, cells: np.ndarray) -> np.ndarray:
        """(len(cells), 8) int64: index of each neighbour cell (order of _OFFS) or -1."""
        code = self.code[cells]
        fl = self.flat[cells]
        nbr = np.full((cells.shape[0], 8), -1, dtype=np.int64)
        for k in range(8):
            has = (code >> np.uint8(k)) & np.uint8(1) != 0
            nbr[has, k] = np.take(self.index, fl[has] + self.offs[k])
        return nbr

    def two_neighbours(self, cells: np.ndarray) -> np.ndarray:
        """(len(cells), 2) int64: the two neighbour cells of cells with exactly two, in increasing order."""
        code = self.code[cells]
        fl = self.flat[cells]
        a = np.take(self.index, fl + self.offs[_BIT0[code]]).astype(np.int64)
        b = np.take(self.index, fl + self.offs[_BIT1[code]]).astype(np.int64)
        return np.column_stack([np.minimum(a, b), np.maximum(a, b)])


def _graph_arrays_numpy(sk: _Skeleton, clr: np.ndarray, resolution: float):
    """The graph's arrays with numpy (the fallback without numba, and the reference the kernels are tested
    against): (kinds, representative cell per node, edge ends u, v, concatenated (sum K, 2) path cells rc,
    path offsets starts (m + 1), lengths, min clearances)."""
    n = sk.flat.shape[0]
    # tips: one neighbour, or two neighbours touching each other (the end of a diagonal line; thin() keeps
    # such cells as line ends) are endpoints; junctions have >= 3 neighbours; the rest are chain cells
    tip2 = _TIP2[sk.code]
    is_node = (sk.deg != 2) | tip2
    node_of, kinds, rep = _nodes(sk, is_node, clr, tip2)
    # loops without any node cell: promote the smallest cell of each to a 'loop' node
    chains = _trace(sk, is_node, node_of)
    if chains is None:
        loop_cells = _loop_breakers(sk, is_node)
        is_node[loop_cells] = True
        node_of[loop_cells] = np.arange(kinds.shape[0], kinds.shape[0] + loop_cells.shape[0])
        kinds = np.concatenate([kinds, np.full(loop_cells.shape[0], "loop", dtype=kinds.dtype)])
        rep = np.concatenate([rep, loop_cells])
        chains = _trace(sk, is_node, node_of)
        assert chains is not None
    eu, ev, cells, starts = chains

    # edges between adjacent node cells of different nodes (e.g. a one-cell spur off a junction)
    node_cells = np.flatnonzero(is_node)
    nb = sk.neighbours(node_cells)
    i_pos, k_idx = np.nonzero(nb >= 0)
    i_idx = node_cells[i_pos]
    j_idx = nb[i_pos, k_idx].astype(np.int64)
    keep = is_node[j_idx] & (i_idx < j_idx) & (node_of[i_idx] != node_of[j_idx])
    di, dj = _spanning_pairs(i_idx[keep], j_idx[keep], node_of)
    # holes enclosed by the cells of one junction cluster: one self-loop each, around the hole
    hu, hcells = _cluster_holes(sk, node_of, kinds)

    all_u = np.concatenate([eu, node_of[di], hu]).astype(np.int64)
    all_v = np.concatenate([ev, node_of[dj], hu]).astype(np.int64)
    lengths_cells = np.concatenate(
        [np.diff(starts), np.full(di.shape[0], 2), [len(c) for c in hcells]]
    ).astype(np.int64)
    cells = np.concatenate([cells, np.column_stack([di, dj]).ravel(), *hcells]).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths_cells)])

    # per-edge length and clearance with reduceat over the concatenated cell sequences
    rc = sk.rc[cells]
    step = np.abs(np.diff(rc, axis=0)).sum(axis=1)
    steplen = np.where(step == 2, np.sqrt(2.0), 1.0)
    steplen[starts[1:-1] - 1] = 0.0  # no step between two edges' sequences
    m = all_u.shape[0]
    if m:
        cum = np.concatenate([[0.0], np.cumsum(steplen)])
        length = (cum[starts[1:] - 1] - cum[starts[:-1]]) * resolution
        min_clr = np.minimum.reduceat(clr[cells], starts[:-1]) if n else np.zeros(0)
    else:
        length = min_clr = np.zeros(0)

    return kinds, rep, all_u, all_v, rc, starts, length, min_clr


def _cluster_holes(
    sk: _Skeleton, node_of: np.ndarray, kinds: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Holes enclosed by the cells of a single junction cluster (an obstacle of a cell or two at a crossing):
    the cluster collapses to one node, so each such hole becomes a self-loop of that node whose path runs
    around the hole. Clusters with holes are found with the Euler number (8-connected cells, 4-connected
    background) from 2 x 2 bit quads, E = (Q1 - Q3 - 2 QD) / 4; holes = 1 - E per cluster (every 2 x 2 quad
    holds cells of at most one cluster, since cells of two clusters are never 8-adjacent). The paths are the
    inner contours of those few clusters (cv2.findContours). Returns (node per hole, cell-index sequences)."""
    import cv2

    junction = sk.deg >= 3
    jcells = np.flatnonzero(junction)
    empty: tuple[np.ndarray, list[np.ndarray]] = (np.zeros(0, dtype=np.int64), [])
    if jcells.shape[0] < 4:  # a hole needs at least four enclosing cells
        return empty
    w2 = sk.w2
    jpad = np.zeros(sk.pad.shape[0], dtype=np.uint8)
    jpad[sk.flat[jcells]] = 1
    fj = sk.flat[jcells]
    nj = node_of[jcells]
    e4 = np.zeros(jcells.shape[0], dtype=np.int64)
    for pos, (dr0, dc0) in enumerate(((-1, -1), (-1, 0), (0, -1), (0, 0))[::-1]):
        # quad with top-left corner at cell + (dr0, dc0); the cell is corner `pos` (00, 01, 10, 11 order)
        t = fj + (dr0 * w2 + dc0)
        v = [np.take(jpad, t + o) for o in (0, 1, w2, w2 + 1)]
        first = np.ones(t.shape[0], dtype=bool)
        for q in range(pos):
            first &= v[q] == 0  # count each quad once, at its first junction cell
        s = v[0].astype(np.int64) + v[1] + v[2] + v[3]
        diag = (s == 2) & (v[0] == v[3])
        e4 += first * ((s == 1).astype(np.int64) - (s == 3) - 2 * diag)
    n_nodes = kinds.shape[0]
    holes = 1 - np.bincount(nj, weights=e4, minlength=n_nodes) / 4.0
    with_holes = np.flatnonzero((np.rint(holes) > 0) & (np.bincount(nj, minlength=n_nodes) > 0))
    if with_holes.size == 0:
        return empty
    sel = np.isin(nj, with_holes)
    cl_cells, cl_nodes = jcells[sel], nj[sel]
    order = np.argsort(cl_nodes, kind="stable")
    cl_cells, cl_nodes = cl_cells[order], cl_nodes[order]
    bounds = np.flatnonzero(np.diff(cl_nodes)) + 1
    hu, hcells = [], []
    heads = cl_nodes[np.concatenate([[0], bounds])].tolist()
    for cells, node in zip(np.split(cl_cells, bounds), heads, strict=True):
        rc = sk.rc[cells]
        r0, c0 = rc.min(axis=0) - 1
        box = np.zeros(tuple(rc.max(axis=0) - (r0, c0) + 2), dtype=np.uint8)
        box[rc[:, 0] - r0, rc[:, 1] - c0] = 1
        contours, hierarchy = cv2.findContours(box, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
        for contour, hier in zip(contours, hierarchy[0], strict=True):
            if hier[3] < 0:
                continue  # an outer boundary
            xy = contour[:, 0, :]
            ring = np.concatenate([xy, xy[:1]])
            flat = (ring[:, 1] + r0 + 1) * w2 + (ring[:, 0] + c0 + 1)
            hu.append(node)
            hcells.append(sk.index[flat].astype(np.int64))
    return np.asarray(hu, dtype=np.int64), hcells


def _spanning_pairs(di: np.ndarray, dj: np.ndarray, node_of: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Adjacent cells of different nodes (only around line tips, so few): keep one pair per node pair and no
    pair that closes a cycle among them (three mutually adjacent tip cells enclose no hole)."""
    parent: dict[int, int] = {}

    def find(x: int) -> int:
        while parent.get(x, x) != x:
            x = parent[x]
        return x

    keep = []
    for e, (a, b) in enumerate(zip(node_of[di].tolist(), node_of[dj].tolist(), strict=True)):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
            keep.append(e)
    k = np.asarray(keep, dtype=np.int64)
    return di[k], dj[k]


def _nodes(sk: _Skeleton, is_node: np.ndarray, clr: np.ndarray, tip2: np.ndarray):
    """node_of (n,) node id per cell (-1 for chain cells), kinds (nodes,), representative cell per node."""
    n = sk.flat.shape[0]
    junction = sk.deg >= 3
    lab = np.arange(n)
    jidx = np.flatnonzero(junction)
    jn = sk.neighbours(jidx)
    jn_ok = jn >= 0
    jn_ok[jn_ok] = junction[jn[jn_ok]]
    jn = np.where(jn_ok, jn, jidx[:, None])
    while jidx.size:  # min-label propagation inside junction clusters (clusters are tiny)
        new = np.minimum(lab[jidx], lab[jn].min(axis=1))
        new = lab[new]  # jump
        if np.array_equal(new, lab[jidx]):
            break
        lab[jidx] = new
    node_cells = np.flatnonzero(is_node)
    roots, inv = np.unique(lab[node_cells], return_inverse=True)
    node_of = np.full(n, -1, dtype=np.int64)
    node_of[node_cells] = inv
    d = sk.deg[roots]
    kinds = np.where(d >= 3, "junction", np.where((d == 1) | tip2[roots], "endpoint", "isolated"))
    kinds = kinds.astype("<U8")
    # representative: the cell of the node farthest from obstacles, then with most skeleton neighbours,
    # then first in row-major order
    key = np.where(np.isnan(clr[node_cells]), 0.0, clr[node_cells])
    order = np.lexsort((-sk.deg[node_cells], -key, inv))
    first = np.ones(order.shape[0], dtype=bool)
    first[1:] = inv[order][1:] != inv[order][:-1]
    rep = node_cells[order[first]]
    return node_of, kinds, rep


def _states(sk: _Skeleton, is_node: np.ndarray):
    """Chain cells and their (cell, direction) successor function."""
    chain = np.flatnonzero(~is_node)
    two = sk.two_neighbours(chain)  # chain cells have exactly two neighbours
    cpos = np.full(sk.flat.shape[0], -1, dtype=np.int64)
    cpos[chain] = np.arange(chain.shape[0])
    # state 2*i + d: at chain cell i, arrived from two[i, d], leaving towards two[i, 1 - d]
    to = np.stack([two[:, 1], two[:, 0]], axis=1).ravel()
    frm = two.ravel()
    here = np.repeat(chain, 2)
    tgt_chain = cpos[to]
    nxt = np.full(to.shape[0], -1, dtype=np.int64)
    ok = tgt_chain >= 0
    # at the target chain cell, the direction whose 'from' is the current cell
    t2 = two[tgt_chain[ok]]
    d = np.where(t2[:, 0] == here[ok], 0, 1)
    nxt[ok] = 2 * tgt_chain[ok] + d
    return chain, here, frm, to, nxt


def _loop_breakers(sk: _Skeleton, is_node: np.ndarray) -> np.ndarray:
    chain, here, _frm, _to, nxt = _states(sk, is_node)
    _rank, mn, done = _pointer_jump(nxt, here.copy())
    return np.unique(mn[~done])


def _trace(sk: _Skeleton, is_node: np.ndarray, node_of: np.ndarray, max_steps: int = 2048):
    """Edges along chains: (u, v, cells, starts) with cells the concatenated cell sequences (node cell,
    chain cells ..., node cell) and starts their offsets (len m + 1); None when a chain is a closed loop.

    All chains are walked in lockstep from both of their ends, cell by cell: a chain cell's next cell is
    (sum of its two neighbours) - (the cell it came from); one array step per cell of the longest chain, so
    the work is proportional to the number of chain cells. When a chain is longer than ``max_steps`` the walk
    gives way to pointer jumping on (cell, direction) states (O(n log L) work in O(log L) array steps). Both
    give the same edges in the same order: one direction per chain (the one whose last state is smaller than
    its reverse's), chains ordered by that last state."""
    chain = np.flatnonzero(~is_node)
    if chain.size == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e, np.zeros(1, dtype=np.int64)
    two = sk.two_neighbours(chain)
    n = is_node.shape[0]
    tsum = np.zeros(n, dtype=np.int64)
    tsum[chain] = two[:, 0] + two[:, 1]
    node_cells = np.flatnonzero(is_node)
    nb = sk.neighbours(node_cells)
    ii, kk = np.nonzero(nb >= 0)
    u0, c0 = node_cells[ii], nb[ii, kk]
    sel = ~is_node[c0]
    u0, c0 = u0[sel], c0[sel]  # a walk starts at each (node cell, chain neighbour) pair
    walks = _walk(is_node, tsum, u0, c0, max_steps)
    if walks is None:
        return _trace_by_pointer_jumping(sk, is_node, node_of)
    seq, seq_wid, last_prev, last_cell, end_node = walks
    sizes = np.array([x.shape[0] for x in seq], dtype=np.int64)
    if int(sizes.sum()) != 2 * chain.shape[0]:
        return None  # chain cells no walk reached: closed loops without a node
    cpos = np.full(n, -1, dtype=np.int64)
    cpos[chain] = np.arange(chain.shape[0])
    # (cell, direction) state ids as in _states: state 2 i + d at chain cell i arrived from two[i, d]
    pc, pl = cpos[c0], cpos[last_cell]
    start_state = 2 * pc + (two[pc, 0] != u0)
    term_state = 2 * pl + (two[pl, 0] != last_prev)
    kw = np.flatnonzero(term_state < (start_state ^ 1))  # one direction per chain
    kw = kw[np.argsort(term_state[kw])]
    m = kw.shape[0]
    newid = np.full(u0.shape[0], -1, dtype=np.int64)
    newid[kw] = np.arange(m)
    g = newid[np.concatenate(seq_wid)]
    kept = g >= 0
    g = g[kept]
    step = np.repeat(np.arange(sizes.shape[0]), sizes)[kept]
    glen = np.bincount(g, minlength=m)
    starts = np.concatenate([[0], np.cumsum(glen + 2)])
    cells = np.empty(int(starts[-1]), dtype=np.int64)
    cells[starts[g] + 1 + step] = np.concatenate(seq)[kept]
    u_cell, v_cell = u0[kw], end_node[kw]
    cells[starts[:-1]] = u_cell
    cells[starts[1:] - 1] = v_cell
    return node_of[u_cell], node_of[v_cell], cells, starts


def _walk(is_node: np.ndarray, tsum: np.ndarray, u0: np.ndarray, c0: np.ndarray, max_steps: int):
    """The lockstep walk of ``_trace`` from the (node cell ``u0``, chain cell ``c0``) pairs: the cells of each
    step with their walk ids, and per walk its last (previous, chain) cells and the node cell it ends at; None
    when a walk is still going after ``max_steps`` steps."""
    n_walks = u0.shape[0]
    prev, cur, wid = u0, c0, np.arange(n_walks)
    last_prev = np.empty(n_walks, dtype=np.int64)
    last_cell = np.empty(n_walks, dtype=np.int64)
    end_node = np.empty(n_walks, dtype=np.int64)
    seq, seq_wid = [], []
    for _ in range(max_steps):
        if cur.size == 0:
            break
        seq.append(cur)
        seq_wid.append(wid)
        nxt = tsum[cur] - prev
        end = is_node[nxt]
        if end.any():
            we = wid[end]
            last_prev[we], last_cell[we], end_node[we] = prev[end], cur[end], nxt[end]
            keep = ~end
            prev, cur, wid = cur[keep], nxt[keep], wid[keep]
        else:
            prev, cur = cur, nxt
    if cur.size:
        return None
    return seq, seq_wid, last_prev, last_cell, end_node


def _trace_by_pointer_jumping(sk: _Skeleton, is_node: np.ndarray, node_of: np.ndarray):
    """``_trace`` by pointer jumping on (cell, direction) states, for chains longer than the lockstep walk."""
    _chain, here, frm, to, nxt = _states(sk, is_node)
    rank, root, done = _pointer_jump(nxt)
    if not done.all():
        return None
    s = np.arange(nxt.shape[0])
    keep = root < root[s ^ 1]  # one direction per chain
    ks = s[keep]
    top = int(rank.max()) + 1
    order = ks[np.argsort(root[ks] * top + (top - 1 - rank[ks]))]  # by chain, then from its u end
    r = root[order]
    first = np.ones(order.shape[0], dtype=bool)
    first[1:] = r[1:] != r[:-1]
    gstart = np.flatnonzero(first)
    m = gstart.shape[0]
    glen = np.diff(np.concatenate([gstart, [order.shape[0]]]))
    u_cell = frm[order[gstart]]
    v_cell = to[r[gstart]]
    # concatenated sequences: [u_cell, chain cells..., v_cell] per edge
    total = order.shape[0] + 2 * m
    starts = np.concatenate([[0], np.cumsum(glen + 2)])
    cells = np.empty(total, dtype=np.int64)
    grp = np.repeat(np.arange(m), glen)
    cells[np.arange(order.shape[0]) + 2 * grp + 1] = here[order]
    cells[starts[:-1]] = u_cell
    cells[starts[1:] - 1] = v_cell
    return node_of[u_cell], node_of[v_cell], cells, starts
