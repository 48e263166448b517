"""Submap probability grids (holoslam.submaps.probgrid): insertion raises returns and lowers the cells a beam
crosses, unknown cells read p_min, growth keeps the lattice, freeze crops to the known cells."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam.sim.world import raycast
from holoslam.submaps.probgrid import GridBuilder, GridConfig, ProbGrid, scan_endpoints

CFG = GridConfig()
# a 4 x 3 m room whose walls run through cell centres (x = 0.025, 4.025; y = 0.025, 3.025), so every return
# lies in one cell whatever the rounding
ROOM = np.array([[0, 0, 4, 0], [4, 0, 4, 3], [4, 3, 0, 3], [0, 3, 0, 0]], float) + 0.025


def at(prob: np.ndarray, origin, res: float, x: float, y: float) -> float:
    """The value of the cell holding (x, y); p_min off the grid."""
    c = int(math.floor((x - origin[0]) / res))
    r = int(math.floor((y - origin[1]) / res))
    if 0 <= r < prob.shape[0] and 0 <= c < prob.shape[1]:
        return float(prob[r, c])
    return CFG.p_min


def room_scan(wTs, beams: int = 360):
    ang = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    r = raycast(ROOM, np.asarray(wTs, float)[None, :2], (ang + wTs[2])[None], 10.0)[0]
    return r, ang


def test_single_beam_return_above_half_beam_below_half_unknown_at_p_min():
    b = GridBuilder(CFG)
    b.insert(np.array([2.0]), np.array([0.0]), np.array([0.0, 0.0, 0.0]))
    res, o = b.res, b.origin
    assert at(b.prob, o, res, 2.01, 0.01) == pytest.approx(CFG.hit_probability)  # the return: > 0.5
    for x in (0.01, 0.5, 1.0, 1.5, 1.96):  # every cell the beam crosses before it
        assert at(b.prob, o, res, x, 0.01) == pytest.approx(CFG.miss_probability)  # < 0.5
    # everything else was never seen: p_min, and not "known"
    assert at(b.prob, o, res, 1.0, 0.5) == pytest.approx(CFG.p_min)
    assert at(b.prob, o, res, -1.0, 0.01) == pytest.approx(CFG.p_min)
    assert at(b.prob, o, res, 2.1, 0.01) == pytest.approx(CFG.p_min)  # behind the return
    assert b.known.sum() == 41
    np.testing.assert_allclose(np.unique(b.prob), [CFG.p_min, CFG.miss_probability, CFG.hit_probability], rtol=1e-6)
    assert b.count == 1


def test_repeated_scans_saturate_at_the_clamps_and_returns_are_not_cleared_by_their_own_scan():
    b = GridBuilder(CFG)
    r, ang = room_scan(np.array([2.0, 1.5, 0.3]))
    for _ in range(60):
        b.insert(r, ang, np.array([2.0, 1.5, 0.3]))
    res, o = b.res, b.origin
    # walls at x = 0 and x = 4 (cells just inside the room hold the returns), interior free
    assert at(b.prob, o, res, 4.025, 1.5) == pytest.approx(CFG.p_max, abs=1e-6)
    assert at(b.prob, o, res, 0.025, 1.5) == pytest.approx(CFG.p_max, abs=1e-6)
    assert at(b.prob, o, res, 2.5, 1.0) == pytest.approx(CFG.p_min, abs=1e-6)  # free after 60 misses
    assert b.known[int((1.0 - o[1]) / res), int((2.5 - o[0]) / res)] == 1  # free: known, at p_min
    # behind the walls nothing was ever seen: unknown, at p_min
    for x, y in ((-0.5, 1.5), (4.5, 1.5), (2.0, -0.5), (2.0, 3.5)):
        assert at(b.prob, o, res, x, y) == pytest.approx(CFG.p_min)
        assert b.known[int((y - o[1]) / res), int((x - o[0]) / res)] == 0
    assert b.prob.min() >= CFG.p_min - 1e-7 and b.prob.max() <= CFG.p_max + 1e-7
    # each cell is updated once per scan: a wall cell that other beams cross at a grazing angle stays a wall
    wall = np.array([[x, 0.025] for x in np.arange(0.3, 3.7, 0.1)] + [[x, 3.025] for x in np.arange(0.3, 3.7, 0.1)])
    vals = np.array([at(b.prob, o, res, x, y) for x, y in wall])
    assert (vals > 0.5).mean() > 0.9, vals


def test_beams_without_return_clear_missing_ray_length_and_far_returns_are_not_hits():
    cfg = GridConfig(max_range=3.0, missing_ray_length=1.0)
    ranges = np.array([np.inf, 3.5, 2.0, np.nan, 0.0])
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, 0.3])
    ex, ey, hit = scan_endpoints(ranges, angles, np.zeros(3), cfg)
    np.testing.assert_array_equal(hit, [False, False, True, False, False])
    np.testing.assert_allclose(np.hypot(ex, ey), [1.0, 1.0, 2.0, 1.0, 1.0])
    b = GridBuilder(cfg)
    b.insert(ranges, angles, np.zeros(3))
    res, o = b.res, b.origin
    assert at(b.prob, o, res, 0.5, 0.01) == pytest.approx(cfg.miss_probability)
    assert at(b.prob, o, res, 1.2, 0.01) == pytest.approx(cfg.p_min)  # cleared only 1 m, no return there
    assert at(b.prob, o, res, 0.01, 3.49) == pytest.approx(cfg.p_min)  # beyond max_range: not a hit
    assert at(b.prob, o, res, -1.99, 0.01) == pytest.approx(cfg.hit_probability)


def test_growth_keeps_every_existing_cell_in_place():
    b = GridBuilder(GridConfig(grow_margin=0.5))
    r, ang = room_scan(np.array([1.0, 1.0, 0.0]))
    b.insert(r, ang, np.array([1.0, 1.0, 0.0]))
    o0, p0, k0 = b.origin, b.prob.copy(), b.known.copy()
    # a scan from 20 m away (a long corridor): the grid must grow down-left and up-right
    far = np.array([25.0, 20.0, 0.0])
    b.insert(np.array([0.5, 0.5, 0.5, 0.5]), np.array([0.0, math.pi / 2, math.pi, -math.pi / 2]), far)
    o1 = b.origin
    assert b.prob.shape[0] > p0.shape[0] and b.prob.shape[1] > p0.shape[1]
    # the new origin lies on the old lattice (an integer number of cells away)
    dc, dr = (o0[0] - o1[0]) / b.res, (o0[1] - o1[1]) / b.res
    assert abs(dc - round(dc)) < 1e-6 and abs(dr - round(dr)) < 1e-6 and dc >= 0 and dr >= 0
    dc, dr = int(round(dc)), int(round(dr))
    h, w = p0.shape
    np.testing.assert_array_equal(b.prob[dr:dr + h, dc:dc + w], p0)
    np.testing.assert_array_equal(b.known[dr:dr + h, dc:dc + w], k0)
    assert at(b.prob, o1, b.res, 25.51, 20.01) == pytest.approx(CFG.hit_probability)
    # a scan inside the grid does not move it
    b.insert(r, ang, np.array([1.0, 1.0, 0.0]))
    assert b.origin == o1


def test_freeze_crops_to_the_known_cells():
    b = GridBuilder(CFG)
    r, ang = room_scan(np.array([2.0, 1.5, 0.0]))
    for _ in range(3):
        b.insert(r, ang, np.array([2.0, 1.5, 0.0]))
    g = b.freeze()
    assert isinstance(g, ProbGrid) and g.resolution == b.res and g.p_min == CFG.p_min
    # the builder grew 5 m around the scan; the frozen grid is the room plus a 2-cell border
    assert b.prob.shape[0] > 100 and g.prob.shape == (int(round(3.0 / b.res)) + 4 + 1,
                                                      int(round(4.0 / b.res)) + 4 + 1)
    assert g.prob.shape[0] * g.prob.shape[1] < b.prob.size / 4
    # same values at the same places, nothing known lost
    dc, dr = (g.origin[0] - b.origin[0]) / b.res, (g.origin[1] - b.origin[1]) / b.res
    dc, dr = int(round(dc)), int(round(dr))
    h, w = g.prob.shape
    np.testing.assert_array_equal(g.prob, b.prob[dr:dr + h, dc:dc + w])
    assert (g.prob > CFG.p_min).sum() == (b.prob > CFG.p_min).sum()
    x0, y0, x1, y1 = g.known_bounds()
    assert x0 == pytest.approx(-0.0, abs=1e-6) and y0 == pytest.approx(-0.0, abs=1e-6)
    assert x1 == pytest.approx(4.0 + b.res, abs=1e-6) and y1 == pytest.approx(3.0 + b.res, abs=1e-6)
    # an empty builder freezes to an empty grid
    empty = GridBuilder(CFG).freeze()
    assert empty.prob.size == 0 and empty.known_bounds()[0] == empty.known_bounds()[2]


def test_a_slower_laser_gets_stronger_odds_updates():
    """``GridConfig.for_rate``: at or above the reference rate the settings are kept; a laser at a quarter of it gets
    four times the log-odds of a hit and of a miss, so a wall gathers the same evidence per metre travelled."""
    import math

    from holoslam.submaps.probgrid import GridConfig

    cfg = GridConfig()
    assert cfg.for_rate(cfg.reference_rate_hz) is cfg and cfg.for_rate(10.0) is cfg and cfg.for_rate(0.0) is cfg
    slow = cfg.for_rate(cfg.reference_rate_hz / 4)

    def logit(p):
        return math.log(p / (1 - p))

    assert logit(slow.hit_probability) == pytest.approx(4 * logit(cfg.hit_probability), rel=1e-12)
    assert logit(slow.miss_probability) == pytest.approx(4 * logit(cfg.miss_probability), rel=1e-12)
    assert 0.69 < slow.hit_probability < 0.70 and 0.46 < slow.miss_probability < 0.47
    off = GridConfig(reference_rate_hz=0.0)
    assert off.for_rate(1.0) is off


def test_returns_are_bridged_only_for_a_laser_whose_returns_lie_farther_apart_than_a_cell():
    """``GridConfig.for_beams`` at ``bridge_over_cells`` 1: a laser whose neighbouring returns lie closer than a cell
    at its median range is not bridged; one whose returns lie farther apart is; at 0 (the default) never, nor a log
    without returns."""
    import math

    from holoslam.submaps.probgrid import GridConfig

    assert GridConfig().for_beams(math.radians(2.0), 2.34).bridge is False  # off by default (README: *Coarse beams*)
    cfg = GridConfig(bridge_over_cells=1.0)
    one_deg = math.radians(1.0)
    assert cfg.for_beams(one_deg, 2.3) is cfg and not cfg.bridge  # 4.0 cm gaps in 5 cm cells
    coarse = cfg.for_beams(2 * one_deg, 2.34)  # ACES with every second beam dropped: 8.2 cm
    assert coarse.bridge and coarse.resolution == cfg.resolution and coarse.hit_probability == cfg.hit_probability
    assert GridConfig(bridge_over_cells=2.0).for_beams(2 * one_deg, 2.34).bridge is False  # 1.6 cells
    assert GridConfig(bridge_over_cells=0.0).for_beams(2 * one_deg, 2.34).bridge is False
    assert cfg.for_beams(one_deg, math.nan) is cfg


def test_a_dotted_wall_is_made_whole_and_an_edge_is_not_bridged():
    """``bridge_returns``: between two neighbouring returns on one surface, points of their chord a cell or less
    apart (on the wall: the wall x = 2 m stays x = 2 m); across a depth edge (a return 1 m behind its neighbour)
    and next to a beam without return, nothing."""
    import numpy as np

    from holoslam.submaps.probgrid import bridge_returns

    a = np.radians(np.arange(-40.0, 41.0, 2.0))
    r = 2.0 / np.cos(a)  # the wall x = 2 m, returns 7-9 cm apart
    r[5] = np.inf  # no return
    r[30] += 1.0  # a return 1 m behind the wall: an edge on each side
    rb, ab = bridge_returns(r, a, 0.05, 70.0)
    assert np.array_equal(rb[:r.size], r) and np.array_equal(ab[:a.size], a)  # the beams themselves first
    x, y = rb[r.size:] * np.cos(ab[r.size:]), rb[r.size:] * np.sin(ab[r.size:])
    assert np.allclose(x, 2.0, atol=1e-9)  # every bridging point on the wall
    pts = np.sort(np.concatenate([2.0 * np.tan(np.delete(a, [5, 30])), y]))
    gaps = np.diff(pts)
    assert gaps.max() > 0.1  # the holes at the missing return and at the edge stay
    assert np.sum(gaps > 0.05 + 1e-9) == 2  # where beams 5 and 30 were: nothing else wider than a cell
    assert not np.any((y > 2.0 * np.tan(a[29])) & (y < 2.0 * np.tan(a[31])))  # nothing bridges across the edge
    # a circle of 3 m at 2 deg: 10.5 cm chords, two points each
    c = np.radians(np.arange(-90.0, 91.0, 2.0))
    rc, _ = bridge_returns(np.full(c.size, 3.0), c, 0.05, 70.0)
    assert rc.size == c.size + 2 * (c.size - 1)


def test_beam_spacing_and_median_range_are_read_from_the_scans():
    """``beam_step_and_range``: the median beam step and the median of the returns within the grid's range, over
    scans spread through the log; beams without return and returns past the range are not counted."""
    import math

    import numpy as np

    from holoslam.submaps.frontend import beam_step_and_range
    from holoslam.types import Scan

    def scan(k, ranges):
        r = np.asarray(ranges, np.float32)
        return Scan(k, "laser", -math.pi / 2, math.radians(2.0), 0.1, 40.0, r, np.isfinite(r) & (r < 40.0))

    scans = [scan(k, [1.0, 2.0, np.inf, 3.0, 35.0]) for k in range(1000)]
    step, median = beam_step_and_range(scans, 30.0)
    assert step == pytest.approx(math.radians(2.0)) and median == pytest.approx(2.0)  # 35 m is past 30 m
    assert all(math.isnan(v) for v in beam_step_and_range([], 30.0))
    assert math.isnan(beam_step_and_range([scan(0, [np.inf] * 5)], 30.0)[1])
