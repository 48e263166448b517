"""Skeleton -> topology graph: invariants on random maps, geometry of edges, pruning, GraphML readiness; map
cleaning before thinning (components and cycles of real maps)."""

from pathlib import Path

import cv2
import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from repo_paths import SHARED
from test_thinning import topology

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.thinning import count_removable, thin
from holoslam.maps.topology import (
    clearance_map,
    cycle_rank,
    path_from_string,
    path_to_string,
    prune_spurs,
    skeleton_to_graph,
    to_graphml_ready,
    topology_from_grid,
)

# Random maps: free space with rectangular obstacles of at least 3 x 3 cells (the documented minimum hole
# size: a smaller obstacle right at a crossing can sit inside one junction cluster, see topology.py).
rect = st.tuples(st.integers(0, 40), st.integers(0, 40), st.integers(3, 9), st.integers(3, 9))


def room_map(h, w, rects):
    m = np.ones((h, w), bool)
    for r, c, dh, dw in rects:
        m[r : r + dh, c : c + dw] = False
    return m


@settings(max_examples=120, deadline=None)
@given(st.integers(3, 45), st.integers(3, 45), st.lists(rect, max_size=10))
def test_graph_has_the_topology_of_free_space(h, w, rects):
    m = room_map(h, w, rects)
    sk = thin(m)
    assert count_removable(sk) == 0
    G = skeleton_to_graph(sk, clearance=clearance_map(m))
    comps, holes = topology(m)
    assert nx.number_connected_components(G) == comps
    assert cycle_rank(G) == holes
    # every skeleton cell lies on an edge path or is a node cell
    on = np.zeros_like(sk)
    for _u, _v, d in G.edges(data=True):
        p = d["path"]
        assert (np.abs(np.diff(p, axis=0)).max(axis=1) == 1).all()  # 8-connected steps
        assert sk[p[:, 0], p[:, 1]].all()
        on[p[:, 0], p[:, 1]] = True
    for _n, d in G.nodes(data=True):
        on[d["row"], d["col"]] = True
    junction_cells = sk & ~on
    assert junction_cells.sum() <= 3 * sum(1 for _, k in G.nodes(data="kind") if k == "junction")
    # pruning keeps components and cycles
    prune_spurs(G, 5.0, 2.0)
    assert nx.number_connected_components(G) == comps
    assert cycle_rank(G) == holes


def test_two_corridors_around_a_block_give_parallel_edges():
    m = np.zeros((30, 60), bool)
    m[5:25, 5:55] = True
    m[12:18, 20:40] = False  # a block in the middle: a loop around it
    G = skeleton_to_graph(thin(m), clearance=clearance_map(m), prune_spur_m=3.0, spur_clearance_factor=2.0)
    assert cycle_rank(G) == 1  # the corner spurs are pruned, the two junctions merged away: one loop
    assert [k for _, k in G.nodes(data="kind")] == ["loop"]
    m = np.pad(m, ((0, 0), (30, 30)))
    m[13:17, 0:36] = True  # long corridors to the west and east: the ring now has two junctions
    m[13:17, 84:120] = True
    G = skeleton_to_graph(thin(m), clearance=clearance_map(m), prune_spur_m=3.0, spur_clearance_factor=2.0)
    assert cycle_rank(G) == 1
    junctions = [n for n, k in G.nodes(data="kind") if k == "junction"]
    assert len(junctions) == 2 and G.number_of_nodes() == 4
    assert G.number_of_edges(*junctions) == 2  # two corridors around the block, kept as parallel edges


