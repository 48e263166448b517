"""Scan-to-grid matching (holoslam.submaps.scanmatch, seed 002 Eq. 12) on scans ray-cast in small synthetic
worlds: accuracy from an odometry-like prediction, the covariance's 95 % coverage, corridors.

As in the front end, a submap's grid lives in the frame of a node (its anchor), so the room's walls are not
aligned with the lattice; ``in_frame`` puts a world in that frame, where poses are then compared. (A world whose
walls lie on cell boundaries, axis-aligned, is the quantisation's worst case: see the last test.) Two sensors: a
360-beam scanner and the household's LMS-200-like laser (181 beams over -90..+90 deg, 8 m, ranges rounded to
1 mm)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from holoslam import geometry as g
from holoslam.sim.world import raycast
from holoslam.submaps.probgrid import GridBuilder, GridConfig, ProbGrid
from holoslam.submaps.scanmatch import MatchConfig, match_scan

# a 5 x 4 m room with a box and a half wall, so every pose is constrained
ROOM = np.array([
    [0, 0, 5, 0], [5, 0, 5, 4], [5, 4, 0, 4], [0, 4, 0, 0],
    [3.0, 1.0, 3.6, 1.0], [3.6, 1.0, 3.6, 1.5], [3.6, 1.5, 3.0, 1.5], [3.0, 1.5, 3.0, 1.0],
    [0.0, 2.5, 1.2, 2.5],
], float)
# a corridor 2 m wide and 60 m long along x: nothing in range fixes a position along it
CORRIDOR = np.array([[-30.0, 0.012, 30.0, 0.012], [-30.0, 2.012, 30.0, 2.012]])
BEAMS_360 = np.linspace(-math.pi, math.pi, 360, endpoint=False)
BEAMS_LMS = np.radians(np.arange(-90.0, 91.0, 1.0))
CHI2_3_95 = chi2.ppf(0.95, 3)


def ray_scan(segs, wTs, beams, rng=None, sigma=0.0, max_range=8.0) -> np.ndarray:
    """Ranges of a scan cast from wTs (inf: no return), with N(0, sigma) noise rounded to 1 mm."""
    r = raycast(segs, np.asarray(wTs, float)[None, :2], (beams + wTs[2])[None], max_range)[0]
    if rng is not None and sigma > 0:
        r = np.round(r + rng.normal(0.0, sigma, r.shape), 3)
    return r


def points(ranges, beams) -> np.ndarray:
    ok = np.isfinite(ranges)
    return np.column_stack([ranges[ok] * np.cos(beams[ok]), ranges[ok] * np.sin(beams[ok])])


def grid_from(segs, poses, beams, rng=None, sigma=0.0) -> ProbGrid:
    b = GridBuilder(GridConfig())
    for p in poses:
        b.insert(ray_scan(segs, p, beams, rng, sigma), beams, p)
    return b.freeze()


def match(grid: ProbGrid, b_pts, pred):
    """The default matcher (local SLAM's settings)."""
    return match_scan(grid.prob, grid.origin, grid.resolution, b_pts, pred, MatchConfig())


def in_frame(segs: np.ndarray, wTa) -> np.ndarray:
    """Wall segments (M, 4) of the world expressed in the frame a at wTa."""
    aTw = g.inverse(np.asarray(wTa, float))
    return np.hstack([g.transform_points(aTw, segs[:, :2]), g.transform_points(aTw, segs[:, 2:])])


ANCHOR = np.array([2.0, 2.0, 0.2])  # the known pose of the first scan, the submap's anchor
ROOM_A = in_frame(ROOM, ANCHOR)
A = np.zeros(3)  # the anchor in its own frame


def _steps():
    """Eight second-scan poses 0.05 m / 3 deg from A, and odometry-like predictions of each: 1 cm and 1 deg off
    (a wheel slip), in eight directions."""
    for k in range(8):
        a = k * math.pi / 4
        inc = np.array([0.05 * math.cos(a + 0.3), 0.05 * math.sin(a + 0.3), math.radians(3.0) * (1 if k % 2 else -1)])
        slip = np.array([0.01 * math.cos(a), 0.01 * math.sin(a), math.radians(1.0) * (-1 if k % 3 else 1)])
        true = g.compose(A, inc)
        yield true, g.compose(true, slip)


@pytest.mark.parametrize(
    "case, max_mm, max_deg",
    [
        # measured (this commit): 3.7 mm / 0.28 deg worst of eight
        ("one noiseless 360-beam scan", 5.0, 0.3),
        # measured: 7.1 mm / 0.24 deg worst of eight with translation prior 10, 5.4 mm / 0.28 deg with 30
        ("ten LMS-200 scans, 1 cm noise", 9.0, 0.35),
    ],
)
def test_second_scan_matched_from_an_odometry_prediction(case, max_mm, max_deg):
    rng = np.random.default_rng(0)
    if case.startswith("one"):
        beams, sigma = BEAMS_360, 0.0
        grid = grid_from(ROOM_A, [A], beams)
    else:  # a submap as local SLAM fills it: ten scans over the 0.27 m before A
        beams, sigma = BEAMS_LMS, 0.01
        grid = grid_from(ROOM_A, [g.compose(A, np.array([-0.03 * (9 - j), 0.0, 0.0])) for j in range(10)], beams,
                         rng, sigma)
    errs, pred_errs = [], []
    for true, pred in _steps():
        m = match(grid, points(ray_scan(ROOM_A, true, beams, rng, sigma), beams), pred)
        assert m.ok and m.score >= MatchConfig().min_score
        e, ep = g.between(true, m.aTb), g.between(true, pred)
        errs.append([math.hypot(e[0], e[1]) * 1e3, abs(math.degrees(e[2]))])
        pred_errs.append([math.hypot(ep[0], ep[1]) * 1e3, abs(math.degrees(ep[2]))])
    errs, pred_errs = np.array(errs), np.array(pred_errs)
    assert errs[:, 0].max() <= max_mm and errs[:, 1].max() <= max_deg, errs.max(axis=0)
    # the prediction alone is outside those bounds: the match did the work
    assert pred_errs[:, 0].min() > max_mm and pred_errs[:, 1].min() > max_deg


# --- the covariance: 95 % coverage over 200 random scans with range noise ---


@pytest.fixture(scope="module")
def coverage_run():
    """200 LMS-200 scans (1 cm noise) from random poses 0.05 m / 3 deg from the last node of a ten-scan submap,
    each matched from a prediction off by N(0, 1 cm) per axis and N(0, 0.5 deg): (Mahalanobis d^2, errors)."""
    room = in_frame(ROOM, np.array([1.0, 1.2, 0.5]))
    rng0 = np.random.default_rng(1234)
    grid = grid_from(room, [np.array([0.03 * j, 0.0, 0.0]) for j in range(10)], BEAMS_LMS, rng0, 0.01)
    last = np.array([0.27, 0.0, 0.0])
    d2, errs = [], []
    for k in range(200):
        rng = np.random.default_rng(k)
        a = rng.uniform(0, 2 * math.pi)
        true = g.compose(last, np.array([0.05 * math.cos(a), 0.05 * math.sin(a),
                                         math.radians(3.0) * rng.choice([-1, 1])]))
        pred = g.compose(true, np.array([rng.normal(0, 0.01), rng.normal(0, 0.01), math.radians(rng.normal(0, 0.5))]))
        m = match(grid, points(ray_scan(room, true, BEAMS_LMS, rng, 0.01), BEAMS_LMS), pred)
        e = g.between(true, m.aTb)  # in the pose's own frame, as the covariance
        d2.append(float(e @ np.linalg.solve(m.cov_aTb, e)))
        errs.append(e)
    return np.array(d2), np.array(errs)


def test_match_covariance_is_not_overconfident(coverage_run):
    d2, errs = coverage_run
    coverage = float(np.mean(d2 < CHI2_3_95))
    assert coverage >= 0.8, coverage  # measured (this commit): 1.0
    assert np.sqrt(np.mean(errs[:, :2] ** 2)) < 0.006  # measured 3.2 mm rms per axis (4.3 at 7ef252d)


@pytest.mark.xfail(strict=True, reason=(
    "measured coverage 1.0 (200/200), median d^2 0.13 (317a541; 0.19 at 7ef252d) against chi2(3)'s 2.37: on a "
    "well-filled submap the score surface (kappa 200) is a single pose, and the covariance is the lattice floor "
    "res^2/12 (14.4 mm sigma) while the refined pose errs 3-4 mm rms per axis (_grid_fast.surface_covariance). "
    "Tried: the refinement's own covariance (residual variance x inverse Gauss-Newton Hessian) as the floor gives "
    "coverage 0.99 / median d^2 0.76 here, but the bundled run's anchor 95 % coverage falls 0.93 -> 0.84 with "
    "the anchors as accurate (9 mm): a submap's matches share its grid, and as independent factors they "
    "overstate the information; the conservative floor stands in for that correlation until it is modelled"))
def test_match_covariance_is_not_overly_conservative(coverage_run):
    d2, _ = coverage_run
    assert float(np.mean(d2 < CHI2_3_95)) <= 0.999


# --- corridors ---


def _corridor_grid(heading: float, seed: int) -> ProbGrid:
    """A submap of 21 scans along 2 m of the corridor, lateral and heading wobble, 1 cm noise."""
    rng = np.random.default_rng(seed)
    poses = [np.array([x, 0.9 + rng.normal(0, 0.05), heading + rng.normal(0, 0.05)])
             for x in np.arange(-1.0, 1.01, 0.1)]
    return grid_from(CORRIDOR, poses, BEAMS_360, rng, 0.01)


@pytest.mark.parametrize("heading", [0.0, 0.3, -0.3, math.pi - 0.2])
def test_corridor_covariance_is_longest_along_the_corridor(heading):
    grid = _corridor_grid(heading, 1)
    true = np.array([0.03, 0.95, heading + math.radians(3.0)])
    rng = np.random.default_rng(11)
    pred = g.compose(true, np.array([0.01, -0.01, math.radians(0.5)]))
    m = match(grid, points(ray_scan(CORRIDOR, true, BEAMS_360, rng, 0.01), BEAMS_360), pred)
    assert m.ok
    # the covariance is in the pose's own frame: rotate its x-y block into the world (corridor along x)
    R = g.rot2(m.aTb[2])
    w, V = np.linalg.eigh(R @ m.cov_aTb[:2, :2] @ R.T)
    major = V[:, 1]
    off_axis = math.degrees(math.acos(min(1.0, abs(major[0]))))
    assert off_axis < 10.0, off_axis  # measured 0.0-6.7 deg
    assert math.sqrt(w[1]) > 2.5 * math.sqrt(w[0]), np.sqrt(w)  # measured 59-83 mm along, 15-23 mm across
    assert abs(m.aTb[1] - true[1]) < 0.02  # across the corridor the walls fix the pose


def test_corridor_match_stays_at_the_prediction_along_the_corridor():
    """Nothing in range fixes a position along the corridor: the translation prior holds the prediction there
    (no random walk scan after scan), so the along-corridor error is the prediction's, not larger."""
    along, pred_along = [], []
    for trial in range(20):
        heading = (0.0, 0.3, -0.3, math.pi - 0.2)[trial % 4]
        grid = _corridor_grid(heading, trial)
        rng = np.random.default_rng(100 + trial)
        true = np.array([0.03, 0.95, heading + math.radians(3.0)])
        pred = g.compose(true, np.array([rng.normal(0, 0.01), rng.normal(0, 0.01), math.radians(rng.normal(0, 0.5))]))
        m = match(grid, points(ray_scan(CORRIDOR, true, BEAMS_360, rng, 0.01), BEAMS_360), pred)
        along.append(m.aTb[0] - true[0])
        pred_along.append(pred[0] - true[0])
    rms, rms_pred = float(np.sqrt(np.mean(np.square(along)))), float(np.sqrt(np.mean(np.square(pred_along))))
    # measured 9.9 mm against the prediction's 10.1 mm with translation prior 10; 14.6 mm against 9.9 mm with 30
    # (the prior holds the odometry prediction; the map's weak along-corridor pull adds a little)
    assert rms < 1.8 * rms_pred, (rms, rms_pred)



def test_a_scan_reaching_past_the_mapped_walls_is_not_pulled_back():
    """A forward-looking laser (180 deg, 8 m) driving down a corridor: the submap's walls end 8 m ahead of the last
    scan inserted, and the next scan, 0.4 m on, reaches 0.4 m past them into cells never seen. Its points there score
    as free wherever it is put, except pulled back onto the mapped walls: the window's best lies a cell or two behind
    the (here exact) prediction. The refinement starts at the prediction unless the window's best gains
    ``seed_margin``: local SLAM then keeps the motion; with the window's best as the seed it shortens it."""
    rng = np.random.default_rng(5)
    poses = [np.array([x, 1.0, 0.0]) for x in np.arange(-2.0, 0.01, 0.4)]
    grid = grid_from(CORRIDOR, poses, BEAMS_LMS, rng, 0.01)
    keep, seeded = [], []
    for _ in range(10):
        true = np.array([0.4, 1.0 + rng.normal(0, 0.02), rng.normal(0, 0.005)])
        pts = points(ray_scan(CORRIDOR, true, BEAMS_LMS, rng, 0.01), BEAMS_LMS)
        keep.append(match(grid, pts, true).aTb[0] - true[0])
        m = match_scan(grid.prob, grid.origin, grid.resolution, pts, true, MatchConfig(seed_margin=0.0))
        seeded.append(m.aTb[0] - true[0])
    assert abs(float(np.mean(keep))) < 0.01  # measured -5 mm (10 scans)
    assert float(np.mean(seeded)) < -0.02  # measured -35 mm: the motion shortened by a tenth


# --- when a match is not trusted ---


def test_scan_off_the_map_or_too_short_is_not_trusted():
    grid = grid_from(ROOM_A, [A], BEAMS_360)
    pts = points(ray_scan(ROOM_A, A, BEAMS_360), BEAMS_360)
    assert match(grid, pts, A).ok
    # the same scan predicted 3 m away, outside the room: it scores as unknown space, kept at the prediction
    far = A + np.array([3.0, 3.0, 0.0])
    m = match(grid, pts, far)
    assert not m.ok and m.score < MatchConfig().min_score and np.hypot(*(m.aTb[:2] - far[:2])) < 0.15
    # fewer points than min_points: the prediction back, untrusted
    few = match(grid, pts[:5], A + 0.01)
    assert not few.ok and np.array_equal(few.aTb, A + 0.01)


def test_walls_on_cell_boundaries_bias_a_match_by_at_most_half_a_cell():
    """The quantisation's worst case: a grid in the world frame of an axis-aligned room whose walls lie exactly
    on cell boundaries. A return at a wall goes to the cell beyond the boundary, whose value stands for its
    centre, so each wall's peak sits half a cell off and a scan matched into the grid of itself lands up to
    half a cell away (measured 17.6 / 19.4 mm in x / y with 5 cm cells; the tests above keep walls oblique to
    the lattice, as a node-anchored submap does)."""
    wTs = np.array([2.0, 2.0, 0.2])
    grid = grid_from(ROOM, [wTs], BEAMS_360)
    m = match(grid, points(ray_scan(ROOM, wTs, BEAMS_360), BEAMS_360), wTs)
    e = m.aTb - wTs
    assert m.ok and np.all(np.abs(e[:2]) <= grid.resolution / 2) and abs(e[2]) < math.radians(0.2), e


def test_surface_covariance_kernel_is_the_weighted_moment():
    """The compiled score-surface covariance equals the numpy formula (weighted second moment about the refined
    pose, lattice floors, rotated into the pose's frame), including a heading across +-pi."""
    from holoslam.submaps._grid_fast import surface_covariance

    rng = np.random.default_rng(5)
    for pred2 in (0.3, np.pi - 0.004):
        S = rng.uniform(0.2, 0.8, (9, 5, 5))
        off = (np.arange(5) - 2) * 0.05
        angles = (np.arange(9) - 4) * 0.002
        pred = np.array([1.0, -2.0, pred2])
        aTb = pred + np.array([0.01, -0.02, 0.003])
        w = np.exp(200.0 * (S - S.max()))
        w /= w.sum()
        D = np.stack(np.broadcast_arrays(pred[0] + off[None, None, :] - aTb[0], pred[1] + off[None, :, None] - aTb[1],
                                         (pred[2] + angles[:, None, None] - aTb[2] + np.pi) % (2 * np.pi) - np.pi))
        D = D.reshape(3, -1)
        cov = (D * w.ravel()) @ D.T + np.diag([0.05**2 / 12, 0.05**2 / 12, 0.01**2 / 12])
        c, s = np.cos(aTb[2]), np.sin(aTb[2])
        J = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        got = surface_covariance(S, *pred, off, angles, *aTb, 200.0, 0.05, 0.01)
        assert np.allclose(got, J @ cov @ J.T, rtol=1e-12, atol=1e-18)


def test_window_seed_is_the_discounted_best_or_the_centre():
    """The compiled seed of a correlative window is numpy's argmax of the scores discounted by distance and angle
    from the prediction, and the centre cell of that angle when the best gains less than the seed margin."""
    from holoslam.submaps._grid_fast import window_seed

    rng = np.random.default_rng(9)
    res, angles = 0.05, (np.arange(-20, 21)) * 0.012
    off = (np.arange(5) - 2) * res
    for k in range(200):
        S = rng.uniform(0.3, 0.8, (41, 5, 5))
        if k % 4 == 0:
            S = np.round(S, 1)  # ties: the first of equals wins, as numpy's argmax
        disc = S * np.exp(-(0.1 * (off[None, :, None] ** 2 + off[None, None, :] ** 2) + 0.1 * angles[:, None, None] ** 2))
        a, j, i = np.unravel_index(int(np.argmax(disc)), S.shape)
        margin = 0.04 if k % 2 else 0.0
        if S[a, j, i] - S[a, 2, 2] < margin:
            j = i = 2
        assert window_seed(S, res, angles, 0.1, 0.1, margin) == (a, j, i)


def test_refinement_step_solve_is_numpys():
    """The matcher's unrolled 3x3 solve (``_grid_fast._solve3``) gives ``np.linalg.solve``'s step, also where
    the pivot must move rows (a zero leading entry)."""
    from holoslam.submaps._grid_fast import _solve3

    rng = np.random.default_rng(7)
    mats = [np.array([[0.0, 2.0, 1.0], [3.0, 1.0, 0.5], [1.0, 0.0, 4.0]])]
    mats += [(m := rng.normal(size=(3, 3))) @ m.T + np.eye(3) * 1e-3 for _ in range(50)]
    for A in mats:
        b = rng.normal(size=3)
        assert np.allclose(_solve3(A, b), np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)


def test_refinement_gradient_is_the_cost_derivative():
    """``_lsq_terms``' gradient (J^T r) is the cost's derivative (central differences of the cost, halved as the
    matcher's is), at poses inside cells of a filled room grid, and its Hessian is positive semi-definite."""
    from holoslam.submaps._grid_fast import _lsq_terms

    rng = np.random.default_rng(3)
    grid = grid_from(ROOM_A, [A], BEAMS_360)
    b = points(ray_scan(ROOM_A, A, BEAMS_360), BEAMS_360)
    px, py = b[:, 0].copy(), b[:, 1].copy()
    ox, oy = grid.origin
    s, pred = 20.0 / math.sqrt(len(px)), np.array([0.01, -0.01, 0.01])

    def terms(x):
        H, gr, Hocc = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3))
        c, _ = _lsq_terms(grid.prob, ox, oy, grid.resolution, px, py, s, *pred, 30.0, 60.0, 0.1, *x, H, gr, Hocc,
                          True)
        return c, gr, H

    for _ in range(5):
        x = rng.normal(0.0, [0.02, 0.02, 0.01])
        c, gr, H = terms(x)
        h = np.array([1e-6, 1e-6, 1e-7])
        num_g = [(terms(x + h[k] * np.eye(3)[k])[0] - terms(x - h[k] * np.eye(3)[k])[0]) / (4 * h[k])
                 for k in range(3)]
        assert np.allclose(gr, num_g, rtol=1e-4, atol=1e-6)
        assert np.linalg.eigvalsh(H).min() >= -1e-9 * np.abs(H).max()


