"""The store's merged occupancy grid: every working submap's probability grid moved into the world by its
anchor, one world grid at the submaps' resolution. Within a session its submaps' log-odds add (they saw the
home at the same time); across sessions the newer session's known cells replace the older ones' (the home
changed: a moved sofa's old footprint is freed where the new session saw it free)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["MergedGrid", "merge_submaps", "overlay", "to_occupancy_grid"]


@dataclass(frozen=True, eq=False)
class MergedGrid:
    """``prob`` (H, W) float32 occupancy probability (0.5 where unknown), ``known`` (H, W) bool, and the world
    position of cell (0, 0)'s lower-left corner; row 0 is the lowest y (as ``OccupancyGrid``)."""

    prob: np.ndarray
    known: np.ndarray
    origin: tuple[float, float]
    resolution: float

    def occupied_between(self, a: np.ndarray, b: np.ndarray, p_occupied: float, skip_end_m: float) -> np.ndarray:
        """For segments a[i] -> b[i] (N, 2), whether a known cell above ``p_occupied`` lies on them, the last
        ``skip_end_m`` before b left out (an object stands on furniture the laser sees). Sampled every half cell."""
        a = np.asarray(a, np.float64).reshape(-1, 2)
        b = np.asarray(b, np.float64).reshape(-1, 2)
        d = b - a
        length = np.hypot(d[:, 0], d[:, 1])
        n = int(np.ceil(max(float(length.max(initial=0.0)), 1e-9) / (0.5 * self.resolution))) + 1
        f = np.linspace(0.0, 1.0, n)
        pts = a[:, None, :] + f[None, :, None] * d[:, None, :]
        usable = (f[None, :] * length[:, None]) <= (length[:, None] - skip_end_m)
        c = np.floor((pts[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        r = np.floor((pts[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        H, W = self.prob.shape
        inside = (r >= 0) & (r < H) & (c >= 0) & (c < W)
        rr, cc = np.clip(r, 0, H - 1), np.clip(c, 0, W - 1)
        occ = inside & usable & self.known[rr, cc] & (self.prob[rr, cc] > p_occupied)
        return np.asarray(occ.any(axis=1))


def _logit(p: np.ndarray) -> np.ndarray:
    q = np.clip(p, 1e-3, 1 - 1e-3)
    return np.log(q / (1 - q))


def merge_submaps(wTa: np.ndarray, grids: Sequence[tuple[Any, Any, tuple[float, float], float]],
                  session_of: Sequence[int], margin_m: float = 0.5) -> MergedGrid:
    """Merge submap grids (prob, known, origin, resolution in the anchor frame) placed at ``wTa`` (N, 3), newer
    sessions (higher ``session_of``) winning (module docstring). Nearest-cell lookup of each world cell centre."""
    if not len(grids):
        return MergedGrid(np.full((1, 1), 0.5, np.float32), np.zeros((1, 1), bool), (0.0, 0.0), 0.05)
    res = float(grids[0][3])
    corners = []
    for T, (p, _k, o, r) in zip(wTa, grids, strict=True):
        h, w = p.shape
        box = np.array([[o[0], o[1]], [o[0] + w * r, o[1]], [o[0], o[1] + h * r], [o[0] + w * r, o[1] + h * r]])
        corners.append(g.transform_points(T, box))
    allc = np.vstack(corners)
    lo = np.floor((allc.min(axis=0) - margin_m) / res) * res
    hi = np.ceil((allc.max(axis=0) + margin_m) / res) * res
    W, H = (int(round(v)) for v in (hi - lo) / res)
    prob = np.full((H, W), 0.5, np.float32)
    known = np.zeros((H, W), bool)
    order = np.argsort(np.asarray(session_of), kind="stable")
    sessions = np.asarray(session_of)[order]
    for s in np.unique(sessions):
        L = np.zeros((H, W))
        K = np.zeros((H, W), bool)
        for k in order[sessions == s].tolist():
            p, kn, o, r = grids[k]
            c0, r0 = (np.floor((corners[k].min(axis=0) - lo) / res)).astype(int)
            c1, r1 = (np.ceil((corners[k].max(axis=0) - lo) / res)).astype(int)
            rr, cc = np.mgrid[max(r0, 0):min(r1, H), max(c0, 0):min(c1, W)]
            centres = np.column_stack([lo[0] + (cc.ravel() + 0.5) * res, lo[1] + (rr.ravel() + 0.5) * res])
            a = g.transform_points(g.inverse(wTa[k]), centres)
            ac = np.floor((a[:, 0] - o[0]) / r).astype(np.int64)
            ar = np.floor((a[:, 1] - o[1]) / r).astype(np.int64)
            ok = (ar >= 0) & (ar < p.shape[0]) & (ac >= 0) & (ac < p.shape[1])
            ok[ok] = kn[ar[ok], ac[ok]]
            L[rr.ravel()[ok], cc.ravel()[ok]] += _logit(p[ar[ok], ac[ok]].astype(np.float64))
            K[rr.ravel()[ok], cc.ravel()[ok]] = True
        prob[K] = (1.0 / (1.0 + np.exp(-L[K]))).astype(np.float32)
        known |= K
    kr, kc = np.nonzero(known)
    if kr.size == 0:
        return MergedGrid(prob, known, (float(lo[0]), float(lo[1])), res)
    m = int(round(margin_m / res))  # cropped to the known cells and the margin
    r0, r1 = max(int(kr.min()) - m, 0), min(int(kr.max()) + m + 1, H)
    c0, c1 = max(int(kc.min()) - m, 0), min(int(kc.max()) + m + 1, W)
    return MergedGrid(np.ascontiguousarray(prob[r0:r1, c0:c1]), np.ascontiguousarray(known[r0:r1, c0:c1]),
                      (float(lo[0] + c0 * res), float(lo[1] + r0 * res)), res)


def overlay(base: MergedGrid, top: MergedGrid | None) -> MergedGrid:
    """``base`` with ``top``'s known cells replacing its own (the newer observation wins, as across sessions in
    ``merge_submaps``), over the union of both extents. Both grids' cells lie on the same lattice (origins on
    multiples of the resolution from the world's origin, as ``merge_submaps`` makes them); ``top`` None: ``base``."""
    if top is None or not top.known.any():
        return base
    res = base.resolution
    lo = np.minimum(base.origin, top.origin)
    hi = np.maximum(np.asarray(base.origin) + np.array(base.prob.shape[::-1]) * res,
                    np.asarray(top.origin) + np.array(top.prob.shape[::-1]) * res)
    W, H = (int(round(v)) for v in (hi - lo) / res)
    prob = np.full((H, W), 0.5, np.float32)
    known = np.zeros((H, W), bool)
    for m in (base, top):
        c0, r0 = (int(round(v)) for v in (np.asarray(m.origin) - lo) / res)
        h, w = m.prob.shape
        sub_p, sub_k = prob[r0:r0 + h, c0:c0 + w], known[r0:r0 + h, c0:c0 + w]
        sub_p[m.known] = m.prob[m.known]
        sub_k |= m.known
    return MergedGrid(prob, known, (float(lo[0]), float(lo[1])), res)


def to_occupancy_grid(m: MergedGrid):
    """The merged grid as an ``OccupancyGrid`` (-1 unknown, 0..100)."""
    from holoslam.maps.grid import OccupancyGrid

    occ = np.where(m.known, np.rint(m.prob * 100.0), -1).astype(np.int8)
    return OccupancyGrid(occ, m.resolution, m.origin[0], m.origin[1])
