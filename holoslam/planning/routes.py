"""Planning queries on the two-layer graph: pose -> pose and pose -> object.

A query is one compiled call (numba, :mod:`holoslam.planning._fast`) after an O(1) point location; nothing
touches the grid cell by cell except the final exact segment checks.

1. **Locate** start and goal: the region under each point, O(1) through the block-id label image. A point in
   no free block (an obstacle, unknown space, a mixed block below the minimum block size) is moved to the
   centre of the nearest free-block cell within ``snap_radius_m``; farther than that the query raises
   ``PlanningError``. Regions overlap: every region holding the start (the goal) may begin (end) the route;
   they are found through a bucket index of the regions (:func:`region_buckets`), not a scan of all.
2. **Corridor search**: A* over the *ports* (the distinct corners and the centre of each portal; a portal is
   the intersection of two adjacent regions' closed rectangles) with edges between the ports of one region,
   weighted by their distance. The edges are not stored: a port's neighbours are read from the port lists of
   its two regions (coordinates inline), and the region a port was reached through is not scanned again from
   it (convexity: its ports are no closer through it). The heuristic is the larger of the Euclidean distance
   and 14 ALT landmark bounds ``|d(l, goal) - d(l, v)|`` (landmarks picked farthest-first, their distances
   precomputed by ``scipy.sparse.csgraph.dijkstra`` in :func:`build_planner`; 14 so that a port's coordinates
   and landmark distances fill one 64-byte row; when several regions hold the goal, the bounds are taken
   through each of them and the smallest kept, since the goal joins their ports where the port graph may
   not: ``_fast.astar._goal_distances``); both are consistent, and the search weights the heuristic by
   ``HEURISTIC_WEIGHT`` = 1.2 (weighted A*: the corridor costs at most 1.2 times the port-graph optimum, and
   the funnel below only shortens the path; on the tiled 4000 x 4000 map of the benchmark it expanded a
   median 208 ports instead of 1,804 over 40 random pairs, with path lengths still within 10 % of grid A*
   there and in the random-map measurement below). The search keeps a per-thread workspace (one 32-byte
   record a port: generation stamp, cost, heuristic, parent, heap slot; an indexed binary heap with
   decrease-key), so a query touches only the ports it meets, and the ports are numbered in a spatial order
   so that those of one region share cache lines. The port path gives the corridor: the sequence of portals
   (and so of convex regions) from start to goal, trimmed to enter at the last region holding the start and
   leave at the first holding the goal.
3. **Funnel**: the shortest polyline through the corridor's portal boxes in order (the funnel algorithm on
   the angular intervals the boxes subtend from the current apex; a straight piece that meets boxes i..j is
   covered by the convex regions between them, so it is collision-free by construction). The same is done
   for the greedily shortcut corridor (jumping to the last later region adjacent to the current one) and the
   shorter path wins.
4. **String-pull and validate**: a windowed string pull on the grid (shortcuts through regions outside the
   corridor), then collinear points are dropped and every returned segment is checked exactly on the grid:
   the shortcuts when the string pull accepts them, the other segments after it. The check reads the free
   mask as 8 x 8-cell tiles of 64 bits and skips, in one step, the part of a segment inside a square of
   fully free 4 x 4-cell blocks (the blocks' chessboard clearance), with the same answer as
   :func:`segments_free`; a string-pull shortcut is first checked near the corner it cuts, where the taut
   funnel path's shortcuts nearly always fail.

Speed (``benchmarks/bench_planning.py``, tiled household maps, median query against pyastar2d grid A* over
the same pairs): about 0.06 ms on 1000 x 1000 cells (over 100x faster than grid A*), 0.15 ms on 2000 x 2000
and 0.45 ms on 4000 x 4000; most of it is the corridor search, then the two funnels and the grid checks.

Collision model: the robot is a point on the planner's free mask (the cells covered by free blocks; the map's
obstacles are expected to be inflated by the robot radius, as seed 003 assumes). A segment is collision-free
when every point of it lies in the closed union of free cells (:func:`segments_free`, exact up to
``EPS_CELLS`` = 1e-9 cells for float rounding): a path may touch an obstacle's edge and may pass diagonally
between two obstacle cells meeting at a corner, as an 8-connected grid planner does.

Length guarantee (checked against 8-connected grid A* in ``tests/test_routes.py`` on random maps and in
``benchmarks/bench_planning.py``): a returned path is at most ``LENGTH_FACTOR`` = 1.25 times the grid A*
length between the same cell centres. This is an empirical bound, not a theorem: the corridor is chosen by
distances between portal corners and centres, which can miss a shorter corridor on cluttered maps. Measured
over 2,959 queries on adversarial random maps (random rectangles and single-cell obstacles, 8-48 cells a
side) with the exact search and corner ports only: median 0.83, 99th percentile 1.00, 0.1 % above 1.10,
worst 1.20; with ``HEURISTIC_WEIGHT`` = 1.2, over 1,504 such queries: median 0.83, 99th percentile 1.00,
none above 1.10, worst 1.04. Corner ports alone gave 1.37 on one map hypothesis found (a wide portal
crossed near its middle); with the centre ports, over 1,500 other such queries: median 0.835, 99th
percentile 1.00, worst 1.01. A goal held by two regions that the region graph joins only through others
made the landmark bound overestimate (1.6x on a map hypothesis found; 3 of 3,000 random maps over
``LENGTH_FACTOR``); with the bounds taken by goal region, over 29,796 queries on 6,000 such maps: median
0.83, 99th percentile 1.00, none above 1.10, worst 1.08. On household-like maps the paths are shorter than
grid A* (any-angle): worst 0.99 on the reference household and 0.92 on the tiled large maps in the
benchmark.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from holoslam.errors import PlanningError
from holoslam.planning.segments import EPS_CELLS, path_length, segments_free
from holoslam.planning.twolayer import TwoLayerGraph, unique_int

__all__ = [
    "LENGTH_FACTOR",
    "Route",
    "RoutePlanner",
    "build_planner",
    "plan_path",
    "plan_to_object",
    "segments_free",
    "path_length",
]

LENGTH_FACTOR = 1.25
HEURISTIC_WEIGHT = 1.2  # weighted A* over the port graph: corridor cost <= 1.2 x the port-graph optimum


@dataclass(frozen=True, slots=True)
class Route:
    """A planned route: the holographic places passed (node keys, empty for a pose -> pose query), the metric
    waypoints (K, 2) world (x, y) from start to goal, its length in metres and the layer-2 regions crossed."""

    places: tuple[str, ...]
    waypoints: np.ndarray
    length: float
    regions: tuple[int, ...] = ()
    goal_place: str | None = None


@dataclass(frozen=True, slots=True)
class RoutePlanner:
    """The precomputed query structure over a :class:`TwoLayerGraph` (see the module docstring).

    Points are in cell-boundary coordinates (u = column axis, v = row axis). Portal k (= region edge k of the
    graph, joining regions ``graph.region_edges[k]``) is the closed box ``portal_boxes[k]`` = (u0, v0, u1,
    v1), with centre ``portal_uv[k]``; ``region_portal_ptr`` / ``region_portal_ids`` (CSR) list each
    region's portals. The portal graph (CSR ``adj_ptr``, ``adj_dst``, ``adj_w``) joins two portals of one
    region, weighted by the distance of their centres in cells. ``kernels`` is the compiled kernel module
    (:mod:`holoslam.planning._fast`).
    """

    graph: TwoLayerGraph
    portal_uv: np.ndarray  # (F, 2)
    portal_boxes: np.ndarray  # (F, 4) u0, v0, u1, v1
    port_uv: np.ndarray  # (NP, 2) search nodes: the distinct corners and the centre of each portal
    port_portal: np.ndarray  # (NP,) the portal of each port (ascending)
    region_portal_ptr: np.ndarray  # (R+1,)
    region_portal_ids: np.ndarray
    region_component: np.ndarray  # (R,) connected component of the region graph
    adj_ptr: np.ndarray = field(repr=False)  # (F+1,)
    adj_dst: np.ndarray = field(repr=False)  # (A,)
    adj_w: np.ndarray = field(repr=False)  # (A,) cells
    landmark_dist: np.ndarray = field(repr=False)  # (F, L) portal-graph distances from L landmark portals
    free: np.ndarray = field(repr=False)  # (H, W) bool planner free mask
    kernels: Any = field(repr=False, default=None)  # the compiled kernel module
    _cache: dict = field(repr=False, default_factory=dict, compare=False)


def _kernels():
    try:
        from holoslam.planning import _fast
    except ImportError as e:  # pragma: no cover - numba is a declared dependency
        raise PlanningError(
            f"the compiled planning kernels need numba ({e}); install it: pip install numba"
        ) from e
    return _fast


def _components(n: int, edges: np.ndarray) -> np.ndarray:
    """Connected component label (smallest member id) per node: vectorised union-find by min-label hooking."""
    parent = np.arange(n, dtype=np.int64)
    if edges.shape[0] == 0:
        return parent
    a, b = edges[:, 0], edges[:, 1]
    while True:
        while True:
            pp = parent[parent]
            if np.array_equal(pp, parent):
                break
            parent = pp
        ra, rb = parent[a], parent[b]
        m = ra != rb
        if not m.any():
            return parent
        lo, hi = np.minimum(ra[m], rb[m]), np.maximum(ra[m], rb[m])
        np.minimum.at(parent, hi, lo)


def _landmarks(aptr: np.ndarray, dst: np.ndarray, w: np.ndarray, n: int, k: int) -> np.ndarray:
    """(n, k) shortest-path distances from k landmark nodes picked by farthest-point selection (the next
    landmark is the node farthest from all chosen ones; unreachable counts as farthest, so every component
    gets landmarks), one compiled Dijkstra (scipy.sparse.csgraph) per landmark."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    k = min(k, n)
    if k == 0:
        return np.zeros((n, 0))
    # zero-length edges (portals with coincident centres) would vanish from a sparse matrix
    A = csr_matrix((np.maximum(w, 1e-9), dst, aptr), shape=(n, n))
    D = np.empty((n, k))
    near = np.full(n, np.inf)
    cur = 0
    for i in range(k):
        D[:, i] = dijkstra(A, directed=True, indices=cur)
        near = np.minimum(near, D[:, i])
        cur = int(np.argmax(near))
        if near[cur] == 0.0:  # every node is a landmark already
            return np.ascontiguousarray(D[:, : i + 1])
    return D


