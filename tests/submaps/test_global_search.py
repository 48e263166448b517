"""The global loop search's pieces: the max-pooled grid bounds the fine one, the window is clipped to the submap,
and a scan is found anywhere in a whole submap at any heading (holoslam.submaps.global_search)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.submaps import bnb
from holoslam.submaps.global_search import clip_window, coarse_match, pool_factor, pool_grid


def test_pooled_grid_is_the_block_maximum_with_the_same_origin():
    rng = np.random.default_rng(0)
    p = rng.uniform(0.1, 0.9, (9, 7)).astype(np.float32)
    q = pool_grid(p, 4)
    assert q.shape == (3, 2)
    for r in range(3):
        for c in range(2):
            assert q[r, c] == p[4 * r:4 * r + 4, 4 * c:4 * c + 4].max()
    assert pool_grid(p, 1) is p or np.array_equal(pool_grid(p, 1), p)


def test_coarse_cells_are_never_smaller_than_asked():
    """The coarse search's thresholds were measured on 20 cm cells: a grid whose cell does not divide that pools
    to the next larger coarse cell, never a smaller one; 5 cm pools 4 to a side despite 0.2 / 0.05 > 4 in floats."""
    assert pool_factor(0.2, 0.05) == 4
    assert pool_factor(0.2, 0.0817) == 3  # 24.5 cm, not 2 (16.3 cm)
    assert pool_factor(0.2, 0.1) == 2 and pool_factor(0.2, 0.3) == 1
    assert pool_factor(0.0, 0.05) == 1 and pool_factor(0.2, 0.0) == 1  # off, or a degenerate grid
    for res in np.linspace(0.02, 0.25, 47):
        f = pool_factor(0.2, float(res))
        assert f * res >= 0.2 - 1e-9 and (f == 1 or (f - 1) * res < 0.2 - 1e-9)


def test_window_clipped_to_the_grid_or_none_when_it_misses():
    centre, wx, wy = clip_window(np.array([1.0, 1.0, 0.3]), 50.0, 50.0, (-2.0, -1.0), (40, 100), 0.1)
    # the grid spans x in [-2, 8], y in [-1, 3]: the whole grid
    assert centre == pytest.approx([3.0, 1.0, 0.3]) and (wx, wy) == pytest.approx((5.0, 2.0))
    assert clip_window(np.array([20.0, 0.0, 0.0]), 5.0, 5.0, (-2.0, -1.0), (40, 100), 0.1) is None


def _room(res: float = 0.05):
    """An L-shaped room's walls on a 12 x 8 m grid (no symmetry: one pose fits)."""
    H, W = int(8 / res), int(12 / res)
    p = np.full((H, W), 0.1, np.float32)
    p[int(1 / res), int(1 / res):int(11 / res)] = 0.9
    p[int(7 / res), int(1 / res):int(6 / res)] = 0.9
    p[int(4 / res), int(6 / res):int(11 / res)] = 0.9
    p[int(1 / res):int(7 / res), int(1 / res)] = 0.9
    p[int(4 / res):int(7 / res), int(6 / res)] = 0.9
    p[int(1 / res):int(4 / res), int(11 / res)] = 0.9
    return p


def _room_scan(aTb: np.ndarray, res: float):
    """The L-shaped room's grid and every third of its wall cells seen from pose ``aTb`` (base frame points)."""
    prob = _room(res)
    occ = np.argwhere(prob > 0.5)
    wall = np.column_stack([(occ[:, 1] + 0.5) * res, (occ[:, 0] + 0.5) * res])
    return prob, g.transform_points(g.inverse(aTb), wall[::3])


def test_a_scan_is_found_anywhere_in_the_whole_submap_at_any_heading():
    res = 0.05
    aTb = np.array([4.0, 3.0, math.radians(137.0)])
    prob, b_pts = _room_scan(aTb, res)
    pre = bnb.precompute(pool_grid(prob, 4), 7, origin=(0.0, 0.0), res=4 * res)
    centre, wx, wy = clip_window(np.array([0.0, 0.0, 0.0]), 100.0, 100.0, (0.0, 0.0), pre.shape, pre.res)
    hit = coarse_match(pre, b_pts, centre, wx, wy, math.pi, 0.6, 15.0)
    assert hit is not None
    assert np.hypot(*(hit.aTb[:2] - aTb[:2])) < 2 * 4 * res
    assert abs(g.wrap(hit.aTb[2] - aTb[2])) < math.radians(2.0)