def test_ring_without_junction_is_one_node_with_a_self_loop():
    m = np.zeros((20, 20), bool)
    m[3:17, 3:17] = True
    m[6:14, 6:14] = False  # a 3-wide ring of free space
    sk = thin(m)
    G = skeleton_to_graph(sk, prune_spur_m=3.0)  # corner tips of the square ring are pruned
    assert G.number_of_nodes() == 1 and G.number_of_edges() == 1
    ((n, kind),) = G.nodes(data="kind")
    assert kind == "loop" and G.has_edge(n, n)
    ((_, _, d),) = G.edges(data=True)
    assert 40 <= len(d["path"]) <= sk.sum() + 2
    # a diamond ring (every cell has two non-touching neighbours) has no junction at all: a 'loop' node
    ring = np.zeros((7, 7), bool)
    ring[1, 3] = ring[2, 2] = ring[2, 4] = ring[3, 1] = ring[3, 5] = ring[4, 2] = ring[4, 4] = ring[5, 3] = (
        True
    )
    G = skeleton_to_graph(ring)
    ((n, kind),) = G.nodes(data="kind")
    ((_, _, d),) = G.edges(data=True)
    assert kind == "loop" and G.has_edge(n, n) and len(d["path"]) == 9
    assert np.array_equal(d["path"][0], d["path"][-1]) and d["length"] == pytest.approx(8 * np.sqrt(2))


def test_lengths_clearance_and_world_coordinates():
    m = np.zeros((11, 41), bool)
    m[3:8, 0:41] = True  # 5-wide corridor along x, open at both ends of the grid
    m[3:8, 0] = m[3:8, 40] = False
    res = 0.1
    G = skeleton_to_graph(
        thin(m),
        resolution=res,
        origin_x=2.0,
        origin_y=-1.0,
        clearance=clearance_map(m, res),
        prune_spur_m=0.35,
    )
    assert G.number_of_edges() == 1  # the forks into the corridor's end corners are pruned
    ((u, v, d),) = G.edges(data=True)
    cols = d["path"][:, 1]
    assert (d["path"][2:-2, 0] == 5).all()  # the middle row
    steps = np.abs(np.diff(d["path"], axis=0)).sum(axis=1)
    assert d["length"] == pytest.approx(((steps == 1).sum() + np.sqrt(2) * (steps == 2).sum()) * res)
    assert d["length"] >= (cols.max() - cols.min()) * res
    assert d["min_clearance"] <= 3 * res + 1e-9  # row 5's centre is 3 cells from the walls (rows 2 and 8)
    assert d["min_clearance"] >= 1 * res - 1e-9
    for n in (u, v):
        nd = G.nodes[n]
        assert nd["kind"] == "endpoint"
        assert nd["x"] == pytest.approx(2.0 + (nd["col"] + 0.5) * res)
        assert nd["y"] == pytest.approx(-1.0 + (nd["row"] + 0.5) * res)
        assert nd["submap"] == -1
    assert d["path_from"] in (u, v)


def test_diagonal_length_and_isolated_cells():
    sk = np.zeros((8, 8), bool)
    for i in range(1, 6):
        sk[i, i] = True
    sk[7, 0] = True
    G = skeleton_to_graph(sk, resolution=0.5)
    kinds = sorted(k for _, k in G.nodes(data="kind"))
    assert kinds == ["endpoint", "endpoint", "isolated"]
    ((_, _, d),) = G.edges(data=True)
    assert d["length"] == pytest.approx(4 * np.sqrt(2) * 0.5)


def test_spur_pruning_removes_short_spur_and_merges_the_junction():
    sk = np.zeros((20, 40), bool)
    sk[10, 2:38] = True  # a long line
    sk[7:10, 20] = True  # a 3-cell spur off its middle
    G = skeleton_to_graph(sk)
    assert G.number_of_nodes() == 4 and G.number_of_edges() == 3
    removed = prune_spurs(G, 5.0)
    assert removed == 1
    assert G.number_of_nodes() == 2 and G.number_of_edges() == 1
    ((_, _, d),) = G.edges(data=True)
    assert len(d["path"]) == 36 and d["length"] == pytest.approx(35.0)
    # the last edge of a component is never pruned
    assert prune_spurs(G, 1000.0) == 0


def test_submap_attribute_is_the_nearest_anchor_and_graphml_ready():
    grid = OccupancyGrid.from_free_mask(room_map(30, 60, [(10, 25, 8, 8)]), 0.1)
    anchors = np.array([[0.0, 0.0, 0.0], [6.0, 3.0, 1.0]])
    G = topology_from_grid(grid, anchors_wTa=anchors)
    for _n, d in G.nodes(data=True):
        want = int(np.argmin(np.hypot(anchors[:, 0] - d["x"], anchors[:, 1] - d["y"])))
        assert d["submap"] == want
        assert d["clearance"] > 0
    H = to_graphml_ready(G)
    for _u, _v, d in H.edges(data=True):
        assert all(isinstance(x, (int, float, str)) for x in d.values())
    for (_u, _v, d), (_a, _b, e) in zip(G.edges(data=True), H.edges(data=True), strict=True):
        assert np.array_equal(path_from_string(e["path"]), d["path"])
    nx.generate_graphml(H)  # accepted by networkx's writer


