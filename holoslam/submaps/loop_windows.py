"""The loop search's windows: how far from the estimate a node's match in an old submap is sought, and whether a
match found lies within the bound its window stands for.

A window's half-widths (x m, y m, heading rad, in the old submap's axes) are the drift since the last closure
(``base_window_xy + window_rate`` per metre of graph path, likewise in degrees) or ``window_sigmas`` of the node's
covariance relative to the old submap, the larger; then bounded by dead reckoning's disagreement with the estimate
(with a compass: at most the base plus ``agreement_factor`` times it) or, without a compass, widened to at least
the base plus ``disagreement_window`` times it. Pure functions of ``LoopConfig`` and numpy arrays; the search
(``holoslam.submaps.loops``) caps the windows at ``max_window_xy`` / ``max_window_deg`` and hands what lies
beyond to the global search (``is_global``).
"""

from __future__ import annotations

import math

import numpy as np

from holoslam.submaps.loop_config import LoopConfig

__all__ = ["Windows", "agreement_bound", "beyond_ellipse", "drift_windows", "is_global"]

Windows = tuple[np.ndarray, np.ndarray, np.ndarray]  # (wx m, wy m, wth rad), each (M,)


def drift_windows(cfg: LoopConfig, graph_distance_m: np.ndarray, cov_mTr: np.ndarray | None = None,
                  mTr: np.ndarray | None = None) -> Windows:
    """The windows of M old submaps from the drift alone: graph distances (M,) and, when given, covariances
    (M, 3, 3) of the node's poses ``mTr`` (M, 3) in them, whose ``window_sigmas`` (in the submaps' axes) widen
    them; uncapped, the heading at most a half turn."""
    xy = cfg.base_window_xy + cfg.window_rate * graph_distance_m
    th = np.radians(cfg.base_window_deg + cfg.window_deg_rate * graph_distance_m)
    if cov_mTr is None or mTr is None:
        return xy, xy.copy(), np.minimum(th, math.pi)
    cs, sn = np.cos(mTr[:, 2]), np.sin(mTr[:, 2])
    a, b, d = cov_mTr[:, 0, 0], cov_mTr[:, 0, 1], cov_mTr[:, 1, 1]
    # R S R^T of the position block, R = rot2(mTr's heading): its diagonal
    sxx = cs * cs * a - 2.0 * cs * sn * b + sn * sn * d
    syy = sn * sn * a + 2.0 * cs * sn * b + cs * cs * d
    k = cfg.window_sigmas
    wx = k * np.sqrt(np.maximum(sxx, 0.0))
    wy = k * np.sqrt(np.maximum(syy, 0.0))
    wth = np.minimum(k * np.sqrt(np.maximum(cov_mTr[:, 2, 2], 0.0)), math.pi)
    return np.maximum(xy, wx), np.maximum(xy, wy), np.minimum(np.maximum(th, wth), math.pi)


def agreement_bound(cfg: LoopConfig, win: Windows, disagreement: tuple[np.ndarray, np.ndarray] | None,
                    compass: bool = True) -> Windows:
    """Windows (wx, wy, wth) bounded by dead reckoning's disagreement (m, rad) with the estimate: with a
    compass at most the base plus ``agreement_factor`` times it, without one at least the base plus
    ``disagreement_window`` times it (up to ``max_window_xy``; ``LoopConfig``); unchanged without one."""
    wx, wy, wth = win
    if disagreement is None:
        return wx, wy, wth
    if not compass:
        if cfg.disagreement_window <= 0:
            return wx, wy, wth
        d = disagreement[0]
        f = np.where(np.isfinite(d), np.minimum(cfg.base_window_xy + cfg.disagreement_window * d, cfg.max_window_xy),
                     0.0)
        return np.maximum(wx, f), np.maximum(wy, f), wth
    if cfg.agreement_factor <= 0:
        return wx, wy, wth
    bxy = cfg.base_window_xy + cfg.agreement_factor * disagreement[0]
    return (np.minimum(wx, bxy), np.minimum(wy, bxy),
            np.minimum(wth, math.radians(cfg.base_window_deg) + cfg.agreement_factor * disagreement[1]))


def is_global(cfg: LoopConfig, wx: float, wy: float, wth: float) -> bool:
    """Whether a window reaches beyond the caps (``max_window_xy`` / ``max_window_deg``): the global search's."""
    return max(wx, wy) > cfg.max_window_xy or wth > math.radians(cfg.max_window_deg) + 1e-12


def beyond_ellipse(aTb, seed, wxy, scale: float) -> bool:
    """Whether the match at ``aTb`` lies outside the ellipse inscribed in its window (half-widths ``wxy`` about
    ``seed``), scaled by ``scale`` (``LoopConfig.far_from_seed``; inf: never)."""
    wx, wy = (float(w) for w in np.broadcast_to(np.asarray(wxy, np.float64), (2,)))
    dx, dy = float(aTb[0]) - float(seed[0]), float(aTb[1]) - float(seed[1])
    return (dx / wx) ** 2 + (dy / wy) ** 2 > scale ** 2
