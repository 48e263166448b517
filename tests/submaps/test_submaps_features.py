"""Scan features H on synthetic scans of a known room: lines, corners, crossings and points at known places."""

from __future__ import annotations

import math

import numpy as np

from holoslam.sim.world import raycast
from holoslam.submaps.features import _split, _split_all, extract_features, split_runs, transform_features

# a 5 x 4 m room; a 0.04 m square leg at (3.5, 1.0); a free-standing 1 m wall piece from (1, 3) to (2, 3)
WALLS = np.array([[0, 0, 5, 0], [5, 0, 5, 4], [5, 4, 0, 4], [0, 4, 0, 0]], float)
LEG = np.array([[3.48, 0.98, 3.52, 0.98], [3.52, 0.98, 3.52, 1.02], [3.52, 1.02, 3.48, 1.02],
                [3.48, 1.02, 3.48, 0.98]])
ROOM_CORNERS = np.array([[0, 0], [5, 0], [5, 4], [0, 4]], float)


def scan(wTs, segs, sigma=0.0, seed=0, beams=361):
    ang = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    r = raycast(segs, np.asarray(wTs)[None, :2], (ang + wTs[2])[None], 8.0)[0]
    r = r + np.random.default_rng(seed).normal(0, sigma, r.shape) if sigma else r
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])


def nearest(a, b):
    return np.min(np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]), axis=1)


def test_room_walls_and_corners():
    wTs = np.array([2.2, 1.7, 0.4])
    f = transform_features(wTs, extract_features(scan(wTs, WALLS, sigma=0.005)))
    assert f.segments.shape[0] == 4
    # every fitted line is one of the walls: |n . p - d| small at both wall ends
    for w in WALLS:
        res = np.abs(f.lines[:, :2] @ w[:2] - f.lines[:, 2]) + np.abs(f.lines[:, :2] @ w[2:] - f.lines[:, 2])
        assert res.min() < 0.02
    assert f.corners.shape[0] == 4
    assert np.all(nearest(ROOM_CORNERS, f.corners) < 0.02)


def test_leg_is_a_point_and_occluded_corner_is_a_crossing():
    wTs = np.array([1.0, 0.9, 0.0])
    segs = np.vstack([WALLS, LEG])
    f = transform_features(wTs, extract_features(scan(wTs, segs, beams=720)))  # 0.5 deg beams
    assert f.points.shape[0] == 1 and np.hypot(*(f.points[0] - [3.5, 1.0])) < 0.05
    # with a 1 m wall piece in front of the corner (0, 4) from (0.5, 3.5) the corner is hidden: the extended
    # walls still cross there
    block = np.array([[-0.5, 3.0, 1.0, 4.5]]) * 0 + np.array([[0.05, 3.0, 0.6, 3.95]])
    wTs2 = np.array([3.0, 1.0, 0.0])
    f2 = transform_features(wTs2, extract_features(scan(wTs2, np.vstack([WALLS, block]))))
    assert np.min(nearest(np.array([[0.0, 4.0]]), np.vstack([f2.crossings, f2.corners]))) < 0.05


def test_features_move_with_the_robot():
    # extracting in the scan frame then transforming equals the features of the world (invariance)
    for k, wTs in enumerate([np.array([1.0, 1.0, 0.0]), np.array([4.0, 3.0, 2.5]), np.array([2.5, 2.0, -1.2])]):
        f = transform_features(wTs, extract_features(scan(wTs, WALLS, sigma=0.005, seed=k)))
        # a corner seen at grazing incidence may come out as a crossing of the extended walls instead
        assert np.all(nearest(ROOM_CORNERS, np.vstack([f.corners, f.crossings])) < 0.03)
        assert f.corners.shape[0] >= 3 and np.all(nearest(f.corners, ROOM_CORNERS) < 0.03)  # none spurious


def test_split_runs_cuts_at_gaps():
    pts = np.array([[1, 0], [1, 0.05], [1, 0.1], [2, 1], [2, 1.05]], float)
    assert split_runs(pts) == [(0, 3), (3, 5)]
    assert split_runs(np.zeros((0, 2))) == []


def test_compiled_split_gives_the_pieces_of_the_reference_split():
    # the compiled split of every run of a scan at once must cut exactly where the per-run numpy split cuts
    rng = np.random.default_rng(4)
    segs = np.vstack([WALLS, LEG, [[1, 3, 2, 3]], [[0.5, 0.5, 1.5, 1.2], [1.5, 1.2, 2.5, 0.6]]])
    for k in range(30):
        wTs = np.array([rng.uniform(0.5, 4.5), rng.uniform(0.5, 3.5), rng.uniform(-3, 3)])
        pts = scan(wTs, segs, sigma=0.01 * (k % 3), seed=k, beams=int(rng.integers(90, 720)))
        if k % 5 == 0:
            pts = np.round(pts, 2)  # collinear and repeated points: ties in the farthest point
        runs = split_runs(pts)
        marked = [bool(rng.random() < 0.8) for _ in runs]
        tol = float(rng.choice([0.01, 0.03, 0.1]))
        got = _split_all(pts, runs, marked, tol)
        want = {a: _split(pts[a:b], tol, 0) for (a, b), m in zip(runs, marked, strict=True) if m}
        assert got == want
