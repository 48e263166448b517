"""A corridor's periodic aliases: the scan's score along a loop closure's least certain axis, beyond its window.

A windowed loop search (``holoslam.submaps.loops``) sees the poses within its window only. Along a corridor of
identical rooms or regularly spaced doors the scan fits every period along it about as well: where the window
holds one of those places and not the truth (the estimate drifted a period or more), the match is sharp, no
second peak shows in the window, and the closure pulls the new submap a room's width along the corridor with a
centimetre covariance. On the simulated 350 m building such closures are nearly all of the wrong ones (~20 of ~90
a run: heading within 1 deg, 4-7 m along a corridor) and on the shared intel log with wide windows (7.8-9.1 m).

:func:`periodic_peaks` scores the matched scan shifted along the major axis of the match's covariance (the
corridor's direction where the match is a ridge; any direction otherwise) up to ``search_m`` each way, by the
cells holding its points (nearest cell; outside the grid the floor ``p_min``; compiled,
``_grid_fast.line_scores``), and returns the shifted poses
whose score is a local maximum within ``margin`` of the match's own, farther than ``exclude_m`` from it (the
match's own peak). A closure with such peaks keeps their spread along that axis in its covariance
(``bnb_window.spanning_covariance``, as a second peak inside the window does): it still fixes the position across
the corridor and the heading, not which period along it.
"""

from __future__ import annotations

import math

import numpy as np

from holoslam import geometry as g

__all__ = ["periodic_peaks"]


def periodic_peaks(prob: np.ndarray, origin: tuple[float, float], resolution: float, p_min: float,
                   b_points: np.ndarray, aTb: np.ndarray, cov_aTb: np.ndarray, margin: float, search_m: float,
                   exclude_m: float) -> list[np.ndarray]:
    """The poses (3,) along ``cov_aTb``'s major axis through ``aTb`` (within ``search_m``, beyond ``exclude_m``)
    where the scan's points ``b_points`` (N, 2, base frame) score a local maximum no more than ``margin`` below
    their score at ``aTb``, on the probability grid ``prob`` (cell (r, c) at ``origin`` + (c, r) ``resolution``)."""
    from holoslam.submaps import _grid_fast as fast

    if search_m <= exclude_m or len(b_points) == 0:
        return []
    _ev, V = np.linalg.eigh(np.asarray(cov_aTb, np.float64)[:2, :2])
    u = V[:, 1]  # the least certain direction
    steps = int(math.floor(search_m / resolution))
    shifts = np.arange(-steps, steps + 1) * resolution
    a_pts = g.transform_points(aTb, b_points)
    score = fast.line_scores(np.ascontiguousarray(prob, np.float32), float(origin[0]), float(origin[1]),
                             float(resolution), np.ascontiguousarray(a_pts[:, 0], np.float64),
                             np.ascontiguousarray(a_pts[:, 1], np.float64), float(u[0]), float(u[1]), shifts,
                             float(p_min))
    at = score[steps] - margin
    k = np.arange(1, len(shifts) - 1)
    peak = ((score[k] >= score[k - 1]) & (score[k] >= score[k + 1]) & (score[k] >= at)
            & (np.abs(shifts[k]) >= exclude_m))
    return [np.array([aTb[0] + d * u[0], aTb[1] + d * u[1], aTb[2]]) for d in shifts[k[peak]]]