def test_path_string_round_trip_and_errors():
    p = np.array([[0, 1], [2, 3], [10, 200]])
    assert np.array_equal(path_from_string(path_to_string(p)), p)
    assert path_from_string("").shape == (0, 2)
    with pytest.raises(MapError):
        path_from_string("1,2;x")
    with pytest.raises(MapError):
        skeleton_to_graph(np.zeros(4, bool))
    with pytest.raises(MapError):
        skeleton_to_graph(np.zeros((4, 4), bool), resolution=0.0)


def test_empty_skeleton_gives_empty_graph():
    G = skeleton_to_graph(np.zeros((5, 5), bool))
    assert G.number_of_nodes() == 0 and G.number_of_edges() == 0


# Small obstacles (1 x 1 up to 3 x 3 cells), which can sit right at a crossing inside one junction cluster.
small_rect = st.tuples(st.integers(0, 30), st.integers(0, 30), st.integers(1, 3), st.integers(1, 3))


@settings(max_examples=120, deadline=None)
@given(st.integers(3, 32), st.integers(3, 32), st.lists(small_rect, max_size=14))
def test_holes_of_any_size_give_cycles(h, w, rects):
    m = room_map(h, w, rects)
    sk = thin(m)
    G = skeleton_to_graph(sk)
    comps, holes = topology(m)
    assert nx.number_connected_components(G) == comps
    assert cycle_rank(G) == holes
    for _u, _v, d in G.edges(data=True):
        p = d["path"]
        assert sk[p[:, 0], p[:, 1]].all()
        assert (np.abs(np.diff(p, axis=0)).max(axis=1) == 1).all()


def test_one_cell_obstacle_at_a_crossing_is_a_self_loop_of_the_junction():
    sk = np.zeros((11, 11), bool)
    sk[5, :] = sk[:, 5] = True  # a plus: one crossing
    sk[4:7, 4:7] = True
    sk[5, 5] = False  # a one-cell hole enclosed by the crossing's junction cells
    assert topology(sk) == (1, 1)
    G = skeleton_to_graph(sk)
    assert cycle_rank(G) == 1
    ((n, kind),) = [(n, k) for n, k in G.nodes(data="kind") if k == "junction"]
    (d,) = G.get_edge_data(n, n).values()  # the self-loop
    p = d["path"]
    assert np.array_equal(p[0], p[-1]) and len(p) >= 5
    assert np.abs(p - 5).max(axis=1).tolist() == [1] * len(p)  # on the ring of junction cells around (5, 5)
    steps = np.abs(np.diff(p, axis=0)).sum(axis=1)
    assert d["length"] == pytest.approx((steps == 1).sum() + np.sqrt(2.0) * (steps == 2).sum())
    assert sum(1 for _, k in G.nodes(data="kind") if k == "endpoint") == 4


def test_bulk_graph_equals_networkx_public_build():
    import holoslam.maps.topology as topo

    rng = np.random.default_rng(5)
    n = 30
    u = rng.integers(0, n, 200)
    v = rng.integers(0, n, 200)
    nodes = [{"i": i} for i in range(n)]
    edges = [{"e": e} for e in range(200)]
    G = topo._bulk_multigraph(nodes, u, v, edges)
    H = nx.MultiGraph()
    H.add_nodes_from(enumerate({"i": i} for i in range(n)))
    H.add_edges_from(zip(u.tolist(), v.tolist(), ({"e": e} for e in range(200)), strict=True))
    assert dict(G.nodes(data=True)) == dict(H.nodes(data=True))
    assert sorted(G.edges(keys=True, data="e")) == sorted(H.edges(keys=True, data="e"))
    assert G.adj == H.adj
    G.add_edge(0, 1)  # still an ordinary, mutable MultiGraph
    assert G.number_of_edges() == 201 and G.has_edge(1, 0)


