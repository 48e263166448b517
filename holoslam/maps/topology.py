"""Skeleton -> topology graph (SPEC.md §2): nodes at junctions and endpoints, edges along the skeleton.

The skeleton is a (H, W) bool mask, 8-connected (``holoslam.maps.thinning.thin``). Every skeleton cell is
classified by its number of skeleton neighbours: 0 isolated, 1 endpoint, 2 chain, >= 3 junction. Adjacent
junction cells form one junction node (a cluster); its representative cell is the cluster cell farthest from
obstacles. Chains of chain cells become edges between the nodes at their two ends. A closed loop with no
junction (a ring of free space around an obstacle) gets one node of kind ``'loop'`` at its first cell and a
self-loop edge. Parallel edges (two corridors around an obstacle between the same junctions) are kept: the
graph is a ``networkx.MultiGraph``.

Tracing is vectorised: every chain cell has exactly two skeleton neighbours, so "walk along the chain" is a
successor function on (cell, direction) states. All chains are walked in lockstep from their ends (one array
step per cell of the longest chain; work proportional to the number of chain cells); chains longer than 2048
cells fall back to pointer jumping (doubling: O(n log L) work in O(log L) array steps). Cells are found and
classified with one pass over the grid (a padded copy, flat indices, 8-neighbour codes looked up in tables);
no per-cell Python loops. The graph's dicts are written in bulk (``_bulk_multigraph``) with Python's cyclic
garbage collector paused; edge paths are views into one concatenated (sum K, 2) array. Python loops only over
edges and nodes when the graph is built, over junction clusters with holes, and over pruned spurs.

Compiled path (what runs when numba is installed, :mod:`holoslam.maps._topology_fast`): node labelling,
chain tracing (one walk per chain), adjacent node-cell pairs and edge lengths as numba kernels returning the
same arrays in the same order (``_graph_arrays_numba`` vs ``_graph_arrays_numpy``, tested equal); on the
tiled 4000 x 4000 household map most of the remaining time is building the networkx dicts.

Spur pruning (documented length): an edge with an endpoint node at one end and a junction at the other is
a spur; it is removed when its length is below ``max(prune_spur_m, spur_clearance_factor * clearance of its
junction)`` (a branch that does not leave the junction's free disc is thinning noise from a wall corner).
Pruning repeats until nothing changes, a junction left with two edges is merged away (its two edges joined),
and the last edge of a component is never removed. Pruning removes only leaves, so the number of components
and of independent cycles does not change.

Line tips: a cell with one skeleton neighbour, or with two that touch each other (the end of a diagonal or
staircase line, which ``thin`` keeps as a line end), is an endpoint.

Holes inside a junction cluster: an obstacle of a cell or two right at a crossing can be enclosed only by
junction cells, which collapse to one node. Such clusters are found with their Euler number (2 x 2 bit
quads) and each hole becomes a self-loop of the junction node whose path runs around the hole (the cluster's
inner contour), so the graph's independent cycles equal the skeleton's holes at every size.

Node attributes: ``x``, ``y`` (world metres, the cell centre), ``row``, ``col``, ``kind`` ('junction' |
'endpoint' | 'isolated' | 'loop'), ``clearance`` (metres to the nearest obstacle), ``submap`` (index of the
nearest anchor or -1). Edge attributes: ``path`` ((K, 2) int64 (row, col) cells from the node at ``u`` ... to
the node at the other end),
``path_from`` (the node id at ``path[0]``), ``length`` (metres, sum of 8-connected steps of 1 or sqrt(2)
cells x resolution), ``min_clearance`` (metres).
"""

from __future__ import annotations

import gc
from typing import TYPE_CHECKING

import numpy as np

from holoslam.errors import MapError

if TYPE_CHECKING:
    import networkx as nx

    from holoslam.maps.grid import OccupancyGrid

__all__ = [
    "skeleton_to_graph",
    "topology_from_grid",
    "clearance_map",
    "prune_spurs",
    "to_graphml_ready",
    "path_to_string",
    "path_from_string",
    "cycle_rank",
]


