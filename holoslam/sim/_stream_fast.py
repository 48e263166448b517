"""Compiled kernel (numba, ``cache=True``) of the camera-stream renderer, :mod:`holoslam.sim.stream_render`:
the floor / wall / ceiling background of one frame, the same model as ``holoslam.sim.render._background``
(ray per pixel; floor and ceiling planes; the wall distance per column from the middle row's ray; wood planks
along x with grain; distance shading) in one pass over the pixels, in float32. Imported lazily."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT


@nb.njit(**JIT)
def background(K: np.ndarray, wRc: np.ndarray, wtc: np.ndarray, rwall: np.ndarray, ceiling: float,
               out: np.ndarray) -> None:
    """Fill ``out`` (H, W, 3) float32 BGR with the background seen through ``K`` (3, 3) from the camera pose
    (``wRc`` (3, 3), ``wtc`` (3,)); ``rwall`` (W,) the horizontal distance to the wall along each column."""
    h, w = out.shape[0], out.shape[1]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    for c in range(w):
        rw = rwall[c]
        shade = min(1.0, max(0.6, 1.0 - 0.05 * rw))
        wall0, wall1, wall2 = 176.0 * shade, 196.0 * shade, 212.0 * shade
        xn = (c - cx) / fx
        for r in range(h):
            yn = (r - cy) / fy
            d0 = wRc[0, 0] * xn + wRc[0, 1] * yn + wRc[0, 2]
            d1 = wRc[1, 0] * xn + wRc[1, 1] * yn + wRc[1, 2]
            d2 = wRc[2, 0] * xn + wRc[2, 1] * yn + wRc[2, 2]
            horiz = math.sqrt(d0 * d0 + d1 * d1) + 1e-12
            b, g, rr = wall0, wall1, wall2
            if d2 < 0.0:
                t = wtc[2] / -d2
                rf = t * horiz
                if rf < rw:
                    fxw = wtc[0] + d0 * t
                    fyw = wtc[1] + d1 * t
                    band = math.floor(fyw / 0.15)
                    plank = band - 2.0 * math.floor(band / 2.0)
                    grain = 0.06 * math.sin(fxw * 9.0 + 3.0 * band)
                    k = (0.9 + 0.1 * plank + grain) * min(1.0, max(0.6, 1.0 - 0.04 * rf))
                    b, g, rr = 70.0 * k, 110.0 * k, 150.0 * k
            elif d2 > 0.0:
                t = (ceiling - wtc[2]) / d2
                if t * horiz < rw:
                    b, g, rr = 225.0, 228.0, 230.0
            out[r, c, 0] = b
            out[r, c, 1] = g
            out[r, c, 2] = rr