def test_a_corridor_match_keeps_its_uncertainty_along_the_corridor():
    """A corridor's scan fixes the position across it and the heading, not the position along it: the global
    search's match is kept (not rejected) with a covariance whose spread lies along the corridor."""
    from holoslam.submaps.loops import LoopConfig, LoopSearch
    from holoslam.submaps.probgrid import ProbGrid
    from holoslam.submaps.scanmatch import MatchConfig

    res = 0.05
    # a 40 m corridor 2 m wide along x: a wall at y = 1, a row of cupboards (0.5 m every 1 m) at y = 3, so that
    # a scan tells the corridor's two directions apart but not where along it it was taken (to 1 m)
    H, W = int(4 / res), int(40 / res)
    prob = np.full((H, W), 0.1, np.float32)
    prob[int(1 / res), :] = 0.9
    dashed = (np.arange(W) * res) % 1.0 < 0.5
    prob[int(3 / res), dashed] = 0.9
    ls = LoopSearch(LoopConfig(), MatchConfig())
    ls.add_submap(0, ProbGrid(prob, (0.0, 0.0), res))
    xs = np.arange(0.0, 40.0, 0.05)
    xd = xs[(xs % 1.0) < 0.5]
    wall = np.vstack([np.column_stack([xs, np.full_like(xs, 1.025)]), np.column_stack([xd, np.full_like(xd, 3.025)])])
    mTr = np.array([20.0, 2.0, 0.2])
    near = wall[np.hypot(*(wall - mTr[:2]).T) < 6.0]  # what a laser at the node sees: 6 m of either wall
    b_pts = g.transform_points(g.inverse(mTr), near)
    cand, reasons = ls._global(ls._coarse(0), ls._precomputed(0), 0, 5, np.zeros(3), np.diag([1e-6, 1e-6, 1e-8]),
                               b_pts, b_pts, np.array([15.0, 2.5, 0.0]), 30.0, 30.0)
    assert cand is not None, reasons
    assert "global: ambiguous, kept with the peaks' spread" in reasons
    # across the corridor and in heading the match is right and sure; along it, it is as unsure as it is wrong
    mTn = cand.mTn  # nTr = identity: the node is the anchor
    assert abs(mTn[1] - 2.0) < 0.1 and abs(g.wrap(mTn[2] - 0.2)) < math.radians(1.0)
    R = g.rot2(mTn[2])
    cov_m = R @ cand.cov_mTn[:2, :2] @ R.T  # in the submap's (the corridor's) axes
    # measured: 0.82 m along (the cupboards' 1 m period, peaks within the +-1 m fine window), 0.014 m across
    assert math.sqrt(cov_m[0, 0]) > 20 * math.sqrt(cov_m[1, 1])
    assert 0.4 < math.sqrt(cov_m[0, 0]) < 1.6


def test_the_submaps_a_waiting_closure_predicts_are_searched_first():
    from holoslam.submaps.loop_config import LoopConfig
    from holoslam.submaps.loops import LoopCandidate, LoopSearch
    from holoslam.submaps.scanmatch import MatchConfig

    loops = LoopSearch(LoopConfig(), MatchConfig())
    # old anchors along a corridor every 10 m; the new part (anchors 5, 6) was carried: its estimate is 100 m off
    est = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0], [40, 0, 0],
                    [100, 50, 1.0], [0, 0, 0]], np.float64)
    est[6] = g.compose(est[5], np.array([2.0, 0.0, 0.0]))  # 2 m on, straight ahead
    loops.grids = {m: None for m in range(5)}
    assert loops._hypothesis_distances(est, est[6]) == {}  # nothing waits: the round-robin order alone
    # a waiting closure says anchor 5 stands at (21, 0, 0), facing along the corridor
    mTn = g.between(est[2], np.array([21.0, 0.0, 0.0]))
    loops.consistency.pending.append(LoopCandidate(2, 5, mTn, np.eye(3) * 1e-4, 0.7, 1e5, 10.0))
    near = loops._hypothesis_distances(est, est[6])  # the node 2 m on from anchor 5: (23, 0) by that closure
    assert sorted(near, key=near.get) == [2, 3, 1]  # within 15 m, nearest first
    assert near[2] == pytest.approx(3.0, abs=1e-6)
    assert 0 not in near and 4 not in near  # 23 m and 17 m away


