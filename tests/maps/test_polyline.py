"""Compact written paths (holoslam.maps.polyline) and the robot-sized spur rule of the topology (issue 26)."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.polyline import compact_paths, douglas_peucker, simplify_path


def _seg_dist(p, a, b):
    d = b - a
    t = np.clip(((p - a) @ d) / max(float(d @ d), 1e-12), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * d - p).T)


def test_straight_and_bent_paths_keep_their_corners_only():
    line = np.column_stack([np.zeros(100, int), np.arange(100)])
    assert douglas_peucker(line, 1.0).tolist() == [0, 99]
    ell = np.concatenate([line, np.column_stack([np.arange(1, 50), np.full(49, 99)])])
    assert douglas_peucker(ell, 1.0).tolist() == [0, 99, 148]
    loop = np.array([[0, 0], [0, 5], [5, 5], [5, 0], [0, 0]])  # closed: both ends the same cell
    assert douglas_peucker(loop, 1.0).tolist() == [0, 1, 2, 3, 4] or len(douglas_peucker(loop, 1.0)) >= 3


@pytest.mark.parametrize("seed", range(5))
def test_every_dropped_point_lies_within_the_tolerance(seed):
    rng = np.random.default_rng(seed)
    steps = rng.integers(-1, 2, size=(400, 2))
    p = np.cumsum(steps, axis=0)
    keep = douglas_peucker(p, 1.0)
    assert keep[0] == 0 and keep[-1] == len(p) - 1 and np.all(np.diff(keep) > 0)
    assert len(keep) < len(p)
    for a, b in zip(keep[:-1], keep[1:], strict=True):
        inner = p[a + 1 : b].astype(float)
        if inner.size:
            assert _seg_dist(inner, p[a].astype(float), p[b].astype(float)).max() <= 1.0 + 1e-9


def test_compact_paths_copies_and_records_the_tolerance():
    G = nx.MultiGraph(resolution=0.05)
    path = np.column_stack([np.full(50, 3), np.arange(50)])
    G.add_edge(0, 1, path=path, length=2.45, passage=(path * 0.05).astype(float))
    H = compact_paths(G)
    d = next(iter(H.edges(data=True)))[2]
    assert d["path"].shape == (2, 2) and d["passage"].shape == (2, 2) and d["length"] == 2.45
    assert G.edges[0, 1, 0]["path"].shape == (50, 2)  # the graph itself is not changed
    assert H.graph["path_tolerance_m"] == pytest.approx(0.05)
    assert simplify_path(path[:2], 1.0).shape == (2, 2)


def test_spurs_shorter_than_the_robot_are_pruned_and_counted():
    import networkx as nx

    from holoslam.maps.settings import TopologyConfig
    from holoslam.maps.topology import cycle_rank, topology_from_settings

    free = np.zeros((80, 120), dtype=bool)
    free[30:46, 5:115] = True  # a corridor 0.8 m wide, 5.5 m long
    for c in range(15, 110, 12):  # notches in its wall, 0.3 m deep, and one alcove 1.0 m deep
        free[46:52, c : c + 4] = True
    free[46:66, 60:70] = True
    grid = OccupancyGrid.from_free_mask(free, 0.05)
    small = topology_from_settings(grid, TopologyConfig(), robot_radius_m=0.05)
    robot = topology_from_settings(grid, TopologyConfig(), robot_radius_m=0.26)
    assert robot.graph["spur_beyond_clearance_m"] == pytest.approx(0.52)
    # the notches: 0.69 m branches from junctions of clearance 0.41 m (0.28 m beyond it) are pruned, and the
    # corridor's own short ends; left: a corridor (ending in its outermost notches) and the 1 m alcove
    assert small.graph["spurs_pruned"] == 10 and robot.graph["spurs_pruned"] == 17
    ends = sorted((d["row"], d["col"]) for n, d in robot.nodes(data=True) if d["kind"] == "endpoint")
    assert len(ends) == 3 and ends[-1] == (65, 60)
    assert len([d for _n, d in small.nodes(data=True) if d["kind"] == "endpoint"]) == 10
    for G in (small, robot):
        assert nx.number_connected_components(G) == 1 and cycle_rank(G) == 0
