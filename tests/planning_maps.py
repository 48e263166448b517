"""Synthetic free masks for the planning and holographic tests: random obstacle maps and a small flat."""

from __future__ import annotations

import numpy as np


def random_map(seed: int, h: int, w: int, n_rect: int, n_dots: int) -> np.ndarray:
    """Random free mask: rectangles and single cells of obstacles."""
    rng = np.random.default_rng(seed)
    free = np.ones((h, w), dtype=bool)
    for _ in range(n_rect):
        r, c = rng.integers(0, h), rng.integers(0, w)
        free[r : r + rng.integers(1, max(h // 3, 2)), c : c + rng.integers(1, max(w // 3, 2))] = False
    free[rng.integers(0, h, n_dots), rng.integers(0, w, n_dots)] = False
    return free


def apartment_free(res: float = 0.05) -> np.ndarray:
    """A 10.5 x 9.5 m flat: outer walls, four rooms and a hall, doorways, furniture."""
    H, W = int(round(9.5 / res)), int(round(10.5 / res))
    occ = np.zeros((H, W), dtype=bool)
    t = 2
    occ[:t, :] = occ[-t:, :] = True
    occ[:, :t] = occ[:, -t:] = True

    def c(x):
        return int(round(x / res))

    occ[:, c(4.0) : c(4.0) + t] = True  # west rooms | east
    occ[c(5.0) : c(5.0) + t, :] = True  # south | north
    occ[c(5.0) :, c(7.5) : c(7.5) + t] = True
    occ[c(2.5) : c(2.5) + t, c(4.0) :] = True
    for y0, y1 in ((1.0, 1.9), (6.5, 7.4)):  # doors in the x = 4 wall
        occ[c(y0) : c(y1), c(4.0) : c(4.0) + t] = False
    for x0, x1 in ((1.5, 2.4), (5.0, 5.9)):  # doors in the y = 5 wall
        occ[c(5.0) : c(5.0) + t, c(x0) : c(x1)] = False
    occ[c(7.0) : c(7.9), c(7.5) : c(7.5) + t] = False
    occ[c(2.5) : c(2.5) + t, c(8.0) : c(8.9)] = False
    for x, y, w_, h_ in (
        (1.0, 3.0, 1.2, 0.8),
        (5.5, 0.5, 1.5, 0.6),
        (8.5, 6.0, 0.8, 1.5),
        (2.0, 7.5, 1.0, 1.0),
    ):
        occ[c(y) : c(y + h_), c(x) : c(x + w_)] = True
    return ~occ
