"""The map check of a global closure (``holoslam.submaps.loop_verify``): two identical rooms, one with a wall
the other lacks nearby; the alias that lays one room onto the other is refused, the right match is not."""

import numpy as np
import pytest

from holoslam.submaps.loop_verify import Agreement, VerifyConfig, map_agreement
from holoslam.submaps.probgrid import ProbGrid

RES = 0.05


def _world() -> np.ndarray:
    """A 40 x 16 m floor (rows y, cols x): room A at x 5-9 m, room B at x 25-29 m (y 5-9 m, a door in the east
    wall), and a 4 m wall 3 m north of B only."""
    w = np.zeros((int(16 / RES), int(40 / RES)), bool)

    def wall(x0, y0, x1, y1):
        w[int(y0 / RES):int(y1 / RES) + 1, int(x0 / RES):int(x1 / RES) + 1] = True

    for x in (5.0, 25.0):
        wall(x, 5, x + 4, 5)
        wall(x, 9, x + 4, 9)
        wall(x, 5, x, 9)
        wall(x + 4, 5, x + 4, 6.5)
        wall(x + 4, 7.5, x + 4, 9)
    wall(25, 12, 29, 12)
    return w


def _grid(world: np.ndarray, x0: float, x1: float) -> ProbGrid:
    """The part x0..x1 of the world as a fully observed grid in the world's frame."""
    c0, c1 = int(x0 / RES), int(x1 / RES)
    walls = world[:, c0:c1]
    prob = np.where(walls, 0.9, 0.1).astype(np.float32)
    return ProbGrid(prob, (x0, 0.0), RES, 0.1, np.ones_like(walls))


def test_an_alias_room_is_refused_and_the_right_match_kept():
    world = _world()
    cfg = VerifyConfig()
    # old submaps 0 (room A) and 1 (room B); the new node's submap 10 follows submap 9, which saw room B
    grids = {0: _grid(world, 0, 15), 1: _grid(world, 18, 36), 9: _grid(world, 20, 35)}
    est = np.zeros((11, 3))  # every anchor at the world's origin: grid frames are the world's
    part = np.zeros(11, np.int64)
    alias = map_agreement(grids, est, part, 0, 10, np.array([-20.0, 0.0, 0.0]), cfg)  # B laid onto A
    assert alias.support > 200  # the rooms' walls agree ...
    assert alias.conflict >= 80  # ... but all of B's extra wall (81 cells) lies in A's known free space
    assert alias.verdict(cfg) is False
    right = map_agreement(grids, est, part, 1, 10, np.zeros(3), cfg)
    assert right.verdict(cfg) is True and right.fraction > 0.99
    # 0.3 m off: the walls no longer meet within the 0.1 m tolerance
    off = map_agreement(grids, est, part, 1, 10, np.array([0.3, 0.0, 0.0]), cfg)
    assert off.verdict(cfg) is False


def test_no_overlap_gives_no_verdict_and_parts_are_kept_apart():
    world = _world()
    cfg = VerifyConfig()
    grids = {0: _grid(world, 0, 15), 5: _grid(world, 20, 35)}
    est = np.zeros((6, 3))
    far = map_agreement(grids, est, np.zeros(6, np.int64), 0, 5, np.zeros(3), cfg)  # side by side
    assert far.support + far.conflict == 0 and far.verdict(cfg) is None
    # the new submap's neighbours are those of its own part: across a break there is nothing to compare
    part = np.array([0, 0, 0, 0, 0, 1])
    grids[4] = _grid(world, 20, 35)
    assert map_agreement(grids, est, part, 0, 5, np.array([-20.0, 0.0, 0.0]), cfg) == Agreement(0, 0)


def test_the_check_is_scaled_like_the_loop_search_s_scores_and_never_raised():
    """A sparse laser's scale (below 1) lowers the agreement the check asks for in proportion; a scale above 1
    (a laser fuller than the reference) leaves it as measured on full-rate logs."""
    cfg = VerifyConfig()
    assert cfg.scaled(0.8).min_agreement == pytest.approx(0.72)
    assert cfg.scaled(1.3).min_agreement == cfg.min_agreement
    assert Agreement(75, 25).verdict(cfg) is False and Agreement(75, 25).verdict(cfg.scaled(0.8)) is True
