"""A corridor's periodic aliases (holoslam.submaps.periodic): along a corridor whose doors repeat every 5 m the
scan fits every period as well as its own place, and those places are found beyond any window; along one whose
doors do not repeat, or across the corridor, nothing is; a loop search keeps such a closure with their spread."""

from __future__ import annotations

import numpy as np
import pytest

from holoslam.submaps.periodic import periodic_peaks

RES, P_MIN = 0.05, 0.1


def _corridor(doors: list[float]) -> tuple[np.ndarray, tuple[float, float]]:
    """A 40 m corridor along x, 2 m wide (walls at y = +-1), a 1 m door in both walls at each x of ``doors`` with
    a room's back wall 2 m behind it: occupied 0.9, free 0.2, the rest unknown (p_min)."""
    origin = (0.0, -4.0)
    prob = np.full((160, 800), P_MIN, np.float32)
    x = (np.arange(800) + 0.5) * RES
    y = origin[1] + (np.arange(160) + 0.5) * RES
    X, Y = np.meshgrid(x, y)
    in_door = np.zeros_like(X, bool)
    for d in doors:
        in_door |= (X >= d) & (X < d + 1.0)
    prob[np.abs(Y) < 1.0] = 0.2
    prob[(np.abs(np.abs(Y) - 1.0) < RES) & ~in_door] = 0.9
    prob[(np.abs(Y) < 3.0) & in_door & (np.abs(Y) >= 1.0)] = 0.2
    prob[(np.abs(np.abs(Y) - 3.0) < RES) & in_door] = 0.9
    return prob, origin


def _scan(prob: np.ndarray, origin, at: float, reach: float = 4.0) -> np.ndarray:
    """The occupied cells within ``reach`` of (at, 0), in the frame of a robot standing there facing +x."""
    r, c = np.nonzero(prob >= 0.9)
    pts = np.column_stack([origin[0] + (c + 0.5) * RES, origin[1] + (r + 0.5) * RES])
    near = np.hypot(pts[:, 0] - at, pts[:, 1]) <= reach
    return pts[near] - [at, 0.0]


ALONG = np.diag([1.0, 1e-4, 1e-6])  # a match blind along the corridor (x): its covariance a ridge along x


def test_a_corridor_whose_doors_repeat_every_5_m_shows_its_aliases_5_m_along():
    prob, origin = _corridor([float(d) for d in range(2, 40, 5)])
    pts = _scan(prob, origin, 20.0)
    aTb = np.array([20.0, 0.0, 0.0])
    peaks = periodic_peaks(prob, origin, RES, P_MIN, pts, aTb, ALONG, 0.03, 10.0, 1.0)
    along = sorted(round(float(p[0] - 20.0), 2) for p in peaks)
    assert -5.0 in along and 5.0 in along  # the neighbouring periods (and maybe +-10 m, the next ones)
    assert all(abs(abs(d) - 5.0) < 0.11 or abs(abs(d) - 10.0) < 0.11 for d in along)
    assert all(p[1] == pytest.approx(0.0) and p[2] == 0.0 for p in peaks)  # along the axis, the heading kept
    # across the corridor nothing fits: the same match with its ridge across finds none
    across = np.diag([1e-4, 1.0, 1e-6])
    assert periodic_peaks(prob, origin, RES, P_MIN, pts, aTb, across, 0.03, 10.0, 1.0) == []
    # within the match's own peak (exclude_m) and beyond a shorter reach: none
    assert periodic_peaks(prob, origin, RES, P_MIN, pts, aTb, ALONG, 0.03, 4.0, 1.0) == []


def test_a_corridor_whose_doors_do_not_repeat_has_no_alias():
    # two doors in view (17.5 and 21 m), 3.5 m apart: no other pair of doors is, so no shift fits both
    prob, origin = _corridor([2.0, 9.0, 17.5, 21.0, 27.5, 33.0])
    pts = _scan(prob, origin, 20.0)
    assert periodic_peaks(prob, origin, RES, P_MIN, pts, np.array([20.0, 0.0, 0.0]), ALONG, 0.03, 10.0, 1.0) == []


def test_a_loop_search_keeps_a_periodic_closure_with_the_spread_along_the_corridor():
    from holoslam.submaps.bnb_window import spanning_covariance

    prob, origin = _corridor([float(d) for d in range(2, 40, 5)])
    pts = _scan(prob, origin, 20.0)
    aTb = np.array([20.0, 0.0, 0.0])
    tight = np.diag([1e-4, 1e-4, 1e-6])
    peaks = periodic_peaks(prob, origin, RES, P_MIN, pts, aTb, ALONG, 0.03, 10.0, 1.0)
    cov = spanning_covariance(aTb, tight, peaks)
    assert np.sqrt(cov[0, 0]) > 3.0 and np.sqrt(cov[1, 1]) < 0.02  # metres along, centimetres across


def test_the_periodic_settings_refuse_what_cannot_work():
    from holoslam.submaps.loop_config import LoopConfig
    from holoslam.submaps.loops import LoopSearch
    from holoslam.submaps.scanmatch import MatchConfig

    for bad in ({"periodic_search_m": -1.0}, {"periodic_exclude_m": -0.5}, {"periodic_search_m": float("inf")}):
        with pytest.raises(ValueError, match="periodic_search_m"):
            LoopSearch(LoopConfig(**bad), MatchConfig())


def test_the_compiled_line_scores_are_the_mean_probability_of_the_moved_points_in_their_cells():
    from holoslam.submaps import _grid_fast as fast

    rng = np.random.default_rng(3)
    prob = rng.uniform(0.1, 0.9, (40, 60)).astype(np.float32)
    origin, u = (-1.0, 2.0), np.array([0.6, 0.8])
    ax, ay = rng.uniform(-1.5, 2.5, 50), rng.uniform(1.5, 4.5, 50)  # some points leave the grid when moved
    shifts = np.arange(-40, 41) * RES
    got = fast.line_scores(prob, origin[0], origin[1], RES, ax, ay, u[0], u[1], shifts, P_MIN)
    col = np.floor((ax[None] + shifts[:, None] * u[0] - origin[0]) / RES).astype(int)
    row = np.floor((ay[None] + shifts[:, None] * u[1] - origin[1]) / RES).astype(int)
    inside = (row >= 0) & (row < 40) & (col >= 0) & (col < 60)
    want = np.where(inside, prob[row.clip(0, 39), col.clip(0, 59)], P_MIN).mean(axis=1)
    assert 0 < inside.mean() < 1  # both kinds of point are scored
    np.testing.assert_allclose(got, want, atol=1e-6)
