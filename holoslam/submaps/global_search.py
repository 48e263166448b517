"""The global loop search: a scan against a whole old submap, over every heading, when the estimate is too
uncertain for a window (Hess et al. 2016 §V: Cartographer searches sampled nodes against every finished submap
with the same branch and bound and accepts a global match at a higher score, ``global_localization_min_score``
0.6).

A window of tens of metres and every heading at the map's 5 cm costs 0.3-1.2 s per submap on a real log's
submaps (aces, 30 x 50 m, 1,100-1,800 headings): too slow to try often. The search is therefore coarse to fine:

1. **coarse**: branch and bound over the submap's grid max-pooled to ``resolution_m`` (0.2 m: 20-70 ms per whole
   aces submap), with the scan's points within ``max_range_m`` (the angular step is the one that moves the
   farthest point by one coarse cell), inside the window clipped to the submap's extent; max-pooling never lowers
   a cell, so the coarse best is an upper bound of the fine one and a right match cannot be pruned there;
2. **fine**: the window's full-resolution branch and bound within ``check_xy_m`` / ``check_deg`` of the coarse best
   (the caller's ``bnb_window.SearchWindow``, whose second-peak search then tells whether the match is ambiguous at the 5 cm scale).
"""

from __future__ import annotations

import math

import numpy as np

from holoslam.submaps import bnb

__all__ = ["pool_grid", "pool_factor", "clip_window", "coarse_match"]


def pool_factor(coarse_m: float, resolution_m: float) -> int:
    """The cells of ``resolution_m`` to a side of a coarse cell at least ``coarse_m`` wide (at least 1): the coarse
    scores' thresholds were measured on 20 cm cells pooled from 5 cm ones, and smaller coarse cells score lower.
    A grid of 8.2 cm cells pools 3 to a side (24.5 cm), not the nearest 2 (16.3 cm: on ACES kidnapped at 1.4 Hz with
    half its beams, mapped at 8.2 cm, 117 of 263 global searches then found no coarse match, 73 at 24.5 cm)."""
    if not coarse_m > 0 or not resolution_m > 0:
        return 1
    return max(1, math.ceil(coarse_m / resolution_m - 1e-9))


def pool_grid(prob: np.ndarray, factor: int) -> np.ndarray:
    """The grid max-pooled over ``factor`` x ``factor`` blocks (cells past the edge count as ``bnb.OUTSIDE``):
    cell (r, c) of the result covers fine cells [r f, (r + 1) f) x [c f, (c + 1) f), so the origin is the same."""
    p = np.asarray(prob, np.float32)
    f = max(1, int(factor))
    if f == 1:
        return p
    h, w = p.shape
    H, W = -(-h // f), -(-w // f)
    q = np.full((H * f, W * f), bnb.OUTSIDE, np.float32)
    q[:h, :w] = p
    return q.reshape(H, f, W, f).max(axis=(1, 3))


def clip_window(seed: np.ndarray, wx: float, wy: float, origin: tuple[float, float], shape: tuple[int, int],
                res: float) -> tuple[np.ndarray, float, float] | None:
    """The part of the window seed +- (wx, wy) (the base's position in the submap's frame) inside the submap's
    grid (``shape`` (H, W) cells of ``res`` m from ``origin``): its centre as a new seed (same heading) and its
    half-widths; None when the window misses the grid (the robot cannot stand where that submap saw nothing)."""
    x0, y0 = origin
    x1, y1 = x0 + shape[1] * res, y0 + shape[0] * res
    lo_x, hi_x = max(seed[0] - wx, x0), min(seed[0] + wx, x1)
    lo_y, hi_y = max(seed[1] - wy, y0), min(seed[1] + wy, y1)
    if lo_x > hi_x or lo_y > hi_y:
        return None
    centre = np.array([(lo_x + hi_x) / 2, (lo_y + hi_y) / 2, seed[2]])
    return centre, (hi_x - lo_x) / 2, (hi_y - lo_y) / 2


def coarse_match(pre_coarse: bnb.PrecomputedGrids, b_pts: np.ndarray, seed: np.ndarray, wx: float, wy: float,
                 wth: float, min_score: float, max_range_m: float) -> bnb.Match | None:
    """Step 1 of the module docstring: the best pose of the coarse grid above ``min_score`` in the window."""
    p = np.asarray(b_pts, np.float64).reshape(-1, 2)
    near = p[np.hypot(p[:, 0], p[:, 1]) <= max_range_m]
    if len(near) < max(10, len(p) // 4):  # a scan of far returns only: all of them
        near = p
    return bnb.search(pre_coarse, near, seed, (wx, wy), min(float(wth), math.pi), min_score)