def test_the_wide_search_s_check_counts_only_the_points_both_poses_put_on_explored_cells():
    """``explored_gain`` (the wide search's check, ``MatchConfig.wide_on_explored``): a pose 0.3 m off in a room
    puts fewer of the scan's points on occupied cells than the right one, counted over the points both poses put
    on explored cells; points on unexplored cells (here 40 far outside the grid, as a scan reaching into a room the
    grid never saw) read p_min wherever the pose is and are left out. On intel at 1.4 Hz the wide search's pose
    1.1 m back along a corridor scored 0.62 against the right pose's 0.48 and gained nothing on those points."""
    from holoslam.submaps.scanmatch import explored_gain

    rng = np.random.default_rng(7)
    room = GridBuilder(GridConfig())
    for p in ([1.0, 1.0, 0.0], [2.0, 2.0, 1.0], [3.5, 3.0, 2.5]):
        room.insert(ray_scan(ROOM, np.array(p), BEAMS_360, rng, 0.01), BEAMS_360, np.array(p))
    at = np.array([2.0, 1.5, 0.3])
    pts = points(ray_scan(ROOM, at, BEAMS_360, rng, 0.01), BEAMS_360)
    wrong = at + np.array([0.3, 0.0, 0.0])
    gain, n = explored_gain(room.prob, room.known, room.origin, room.res, pts, wrong, at)
    assert n >= 100 and gain > 0.15, (gain, n)  # measured 0.26 over 263 points (the margin: 0.05)
    back, n_back = explored_gain(room.prob, room.known, room.origin, room.res, pts, at, wrong)
    assert back == pytest.approx(-gain) and n_back == n
    far = np.vstack([pts, np.full((40, 2), 100.0)])
    assert explored_gain(room.prob, room.known, room.origin, room.res, far, wrong, at) == (pytest.approx(gain), n)


