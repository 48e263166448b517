"""GraphML / JSON node-link and planning.json round trips (lossless, attribute by attribute)."""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_maps import apartment_free, random_map

from holoslam.errors import MapError
from holoslam.io.graphs import (
    decode_value,
    encode_value,
    read_graphml,
    read_node_link_json,
    write_graph_files,
    write_graphml,
    write_node_link_json,
)
from holoslam.io.planning import read_planning, write_planning
from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.holographic import ObjectInfo, build_holographic
from holoslam.maps.topology import topology_from_grid
from holoslam.planning.routes import plan_path
from holoslam.planning.twolayer import build_two_layer


def same_value(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
        )
    if isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b):
        return True
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return (
            type(a) is type(b)
            and len(a) == len(b)
            and all(same_value(x, y) for x, y in zip(a, b, strict=False))
        )
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_value(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


def assert_same_graph(G, H) -> None:
    assert type(G) is type(H)
    assert same_value(dict(G.graph), dict(H.graph)), (G.graph, H.graph)
    assert set(G.nodes) == set(H.nodes)
    for n in G.nodes:
        assert [type(x) for x in (n,)] == [type(m) for m in H.nodes if m == n][:1]
        assert same_value(dict(G.nodes[n]), dict(H.nodes[n])), n
    ge = list(G.edges(keys=True)) if G.is_multigraph() else list(G.edges())
    assert G.number_of_edges() == H.number_of_edges()
    for e in ge:
        assert H.has_edge(*e), e
        assert same_value(dict(G.edges[e]), dict(H.edges[e])), e


@pytest.fixture(scope="module")
def graphs():
    grid = OccupancyGrid.from_free_mask(apartment_free(0.05), 0.05)
    topo = topology_from_grid(grid)
    objs = [
        ObjectInfo(
            "CUP-1",
            "cup",
            np.array([3.0, 0.8, 0.8]),
            np.diag([1e-4, 2e-4, np.nan]),
            (("g", "handle"),),
            "HL1;CUP-1;cup;g=handle",
            {"size_m": 0.1, "n_keypoints": 42},
        ),
        ObjectInfo("AC-1", "air_conditioner", np.array([0.3, 8.0, 3.2])),
    ]
    holo = build_holographic(grid, topo, np.array([[1.0, 1.0, 0.3], [6.0, 7.0, -2.0]]), [4, 9], objs)
    return topo, holo, grid


def test_topology_and_holographic_round_trip(graphs, tmp_path):
    topo, holo, _ = graphs
    assert topo.is_multigraph() and holo.number_of_nodes() > 5
    for G, stem in ((topo, "topology"), (holo, "holographic")):
        gml, js = write_graph_files(G, tmp_path, stem)
        assert gml == tmp_path / f"{stem}.graphml" and js == tmp_path / f"{stem}.json"
        assert sorted(p.name for p in tmp_path.iterdir() if p.stem == stem) == [
            f"{stem}.graphml",
            f"{stem}.json",
        ]
        assert_same_graph(G, read_graphml(gml))
        assert_same_graph(G, read_node_link_json(js))
    # the GraphML holds scalars only: a standard reader sees strings/numbers, and kind/place are plain text
    raw = nx.read_graphml(tmp_path / "holographic.graphml")
    assert raw.nodes["CUP-1"]["kind"] == "object"
    assert all(not isinstance(v, list | dict) for _, d in raw.nodes(data=True) for v in d.values())
    assert {d["kind"] for _, d in raw.nodes(data=True)} == {"environment", "object"}


def test_special_values_round_trip(tmp_path):
    G = nx.MultiGraph(name="x", meta={"a": [1, 2.5]})
    G.add_node(
        3,
        s="json:not really",
        t="str:also",
        f=float("nan"),
        i=np.int64(7),
        b=True,
        arr=np.arange(6).reshape(2, 3),
    )
    G.add_node(5, s="plain", mixed=1)
    G.add_node(8, mixed="one")  # one attribute key, two types
    G.add_edge(3, 5, key=0, w=0.1 + 0.2, none=None, lst=[1, "a", [2.0]], inf=float("inf"))
    G.add_edge(3, 5, key=1, w=1e-300)
    write_graphml(G, tmp_path / "g.graphml")
    write_node_link_json(G, tmp_path / "g.json")
    H1 = read_graphml(tmp_path / "g.graphml")
    H2 = read_node_link_json(tmp_path / "g.json")
    # numpy scalars come back as Python scalars of the same value
    G.nodes[3]["i"] = 7
    for H in (H1, H2):
        assert_same_graph(G, H)
    D = nx.DiGraph()
    D.add_edge(("a", 1), ("b", 2), w=np.array([1.5, np.nan], dtype=np.float32))
    write_graphml(D, tmp_path / "d.graphml")
    assert_same_graph(D, read_graphml(tmp_path / "d.graphml"))


@settings(max_examples=100, deadline=None)
@given(
    st.one_of(
        st.integers(-(2**62), 2**62),
        st.floats(allow_nan=True),
        st.text(),
        st.booleans(),
        st.lists(st.one_of(st.integers(-100, 100), st.text(max_size=5), st.floats(allow_nan=False))),
    )
)
def test_encode_decode_value(v):
    assert same_value(decode_value(encode_value(v)), v)


def test_bad_files_raise_map_error(tmp_path):
    (tmp_path / "bad.graphml").write_text("<graphml><oops")
    with pytest.raises(MapError, match="bad.graphml"):
        read_graphml(tmp_path / "bad.graphml")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(MapError, match="bad.json"):
        read_node_link_json(tmp_path / "bad.json")
    (tmp_path / "x.json").write_text(json.dumps({"nodes": 3}))
    with pytest.raises(MapError):
        read_node_link_json(tmp_path / "x.json")
    with pytest.raises(MapError, match="plain file name"):
        write_graph_files(nx.Graph(), tmp_path, "../escape")
    with pytest.raises(MapError, match="does not exist"):
        write_graph_files(nx.Graph(), tmp_path / "missing", "g")


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 3))
def test_planning_json_round_trip(seed, m):
    import tempfile
    from pathlib import Path

    free = random_map(seed, 37, 23, 6, 10)
    grid = OccupancyGrid.from_free_mask(free, 0.1, origin_x=-1.5, origin_y=2.0)
    tl = build_two_layer(grid, m)
    with tempfile.TemporaryDirectory() as d:
        p = write_planning(tl, Path(d) / "planning.json")
        back = read_planning(p)
    for f in tl.__dataclass_fields__:
        a, b = getattr(tl, f), getattr(back, f)
        if isinstance(a, np.ndarray):
            assert a.shape == b.shape and np.array_equal(a, b), f
        else:
            assert a == b, f