def test_a_global_match_turned_beyond_the_heading_window_is_dropped():
    """The global search tries every heading, but a node that has not lost track cannot have turned further than
    its window allows: the right pose, 137 deg from a seed whose window says +-40 deg, is not a closure; with
    every heading allowed (after a break) it is."""
    from holoslam.submaps.loops import LoopConfig, LoopSearch
    from holoslam.submaps.probgrid import ProbGrid
    from holoslam.submaps.scanmatch import MatchConfig

    res = 0.05
    mTr = np.array([4.0, 3.0, math.radians(137.0)])
    prob, b_pts = _room_scan(mTr, res)
    ls = LoopSearch(LoopConfig(), MatchConfig())
    ls.add_submap(0, ProbGrid(prob, (0.0, 0.0), res))
    seed = np.array([5.0, 3.5, 0.0])
    args = (ls._coarse(0), ls._precomputed(0), 0, 5, np.zeros(3), np.diag([1e-6, 1e-6, 1e-8]), b_pts, b_pts, seed,
            3.0, 3.0)
    cand, reasons = ls._global(*args, math.radians(40.0))
    assert cand is None and reasons[-1] == "global: turned beyond the heading window"
    cand, reasons = ls._global(*args, math.pi)
    assert cand is not None, reasons
    assert np.hypot(*(cand.mTn[:2] - mTr[:2])) < 0.1 and abs(g.wrap(cand.mTn[2] - mTr[2])) < math.radians(1.0)
    gated = LoopSearch(LoopConfig(global_within_heading_window=False), MatchConfig())
    gated.add_submap(0, ProbGrid(prob, (0.0, 0.0), res))
    assert gated._global(gated._coarse(0), gated._precomputed(0), *args[2:], math.radians(40.0))[0] is not None


def test_a_global_match_far_beyond_the_position_window_is_dropped():
    """The global search covers the whole old submap, but a match must lie within ``global_window_ratio`` times the
    window of the seed: the right pose, 3 m from a seed (x) whose window says +-1 m (3x), is not a closure; with a
    window of +-2.5 m (1.2x) it is. In a building of identical corridors and rooms the aliases lay 3-11x their window
    away."""
    from holoslam.submaps.loops import LoopConfig, LoopSearch
    from holoslam.submaps.probgrid import ProbGrid
    from holoslam.submaps.scanmatch import MatchConfig

    res = 0.05
    mTr = np.array([4.0, 3.0, math.radians(20.0)])
    prob, b_pts = _room_scan(mTr, res)
    ls = LoopSearch(LoopConfig(), MatchConfig())
    ls.add_submap(0, ProbGrid(prob, (0.0, 0.0), res))
    seed = np.array([1.0, 2.0, math.radians(20.0)])  # 3.0 m off in x, 1.0 m in y
    head = (ls._coarse(0), ls._precomputed(0), 0, 5, np.zeros(3), np.diag([1e-6, 1e-6, 1e-8]), b_pts, b_pts, seed)
    cand, reasons = ls._global(*head, 1.0, 1.0, math.radians(30.0))
    assert cand is None and reasons[-1] in ("global: beyond the window", "global: ambiguous beyond the window")
    cand, reasons = ls._global(*head, 2.5, 2.5, math.radians(30.0))
    assert cand is not None, reasons
    assert np.hypot(*(cand.mTn[:2] - mTr[:2])) < 0.1
