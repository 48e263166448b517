"""Planning queries: exact segment check, paths collision-free and within LENGTH_FACTOR of grid A*."""

from __future__ import annotations

import cv2
import numpy as np
import pyastar2d  # dev/benchmark only: the reference planner
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from planning_maps import apartment_free, random_map

from holoslam.errors import PlanningError
from holoslam.maps.grid import OccupancyGrid
from holoslam.planning.routes import LENGTH_FACTOR, build_planner, path_length, plan_path, segments_free
from holoslam.planning.twolayer import build_two_layer


def astar_length(free: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> float | None:
    w = np.where(free, 1.0, np.inf).astype(np.float32)
    p = pyastar2d.astar_path(w, a, b, allow_diagonal=True)
    return None if p is None else path_length(p)


def point_in_closed_free(free: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Reference: a point lies in the closed union of free cells (cell (r, c) = [c, c+1] x [r, r+1])."""
    h, w = free.shape
    ok = np.zeros(u.shape, dtype=bool)
    for c in (np.floor(u), np.ceil(u) - 1):
        for r in (np.floor(v), np.ceil(v) - 1):
            c_, r_ = c.astype(int), r.astype(int)
            inside = (
                (c_ >= 0)
                & (c_ < w)
                & (r_ >= 0)
                & (r_ < h)
                & (c_ <= u)
                & (u <= c_ + 1)
                & (r_ <= v)
                & (v <= r_ + 1)
            )
            o = np.zeros(u.shape, dtype=bool)
            o[inside] = free[r_[inside], c_[inside]]
            ok |= o
    return ok


quarter = st.integers(0, 40).map(lambda k: k / 4.0)


@settings(max_examples=150, deadline=None)
@given(
    st.integers(0, 2**31 - 1),
    st.lists(st.tuples(quarter, quarter, quarter, quarter), min_size=1, max_size=8),
)
def test_segments_free_matches_dense_sampling(seed, segs):
    """Endpoints on a quarter-cell lattice in a 10 x 10 grid: every piece of a segment inside one cell is
    longer than 1/1600 of the segment, so 8000 samples see every cell the segment enters."""
    free = random_map(seed, 10, 10, 3, 8)
    s = np.array(segs, dtype=np.float64)
    got = segments_free(free, s[:, :2], s[:, 2:])
    t = (np.arange(8000) + 0.5) / 8000
    for k, (u0, v0, u1, v1) in enumerate(s.tolist()):
        u = u0 + (u1 - u0) * np.append(t, [0.0, 1.0])
        v = v0 + (v1 - v0) * np.append(t, [0.0, 1.0])
        assert got[k] == bool(point_in_closed_free(free, u, v).all()), (k, s[k])


def test_segments_free_corner_and_boundary_cases():
    free = np.array([[True, False], [False, True]])  # two free cells meeting at a corner
    # through the shared corner point (the diagonal move of an 8-connected planner): free
    assert segments_free(free, [[0.5, 0.5]], [[1.5, 1.5]]).all()
    # off the diagonal it enters an occupied cell
    assert not segments_free(free, [[0.5, 0.5]], [[1.5, 1.2]]).any()
    # along the boundary line between a free and an occupied cell: free; outside the grid: not free
    assert segments_free(free, [[0.0, 1.0]], [[2.0, 1.0]]).all()  # each half has a free cell on one side
    corner = np.array([[True, False], [False, False]])
    assert not segments_free(corner, [[1.0, 1.0]], [[2.0, 1.0]]).any()  # both sides occupied
    # float rounding off a grid line does not flip the answer
    assert segments_free(free, [[0.0, 1.0 + 1e-12]], [[2.0, 1.0 - 1e-12]]).all()
    assert segments_free(np.ones((2, 2), bool), [[1.0, 0.0]], [[1.0, 2.0]]).all()
    assert not segments_free(np.ones((2, 2), bool), [[1.0, 1.0]], [[3.0, 1.0]]).any()


def _check_route(tl, planner, free, a, b):
    res = tl.resolution
    s_xy = np.array([(a[1] + 0.5) * res, (a[0] + 0.5) * res])
    g_xy = np.array([(b[1] + 0.5) * res, (b[0] + 0.5) * res])
    r = plan_path(planner, s_xy, g_xy)
    assert np.allclose(r.waypoints[0], s_xy) and np.allclose(r.waypoints[-1], g_xy)
    uv = r.waypoints / res
    assert segments_free(free, uv[:-1], uv[1:]).all()
    assert r.length == pytest.approx(path_length(r.waypoints))
    ref = astar_length(free, a, b)
    assert ref is not None
    assert r.length <= LENGTH_FACTOR * ref * res + 1e-9
    # never shorter than the straight line
    assert r.length >= np.hypot(*(g_xy - s_xy)) - 1e-9
    return r.length / max(ref * res, 1e-12)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 2**31 - 1),
    st.integers(8, 48),
    st.integers(8, 48),
    st.integers(0, 14),
    st.integers(0, 40),
    st.integers(0, 2**31 - 1),
)
# found by hypothesis: 1.37x the A* length while regions had only corner ports (centre ports fixed it)
@example(20197, 8, 27, 3, 4, 20197)
# found by hypothesis (derandomize off): 1.6x, the goal in two overlapping regions the region graph does not
# join directly made the landmark bound overestimate (test_landmark_bounds_stay_below_the_distance_to_the_goal)
@example(38, 14, 48, 7, 23, 14)
def test_random_maps_paths_valid_and_within_factor_of_astar(seed, h, w, n_rect, n_dots, qseed):
    free = random_map(seed, h, w, n_rect, n_dots)
    tl = build_two_layer(free, 1, resolution=0.05)
    planner = build_planner(tl)
    cells = np.argwhere(free)
    if cells.shape[0] < 2:
        return
    _, cc = cv2.connectedComponents(free.astype(np.uint8), connectivity=8)
    rng = np.random.default_rng(qseed)
    for _ in range(5):
        a, b = (tuple(int(x) for x in cells[i]) for i in rng.integers(0, cells.shape[0], 2))
        if cc[a] == cc[b]:
            _check_route(tl, planner, free, a, b)
        else:
            with pytest.raises(PlanningError, match="cannot be reached"):
                plan_path(
                    planner,
                    np.array([(a[1] + 0.5) * 0.05, (a[0] + 0.5) * 0.05]),
                    np.array([(b[1] + 0.5) * 0.05, (b[0] + 0.5) * 0.05]),
                )


def test_household_queries_valid_and_shorter_than_factor():
    free = apartment_free()
    tl = build_two_layer(OccupancyGrid.from_free_mask(free, 0.05), 1)
    planner = build_planner(tl)
    cells = np.argwhere(free)
    rng = np.random.default_rng(7)
    ratios = [
        _check_route(tl, planner, free, tuple(cells[i]), tuple(cells[j]))
        for i, j in rng.integers(0, cells.shape[0], (40, 2))
    ]
    assert max(ratios) <= 1.10  # the goal on household-like maps (tighter than LENGTH_FACTOR)


def test_planning_errors_are_clear():
    free = apartment_free()
    free[:, 100:] = False  # cut the flat in two: the east part is now unreachable (and occupied)
    free[5:20, 150:190] = True
    tl = build_two_layer(OccupancyGrid.from_free_mask(free, 0.05), 1)
    with pytest.raises(PlanningError, match="not in free space"):
        plan_path(tl, np.array([6.5, 5.0]), np.array([1.0, 1.0]))  # start deep in the occupied half
    with pytest.raises(PlanningError, match="cannot be reached"):
        plan_path(tl, np.array([1.0, 1.0]), np.array([8.5, 0.5]))
    with pytest.raises(PlanningError, match="finite"):
        plan_path(tl, np.array([np.nan, 1.0]), np.array([1.0, 1.0]))
    # a start just inside a wall snaps to the nearest free cell
    r = plan_path(tl, np.array([0.06, 1.0]), np.array([1.0, 1.0]))
    assert tl.region_at(r.waypoints[:1])[0] >= 0


@settings(max_examples=100, deadline=None)
@given(
    st.integers(0, 2**31 - 1),
    st.lists(st.tuples(quarter, quarter, quarter, quarter), min_size=1, max_size=8),
)
def test_compiled_segment_check_matches_segments_free(seed, segs):
    """The compiled check the planner validates with (``_fast.seg_free_tiles``) agrees with ``segments_free``,
    itself checked against dense sampling above."""
    from holoslam.planning import _fast

    free = random_map(seed, 10, 10, 3, 8)
    bits, _ = _fast.tile_bits(free)
    tclear = _fast.block_clearance(free)
    s = np.array(segs, dtype=np.float64)
    ref = segments_free(free, s[:, :2], s[:, 2:])
    got = [_fast.seg_free_tiles(bits, tclear, 10, 10, u0, v0, u1, v1, 1e-9) for u0, v0, u1, v1 in s.tolist()]
    assert got == ref.tolist()


def _corridor_case(seed, h, w, qseed):
    """A random map, a query and the corridor (portal boxes) the planner's regions give for it."""
    free = random_map(seed, h, w, 6, 20)
    tl = build_two_layer(free, 1, resolution=1.0)
    planner = build_planner(tl)
    return free, tl, planner


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(8, 40), st.integers(8, 40), st.integers(0, 2**31 - 1))
def test_funnel_is_shortest_through_the_boxes_and_collision_free(seed, h, w, qseed):
    """The corridor path through a chain of portal boxes (funnel, polished by coordinate descent where it
    turns back) starts and ends right, is collision-free, is no longer than the polyline through the box
    centres and within ``LENGTH_FACTOR`` of the convex optimum (exact coordinate descent, ``_fast.refine``,
    run long). Not always equal to it: the funnel bends at box corners only."""
    from holoslam.planning import _fast

    free, tl, planner = _corridor_case(seed, h, w, qseed)
    E = tl.region_edges
    if E.shape[0] == 0:
        return
    rng = np.random.default_rng(qseed)
    # a self-avoiding random walk along the region graph gives a chain of portals, consecutive ones sharing a region
    r = int(rng.integers(0, tl.n_regions))
    chain, regs = [], [r]
    for _ in range(int(rng.integers(1, 8))):
        inc = np.nonzero((E[:, 0] == r) | (E[:, 1] == r))[0]
        inc = inc[~np.isin(np.where(E[inc, 0] == r, E[inc, 1], E[inc, 0]), regs)]  # self-avoiding
        if inc.shape[0] == 0:
            break
        k = int(rng.choice(inc))
        r = int(E[k, 0] if E[k, 1] == r else E[k, 1])
        chain.append(k)
        regs.append(r)
    if not chain:
        return
    R = tl.regions  # start / goal: random points of the first / last region (boundary coordinates)
    s = np.array([rng.uniform(R[regs[0], 1], R[regs[0], 3]), rng.uniform(R[regs[0], 0], R[regs[0], 2])])
    g = np.array([rng.uniform(R[regs[-1], 1], R[regs[-1], 3]), rng.uniform(R[regs[-1], 0], R[regs[-1], 2])])
    boxes = np.ascontiguousarray(planner.portal_boxes[chain])
    f = _fast.corridor_path(s[0], s[1], g[0], g[1], boxes, 200)
    ref = _fast.refine(s[0], s[1], g[0], g[1], boxes, 5000, 1e-12)
    assert np.allclose(f[0], s) and np.allclose(f[-1], g)
    centres = np.vstack([s, (boxes[:, :2] + boxes[:, 2:]) / 2, g])
    assert path_length(f) <= path_length(centres) + 1e-9
    assert path_length(f) <= LENGTH_FACTOR * path_length(ref) + 1e-6
    assert segments_free(free, f[:-1], f[1:]).all()


def test_start_in_overlapping_regions_enters_the_corridor_late():
    """Regression (found by hypothesis): the start cell lies in two overlapping regions and the best route
    leaves from the second; the path must not detour through the first region's portal."""
    free = random_map(22845882, 8, 28, 8, 29)
    tl = build_two_layer(free, 1, resolution=0.05)
    planner = build_planner(tl)
    _check_route(tl, planner, free, (3, 1), (5, 2))
    r = plan_path(planner, np.array([0.075, 0.175]), np.array([0.125, 0.275]))
    ref = astar_length(free, (3, 1), (5, 2))
    assert r.length <= ref * 0.05 + 1e-9  # any-angle: never longer than the 8-connected grid path here


def _shortcut_by_search(regs, ekeys, nr):
    """The reference greedy corridor shortcut: from each kept region jump to the last later region of ``regs``
    adjacent to it (``ekeys`` = sorted ``lo * nr + hi`` keys of the region edges); portal ids, or none."""
    out, i, m = [], 0, len(regs)
    while i < m - 1:
        for j in range(m - 1, i, -1):
            a, b = int(regs[i]), int(regs[j])
            key = min(a, b) * nr + max(a, b)
            k = int(np.searchsorted(ekeys, key))
            if a != b and k < len(ekeys) and ekeys[k] == key:
                out.append(k)
                i = j
                break
        else:  # consecutive regions of a corridor are always adjacent; otherwise no shortcut
            return np.zeros(0, dtype=np.int64)
    return np.array(out, dtype=np.int64)


def test_shortcut_through_the_adjacency_equals_the_search_over_later_regions():
    """``shortcut_corridor_adj`` (used by the query) returns the same portals as the search over later regions on
    random walks over the region graph (walks revisit regions, like trimmed corridors may not, a harder case)."""
    from holoslam.planning import _fast

    tl = build_two_layer(OccupancyGrid.from_free_mask(apartment_free(), 0.05), 1)
    planner = build_planner(tl)
    E = np.ascontiguousarray(tl.region_edges, dtype=np.int64)
    nr = tl.n_regions
    ekeys = E[:, 0] * nr + E[:, 1]
    rptr, rids = planner.region_portal_ptr, planner.region_portal_ids
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(300):
        r = int(rng.integers(nr))
        walk = [r]
        for _ in range(int(rng.integers(1, 40))):
            nbr = rids[rptr[r] : rptr[r + 1]]
            if nbr.shape[0] == 0:
                break
            f = int(nbr[rng.integers(nbr.shape[0])])
            r = int(E[f, 0] + E[f, 1] - r)
            walk.append(r)
        regs = np.array(walk, dtype=np.int64)
        want = _shortcut_by_search(regs, ekeys, nr)
        got = _fast.shortcut_corridor_adj(regs, rptr, rids, E, nr)
        assert np.array_equal(got, want), walk
        checked += regs.shape[0] > 2
    assert checked > 100


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**31 - 1), st.integers(1, 70), st.integers(1, 70), st.integers(0, 4), st.integers(0, 12)
)
def test_clearance_is_the_chessboard_distance_to_the_nearest_blocked_cell(seed, h, w, n_rect, n_dots):
    """``chessboard_clearance``: L-infinity distance of each free cell to the nearest cell that is not free,
    the outside of the grid counting as blocked (reference: OpenCV's exact chessboard transform)."""
    from holoslam.planning import _fast

    free = random_map(seed, h, w, n_rect, n_dots)
    got = _fast.chessboard_clearance(free)
    ref = cv2.distanceTransform(np.pad(free, 1).astype(np.uint8), cv2.DIST_C, 3)[1:-1, 1:-1]
    assert np.array_equal(got, np.minimum(np.rint(ref), 255).astype(np.uint8))


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**31 - 1),
    st.integers(1, 100),
    st.integers(1, 100),
    st.integers(0, 4),
    st.integers(0, 10),
    st.integers(0, 2**31 - 1),
)
def test_jumping_segment_check_equals_the_exact_one(seed, h, w, n_rect, n_dots, sseed):
    """``seg_free_tiles`` (the query's check: reads the mask as 64-bit tiles of 8 x 8 cells and skips the
    pieces inside the square of free 4 x 4-cell blocks the block clearance proves) gives ``segments_free``'s answer: long
    segments over open maps (where it jumps), endpoints on a quarter-cell lattice and on grid lines,
    axis-parallel segments, points off the grid."""
    from holoslam.planning import _fast

    free = random_map(seed, h, w, n_rect, n_dots)
    bits, full = _fast.tile_bits(free)
    assert np.array_equal(
        full, np.pad(free, ((0, -h % 8), (0, -w % 8))).reshape(-(-h // 8), 8, -(-w // 8), 8).all(axis=(1, 3))
    )
    tclear = _fast.block_clearance(free)
    rng = np.random.default_rng(sseed)
    n = 300
    a = rng.uniform(-1, [w + 1, h + 1], (n, 2))
    b = rng.uniform(-1, [w + 1, h + 1], (n, 2))
    lattice = rng.random(n) < 0.4
    a[lattice], b[lattice] = np.round(a[lattice] * 4) / 4, np.round(b[lattice] * 4) / 4
    flat = rng.random(n) < 0.15
    b[flat, 0] = a[flat, 0]
    wants = segments_free(free, a, b).tolist()
    for (au, av), (bu, bv), want in zip(a.tolist(), b.tolist(), wants, strict=True):
        assert _fast.seg_free_tiles(bits, tclear, h, w, au, av, bu, bv, 1e-9) == want, (au, av, bu, bv)


def test_region_buckets_give_exactly_the_regions_holding_a_point():
    """The query's point location (bucket index, ``_regions_at``) lists, ascending, every region whose closed
    rectangle holds the point, on and off region boundaries (brute force over all regions as reference)."""
    from holoslam.planning import _fast
    from holoslam.planning.routes import region_buckets

    free = apartment_free()
    tl = build_two_layer(OccupancyGrid.from_free_mask(free, 0.05), 1)
    R = tl.regions
    ptr, ids, grid = region_buckets(R, tl.shape)
    rng = np.random.default_rng(5)
    h, w = tl.shape
    pts = np.vstack(
        [
            rng.uniform(0, [w, h], (400, 2)),
            np.round(rng.uniform(0, [w, h], (400, 2)) * 2) / 2,  # many on cell and region boundaries
            np.column_stack([R[:, 1], R[:, 0]]),  # region corners
            np.column_stack([R[:, 3], R[:, 2]]),
        ]
    )
    out = np.empty(max(int(grid[2]), 1), dtype=np.int64)
    hits = 0
    for u, v in pts.tolist():
        k = _fast._regions_at(R, ptr, ids, int(grid[0]), int(grid[1]), u, v, out)
        want = np.nonzero((R[:, 1] <= u) & (u <= R[:, 3]) & (R[:, 0] <= v) & (v <= R[:, 2]))[0]
        assert out[:k].tolist() == want.tolist(), (u, v)
        hits += k > 1
    assert hits > 50  # overlapping regions and shared boundaries were exercised


def test_box_interval_with_fewer_atan2_equals_the_exact_one():
    """The funnel's ``_box_interval`` (atan2 only for the corners near the extremes) returns exactly what
    ``_box_interval_exact`` (atan2 for every corner) returns, on lattice points and boxes (many corners on
    one ray from the point: the tie rule), off-lattice points, degenerate boxes and points on box edges."""
    from holoslam.planning import _fast

    rng = np.random.default_rng(11)
    fast_cases = 0
    for _ in range(20000):
        u0, v0 = rng.integers(0, 12, 2) / rng.choice([1, 2])
        u1, v1 = u0 + rng.integers(0, 6) / rng.choice([1, 2]), v0 + rng.integers(0, 6) / rng.choice([1, 2])
        box = np.array([[u0, v0, u1, v1]])
        if rng.random() < 0.6:
            a = rng.integers(-4, 20, 2) / rng.choice([1, 2])
        else:
            a = rng.uniform(-4, 20, 2)
        ax, ay = float(a[0]), float(a[1])
        got = _fast._box_interval(ax, ay, box, 0)
        assert got == _fast._box_interval_exact(ax, ay, box, 0), (box, ax, ay)
        cx, cy = (u0 + u1) / 2 - ax, (v0 + v1) / 2 - ay
        corners = [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
        fast_cases += not got[-1] and all(cx * (x - ax) + cy * (y - ay) > 0 for x, y in corners)
    assert fast_cases > 5000  # the shortcut path was exercised


def _goal_distances_and_bounds(planner, gu, gv):
    """For a goal point (u, v): every port's exact distance to the goal over the search's graph (ports joined
    when they share a region, the goal joined to the ports of every region holding it) and the search's
    unweighted heuristic (Euclidean and landmark bounds, ``astar._goal_distances``, ``astar._alt``), with the
    number of regions holding the goal."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from holoslam.planning._fast import astar, queries
    from holoslam.planning.routes import _query_arrays

    graph, links, locate, _ = _query_arrays(planner)
    rp_ptr, rp_id, _, node, ea, eb = graph
    cuv, _, pp, pslot, rptr, rids, _, _ = links
    regions, bptr, bids, bgrid = locate
    gr = np.empty(max(int(bgrid[2]), 1), dtype=np.int64)
    ng = queries._regions_at(regions, bptr, bids, int(bgrid[0]), int(bgrid[1]), gu, gv, gr)
    gr = gr[:ng]
    last = queries._ports_of(gr, rptr, rids, pp, pslot)
    n = node.shape[0]
    w = {}
    for r in range(rp_ptr.shape[0] - 1):
        ids = rp_id[rp_ptr[r] : rp_ptr[r + 1]].tolist()
        for a in ids:
            for b in ids:
                if a != b:
                    w[a, b] = max(float(np.hypot(*(cuv[a] - cuv[b]))), 1e-12)
    for p in last.tolist():
        w[p, n] = w[n, p] = max(float(np.hypot(cuv[p, 0] - gu, cuv[p, 1] - gv)), 1e-12)
    k = np.array(list(w), dtype=np.int64).reshape(-1, 2)
    d = dijkstra(coo_matrix((list(w.values()), (k[:, 0], k[:, 1])), shape=(n + 1, n + 1)).tocsr(), indices=n)[
        :n
    ]
    dgoal = astar._goal_distances(node, last, ea, eb, gr, gu, gv, node.shape[1] - 2)
    h = np.array(
        [astar._alt(node, dgoal, v, float(np.hypot(cuv[v, 0] - gu, cuv[v, 1] - gv))) for v in range(n)]
    )
    return d, h, ng


def test_landmark_bounds_stay_below_the_distance_to_the_goal():
    """Regression (found by hypothesis, hidden by derandomize): the goal lies in two overlapping regions that
    the region graph joins only through others (adjacency comes from the regions' blocks), so through the
    goal two ports are nearer than over the port graph, and the landmark bound d(l, v) - d(l, goal) exceeded
    the distance to the goal (by up to 19 cells on this map): the weighted search returned a corridor 2x
    the optimum and a path 1.6x the A* length. The heuristic is now below the exact distance at every port,
    here and for goals held by several regions of the flat."""
    free = random_map(38, 14, 48, 7, 23)
    tl = build_two_layer(free, 1, resolution=0.05)
    planner = build_planner(tl)
    _check_route(tl, planner, free, (1, 1), (9, 19))
    d, h, ng = _goal_distances_and_bounds(planner, 19.5, 9.5)
    assert ng == 2
    reach = np.isfinite(d)
    assert np.all(h[reach] <= d[reach] * (1 + 1e-6) + 1e-4), float(np.max(h[reach] - d[reach]))
    flat = build_two_layer(OccupancyGrid.from_free_mask(apartment_free(), 0.05), 1)
    fp = build_planner(flat)
    R = flat.regions
    rng = np.random.default_rng(4)
    shared = 0
    for _ in range(400):
        r = int(rng.integers(flat.n_regions))
        u, v = rng.uniform(R[r, 1], R[r, 3]), rng.uniform(R[r, 0], R[r, 2])
        if ((R[:, 1] <= u) & (u <= R[:, 3]) & (R[:, 0] <= v) & (v <= R[:, 2])).sum() < 2:
            continue
        d, h, ng = _goal_distances_and_bounds(fp, u, v)
        reach = np.isfinite(d)
        assert np.all(h[reach] <= d[reach] * (1 + 1e-6) + 1e-4), (u, v, float(np.max(h[reach] - d[reach])))
        shared += 1
        if shared == 20:
            break
    assert shared == 20