def test_planning_json_queries_and_errors(tmp_path):
    grid = OccupancyGrid.from_free_mask(apartment_free(0.05), 0.05)
    tl = build_two_layer(grid, 1)
    back = read_planning(write_planning(tl, tmp_path / "planning.json"))
    s, g = np.array([1.0, 1.0]), np.array([9.5, 8.5])
    assert np.array_equal(plan_path(tl, s, g).waypoints, plan_path(back, s, g).waypoints)
    d = json.loads((tmp_path / "planning.json").read_text())
    assert d["grid"]["min_block_m"] == pytest.approx(0.05)
    assert d["version"] == 2 and d["layer1"]["count"] == tl.n_blocks and len(d["layer2"]["cells"]) == tl.n_regions
    assert (tmp_path / "planning_layer1.npz").is_file()
    d["format"] = "other"
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(MapError, match="bad.json"):
        read_planning(tmp_path / "bad.json")
    d["format"] = "holoslam-planning"
    d["grid"]["shape"] = [1, 1]  # the blocks now lie outside the grid
    (tmp_path / "bad2.json").write_text(json.dumps(d))
    with pytest.raises(MapError, match="outside the grid"):
        read_planning(tmp_path / "bad2.json")
    (tmp_path / "planning_layer1.npz").unlink()
    with pytest.raises(MapError, match="layer-1 array file"):
        read_planning(tmp_path / "planning.json")