@settings(max_examples=60, deadline=None)
@given(st.integers(3, 40), st.integers(3, 40), st.lists(rect, max_size=8))
def test_lockstep_walk_equals_pointer_jumping(h, w, rects):
    import holoslam.maps.topology as topo

    sk = topo._Skeleton(thin(room_map(h, w, rects)))
    tip2 = topo._TIP2[sk.code]
    is_node = (sk.deg != 2) | tip2
    node_of, _kinds, _rep = topo._nodes(sk, is_node, np.full(sk.flat.shape[0], np.nan), tip2)
    a = topo._trace(sk, is_node, node_of)
    b = topo._trace(sk, is_node, node_of, max_steps=0)  # straight to pointer jumping
    assert (a is None) == (b is None)
    if a is not None:
        for x, y in zip(a, b, strict=True):
            assert np.array_equal(x, y)


def _graph_lists(G):
    def nan(x):  # NaN clearances compare equal
        return "nan" if isinstance(x, float) and x != x else x

    nodes = [(v, sorted((k, nan(x)) for k, x in a.items())) for v, a in G.nodes(data=True)]
    edges = [
        (u, v, k, a["path"].tolist(), a["path_from"], a["length"], nan(a["min_clearance"]))
        for u, v, k, a in G.edges(keys=True, data=True)
    ]
    return nodes, edges, [(v, list(G.adj[v])) for v in G]


def _numpy_graph(*args, **kwargs):
    """skeleton_to_graph on its numpy path (as without numba): the reference of the compiled kernels."""
    from unittest import mock

    from holoslam.maps import topology

    with mock.patch.object(topology, "_kernels", lambda: None):
        return skeleton_to_graph(*args, **kwargs)


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.floats(0.2, 0.8), st.integers(0, 2**31 - 1), st.booleans())
def test_compiled_graph_equals_the_numpy_path(h, w, density, seed, thinned):
    """The numba kernels (_topology_fast) give the numpy path's graph: same node ids and attributes, edges in
    the same order with the same keys, paths, lengths and clearances (random masks as skeletons: junction
    clusters with holes, adjacent node cells, loops without nodes; and thinned random maps)."""
    rng = np.random.default_rng(seed)
    m = rng.random((h, w)) < density
    sk = thin(m) if thinned else m
    clr = clearance_map(m, 0.05) if seed % 2 else None
    fast = skeleton_to_graph(sk, resolution=0.05, clearance=clr)
    ref = _numpy_graph(sk, resolution=0.05, clearance=clr)
    assert _graph_lists(fast) == _graph_lists(ref)


def test_compiled_graph_equals_the_numpy_path_on_rings_and_long_chains():
    """Closed loops without any node cell (promoted to 'loop' nodes) and a chain longer than the numpy path's
    lockstep limit (2048 cells: its pointer-jumping branch)."""
    m = np.zeros((60, 2600), bool)
    m[5, 3:2590] = True  # a 2587-cell line
    k = np.arange(7)
    for r0, c0 in ((20, 20), (40, 60)):  # diamonds of diagonal steps: rings of chain cells only
        m[r0 + k, c0 + k] = m[r0 + k, c0 - k] = m[r0 + 12 - k, c0 + k] = m[r0 + 12 - k, c0 - k] = True
    m[57, 60:80] = True
    G = skeleton_to_graph(m, resolution=0.1)
    assert sorted(nx.get_node_attributes(G, "kind").values()).count("loop") == 2
    assert _graph_lists(G) == _graph_lists(_numpy_graph(m, resolution=0.1))


# ------------------------------------------------------------------------------------------ map cleaning

PUBLIC_MAPS = sorted((SHARED / "maps").glob("*.yaml")) + sorted((SHARED / "rooms").glob("*.yaml"))


