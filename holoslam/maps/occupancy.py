"""Occupancy grid from laser scans at known sensor poses (log-odds ray casting, vectorised).

Each beam is sampled at sub-cell steps (``step`` x resolution, default half a cell) from the sensor to its
end;
the cells the samples fall in before the end cell count one "miss" each (a cell crossed by several samples
of one beam counts once: a straight ray leaves a convex cell for good, so repeated consecutive cells are
dropped), the end cell of a beam with a return counts one "hit". A beam without a return (``+inf``, or at or
beyond ``range_max``) clears free space up to ``no_return_clear_m`` (default: the scan's range_max) and
marks nothing occupied; NaN beams and beams below range_min are ignored. Counts are accumulated with
``np.bincount`` over all beams of all scans (scans processed in chunks to bound memory).

Log-odds: L = hits * logit(p_hit) + misses * logit(p_miss), clamped to [-l_max, l_max]; occupancy percent =
round(100 / (1 + exp(-L))); cells never observed are -1 (unknown). The grid's free / occupied thresholds are
the map_server ones (0.196 / 0.65) unless given.

Grid bounds: the sensor positions and beam end points (returns and clearing ends), plus ``margin_m``, snapped
outwards to multiples of the resolution; or explicit ``bounds`` (xmin, ymin, xmax, ymax) for a local grid.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid
from holoslam.types import Scan

__all__ = ["build_grid", "beam_endpoints"]


def _logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


def beam_endpoints(
    wTs: np.ndarray, scans: Sequence[Scan], no_return_clear_m: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All usable beams in world coordinates: origins (B, 2), ends (B, 2), hit (B,) bool (False for a
    no-return beam, whose end is where its clearing stops)."""
    wTs = np.asarray(wTs, dtype=np.float64).reshape(-1, 3)
    if wTs.shape[0] != len(scans):
        raise MapError(
            f"build_grid got {wTs.shape[0]} sensor poses for {len(scans)} scans; pass one pose per scan"
        )
    if not np.isfinite(wTs).all():
        bad = np.flatnonzero(~np.isfinite(wTs).all(axis=1))
        raise MapError(
            f"sensor poses {bad[:5].tolist()} are not finite; drop those scans before building a grid"
        )
    origins, ends, hits = [], [], []
    for i, scan in enumerate(scans):
        r = scan.ranges.astype(np.float64)
        a = scan.angles
        hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
        clear_to = scan.range_max if no_return_clear_m is None else min(no_return_clear_m, scan.range_max)
        noret = (np.isposinf(r) | (np.isfinite(r) & (r >= scan.range_max))) & (clear_to > 0)
        use = hit | noret
        if not use.any():
            continue
        rr = np.where(hit, r, clear_to)[use]
        th = wTs[i, 2] + a[use]
        o = wTs[i, :2]
        e = np.column_stack([o[0] + rr * np.cos(th), o[1] + rr * np.sin(th)])
        origins.append(np.broadcast_to(o, e.shape))
        ends.append(e)
        hits.append(hit[use])
    if not ends:
        z = np.zeros((0, 2))
        return z, z, np.zeros(0, dtype=bool)
    return np.concatenate(origins), np.concatenate(ends), np.concatenate(hits)


def build_grid(
    wTs: np.ndarray,
    scans: Sequence[Scan],
    resolution: float = 0.05,
    *,
    margin_m: float = 0.5,
    bounds: tuple[float, float, float, float] | None = None,
    no_return_clear_m: float | None = None,
    p_hit: float = 0.75,
    p_miss: float = 0.4,
    l_max: float = 6.0,
    step: float = 0.5,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
    chunk_beams: int = 8000,
) -> OccupancyGrid:
    """Ray-cast scans taken at sensor poses ``wTs`` ((N, 3), one per scan) into an occupancy grid."""
    if not np.isfinite(resolution) or resolution <= 0:
        raise MapError(f"grid resolution must be a positive number of metres per cell, got {resolution}")
    if not (0.5 < p_hit < 1.0 and 0.0 < p_miss < 0.5):
        raise MapError(f"need 0.5 < p_hit < 1 and 0 < p_miss < 0.5, got p_hit={p_hit}, p_miss={p_miss}")
    if not 0 < step <= 1:
        raise MapError(f"ray sampling step must be in (0, 1] cells, got {step}")
    origins, ends, hit = beam_endpoints(wTs, scans, no_return_clear_m)
    if bounds is None:
        pts = np.concatenate([np.asarray(wTs, dtype=np.float64).reshape(-1, 3)[:, :2], ends])
        if pts.shape[0] == 0:
            raise MapError(
                "build_grid got no scans and no bounds; give scans or bounds=(xmin, ymin, xmax, ymax)"
            )
        lo = pts.min(axis=0) - margin_m
        hi = pts.max(axis=0) + margin_m
    else:
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        if not (xmax > xmin and ymax > ymin):
            raise MapError(f"bounds must be (xmin, ymin, xmax, ymax) with max > min, got {bounds}")
        lo, hi = np.array([xmin, ymin]), np.array([xmax, ymax])
    lo = np.floor(lo / resolution + 1e-6) * resolution
    w = int(np.ceil((hi[0] - lo[0]) / resolution - 1e-9))
    h = int(np.ceil((hi[1] - lo[1]) / resolution - 1e-9))
    w, h = max(w, 1), max(h, 1)
    ncell = h * w
    hits = np.zeros(ncell, dtype=np.int64)
    misses = np.zeros(ncell, dtype=np.int64)

    def cell_index(xy: np.ndarray) -> np.ndarray:
        col = np.floor((xy[..., 0] - lo[0]) / resolution).astype(np.int64)
        row = np.floor((xy[..., 1] - lo[1]) / resolution).astype(np.int64)
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        return np.where(inside, row * w + col, -1)

    # hits: end cells of beams with a return
    he = cell_index(ends[hit])
    hits += np.bincount(he[he >= 0], minlength=ncell)

    # misses: samples along each beam before its end cell
    ds = step * resolution
    length = np.linalg.norm(ends - origins, axis=1)
    end_cell = cell_index(ends)
    order = np.argsort(length)  # chunks of similar length waste fewer padded samples
    for c0 in range(0, order.shape[0], chunk_beams):
        sel = order[c0 : c0 + chunk_beams]
        ns = int(np.ceil(length[sel].max() / ds)) + 1 if sel.size else 0
        if ns <= 0:
            continue
        t = np.arange(ns) * ds  # (S,)
        o, e, ln = origins[sel], ends[sel], length[sel]
        u = (e - o) / np.maximum(ln, 1e-12)[:, None]
        pts = o[:, None, :] + t[None, :, None] * u[:, None, :]  # (B, S, 2)
        idx = cell_index(pts)
        valid = (t[None, :] < ln[:, None]) & (idx >= 0) & (idx != end_cell[sel][:, None])
        first = np.ones_like(valid)
        first[:, 1:] = idx[:, 1:] != idx[:, :-1]
        take = valid & first
        misses += np.bincount(idx[take], minlength=ncell)

    L = np.clip(hits * _logit(p_hit) + misses * _logit(p_miss), -l_max, l_max)
    prob = 100.0 / (1.0 + np.exp(-L))
    occ = np.where((hits + misses) > 0, np.rint(prob), -1).astype(np.int8).reshape(h, w)
    return OccupancyGrid(
        occ,
        float(resolution),
        float(lo[0]),
        float(lo[1]),
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
    )