def test_angular_step_is_one_cell_at_numpys_range_quantile():
    """The matcher's angular step is the rotation moving the 0.9 quantile of the ranges (numpy's linear quantile,
    to 1e-12: another libm's hypot may differ in its last bit) by one cell; two points or one, or none (1 m), and near points floored at two cells."""
    from holoslam.submaps.scanmatch import angular_step

    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 7, 360, 1081):
        pts = rng.normal(0.0, 4.0, (n, 2))
        d = np.quantile(np.hypot(pts[:, 0], pts[:, 1]), 0.9) if n else 1.0
        d = max(d, 0.1)
        assert angular_step(pts, 0.05) == pytest.approx(math.acos(max(-1.0, 1.0 - 0.05**2 / (2.0 * d * d))), rel=1e-12)
    near = np.full((10, 2), 0.01)
    assert angular_step(near, 0.05) == pytest.approx(math.acos(1.0 - 0.05**2 / (2.0 * 0.1 * 0.1)), rel=1e-12)


def test_quickselect_puts_the_sorted_value_at_k():
    """The angular step's selection gives what a sort puts at k, with ties, sorted and reversed inputs."""
    from holoslam.submaps._grid_fast import _select

    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 10, 101, 1000):
        for data in (rng.normal(size=n), np.round(rng.normal(size=n), 1), np.arange(n, dtype=float),
                     np.arange(n, 0, -1, dtype=float)):
            for k in {0, n // 2, int(0.9 * (n - 1)), n - 1}:
                r = data.copy()
                assert _select(r, k) == np.sort(data)[k]
                assert np.all(r[:k] <= r[k]) and np.all(r[k + 1:] >= r[k])
