"""Self-localisation of a scan in a local map (seed 002 Eq. 12), on the submap's probability grid (SPEC §8).

``match_scan`` takes a scan's points in the base frame, a probability grid and a predicted pose ``aTb``:

1. **Correlative search** (Olson, ICRA 2009): every pose of a window around the prediction (translations on
   the grid's cells, rotations at the step that moves the farthest point by about one cell) is scored by the
   mean probability at the cells its points fall in; the best score, discounted for its distance from the
   prediction (Cartographer's real-time matcher), seeds the next step. Odometry that is metres off is the
   loop-closure search's job (``bnb``); this window covers a scan-to-scan prediction error.
2. **Continuous refinement**: Gauss-Newton with Levenberg damping over
   (x, y, theta), started at the correlative seed, on sum_i (w_occ/sqrt(N) (1 - P(aTb p_i)))^2 + w_t^2 |t - t_pred|^2
   + w_r^2 (theta - theta_pred)^2, P the bicubic interpolation of the grid (Hess et al. 2016); the weak priors
   hold the prediction where the map does not constrain the pose (along a corridor).
3. **Covariance from the score surface** (Olson 2009, §IV): the window's scores, as weights
   exp(kappa (s - s_best)) over the poses, give the weighted second moment about the refined pose, floored by
   the discretisation (a cell and an angular step, uniform). ``kappa`` turns mean probabilities into a
   log-likelihood scale; corridors give long ellipses along the corridor, as they should.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["MatchConfig", "Match", "match_scan", "angular_step", "score_pose", "WidePyramid"]


@dataclass(frozen=True, slots=True)
class MatchConfig:
    """Scan-to-grid matching settings. Defaults: Cartographer's 2D real-time correlative window (0.1 m, 20 deg,
    delta-cost weights 0.1) and Ceres weights for real lasers (SPEC §8: occupied space 20, rotation 1e2;
    rotation 60 here, measured below);
    translation 30: measured on the real logs (first 300-400 s) before the laser prediction (below): 10 / 30 /
    100 gave ACES 3.8 / 3.4 / 3.2 cm and fr079 3.6 / 3.7 / 4.8 cm: a strong prior helps where the wheel odometry
    is good (ACES: its lateral error over the benchmark's 0.3 m relations is 3 mm, the matched poses' 7.5 mm) and
    hurts where it is not. Re-measured on the whole logs with the laser prediction, 30 / 40 / 45 / 50 / 60 / 100
    gave ACES 0.0367 / 0.0354 / 0.0353 / 0.0349 / 0.0348 / 0.0351 m, intel 0.0190 / 0.0196 / 0.0197 / 0.0194 /
    0.0214 / - m, fr079 0.0662 / 0.0664 / 0.0661 / 0.0665 / 0.0661 / 0.0691 m; but on the simulated drifting
    odometry of tests/submaps/test_loops.py (3 % scale, 3 % turn, 2 deg/m) 45 and more let a submap bend until a
    loop aliased two rooms 1.5 m off, and 40 moved the simulated and intel-cut tests' paths to their bounds. 30
    stays: the gain on ACES is a few millimetres and the risk is with biased odometry. A stronger prior sideways
    only (the wheels' scale error is along the motion) gave nothing: sideways 60 / 100 / 200 with 30 along gave
    ACES 0.0379 / 0.0361 / 0.0370 m and intel 0.0200 m (100). Priors adapted to the measured innovations were tried and were worse on fr079 (odometry
    noise estimated through the prior is biased low). ``kappa`` scales the score surface into weights for the
    covariance."""

    linear_window: float = 0.1  # m, half-width of the correlative window
    angular_window_deg: float = 20.0  # half-width
    translation_delta_weight: float = 0.1  # score discount per m^2 of distance from the prediction
    rotation_delta_weight: float = 0.1  # score discount per rad^2
    # score units: the window's best translation seeds the refinement only when it scores this much above the
    # prediction (at the best heading); else the refinement starts at the predicted position. Along a corridor the
    # window's best is pulled back by the walls' unexplored ends and their probability ramp: a bias, not a fix of the
    # odometry (local SLAM shortened straight motion by 1.9 % on aces at full rate, 4.7 % at 1.2 Hz). Measured on
    # aces' whole log: 84 % of the windows peak at the prediction, the others gain a median 0.014 (a cell or two
    # off), while the predictions the odometry really got wrong gain 0.07-0.14 (the 90-99th percentiles); 0.04 sits
    # between. With it: aces 0.0367 -> 0.0355 m, intel 0.0189 -> 0.0187, fr079 0.0429 -> 0.0429 at the laser
    # (0.439 -> 0.441 deg); at 1.0-1.25 Hz aces 0.0468 -> 0.0424 (its straight-motion bias -4.2 -> -0.9 %), intel
    # 0.1152 -> 0.0934, fr079 0.0532 -> 0.0552; 0.02 did half as much on aces. The household's windows peak at its
    # prediction 99.6 % of the time: unchanged
    seed_margin: float = 0.04
    occupied_weight: float = 20.0
    translation_weight: float = 30.0
    # rotation 60: measured on the whole real logs (with the laser prediction below): weight 100 / 60 / 40 gave
    # fr079 0.585 / 0.447 / 0.446 deg, ACES 0.341 / 0.350 / 0.340 deg (3.98 / 3.68 / 3.89 cm); intel 0.415 (100)
    # -> 0.357 deg (60). fr079's wheel odometry turns up to 20 deg the wrong way in a few seconds (169-179 s:
    # -17 deg where a scan-to-scan match and the ground truth say +5 deg): a strong prior holds the match there
    rotation_weight: float = 60.0
    iterations: int = 20
    kappa: float = 200.0  # 1 / score units: weights exp(kappa (s - s_best)) of the score surface
    min_score: float = 0.3  # mean probability below which a match is not trusted (p_min = 0.1 is no overlap)
    # a wide search when the window's best score falls this far below the usual (fr079: the wheel odometry
    # says +0.4 m where the laser and the benchmark's ground truth say -0.4 m, for seconds at a time). Measured
    # on the first 400 s of ACES and fr079 (418 searches at 0.1, each ~40 ms): every search that found a better
    # pose (35, all fr079) followed a drop of 0.12 or more; drops in [0.1, 0.12) (114) found none
    wide_trigger: float = 0.12
    wide_linear_window: float = 1.0  # m
    wide_margin: float = 0.1  # score the wide result must gain over the window's best
    wide_tolerance: float = 0.05  # and it must come this close to the usual score
    wide_depth: int = 4
    min_points: int = 20
    # when the window around the odometry's prediction scores low (``wide_trigger``), the window around the
    # laser's own prediction (the last matched pose moved on at the last matched velocity) replaces it when it
    # scores this much higher. fr079's odometry reports forward motion while the robot backs up (301-308 s: +0.5
    # where the ground truth says -0.5 m/s): there the laser's window scores 0.05-0.3 higher; on ACES, whose
    # odometry is good, the laser's window never scored 0.05 higher (197 of 423 low windows scored higher, all by
    # less than 0.05); a margin of 0.02 took ACES 3.68 -> 3.76 cm (an alias chosen), 0.1 left fr079's breaks
    laser_prediction_margin: float = 0.05
    # the wide search's pose replaces the prediction only when, besides, ``wide_explored_margin`` more of the scan's
    # points that fall on explored cells (cells some scan updated) at both poses land on occupied ones (p > 0.5)
    # there (off: the score alone). A scan reaching into unexplored cells (they read p_min) scores low at the right
    # pose, and a pose back along a corridor puts those points on explored walls: intel at 1.4 Hz, 2071.9 s, the
    # right pose 0.48 against a usual 0.65, the wide search's pose 1.1 m back along the corridor 0.62, one relation
    # 1.03 m off. 0.05: one point in twenty, a clear gain on the evidence both poses share; the score's own margin
    # (0.1) refused fr079's right corrections at 1.4 Hz (0.0534 -> 0.0579 m at the laser, max 0.29 -> 0.66 m)
    wide_on_explored: bool = True
    wide_explored_margin: float = 0.05


@dataclass(frozen=True, slots=True)
class Match:
    aTb: np.ndarray
    cov_aTb: np.ndarray
    score: float  # mean bicubic probability of the points at aTb
    ok: bool


#: the far point's range quantile of ``angular_step``
FAR_QUANTILE = 0.9


def angular_step(b_pts: np.ndarray, resolution: float, quantile: float = FAR_QUANTILE) -> float:
    """The rotation that moves a far point (the ``quantile`` of the ranges) by about one cell (the median
    instead was measured worse on aces: 4.3 cm / 0.39 deg local relation error against 3.8 cm / 0.32 deg)."""
    from holoslam.submaps import _grid_fast as fast

    pts = np.asarray(b_pts, np.float64).reshape(-1, 2)
    return float(fast.angular_step(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                                   float(resolution), float(quantile)))


def explored_gain(prob: np.ndarray, known: np.ndarray, origin, resolution: float, b_pts: np.ndarray,
                  aTb: np.ndarray, bTb: np.ndarray) -> tuple[float, int]:
    """How much better the points ``b_pts`` (N, 2, base frame) fit at pose ``bTb`` than at ``aTb``: of the points
    that fall on explored cells (``known`` nonzero) at both poses, the share on occupied cells (p > 0.5) at ``bTb``
    less that at ``aTb``, and how many those points are. Points on unexplored cells read p_min wherever the pose
    is, and a wall's probability ramps up over the scans that saw it: neither says which pose is right."""
    from holoslam.submaps.probgrid import cells_at

    pts = np.reshape(b_pts, (-1, 2))
    on_a, p_a = cells_at(prob, known, origin, resolution, g.transform_points(np.asarray(aTb, np.float64), pts))
    on_b, p_b = cells_at(prob, known, origin, resolution, g.transform_points(np.asarray(bTb, np.float64), pts))
    on = on_a & on_b
    n = int(np.count_nonzero(on))
    if n == 0:
        return 0.0, 0
    return float(np.mean(p_b[on] > 0.5) - np.mean(p_a[on] > 0.5)), n


def score_pose(prob: np.ndarray, origin, resolution: float, b_pts: np.ndarray, aTb: np.ndarray,
               outside: float = 0.1) -> float:
    """Mean probability (cell lookup) of the points at pose aTb."""
    from holoslam.submaps import _grid_fast as fast

    s = fast.window_scores(prob, origin[0], origin[1], resolution, b_pts[:, 0].copy(), b_pts[:, 1].copy(),
                           float(aTb[0]), float(aTb[1]), float(aTb[2]), 0, np.zeros(1), outside)
    return float(s[0, 0, 0])


def match_scan(prob: np.ndarray, origin: tuple[float, float], resolution: float, b_pts: np.ndarray,
               predicted_aTb: np.ndarray, cfg: MatchConfig = MatchConfig(), outside: float = 0.1,
               expected_score: float | None = None, pyramid: WidePyramid | None = None,
               alternative_aTb: np.ndarray | None = None, known: np.ndarray | None = None) -> Match:
    """Register scan points ``b_pts`` (N, 2, base frame) into the grid around ``predicted_aTb``.

    ``expected_score``: the score matches usually reach here (the caller's running median). When the best
    score of the window falls more than ``wide_trigger`` below it, the prediction is taken to be wrong (wheel
    odometry that slipped, or that disagrees with the laser for a moment) and a branch-and-bound search over
    ``wide_linear_window`` runs; its pose replaces the prediction when it scores ``wide_margin`` higher. A
    wide window is never searched routinely: along a corridor it would jump between equally good places.
    ``alternative_aTb``: a second prediction (the laser's own motion, ``LocalSlam``), searched when the window
    around ``predicted_aTb`` scores low, and kept when it scores ``laser_prediction_margin`` higher: wheel
    odometry can be wrong for seconds (a wheel that slips, an encoder sign lost when backing up).
    ``pyramid``: the caller's cache of the grid's branch-and-bound pyramid (``WidePyramid``), reused while the
    grid is unchanged (scans localised between insertions often trigger several wide searches of one grid).
    ``known``: the grid's explored cells (nonzero where a scan updated them), for ``MatchConfig.wide_on_explored``."""
    from holoslam.submaps import _grid_fast as fast

    pred = np.asarray(predicted_aTb, np.float64)
    pts = np.ascontiguousarray(b_pts, dtype=np.float64)
    if len(pts) < cfg.min_points:
        return Match(pred, np.eye(3), 0.0, False)
    px, py = pts[:, 0].copy(), pts[:, 1].copy()
    res = float(resolution)
    step = fast.angular_step(px, py, res, FAR_QUANTILE)  # angular_step's, without its conversions
    na = int(math.ceil(math.radians(cfg.angular_window_deg) / step))
    angles = np.arange(-na, na + 1) * step
    nxy = int(math.ceil(cfg.linear_window / res))
    S = fast.window_scores(prob, origin[0], origin[1], res, px, py, pred[0], pred[1], pred[2], nxy, angles,
                           outside)
    alt = None if alternative_aTb is None else np.asarray(alternative_aTb, np.float64)
    if alt is not None and expected_score is not None and S.max() < expected_score - cfg.wide_trigger:
        S_alt = fast.window_scores(prob, origin[0], origin[1], res, px, py, alt[0], alt[1], alt[2], nxy, angles,
                                   outside)
        if S_alt.max() > S.max() + cfg.laser_prediction_margin:
            pred, S = alt, S_alt
    if expected_score is not None and S.max() < expected_score - cfg.wide_trigger:
        # the wide pose must score like a usual match (not merely better than a poor window: a scan that sees
        # unexplored space scores low wherever it is put, and a wide window then finds a corridor's alias)
        need = max(float(S.max()) + cfg.wide_margin, expected_score - cfg.wide_tolerance)
        wide = _wide_search(prob, origin, res, pts, pred, cfg, need, pyramid)
        if wide is not None and cfg.wide_on_explored and known is not None:
            ba, bj, bi = (int(v) for v in np.unravel_index(int(np.argmax(S)), S.shape))
            best = np.array([pred[0] + (bi - nxy) * res, pred[1] + (bj - nxy) * res, pred[2] + angles[ba]])
            gain, n = explored_gain(prob, known, origin, res, pts, best, wide)
            if n < cfg.min_points or gain < cfg.wide_explored_margin:
                wide = None
        if wide is not None:
            pred = wide
            S = fast.window_scores(prob, origin[0], origin[1], res, px, py, pred[0], pred[1], pred[2], nxy,
                                   angles, outside)
    off = np.arange(-nxy, nxy + 1) * res
    # the best cell discounted by its distance from the prediction; the predicted position unless it gains
    # seed_margin over it
    a, j, i = fast.window_seed(S, res, angles, cfg.translation_delta_weight, cfg.rotation_delta_weight,
                               cfg.seed_margin)
    seed = np.array([pred[0] + off[i], pred[1] + off[j], g.wrap(float(pred[2] + angles[a]))])  # wrap's scalar path
    # the priors pull toward the prediction, not the correlative seed: along a corridor the window's best cell
    # is noise, and a prior at it would let the estimate random-walk along the corridor scan after scan
    x, y, t, _cost, _occ, _H, _it = fast.lsq_match(
        prob, origin[0], origin[1], res, px, py, seed[0], seed[1], seed[2], pred[0], pred[1], pred[2],
        cfg.occupied_weight, cfg.translation_weight, cfg.rotation_weight, cfg.iterations, outside)
    aTb = np.array([x, y, t])
    score = float(fast.mean_bicubic(prob, origin[0], origin[1], res, px, py, x, y, t, outside))
    cov = fast.surface_covariance(S, float(pred[0]), float(pred[1]), float(pred[2]), off, angles, x, y, t,
                                  float(cfg.kappa), res, float(step))
    return Match(aTb, cov, score, bool(score >= cfg.min_score))


class WidePyramid:
    """A one-grid cache of the wide search's pyramid. The caller sets ``key`` to name the content of the grid
    it matches into (e.g. the submap and its number of inserted scans); a pyramid built for another key is
    rebuilt."""

    def __init__(self) -> None:
        self.key: object = None
        self._built_for: object = None
        self._grids: Any = None

    def grids(self, build: Callable[[], Any]) -> Any:
        if self._grids is None or self._built_for != self.key:
            self._grids, self._built_for = build(), self.key
        return self._grids


def _wide_search(prob, origin, res, pts, pred, cfg: MatchConfig, min_score: float,
                 pyramid: WidePyramid | None = None) -> np.ndarray | None:
    """Branch-and-bound over the wide window (a shallow pyramid: the window is a few dozen cells)."""
    from holoslam.submaps import bnb
    from holoslam.warmup import wait_for_kernels

    wait_for_kernels("holoslam.submaps._bnb_fast")  # a first run's pool compiling it: not twice

    def build():
        return bnb.precompute(prob, cfg.wide_depth, origin=origin, res=res)

    grids = build() if pyramid is None or pyramid.key is None else pyramid.grids(build)
    hit = bnb.search(grids, pts, pred, cfg.wide_linear_window, math.radians(cfg.angular_window_deg),
                     min_score)
    return None if hit is None else np.asarray(hit.aTb, np.float64)
