"""Objects across sessions (seen / moved / gone / new) and the merged grid (newer sessions win, line of sight)."""

from __future__ import annotations

import numpy as np

from holoslam.lifelong.changes import ChangeConfig, Located, classify, in_view_seconds, to_world
from holoslam.lifelong.merge import merge_submaps, to_occupancy_grid
from holoslam.store.records import ObjectState


def _state(oid, xy, sigma=0.01, status="seen", view=(1.0, 0.0)):
    return ObjectState(oid, "cup", "", status, np.array(xy, float), 0.5, np.eye(2) * sigma**2, 2, f"{oid}#1",
                       view=np.array(view, float))


def _loc(oid, xy, sigma=0.01):
    return Located(oid, np.array(xy, float), np.eye(2) * sigma**2, 0.5, 2, None, "cup", "")


def _robot_line(x0, x1, y, seconds):
    n = int(seconds * 10) + 1
    return (np.arange(n, dtype=np.int64) * 100_000_000, np.column_stack([np.linspace(x0, x1, n), np.full(n, y)]))


def test_statuses():
    stored = {"A": _state("A", (0, 0)), "B": _state("B", (5, 0)), "C": _state("C", (20, 20)),
              "D": _state("D", (9, 9)), "G": _state("G", (1, 1), status="gone"),
              "H": _state("H", (2, 2), status="gone"),
              "E": _state("E", (3, 0), sigma=0.5)}
    located = {"A": _loc("A", (0.02, 0.0)), "B": _loc("B", (5.5, 0.0)), "N": _loc("N", (4, 4)),
               "G": _loc("G", (1, 1)), "E": _loc("E", (3.4, 0.0), sigma=0.5), "H": _loc("H", (2.0, 2.8))}
    t, xy = _robot_line(20.5, 22.0, 20.0, 30.0)  # 30 s on C's seen side, nothing else in view
    out = classify(stored, located, t, xy, None, ChangeConfig())
    # G and H were called gone and are located again: known by their labels, not new
    assert out == {"A": "seen", "B": "moved", "N": "new", "G": "seen", "H": "moved", "E": "seen", "C": "gone"}
    # D (far away) keeps its state: no row
    stored["F"] = _state("F", (23.0, 20.0), view=(-1.0, 0.0))  # a second object in view: C gets half the camera
    t, xy = _robot_line(20.5, 22.0, 20.0, 12.0)
    assert "C" not in classify(stored, located, t, xy, None, ChangeConfig())
    t, xy = _robot_line(20.5, 22.0, 20.0, 24.0)
    assert classify(stored, located, t, xy, None, ChangeConfig())["C"] == "gone"


def test_in_view_needs_time_range_side_and_a_clear_line():
    cfg = ChangeConfig()
    t, xy = _robot_line(0.5, 2.0, 0.0, 20.0)
    assert in_view_seconds(np.zeros(2), np.array([1.0, 0.0]), t, xy, None, cfg) > 15
    assert in_view_seconds(np.zeros(2), np.array([-1.0, 0.0]), t, xy, None, cfg) == 0.0  # its label faces away
    t2, xy2 = _robot_line(5.0, 9.0, 0.0, 20.0)
    assert in_view_seconds(np.zeros(2), None, t2, xy2, None, cfg) == 0.0  # out of range
    prob = np.full((40, 40), 0.1, np.float32)
    prob[:, 19:21] = 0.9  # a wall at x = 1 (cells of 0.05 m from x = 0)
    wall = merge_submaps(np.zeros((1, 3)), [(prob, np.ones_like(prob, bool), (0.0, -1.0), 0.05)], [1])
    assert in_view_seconds(np.array([0.1, 0.0]), None, *_robot_line(1.5, 2.0, 0.0, 20.0), wall, cfg) == 0.0


def test_to_world_propagates_the_session_transform():
    w, c = to_world(np.array([1.0, 0.0]), np.eye(2) * 1e-4, np.array([1.0, 2.0, np.pi / 2]), np.diag([0, 0, 1e-2]))
    np.testing.assert_allclose(w, [1.0, 3.0], atol=1e-12)
    assert c[0, 0] > 1e-2 * 0.99 and c[1, 1] < 2e-4  # the heading's uncertainty moves it sideways (x here)


def test_the_newer_session_wins_in_the_merged_grid():
    occ = np.full((20, 20), 0.9, np.float32)
    free = np.full((20, 20), 0.1, np.float32)
    known = np.ones((20, 20), bool)
    m = merge_submaps(np.zeros((2, 3)), [(occ, known, (0.0, 0.0), 0.05), (free, known, (0.0, 0.0), 0.05)], [2, 1])
    g = to_occupancy_grid(m)
    inner = g.occupancy[m.known]
    assert inner.min() >= 85  # session 2 (occupied) wins over session 1 (free), whatever the order given
    half = known.copy()
    half[:, 10:] = False
    m2 = merge_submaps(np.zeros((2, 3)), [(occ, known, (0.0, 0.0), 0.05), (free, half, (0.0, 0.0), 0.05)], [1, 2])
    r, c = np.nonzero(m2.known)
    x = m2.origin[0] + (c + 0.5) * 0.05
    assert m2.prob[r[x < 0.45], c[x < 0.45]].max() < 0.2 and m2.prob[r[x > 0.55], c[x > 0.55]].min() > 0.8