def build_planner(graph: TwoLayerGraph, n_landmarks: int = 14) -> RoutePlanner:
    """Precompute the portal graph of a two-layer graph (vectorised; its size is the sum over regions of the
    square of the region's number of ports), the distances of ``n_landmarks`` landmark ports for the ALT
    heuristic and the query structures (:func:`_query_arrays`)."""
    E = graph.region_edges.astype(np.int64)
    F = E.shape[0]
    R = graph.n_regions
    P = graph.portals.astype(np.float64)  # (row_lo, col_lo, row_hi, col_hi)
    boxes = np.column_stack([P[:, 1], P[:, 0], P[:, 3], P[:, 2]]).reshape(-1, 4)
    cen = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2]).reshape(-1, 2)
    # (region, portal) incidences sorted by region
    owner = np.concatenate([E[:, 0], E[:, 1]])
    pid = np.concatenate([np.arange(F, dtype=np.int64)] * 2)
    o = np.argsort(owner, kind="stable")
    owner, pid = owner[o], pid[o]
    ptr = np.searchsorted(owner, np.arange(R + 1))
    # ports: the distinct corners and the centre of each portal (a segment portal has its two ends and its
    # centre, a corner contact one point); sorted by portal, coordinates exact in half cells
    H2, W2 = 2 * graph.shape[0] + 1, 2 * graph.shape[1] + 1
    cu_ = np.stack([boxes[:, 0], boxes[:, 2], boxes[:, 0], boxes[:, 2], cen[:, 0]], axis=1)
    cv_ = np.stack([boxes[:, 1], boxes[:, 1], boxes[:, 3], boxes[:, 3], cen[:, 1]], axis=1)
    pkey = unique_int(
        (
            (np.arange(F, dtype=np.int64)[:, None] * H2 + np.rint(2 * cv_).astype(np.int64)) * W2
            + np.rint(2 * cu_).astype(np.int64)
        ).ravel()
    )
    port_portal = pkey // (H2 * W2)
    ports = np.column_stack([(pkey % W2) / 2.0, ((pkey // W2) % H2) / 2.0]).reshape(-1, 2)
    portal_port_ptr = np.searchsorted(port_portal, np.arange(F + 1))
    NP = ports.shape[0]
    # (region, port) incidences, grouped by region, then all ordered pairs of distinct ports of one region
    npp = np.diff(portal_port_ptr)
    cnt = npp[pid]
    pown = np.repeat(owner, cnt)
    off0 = np.arange(pown.shape[0]) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    pport = np.repeat(portal_port_ptr[pid], cnt) + off0
    rptr = np.searchsorted(pown, np.arange(R + 1))
    deg = np.diff(rptr)
    dv = deg[pown]
    rep = np.repeat(np.arange(pown.shape[0]), dv)
    off = np.arange(rep.shape[0]) - np.repeat(np.cumsum(dv) - dv, dv)
    src = pport[rep]
    dst = pport[rptr[pown[rep]] + off]
    m = src != dst
    src, dst = src[m], dst[m]
    key = unique_int(src * max(NP, 1) + dst)  # sorted by source, then destination; duplicates dropped
    src, dst = key // max(NP, 1), key % max(NP, 1)
    d = np.hypot(*(ports[src] - ports[dst]).T) if src.shape[0] else np.zeros(0)
    aptr = np.searchsorted(src, np.arange(NP + 1))
    comp = _components(R, graph.region_edges)
    D = _landmarks(aptr, dst, d, NP, n_landmarks)
    planner = RoutePlanner(
        graph, _ro(cen), _ro(boxes), _ro(ports), _ro(port_portal), _ro(ptr), _ro(pid), _ro(comp), _ro(aptr),
        _ro(dst), _ro(d.astype(np.float64)), _ro(D), free=_ro(graph.free_mask()), kernels=_kernels(),
    )
    _query_arrays(planner)  # derived query structures: built here, not by the first query
    return planner


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _locate(
    planner: RoutePlanner, xy: np.ndarray, snap_radius_m: float, what: str
) -> tuple[float, float, int]:
    """(u, v) boundary coordinates and region id of a world point, snapping to the nearest free cell."""
    g = planner.graph
    try:
        x, y = np.asarray(xy, dtype=np.float64).reshape(2).tolist()
    except ValueError as e:
        raise PlanningError(f"the {what} position {xy!r} is not an (x, y) pair in metres: {e}") from e
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlanningError(f"the {what} position {[x, y]} is not a finite (x, y) in metres")
    u, v = (x - g.origin_x) / g.resolution, (y - g.origin_y) / g.resolution
    ci, ri = math.floor(u), math.floor(v)
    h, w = g.shape
    if 0 <= ri < h and 0 <= ci < w:
        b = g.labels[ri, ci]
        if b >= 0:
            return u, v, int(g.region_of_block[b])
    # snap: nearest free-block cell in a window of the snap radius
    k = int(np.ceil(snap_radius_m / g.resolution))
    r0, r1, c0, c1 = max(ri - k, 0), min(ri + k + 1, h), max(ci - k, 0), min(ci + k + 1, w)
    if r0 < r1 and c0 < c1:
        win = g.labels[r0:r1, c0:c1]
        rr, cc = np.nonzero(win >= 0)
        if rr.shape[0]:
            cu, cv = cc + c0 + 0.5, rr + r0 + 0.5
            d = np.hypot(cu - u, cv - v)
            i = int(np.argmin(d))
            if d[i] * g.resolution <= snap_radius_m + 0.5 * g.resolution:
                return (
                    float(cu[i]),
                    float(cv[i]),
                    int(g.region_of_block[g.labels[int(rr[i]) + r0, int(cc[i]) + c0]]),
                )
    raise PlanningError(
        f"the {what} position ({x:.2f}, {y:.2f}) is not in free space of the planning grid "
        "(nor within "
        f"{snap_radius_m} m of it); give a position in a free, known area of the map"
    )


def region_buckets(regions: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bucket index of the regions for point location: square buckets of 2**shift cells (shift from the
    mean region area, so a bucket meets a few regions), each listing, ascending, the regions whose closed
    rectangle meets it. Returns (ptr, ids, [shift, buckets a row, most regions in a bucket]); the bucket of
    a point (u, v) is ``(floor(v) >> shift) * nbx + (floor(u) >> shift)``."""
    R = np.asarray(regions, dtype=np.int64).reshape(-1, 4)
    h, w = shape
    area = float(np.mean((R[:, 2] - R[:, 0]) * (R[:, 3] - R[:, 1]))) if R.shape[0] else 1.0
    shift = int(min(max(round(math.log2(max(area, 1.0)) / 2), 2), 10))
    nbx, nby = (w >> shift) + 1, (h >> shift) + 1
    bu0, bu1 = R[:, 1] >> shift, R[:, 3] >> shift  # the closed rectangle reaches column line c1
    bv0, bv1 = R[:, 0] >> shift, R[:, 2] >> shift
    nx, ny = bu1 - bu0 + 1, bv1 - bv0 + 1
    cnt = nx * ny
    rid = np.repeat(np.arange(R.shape[0], dtype=np.int64), cnt)
    k = np.arange(rid.shape[0]) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    bucket = (bv0[rid] + k // nx[rid]) * nbx + bu0[rid] + k % nx[rid]
    o = np.argsort(bucket, kind="stable")  # regions stay ascending within a bucket
    per = np.bincount(bucket, minlength=nbx * nby)
    ptr = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    grid = np.array([shift, nbx, int(per.max()) if per.shape[0] else 0], dtype=np.int64)
    return ptr, np.ascontiguousarray(rid[o]), grid


def _query_arrays(planner: RoutePlanner) -> tuple:
    """The arrays of :func:`holoslam.planning._fast.query` in their groups (graph, links, locate, grid),
    derived once per planner (by :func:`build_planner`). The ports are renumbered in a spatial order
    (regions along a Z-order curve of their centres, each region's ports numbered on first sight), so the
    ports of one region, which the search meets together, sit together in memory; the per-port arrays are
    in that order and ``pslot`` maps the planner's port ids (the slots of ``pp``) to it. Port rows hold the
    coordinates and the landmark distances as float32 (a row per cache line; the rounding, about 1e-7
    relative, is far below the heuristic weight's slack); the region bucket index and the grid tiles come
    with them."""
    c = planner._cache
    if "query" not in c:  # the port graph's edge list (adj_*) is not needed: edges are the regions' ports
        g = planner.graph
        E = np.ascontiguousarray(g.region_edges, dtype=np.int64).reshape(-1, 2)
        bptr, bids, bgrid = region_buckets(g.regions, g.shape)
        rp_ptr, rp_old, _ = _region_ports(planner)
        new2old, old2new = _spatial_port_order(g.regions, rp_ptr, rp_old, planner.port_uv.shape[0])
        # each region's ports by their new number (ascending: the search reads their records in order)
        reg = np.repeat(np.arange(rp_ptr.shape[0] - 1), np.diff(rp_ptr))
        rp_new = old2new[rp_old]
        o = np.lexsort((rp_new, reg))
        rp_new = rp_new[o]
        uv = planner.port_uv[new2old]
        portal_of = planner.port_portal[new2old]
        uv32 = np.ascontiguousarray(uv[rp_new], dtype=np.float32)
        rows = _port_rows(uv, planner.landmark_dist[new2old])
        graph = (
            rp_ptr,
            rp_new.astype(np.int32),
            uv32,
            rows,
            *(np.ascontiguousarray(E[portal_of, k]) for k in (0, 1)),
        )
        links = (
            np.ascontiguousarray(uv, dtype=np.float64),
            np.ascontiguousarray(portal_of),
            np.searchsorted(planner.port_portal, np.arange(E.shape[0] + 1)),
            old2new,
            planner.region_portal_ptr,
            planner.region_portal_ids,
            E,
            planner.portal_boxes,
        )
        locate = (np.ascontiguousarray(g.regions, dtype=np.int64).reshape(-1, 4), bptr, bids, bgrid)
        world = np.array([g.origin_x, g.origin_y, g.resolution], dtype=np.float64)
        grid = (*_tiles(planner), int(g.shape[0]), int(g.shape[1]), world)
        c["query"] = (graph, links, locate, grid)
    return c["query"]


def _spatial_port_order(
    regions: np.ndarray, rp_ptr: np.ndarray, rp_ids: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(new -> old, old -> new) port numbering: regions sorted along a Z-order (Morton) curve of their centre
    cells, ports numbered in the order the regions list them, each at its first sight."""
    R = np.asarray(regions, dtype=np.int64).reshape(-1, 4)
    cr, cc = (R[:, 0] + R[:, 2]) // 2, (R[:, 1] + R[:, 3]) // 2
    key = np.zeros(R.shape[0], dtype=np.int64)
    for b in range(20):  # interleave the bits of row and column (grids up to a million cells a side)
        key |= ((cr >> b) & 1) << (2 * b + 1) | ((cc >> b) & 1) << (2 * b)
    order = np.argsort(key, kind="stable")
    cnt = np.diff(rp_ptr)[order]
    start = np.repeat(rp_ptr[:-1][order], cnt)
    seq = rp_ids[start + np.arange(start.shape[0]) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    _, first = np.unique(seq, return_index=True)
    new2old = seq[np.sort(first)]
    if new2old.shape[0] < n:  # ports of no region cannot happen (a port is on a portal of two regions)
        new2old = np.concatenate([new2old, np.setdiff1d(np.arange(n), new2old)])
    old2new = np.empty(n, dtype=np.int64)
    old2new[new2old] = np.arange(n)
    return new2old, old2new


def _region_ports(planner: RoutePlanner) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ports of each region (CSR ``ptr`` (R+1,), ``ids`` int32) with their (u, v) as float32 (half cells:
    exact): the port graph's edges without storing them (two ports are joined when they share a region)."""
    ptr, pids = planner.region_portal_ptr, planner.region_portal_ids
    pp = np.searchsorted(planner.port_portal, np.arange(planner.portal_uv.shape[0] + 1))
    per_portal = np.diff(pp)[pids]  # ports of each (region, portal) incidence
    start = np.repeat(pp[pids], per_portal)
    ids = start + np.arange(start.shape[0]) - np.repeat(np.cumsum(per_portal) - per_portal, per_portal)
    rptr = np.concatenate([[0], np.cumsum(per_portal)]).astype(np.int64)[ptr]  # incidences grouped by region
    return rptr, ids.astype(np.int32), np.ascontiguousarray(planner.port_uv[ids], dtype=np.float32)


def _tiles(planner: RoutePlanner) -> tuple[np.ndarray, np.ndarray]:
    """The free mask as 8 x 8-cell tiles of 64 bits (``_fast.tile_bits``) and the chessboard clearance of
    its fully free 4 x 4-cell blocks (``_fast.block_clearance``): what the query's grid checks read
    (``_fast.seg_free_tiles``)."""
    bits, _ = planner.kernels.tile_bits(planner.free)
    return _aligned(bits), planner.kernels.block_clearance(planner.free)


def _aligned(a: np.ndarray) -> np.ndarray:
    """A copy of the 1-D array ``a`` starting on a 64-byte boundary (a cache line)."""
    buf = np.empty(a.shape[0] + 64 // a.itemsize, dtype=a.dtype)
    off = (-buf.ctypes.data % 64) // a.itemsize
    out = buf[off : off + a.shape[0]]
    out[:] = a
    return out


def _port_rows(port_uv: np.ndarray, landmark_dist: np.ndarray) -> np.ndarray:
    """(n, 16k) float32 rows, 64-byte aligned: each port's (u, v) (half cells: exact) and its landmark
    distances, zero padded; with 14 landmarks one cache line a port."""
    n, L = landmark_dist.shape
    width = -(-(2 + L) // 16) * 16
    buf = np.zeros(n * width + 16, dtype=np.float32)
    off = (-buf.ctypes.data % 64) // 4
    rows = buf[off : off + n * width].reshape(n, width)
    rows[:, :2] = port_uv
    rows[:, 2 : 2 + L] = landmark_dist
    return rows


def _workspace(planner: RoutePlanner) -> tuple:
    """The query's reusable per-thread workspace (see ``_fast.corridor_astar`` and ``_fast.query``):
    allocated once, so a query touches only the ports it meets instead of clearing arrays the size of the
    port graph."""
    key = ("ws", threading.get_ident())
    c = planner._cache
    ws = c.get(key)
    if ws is None:
        n = planner.port_uv.shape[0]
        ws = c[key] = (
            np.zeros(n + 2, dtype=planner.kernels.WORKSPACE_DTYPE),  # node records (n + 1: generation)
            np.empty(n + 1, dtype=np.int64),  # heap nodes
            np.empty(n + 1),  # heap keys
            np.full(max(planner.graph.n_regions, 1), -1, dtype=np.int64),  # corridor shortcut scratch
        )
    return ws


def plan_path(
    planner: RoutePlanner | TwoLayerGraph,
    start_xy: np.ndarray,
    goal_xy: np.ndarray,
    snap_radius_m: float = 0.3,
    places: tuple[str, ...] = (),
) -> Route:
    """The shortest metric path between two world points through the convex regions (module docstring).

    Raises ``PlanningError`` when either point is not in (or near) free space or the goal is unreachable.
    """
    if isinstance(planner, TwoLayerGraph):
        planner = build_planner(planner)
    su, sv, rs = _locate(planner, start_xy, snap_radius_m, "start")
    gu, gv, rg = _locate(planner, goal_xy, snap_radius_m, "goal")
    if planner.region_component[rs] != planner.region_component[rg]:
        raise PlanningError(
            f"the goal ({float(goal_xy[0]):.2f}, {float(goal_xy[1]):.2f}) cannot be reached from the start "
            f"({float(start_xy[0]):.2f}, {float(start_xy[1]):.2f}): no free passage joins them in the "
            "planning graph"
        )
    c = planner._cache.get("query") or _query_arrays(planner)
    graph, links, locate, grid = c
    wp, regs, length, status = planner.kernels.query(
        *graph,
        *links,
        *locate,
        *grid,
        su,
        sv,
        rs,
        gu,
        gv,
        rg,
        HEURISTIC_WEIGHT,
        EPS_CELLS,
        *_workspace(planner),
    )
    if status == 1:  # pragma: no cover - the component check above makes this unreachable
        raise PlanningError("no route found between connected regions; rebuild the planning graph")
    if status == 2:
        raise PlanningError("internal planning error: a path segment crosses an obstacle; rebuild the graph")
    wp.setflags(write=False)
    return Route(tuple(places), wp, length, tuple(regs.tolist()))


def plan_to_object(
    planning: RoutePlanner | TwoLayerGraph,
    holographic,
    grid=None,
    object_id: str = "",
    from_xy: np.ndarray | None = None,
    snap_radius_m: float = 0.3,
) -> Route:
    """Route from ``from_xy`` to object ``object_id`` of a holographic graph (``holoslam.maps.holographic``).

    The object's edges give the places it can be handled from and, for each, a standing point (``reach_x``,
    ``reach_y``). A metric path through the convex regions is planned to each standing point and the shortest
    wins; ``places`` is then the topological route (``route_to_object``: environment nodes by passage length,
    from the node nearest the start to the winning place, ending with the object id). ``from_xy`` defaults to
    the first environment node's position. ``grid`` is accepted for the CLI's convenience and only checked
    against the planning graph's shape.

    Raises ``PlanningError`` for an unknown object or an object no place reaches.
    """
    from holoslam.maps.holographic import object_reach_points, route_to_object

    planner = build_planner(planning) if isinstance(planning, TwoLayerGraph) else planning
    if grid is not None and tuple(grid.shape) != tuple(planner.graph.shape):
        raise PlanningError(
            f"the planning graph was built on a {planner.graph.shape} grid but the map is "
            f"{tuple(grid.shape)}; "
            "rebuild planning.json from this map"
        )
    if from_xy is None:
        env = [d for _, d in holographic.nodes(data=True) if d.get("kind") == "environment"]
        if not env:
            raise PlanningError(
                "the holographic graph has no environment node to start from; give --from x,y"
            )
        from_xy = np.array([env[0]["x"], env[0]["y"]])
    from_xy = np.asarray(from_xy, dtype=np.float64).reshape(2)
    reach = object_reach_points(holographic, object_id)  # raises for unknown / unreachable objects
    best: Route | None = None
    last_err: PlanningError | None = None
    for place, xy in reach:
        try:
            r = plan_path(planner, from_xy, xy, snap_radius_m)
        except PlanningError as e:
            last_err = e
            continue
        if best is None or r.length < best.length:
            best = Route((), r.waypoints, r.length, r.regions, place)
    if best is None:
        raise PlanningError(
            f"object {object_id!r} cannot be reached from ({from_xy[0]:.2f}, {from_xy[1]:.2f}): {last_err}"
        )
    places = tuple(route_to_object(holographic, from_xy, object_id, via=best.goal_place))
    return Route(places, best.waypoints, best.length, best.regions, best.goal_place)
