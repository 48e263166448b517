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
edges and nodes when the graph is built, over junction clusters with holes, and over pruned spurs. This
numpy path is :mod:`holoslam.maps._skeleton`.

Compiled path (what runs when numba is installed, :mod:`holoslam.maps._topology_fast`): node labelling,
chain tracing (one walk per chain), adjacent node-cell pairs and edge lengths as numba kernels returning the
same arrays in the same order (``_graph_arrays_numba`` vs ``_graph_arrays_numpy``, tested equal); on the
tiled 4000 x 4000 household map most of the remaining time is building the networkx dicts.

Spur pruning (documented length): an edge with an endpoint node at one end and a junction at the other is
a spur; it is removed when its length is below ``max(prune_spur_m, spur_clearance_factor * clearance of its
junction, clearance + spur_beyond_clearance_m)`` (a branch that does not leave the junction's free disc is
thinning noise from a wall corner; one that leaves it by less than the robot's diameter, ``topology_from_settings``'
``spur_robot_diameters``, is a notch in a wall the robot's body does not fit into, not an alcove or a doorway).
The graph records how many spurs were removed (``spurs_pruned``) and the depth used (``spur_beyond_clearance_m``).
Pruning repeats until nothing changes, a junction left with two edges is merged away (its two edges joined),
and the last edge of a component is never removed. Pruning removes only leaves, so the number of components
and of independent cycles does not change.

Line tips: a cell with one skeleton neighbour, or with two that touch each other (the end of a diagonal or
staircase line, which ``thin`` keeps as a line end), is an endpoint.

Holes inside a junction cluster: an obstacle of a cell or two right at a crossing can be enclosed only by
junction cells, which collapse to one node. Such clusters are found with their Euler number (2 x 2 bit
quads) and each hole becomes a self-loop of the junction node whose path runs around the hole (the cluster's
inner contour), so the graph's independent cycles equal the skeleton's holes at every size.

From a grid (``topology_from_grid``): the free space is first cleaned (:mod:`holoslam.maps.cleaning`: free
regions below 0.25 m^2 dropped, obstacle islands below 0.05 m^2 filled, unknown counted as obstacle, by
default), so with the defaults the graph has one component per significant free region and one independent
cycle per significant obstacle island of the map, not one per speck of sensor noise.

Node attributes: ``x``, ``y`` (world metres, the cell centre), ``row``, ``col``, ``kind`` ('junction' |
'endpoint' | 'isolated' | 'loop'), ``clearance`` (metres to the nearest obstacle), ``submap`` (index of the
nearest anchor or -1). Edge attributes: ``path`` ((K, 2) int64 (row, col) cells from the node at ``u`` ... to
the node at the other end),
``path_from`` (the node id at ``path[0]``), ``length`` (metres, sum of 8-connected steps of 1 or sqrt(2)
cells x resolution), ``min_clearance`` (metres).
"""

from __future__ import annotations

import gc
import weakref
from typing import TYPE_CHECKING

import numpy as np

from holoslam.errors import MapError
from holoslam.maps._skeleton import (  # noqa: F401  (the numpy path; tests reach it through this module)
    _BIT0,
    _BIT1,
    _DEG,
    _OFFS,
    _TIP2,
    _cluster_holes,
    _graph_arrays_numpy,
    _loop_breakers,
    _nodes,
    _pointer_jump,
    _Skeleton,
    _spanning_pairs,
    _states,
    _trace,
)
from holoslam.maps.cleaning import MapCleaning
from holoslam.maps.grid import cells_to_world

_DEFAULT_CLEANING = MapCleaning()

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
    "cleaned_free",
]


_LAST: dict[str, tuple] = {}


# m, the reference robot's radius (seed 002's service robot): ``holoslam.config.RobotConfig.radius_m``'s default,
# here so that the maps layer (the light ``holoslam topology`` command) needs nothing of the run configuration
DEFAULT_ROBOT_RADIUS_M = 0.26


def _reuse(kind: str, source: np.ndarray, key, compute):
    """The last result of ``compute`` for this very ``source`` array (the same object, still alive: a weak
    reference) and ``key``, else a new one. The maps stages ask for the same cleaned free space and clearance
    of one grid several times (topology, rooms, holographic graph); results are read-only."""
    import weakref

    hit = _LAST.get(kind)
    if hit is not None and hit[0]() is source and hit[1] == key:
        return hit[2]
    out = compute()
    out.setflags(write=False)
    try:
        _LAST[kind] = (weakref.ref(source), key, out)
    except TypeError:  # pragma: no cover - ndarrays take weak references
        pass
    return out


def clearance_map(free: np.ndarray, resolution: float = 1.0) -> np.ndarray:
    """(H, W) float64, read-only: Euclidean distance (metres) from each free cell's centre to the nearest
    non-free cell (cells outside the grid count as non-free); 0 on non-free cells. One exact
    cv2.distanceTransform (DIST_MASK_PRECISE) on a zero-bordered uint8 copy, scaled to metres in the same pass as
    the float64 conversion (the last result is reused for the same ``free`` array object)."""
    if isinstance(free, np.ndarray) and free.dtype == bool:
        return _reuse("clearance", free, float(resolution), lambda: _clearance(free, resolution))
    return _clearance(free, resolution)


def _clearance(free: np.ndarray, resolution: float) -> np.ndarray:
    import cv2

    m = np.ascontiguousarray(np.asarray(free, dtype=bool)).view(np.uint8)
    pad = cv2.copyMakeBorder(m, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    d = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    return np.multiply(d, float(resolution), dtype=np.float64)


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
    spur_beyond_clearance_m: float = 0.0,
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
    node_xy = cells_to_world(node_rc, origin_x, origin_y, resolution)
    xs, ys = node_xy[:, 0], node_xy[:, 1]
    submap = _nearest_anchor(node_xy, anchors_wTa)
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
    pruned = 0
    if prune_spur_m > 0 or spur_clearance_factor > 0 or spur_beyond_clearance_m > 0:
        pruned = prune_spurs(G, prune_spur_m, spur_clearance_factor, spur_beyond_clearance_m)
    G.graph.update(spurs_pruned=int(pruned), spur_beyond_clearance_m=float(spur_beyond_clearance_m))
    return G


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
    nbrs: list[dict] = [{} for _ in range(n)]
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


def _nearest_anchor(xy: np.ndarray, anchors_wTa: np.ndarray | None) -> np.ndarray:
    if anchors_wTa is None or len(anchors_wTa) == 0:
        return np.full(xy.shape[0], -1, dtype=np.int64)
    a = np.asarray(anchors_wTa, dtype=np.float64).reshape(-1, 3)[:, :2]
    d2 = ((xy[:, None, :] - a[None, :, :]) ** 2).sum(axis=2)
    return np.argmin(d2, axis=1).astype(np.int64)


def prune_spurs(G: nx.MultiGraph, prune_spur_m: float, spur_clearance_factor: float = 0.0,
                spur_beyond_clearance_m: float = 0.0) -> int:
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
            c = 0.0 if np.isnan(clr) else clr
            limit = max(prune_spur_m, spur_clearance_factor * c, c + spur_beyond_clearance_m)
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


def topology_from_settings(grid: OccupancyGrid, settings, anchors_wTa: np.ndarray | None = None,
                           robot_radius_m: float | None = None) -> nx.MultiGraph:
    """:func:`topology_from_grid` with the run configuration's topology section
    (:class:`holoslam.maps.settings.TopologyConfig`): the one place its fields become the call's options.
    ``robot_radius_m`` (default: ``RobotConfig``'s) sets the depth of ``spur_robot_diameters``."""
    if robot_radius_m is None:
        robot_radius_m = DEFAULT_ROBOT_RADIUS_M
    return topology_from_grid(
        grid,
        anchors_wTa=anchors_wTa,
        prune_spur_m=settings.prune_spur_m,
        spur_beyond_clearance_m=settings.spur_robot_diameters * 2.0 * float(robot_radius_m),
        spur_clearance_factor=settings.spur_clearance_factor,
        erode_cells=settings.erode_cells,
        close_cells=settings.close_cells,
        cleaning=settings.cleaning,
    )


def topology_from_grid(
    grid: OccupancyGrid,
    *,
    anchors_wTa: np.ndarray | None = None,
    prune_spur_m: float = 0.3,
    spur_clearance_factor: float = 1.5,
    spur_beyond_clearance_m: float = 0.0,
    erode_cells: int = 0,
    close_cells: int = 0,
    cleaning: MapCleaning | None = _DEFAULT_CLEANING,
) -> nx.MultiGraph:
    """Free space of the grid -> pre-processed (``close_cells``, ``erode_cells``: ``thinning.preprocess_free``;
    none by default) -> cleaned (:mod:`holoslam.maps.cleaning`, default minimum sizes; None: not cleaned) ->
    thinned skeleton -> topology graph, in one call (defaults: spurs shorter than 0.3 m or 1.5 x their
    junction's clearance are pruned). Cleaning comes after the pre-processing, so the components and cycles
    are those of the significant regions and islands of the pre-processed map. The graph records the
    pre-processing (``close_cells``, ``erode_cells``), the cleaning (``cleaning_*``, which :func:`cleaned_free`
    and the holographic graph read back) and what cleaning changed (``cleaned_*``)."""
    from holoslam.maps.cleaning import clean_free
    from holoslam.maps.thinning import preprocess_free, thin

    free = grid.free
    if erode_cells or close_cells:
        free = preprocess_free(free, erode_cells=erode_cells, close_cells=close_cells)
    report = None
    if cleaning is not None:
        free, report = clean_free(grid, cleaning, free)
        if not (erode_cells or close_cells):  # what cleaned_free gives for this grid: kept for the next stages
            free.setflags(write=False)
            _LAST["cleaned"] = (weakref.ref(grid.occupancy), (grid.free_thresh, cleaning), free)
    skel = thin(free)
    G = skeleton_to_graph(
        skel,
        resolution=grid.resolution,
        origin_x=grid.origin_x,
        origin_y=grid.origin_y,
        clearance=clearance_map(free, grid.resolution),
        anchors_wTa=anchors_wTa,
        prune_spur_m=prune_spur_m,
        spur_clearance_factor=spur_clearance_factor,
        spur_beyond_clearance_m=spur_beyond_clearance_m,
    )
    G.graph.update(close_cells=int(close_cells), erode_cells=int(erode_cells))
    if cleaning is not None:
        G.graph.update(cleaning.as_graph_attrs())
    if report is not None:  # cleaned (set exactly when cleaning is)
        G.graph.update(report.as_graph_attrs())
    return G


def cleaned_free(grid: OccupancyGrid, topology) -> np.ndarray:
    """The grid's free cells cleaned as ``topology`` records (``topology_from_grid``; the raw free cells when
    it records none), without its pre-processing: the free space the holographic graph works on (it has its
    own robot-sized opening)."""
    from holoslam.maps.cleaning import MapCleaning, clean_free

    c = MapCleaning.from_graph_attrs(getattr(topology, "graph", {}))
    if c is None:
        return grid.free
    return _reuse("cleaned", grid.occupancy, (grid.free_thresh, c), lambda: clean_free(grid, c)[0])


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