def clearance_map(free: np.ndarray, resolution: float = 1.0) -> np.ndarray:
    """(H, W) float64: Euclidean distance (metres) from each free cell's centre to the nearest non-free cell
    (cells outside the grid count as non-free); 0 on non-free cells. One exact cv2.distanceTransform
    (DIST_MASK_PRECISE) on a zero-bordered uint8 copy, scaled to metres in the same pass as the float64
    conversion."""
    import cv2

    m = np.ascontiguousarray(np.asarray(free, dtype=bool)).view(np.uint8)
    pad = cv2.copyMakeBorder(m, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    d = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    return np.multiply(d, float(resolution), dtype=np.float64)


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


def skeleton_to_graph(
    skeleton: np.ndarray,
    *,
    resolution: float = 1.0,
    origin_x: float = 0.0,
    origin_y: float = 0.0,
    clearance: np.ndarray | None = None,
    anchors_wTa: np.ndarray | None = None,
    prune_spur_m: float = 0.0,
    spur_clearance_factor: float = 0.0,
) -> nx.MultiGraph:
    """Topology graph of an 8-connected skeleton (module docstring). ``clearance`` is an (H, W) metres map
    (``clearance_map``); without it clearances are NaN. Cell (row, col) has its centre at
    (origin_x + (col + 0.5) * resolution, origin_y + (row + 0.5) * resolution), as in OccupancyGrid."""

    skel = np.asarray(skeleton, dtype=bool)
    if skel.ndim != 2:
        raise MapError(f"a skeleton must be a 2-D (H, W) mask, got shape {skel.shape}")
    if not np.isfinite(resolution) or resolution <= 0:
        raise MapError(f"resolution must be a positive number of metres per cell, got {resolution}")
    if clearance is not None and np.shape(clearance) != skel.shape:
        raise MapError(f"clearance map shape {np.shape(clearance)} differs from the skeleton's {skel.shape}")
    sk = _Skeleton(skel)
    n = sk.flat.shape[0]
    if clearance is not None:
        clr_flat = np.asarray(clearance).reshape(-1)
        clr = clr_flat[sk.rc[:, 0] * sk.w + sk.rc[:, 1]].astype(np.float64)
    else:
        clr = np.full(n, np.nan)
    arrays = _graph_arrays_numba if _kernels() is not None else _graph_arrays_numpy
    kinds, rep, all_u, all_v, rc, starts, length, min_clr = arrays(sk, clr, float(resolution))

    node_rc = sk.rc[rep]
    xs = origin_x + (node_rc[:, 1] + 0.5) * resolution
    ys = origin_y + (node_rc[:, 0] + 0.5) * resolution
    submap = _nearest_anchor(np.column_stack([xs, ys]), anchors_wTa)
    # tens of thousands of small dicts: the cyclic garbage collector would rescan them all repeatedly
    gc_was_on = gc.isenabled()
    gc.disable()
    try:
        node_attrs = [
            {"x": x, "y": y, "row": r, "col": c, "kind": k, "clearance": cl, "submap": s}
            for x, y, r, c, k, cl, s in zip(
                xs.tolist(),
                ys.tolist(),
                node_rc[:, 0].tolist(),
                node_rc[:, 1].tolist(),
                kinds.tolist(),
                clr[rep].tolist(),
                submap.tolist(),
                strict=True,
            )
        ]
        # paths: views into one (sum K, 2) array, one per edge
        st = starts.tolist()
        ul = all_u.tolist()
        edge_attrs = [
            {"path": rc[a:b], "path_from": u, "length": ln, "min_clearance": mc}
            for a, b, u, ln, mc in zip(st[:-1], st[1:], ul, length.tolist(), min_clr.tolist(), strict=True)
        ]
        G = _bulk_multigraph(node_attrs, all_u, all_v, edge_attrs)
    finally:
        if gc_was_on:
            gc.enable()
    G.graph.update(resolution=float(resolution), origin_x=float(origin_x), origin_y=float(origin_y))
    if prune_spur_m > 0 or spur_clearance_factor > 0:
        prune_spurs(G, prune_spur_m, spur_clearance_factor)
    return G


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


def _graph_arrays_numba(sk: _Skeleton, clr: np.ndarray, resolution: float):
    """``_graph_arrays_numpy`` with the compiled kernels (:mod:`holoslam.maps._topology_fast`): same arrays."""
    from holoslam.maps import _topology_fast as kf

    args = (sk.flat, sk.code, sk.index, sk.offs)
    tip2 = _TIP2[sk.code]
    is_node = (sk.deg != 2) | tip2
    node_of, kind_code, rep = kf.nodes(*args, sk.deg, is_node, tip2, clr)
    kinds = _KIND_NAMES[kind_code]
    u_cell, v_cell, cells, starts, complete = kf.trace(*args, _BIT0, _BIT1, is_node)
    if not complete:  # loops without any node cell: promote the smallest cell of each to a 'loop' node
        loop_cells = _loop_breakers(sk, is_node)
        is_node[loop_cells] = True
        node_of[loop_cells] = np.arange(kinds.shape[0], kinds.shape[0] + loop_cells.shape[0])
        kinds = np.concatenate([kinds, np.full(loop_cells.shape[0], "loop", dtype=kinds.dtype)])
        rep = np.concatenate([rep, loop_cells])
        u_cell, v_cell, cells, starts, complete = kf.trace(*args, _BIT0, _BIT1, is_node)
        assert complete
    di, dj = kf.node_pairs(*args, is_node, node_of, kinds.shape[0])
    hu, hcells = _cluster_holes(sk, node_of, kinds)
    all_u = np.concatenate([node_of[u_cell], node_of[di], hu]).astype(np.int64)
    all_v = np.concatenate([node_of[v_cell], node_of[dj], hu]).astype(np.int64)
    extra = [np.column_stack([di, dj]).ravel(), *hcells]
    if di.shape[0] or hcells:
        add = np.array([2] * di.shape[0] + [len(c) for c in hcells], dtype=np.int64)
        starts = np.concatenate([starts, starts[-1] + np.cumsum(add)])
        cells = np.concatenate([cells, *extra]).astype(np.int64)
    rc = sk.rc[cells]
    length, min_clr = kf.lengths(rc, starts, clr[cells], resolution)
    return kinds, rep, all_u, all_v, rc, starts, length, min_clr


_KIND_NAMES = np.array(["junction", "endpoint", "isolated"], dtype="<U8")


def _kernels():
    """The compiled kernels (:mod:`holoslam.maps._topology_fast`), or None when numba is missing."""
    try:
        from holoslam.maps import _topology_fast
    except ImportError:  # pragma: no cover - numba is a declared dependency
        return None
    return _topology_fast


def _bulk_multigraph(node_attrs: list[dict], u: np.ndarray, v: np.ndarray, edge_attrs: list[dict]):
    """The MultiGraph that ``add_nodes_from(enumerate(node_attrs))`` then ``add_edges_from(zip(u, v,
    edge_attrs))`` builds (same nodes, edge keys 0, 1, ... per node pair in insertion order, one key dict
    shared by both directions), written straight into networkx's documented dict-of-dict-of-dict adjacency
    (``G._node``, ``G._adj``) of a fresh graph (nothing cached yet): the public calls cost ~10 us per edge,
    most of the time at 50k+ edges."""
    import networkx as nx

    n, m = len(node_attrs), u.shape[0]
    # key of each edge: its rank among the earlier edges between the same two nodes
    pair = np.minimum(u, v) * max(n, 1) + np.maximum(u, v)
    order = np.argsort(pair, kind="stable")
    ps = pair[order]
    new = np.ones(m, dtype=bool)
    new[1:] = ps[1:] != ps[:-1]
    group_start = np.maximum.accumulate(np.where(new, np.arange(m), 0))
    key = np.empty(m, dtype=np.int64)
    key[order] = np.arange(m) - group_start
    G = nx.MultiGraph()
    G._node.update(enumerate(node_attrs))
    nbrs = [{} for _ in range(n)]
    G._adj.update(enumerate(nbrs))
    first = key == 0
    for a, b, d in zip(
        u[first].tolist(),
        v[first].tolist(),
        [edge_attrs[i] for i in np.flatnonzero(first).tolist()],
        strict=True,
    ):
        kd = {0: d}
        nbrs[a][b] = kd
        nbrs[b][a] = kd
    for a, b, k, i in zip(
        u[~first].tolist(),
        v[~first].tolist(),
        key[~first].tolist(),
        np.flatnonzero(~first).tolist(),
        strict=True,
    ):
        nbrs[a][b][k] = edge_attrs[i]
    return G


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
    empty = (np.zeros(0, dtype=np.int64), [])
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
    cpos = np.full(n, -1, dtype=np.int64)
    cpos[chain] = np.arange(chain.shape[0])
    tsum = np.zeros(n, dtype=np.int64)
    tsum[chain] = two[:, 0] + two[:, 1]
    node_cells = np.flatnonzero(is_node)
    nb = sk.neighbours(node_cells)
    ii, kk = np.nonzero(nb >= 0)
    u0, c0 = node_cells[ii], nb[ii, kk]
    sel = ~is_node[c0]
    u0, c0 = u0[sel], c0[sel]  # a walk starts at each (node cell, chain neighbour) pair
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
    if cur.size == 0:
        sizes = np.array([x.shape[0] for x in seq], dtype=np.int64)
        if int(sizes.sum()) != 2 * chain.shape[0]:
            return None  # chain cells no walk reached: closed loops without a node
        # (cell, direction) state ids as in _states: state 2 i + d at chain cell i arrived from two[i, d]
        pc, pl = cpos[c0], cpos[last_cell]
        start_state = 2 * pc + (two[pc, 0] != u0)
        term_state = 2 * pl + (two[pl, 0] != last_prev)
        kw = np.flatnonzero(term_state < (start_state ^ 1))  # one direction per chain
        kw = kw[np.argsort(term_state[kw])]
        m = kw.shape[0]
        newid = np.full(n_walks, -1, dtype=np.int64)
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


def _nearest_anchor(xy: np.ndarray, anchors_wTa: np.ndarray | None) -> np.ndarray:
    if anchors_wTa is None or len(anchors_wTa) == 0:
        return np.full(xy.shape[0], -1, dtype=np.int64)
    a = np.asarray(anchors_wTa, dtype=np.float64).reshape(-1, 3)[:, :2]
    d2 = ((xy[:, None, :] - a[None, :, :]) ** 2).sum(axis=2)
    return np.argmin(d2, axis=1).astype(np.int64)


def prune_spurs(G: nx.MultiGraph, prune_spur_m: float, spur_clearance_factor: float = 0.0) -> int:
    """Remove short spurs in place (module docstring); returns how many edges were removed."""
    removed = 0
    changed = True
    while changed:
        changed = False
        for leaf in [v for v in G.nodes if G.degree(v) == 1]:
            if leaf not in G or G.degree(leaf) != 1:
                continue
            (_, other, key, data) = next(iter(G.edges(leaf, keys=True, data=True)))
            if other == leaf or G.degree(other) <= 1:
                continue  # the last edge of its component
            clr = G.nodes[other].get("clearance", np.nan)
            limit = max(prune_spur_m, spur_clearance_factor * (0.0 if np.isnan(clr) else clr))
            if data["length"] >= limit:
                continue
            G.remove_node(leaf)
            removed += 1
            changed = True
            if G.degree(other) == 2 and G.number_of_edges(other, other) == 0:
                _merge_through(G, other)
            elif G.degree(other) == 1:
                G.nodes[other]["kind"] = "endpoint"
            elif G.degree(other) == 2:
                G.nodes[other]["kind"] = "loop"
    return removed


def _merge_through(G: nx.MultiGraph, v) -> None:
    """Replace node v (two edges, no self-loop) by one edge joining its neighbours."""
    (_, a, ka, da), (_, b, kb, db) = list(G.edges(v, keys=True, data=True))
    pa = da["path"] if da["path_from"] == a else da["path"][::-1]  # a ... v
    pb = db["path"] if db["path_from"] == v else db["path"][::-1]  # v ... b
    # the two paths end at cells of v: the same cell, or two cells of a junction cluster, joined through the
    # cells on the straight line between them (octile step lengths)
    extra = 0.0
    if np.array_equal(pa[-1], pb[0]):
        path = np.concatenate([pa, pb[1:]])
    else:
        a_end, b_start = pa[-1], pb[0]
        k = int(np.abs(b_start - a_end).max())
        t = np.arange(1, k)[:, None] / k
        mid = np.rint(a_end + t * (b_start - a_end)).astype(pa.dtype)  # straight 8-connected cells between
        path = np.concatenate([pa, mid, pb])
        d = np.abs(np.diff(path[len(pa) - 1 : len(pa) + len(mid) + 1], axis=0))
        extra = float((np.sqrt(2.0) * d.min(axis=1) + (d.max(axis=1) - d.min(axis=1))).sum())
        extra *= G.graph.get("resolution", 1.0)
    G.remove_node(v)
    if a == b:
        G.nodes[a]["kind"] = "loop" if G.degree(a) == 0 else G.nodes[a]["kind"]
    G.add_edge(
        a,
        b,
        path=path,
        path_from=a,
        length=da["length"] + db["length"] + extra,
        min_clearance=min(da["min_clearance"], db["min_clearance"]),
    )


def cycle_rank(G: nx.Graph) -> int:
    """Number of independent cycles: edges - nodes + components (self-loops and parallel edges count)."""
    import networkx as nx

    return G.number_of_edges() - G.number_of_nodes() + nx.number_connected_components(G)


def topology_from_grid(
    grid: OccupancyGrid,
    *,
    anchors_wTa: np.ndarray | None = None,
    prune_spur_m: float = 0.3,
    spur_clearance_factor: float = 1.5,
    erode_cells: int = 0,
    close_cells: int = 0,
) -> nx.MultiGraph:
    """Free space of the grid -> thinned skeleton -> topology graph, in one call (defaults: spurs shorter
    than 0.3 m or 1.5 x their junction's clearance are pruned; no pre-processing)."""
    from holoslam.maps.thinning import thin

    free = grid.free
    skel = thin(free, erode_cells=erode_cells, close_cells=close_cells)
    return skeleton_to_graph(
        skel,
        resolution=grid.resolution,
        origin_x=grid.origin_x,
        origin_y=grid.origin_y,
        clearance=clearance_map(free, grid.resolution),
        anchors_wTa=anchors_wTa,
        prune_spur_m=prune_spur_m,
        spur_clearance_factor=spur_clearance_factor,
    )


def path_to_string(path: np.ndarray) -> str:
    """(K, 2) int cells -> 'r0,c0;r1,c1;...' (compact, for GraphML)."""
    p = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    return ";".join(f"{r},{c}" for r, c in p.tolist())


def path_from_string(text: str) -> np.ndarray:
    """Inverse of path_to_string."""
    if not text:
        return np.zeros((0, 2), dtype=np.int64)
    try:
        return np.array([[int(v) for v in item.split(",")] for item in text.split(";")], dtype=np.int64)
    except ValueError as exc:
        raise MapError(f"edge path {text[:40]!r} is not 'row,col;row,col;...' ({exc})") from exc


def to_graphml_ready(G: nx.MultiGraph) -> nx.MultiGraph:
    """A copy whose attributes are all scalars: edge ``path`` becomes a 'r,c;r,c;...' string."""
    H = G.copy()
    for _u, _v, data in H.edges(data=True):
        if "path" in data and not isinstance(data["path"], str):
            data["path"] = path_to_string(data["path"])
    return H
