"""Occupancy grid from laser scans at known sensor poses (log-odds ray casting, exact grid traversal).

Each beam is traversed exactly, cell by cell, from the sensor to its end (Amanatides-Woo; compiled with numba in
:mod:`holoslam.maps._raycast_fast`, which states the rule at grid lines and corners): every cell the beam's
segment passes through before its end cell counts one "miss" (once per beam: a straight segment leaves a
convex cell for good), the end cell of a beam with a return counts one "hit". A cell is the half-open square
[x0, x0 + resolution) x [y0, y0 + resolution), the rule of ``OccupancyGrid.world_to_cell``; a beam whose
sensor and end share a cell counts no miss. Cells outside the grid count nothing (a beam may leave and
re-enter an explicit ``bounds``). A beam without a return (``+inf``, or at or beyond ``range_max``) clears
free space up to ``no_return_clear_m`` (default: the scan's range_max) and marks nothing occupied; NaN beams
and beams below range_min are ignored.

Log-odds: L = hits * logit(p_hit) + misses * logit(p_miss), clamped to [-l_max, l_max]; occupancy percent =
round(100 / (1 + exp(-L))); cells never observed are -1 (unknown). The grid's free / occupied thresholds are
the map_server ones (0.196 / 0.65) unless given.

Grid bounds: the sensor positions and beam end points (returns and clearing ends), plus ``margin_m``, snapped
outwards to multiples of the resolution; or explicit ``bounds`` (xmin, ymin, xmax, ymax) for a local grid.

Memory: the beams are cast in chunks of whole scans of about ``CHUNK_BEAMS`` beams, so a long log of a dense
laser (an hour of 1,081 beams at 40 Hz is 160 million beams, 1.3 GB per float array) needs the grid and one
chunk's arrays, not every beam at once: the counts are sums over beams, so the grid is the same.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid
from holoslam.types import Scan

__all__ = ["build_grid", "beam_endpoints", "CHUNK_BEAMS"]

# beams per chunk of ray casting: ~10 float64 arrays of this length live at once (~80 MB), enough to keep numpy's
# per-call overhead negligible (a 5 Hz, 180-beam log casts ~5,500 scans per chunk)
CHUNK_BEAMS = 1_000_000
# cells per block when counts become occupancy: ~6 float64 arrays of this length live at once (~50 MB)
CHUNK_CELLS = 1_000_000


def _logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


def _kernel():
    """The compiled traversal (:mod:`holoslam.maps._raycast_fast`), imported on first use (numba ~0.5 s)."""
    from holoslam.maps import _raycast_fast

    return _raycast_fast


def _checked_poses(wTs: np.ndarray, scans: Sequence[Scan]) -> np.ndarray:
    """``wTs`` as an (N, 3) float array, one finite pose per scan, or a MapError saying which are not."""
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
    return wTs


def beam_endpoints(
    wTs: np.ndarray, scans: Sequence[Scan], no_return_clear_m: float | None = None, first_scan: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All usable beams in world coordinates: origins (B, 2), ends (B, 2), hit (B,) bool (False for a
    no-return beam, whose end is where its clearing stops). Beams in scan order, then beam order.
    ``first_scan``: the index of ``scans[0]`` in the whole log, for error messages about a slice of it."""
    wTs = _checked_poses(wTs, scans)
    z = np.zeros((0, 2))
    if not scans:
        return z, z, np.zeros(0, dtype=bool)
    # every beam of every scan at once: per-beam scan index, index within its scan, scan constants
    counts = np.array([s.ranges.shape[0] for s in scans], dtype=np.int64)
    scan_of = np.repeat(np.arange(len(scans)), counts)
    k = np.arange(scan_of.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
    per_scan = np.array(
        [(s.angle_min, s.angle_increment, s.range_min, s.range_max) for s in scans], dtype=np.float64
    ).reshape(-1, 4)
    a_min, a_inc, r_min, r_max = (per_scan[scan_of, j] for j in range(4))
    r = np.concatenate([s.ranges for s in scans]).astype(np.float64)
    max_ = per_scan[:, 3]
    clear_scan = max_ if no_return_clear_m is None else np.minimum(no_return_clear_m, max_)
    clear_to = clear_scan[scan_of]
    hit = np.isfinite(r) & (r >= r_min) & (r < r_max)
    noret = (np.isposinf(r) | (np.isfinite(r) & (r >= r_max))) & (clear_to > 0)
    use = hit | noret
    if not use.any():
        return z, z, np.zeros(0, dtype=bool)
    bad = np.flatnonzero(noret & ~np.isfinite(clear_to))
    if bad.size:
        raise MapError(
            f"scans {(first_scan + np.unique(scan_of[bad])[:5]).tolist()} have beams without a return and an infinite "
            "range_max, so their free space has no end; pass no_return_clear_m (metres) to build_grid"
        )
    scan_of, hit = scan_of[use], hit[use]
    rr = np.where(hit, r[use], clear_to[use])
    th = wTs[scan_of, 2] + (a_min[use] + a_inc[use] * k[use])  # as Scan.angles, plus the heading
    o = wTs[scan_of, :2]
    e = np.column_stack([o[:, 0] + rr * np.cos(th), o[:, 1] + rr * np.sin(th)])
    return o, e, hit


def _chunks(scans: Sequence[Scan], max_beams: int | None = None) -> list[slice]:
    """Consecutive slices of whole scans holding about ``max_beams`` (``CHUNK_BEAMS``) beams each."""
    limit = CHUNK_BEAMS if max_beams is None else max_beams
    out, start, n = [], 0, 0
    for i, s in enumerate(scans):
        n += s.ranges.shape[0]
        if n >= limit:
            out.append(slice(start, i + 1))
            start, n = i + 1, 0
    if start < len(scans):
        out.append(slice(start, len(scans)))
    return out


def _occupancy(hits: np.ndarray, misses: np.ndarray, l_hit: float, l_miss: float, l_max: float) -> np.ndarray:
    """Occupancy (int8, 0-100, -1 unknown) of flat hit / miss counts: the clipped log odds as a percentage,
    in blocks of ``CHUNK_CELLS`` cells so that the float64 intermediates stay small on a building's grid."""
    out = np.empty(hits.shape[0], np.int8)
    for a in range(0, hits.shape[0], CHUNK_CELLS):
        hb, mb = hits[a:a + CHUNK_CELLS], misses[a:a + CHUNK_CELLS]
        L = np.clip(hb * l_hit + mb * l_miss, -l_max, l_max)
        prob = 100.0 / (1.0 + np.exp(-L))
        out[a:a + CHUNK_CELLS] = np.where((hb + mb) > 0, np.rint(prob), -1)
    return out


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
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> OccupancyGrid:
    """Ray-cast scans taken at sensor poses ``wTs`` ((N, 3), one per scan) into an occupancy grid."""
    if not np.isfinite(resolution) or resolution <= 0:
        raise MapError(f"grid resolution must be a positive number of metres per cell, got {resolution}")
    if not (0.5 < p_hit < 1.0 and 0.0 < p_miss < 0.5):
        raise MapError(f"need 0.5 < p_hit < 1 and 0 < p_miss < 0.5, got p_hit={p_hit}, p_miss={p_miss}")
    wTs = _checked_poses(wTs, scans)
    chunks = _chunks(scans)

    def beams_of(sl: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return beam_endpoints(wTs[sl], scans[sl], no_return_clear_m, sl.start)

    only = beams_of(chunks[0]) if len(chunks) == 1 else None  # most logs: one chunk, its beams computed once
    if bounds is None:
        sensors = wTs[:, :2]
        if sensors.shape[0] == 0:
            raise MapError(
                "build_grid got no scans and no bounds; give scans or bounds=(xmin, ymin, xmax, ymax)"
            )
        # per column (a reduction over axis 0 of an (N, 2) array is ~30x slower)
        lo = np.array([sensors[:, k].min() for k in range(2)])
        hi = np.array([sensors[:, k].max() for k in range(2)])
        for sl in chunks:
            ends = (only if only is not None else beams_of(sl))[1]
            if ends.shape[0]:
                lo = np.minimum(lo, [ends[:, 0].min(), ends[:, 1].min()])
                hi = np.maximum(hi, [ends[:, 0].max(), ends[:, 1].max()])
        lo, hi = lo - margin_m, hi + margin_m
    else:
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        if not (xmax > xmin and ymax > ymin):
            raise MapError(f"bounds must be (xmin, ymin, xmax, ymax) with max > min, got {bounds}")
        lo, hi = np.array([xmin, ymin]), np.array([xmax, ymax])
    lo = np.floor(lo / resolution + 1e-6) * resolution
    w = int(np.ceil((hi[0] - lo[0]) / resolution - 1e-9))
    h = int(np.ceil((hi[1] - lo[1]) / resolution - 1e-9))
    w, h = max(w, 1), max(h, 1)
    # int32 counts (a cell would need 2^31 beams through it to overflow), accumulated in place chunk by chunk
    hits = np.zeros(h * w, np.int32)
    misses = np.zeros(h * w, np.int32)
    for sl in chunks:
        origins, ends, hit = only if only is not None else beams_of(sl)
        u0 = (origins - lo) / resolution  # cell units: cell (row, col) = (floor(u[1]), floor(u[0]))
        u1 = (ends - lo) / resolution
        _kernel().cast_counts_into(
            np.ascontiguousarray(u0[:, 0]),
            np.ascontiguousarray(u0[:, 1]),
            np.ascontiguousarray(u1[:, 0]),
            np.ascontiguousarray(u1[:, 1]),
            np.ascontiguousarray(hit),
            h,
            w,
            hits,
            misses,
        )
    occ = _occupancy(hits, misses, _logit(p_hit), _logit(p_miss), l_max).reshape(h, w)
    return OccupancyGrid(
        occ,
        float(resolution),
        float(lo[0]),
        float(lo[1]),
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
    )
