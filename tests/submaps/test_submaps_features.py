"""Scan features H on synthetic scans of a known room: lines, corners, crossings and points at known places."""

from __future__ import annotations

import math

import numpy as np

from holoslam.sim.world import raycast
from holoslam.submaps._fast import split_pieces
from holoslam.submaps.features import extract_features, scans_features, split_runs, transform_features

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


def _reference_split(pts, tol):
    """Split-and-merge's split step in plain numpy, one run: pieces [start, end), each within tol of its chord."""
    out, stack = [], [(0, pts.shape[0])]
    x, y = pts[:, 0], pts[:, 1]
    while stack:
        a, b = stack.pop()
        if b - a < 3:
            out.append((a, b))
            continue
        chx, chy = x[b - 1] - x[a], y[b - 1] - y[a]
        L = np.hypot(chx, chy)
        sx, sy = x[a:b] - x[a], y[a:b] - y[a]
        dist = np.abs(sx * chy - sy * chx) / L if L > 1e-9 else np.hypot(sx, sy)
        k = int(np.argmax(dist))
        if dist[k] > tol and 0 < k < b - a - 1:
            stack += [(a + k, b), (a, a + k + 1)]
        else:
            out.append((a, b))
    return sorted(out)


def test_compiled_split_gives_the_pieces_of_the_reference_split():
    # the compiled split of every run of a scan at once must cut exactly where the per-run numpy split cuts
    rng = np.random.default_rng(4)
    segs = np.vstack([WALLS, LEG, [[1, 3, 2, 3]], [[0.5, 0.5, 1.5, 1.2], [1.5, 1.2, 2.5, 0.6]]])
    for k in range(30):
        wTs = np.array([rng.uniform(0.5, 4.5), rng.uniform(0.5, 3.5), rng.uniform(-3, 3)])
        pts = scan(wTs, segs, sigma=0.01 * (k % 3), seed=k, beams=int(rng.integers(90, 720)))
        if k % 5 == 0:
            pts = np.round(pts, 2)  # collinear and repeated points: ties in the farthest point
        runs = [ab for ab in split_runs(pts) if rng.random() < 0.8]
        tol = float(rng.choice([0.01, 0.03, 0.1]))
        ps, pe = split_pieces(pts[:, 0].copy(), pts[:, 1].copy(), np.array([a for a, _ in runs], np.int64),
                              np.array([b for _, b in runs], np.int64), tol)
        want = sorted((a + p0, a + p1) for a, b in runs for p0, p1 in _reference_split(pts[a:b], tol))
        assert list(zip(ps.tolist(), pe.tolist(), strict=True)) == want


def test_a_submaps_features_are_its_scans_features_moved_into_its_frame():
    # one compiled call for the scans of a submap gives what each scan's features moved by its pose give, stacked
    rng = np.random.default_rng(7)
    segs = np.vstack([WALLS, LEG, [[1, 3, 2, 3]]])
    poses = [np.array([rng.uniform(1, 4), rng.uniform(1, 3), rng.uniform(-3, 3)]) for _ in range(6)]
    scans = [scan(T, segs, sigma=0.005, seed=k) for k, T in enumerate(poses)]
    aTb = np.array([[0.3 * k, -0.2 * k, 0.1 * k] for k in range(6)])
    got = scans_features(aTb, scans)
    parts = [transform_features(T, extract_features(b)) for T, b in zip(aTb, scans, strict=True)]
    for name in ("segments", "lines", "corners", "crossings", "points"):
        want = np.vstack([getattr(f, name) for f in parts])
        assert getattr(got, name).shape == want.shape and np.allclose(getattr(got, name), want, atol=1e-12)
    assert got.segments.shape[0] >= 6 * 4 and got.points.shape[0] >= 4  # every scan's walls; the leg, 5 of 6 see it
    assert scans_features(np.zeros((0, 3)), []).segments.shape == (0, 4)