def significant(free: np.ndarray, res: float, min_free_m2: float = 0.25, min_obstacle_m2: float = 0.05):
    """(free regions of at least min_free_m2, obstacle islands of at least min_obstacle_m2) as issue 14 counts
    them, with scipy.ndimage: 8-connected free regions; islands = 4-connected components of the non-free
    cells (after dropping the small regions) that do not touch the map's edge."""
    from scipy import ndimage

    lab, n = ndimage.label(free, structure=np.ones((3, 3)))
    area = np.bincount(lab.ravel(), minlength=n + 1) * res * res
    keep = area >= min_free_m2
    keep[0] = False
    kept = keep[lab]
    olab, m = ndimage.label(np.pad(~kept, 1, constant_values=True))  # 4-connected by default
    oarea = np.bincount(olab.ravel(), minlength=m + 1) * res * res
    islands = [k for k in range(1, m + 1) if k != olab[0, 0] and oarea[k] >= min_obstacle_m2]
    return int(keep.sum()), len(islands)


def public_grid(path: Path) -> OccupancyGrid:
    """A public map as ../shared/maps/README.md says to count it: nav2_depot's grey 205 is unknown (its YAML's
    free_thresh 0.25 would make it free)."""
    from holoslam.io.grid import read_grid

    g = read_grid(path)
    if path.stem == "nav2_depot":
        img = cv2.imread(str(path.with_suffix(".pgm")), cv2.IMREAD_UNCHANGED)
        occ = np.flipud(np.where(img >= 254, 0, np.where(img == 205, -1, 100))).astype(np.int8)
        g = OccupancyGrid(occ, g.resolution, g.origin_x, g.origin_y, g.occupied_thresh, g.free_thresh)
    return g


@pytest.mark.skipif(not PUBLIC_MAPS, reason="../shared/maps and ../shared/rooms are not here")
@pytest.mark.parametrize("path", PUBLIC_MAPS, ids=lambda p: p.stem)
def test_cleaned_topology_of_public_maps_has_a_component_per_region_and_a_cycle_per_island(path):
    """Issue 14: with the default cleaning the topology of a real map (Nav2, AWS house, the room-segmentation
    benchmark's floors, plain and furnished) has one component per free region of at least 0.25 m^2 and one
    independent cycle per obstacle island of at least 0.05 m^2; the graph reports the same counts."""
    g = public_grid(path)
    G = topology_from_grid(g)
    regions, islands = significant(g.free, g.resolution)
    assert (nx.number_connected_components(G), cycle_rank(G)) == (regions, islands)
    assert (G.graph["cleaned_free_regions"], G.graph["cleaned_islands"]) == (regions, islands)
    assert G.graph["cleaning_min_free_area_m2"] == 0.25 and G.graph["cleaning_min_obstacle_area_m2"] == 0.05
    raw = topology_from_grid(g, cleaning=None)
    assert raw.number_of_nodes() >= G.number_of_nodes()


@pytest.mark.skipif(not PUBLIC_MAPS, reason="../shared/maps and ../shared/rooms are not here")
@pytest.mark.parametrize("sizes", [(1.0, 0.5), (0.05, 0.01)])
def test_cleaning_sizes_are_settings(sizes):
    """Other minimum sizes give the counts of those sizes (two furnished floors and the depot)."""
    from holoslam.maps.cleaning import MapCleaning

    for stem in ("office_a_furnitures", "lab_c_scan_furnitures", "nav2_depot"):
        path = next(p for p in PUBLIC_MAPS if p.stem == stem)
        g = public_grid(path)
        G = topology_from_grid(g, cleaning=MapCleaning(*sizes))
        expected = significant(g.free, g.resolution, *sizes)
        assert (nx.number_connected_components(G), cycle_rank(G)) == expected, stem


def _cleaning_map():
    """A 4 x 3 m room at 5 cm: a table leg (2 x 2 cells), a box (6 x 6), an unknown pocket (3 x 3) and a large
    unknown patch (8 x 8) inside; a free speck (3 x 3) inside the wall block on the right."""
    occ = np.full((60, 90), 100, dtype=np.int8)
    occ[2:58, 2:70] = 0
    occ[10:12, 10:12] = 100  # leg: 0.01 m^2
    occ[30:36, 20:26] = 100  # box: 0.09 m^2
    occ[15:18, 40:43] = -1  # unknown pocket: 0.0225 m^2
    occ[35:43, 45:53] = -1  # unknown patch: 0.16 m^2
    occ[20:23, 78:81] = 0  # free speck in the wall: 0.0225 m^2
    return OccupancyGrid(occ, 0.05)


def test_cleaning_rules_on_a_small_map():
    from holoslam.maps.cleaning import MapCleaning, clean_free

    g = _cleaning_map()
    free, rep = clean_free(g)
    assert rep.free_regions_dropped == 1 and rep.free_cells_dropped == 9 and not free[20:23, 78:81].any()
    assert rep.islands_filled == 2 and rep.island_cells_filled == 4 + 9 and rep.unknown_islands_filled == 0
    assert free[10:12, 10:12].all() and free[15:18, 40:43].all()
    assert not free[30:36, 20:26].any() and not free[35:43, 45:53].any()
    assert (rep.free_regions, rep.islands) == (1, 2)
    G = topology_from_grid(g)
    assert (nx.number_connected_components(G), cycle_rank(G)) == (1, 2)
    raw = topology_from_grid(g, cleaning=None)
    assert (nx.number_connected_components(raw), cycle_rank(raw)) == (2, 4)
    # unknown islands as free: the large unknown patch is filled too, the box still makes a cycle
    free, rep = clean_free(g, MapCleaning(unknown_islands="free"))
    assert free[35:43, 45:53].all() and rep.unknown_islands_filled == 2 and (rep.islands) == 1
    G = topology_from_grid(g, cleaning=MapCleaning(unknown_islands="free"))
    assert cycle_rank(G) == 1
    # zero sizes: nothing dropped or filled
    free, rep = clean_free(g, MapCleaning(0.0, 0.0))
    assert np.array_equal(free, g.free) and rep.free_regions_dropped == rep.islands_filled == 0


def test_an_island_around_a_free_region_is_never_filled():
    """An obstacle ring around a free room stays (filling it would merge two regions), whatever its size."""
    from holoslam.maps.cleaning import MapCleaning, clean_free

    m = np.zeros((40, 40), bool)
    m[1:39, 1:39] = True
    m[10:30, 10:30] = False
    m[11:29, 11:29] = True  # a room inside a one-cell wall ring of 76 cells (0.19 m^2)
    g = OccupancyGrid.from_free_mask(m, 0.05)
    free, rep = clean_free(g, MapCleaning(min_free_area_m2=0.25, min_obstacle_area_m2=1.0))
    assert np.array_equal(free, m) and rep.islands_filled == 0 and (rep.free_regions, rep.islands) == (2, 1)


def test_cleaning_settings_are_checked_and_recorded():
    from holoslam.maps.cleaning import MapCleaning

    with pytest.raises(MapError, match="min_free_area_m2"):
        MapCleaning(min_free_area_m2=-1.0)
    with pytest.raises(MapError, match="unknown_islands"):
        MapCleaning(unknown_islands="maybe")
    c = MapCleaning(0.5, 0.1, "free")
    assert MapCleaning.from_graph_attrs(c.as_graph_attrs()) == c
    assert MapCleaning.from_graph_attrs({}) is None
    G = topology_from_grid(_cleaning_map(), cleaning=c)
    assert MapCleaning.from_graph_attrs(G.graph) == c
    assert "cleaning_min_free_area_m2" not in topology_from_grid(_cleaning_map(), cleaning=None).graph


cleaning_rect = st.tuples(st.integers(0, 44), st.integers(0, 44), st.integers(1, 8), st.integers(1, 8))


@settings(max_examples=80, deadline=None)
@given(
    st.lists(cleaning_rect, max_size=14),
    st.lists(cleaning_rect, max_size=6),
    st.lists(cleaning_rect, max_size=8),
)
def test_cleaned_topology_counts_significant_regions_and_islands(obstacles, unknown, specks):
    """Random 45 x 45 maps at 5 cm (minimum sizes 100 and 20 cells): obstacles and unknown patches of 1-64
    cells, free specks punched into them; components and cycles are the significant regions and islands."""
    occ = np.zeros((45, 45), np.int8)
    for val, rects in ((100, obstacles), (-1, unknown), (0, specks)):
        for r, c, dh, dw in rects:
            occ[r : r + dh, c : c + dw] = val
    g = OccupancyGrid(occ, 0.05)
    G = topology_from_grid(g)
    assert (nx.number_connected_components(G), cycle_rank(G)) == significant(g.free, 0.05)
