"""Submaps (local geometric maps, seed 002 Eq. 10-11): the segmentation policy, the Submap record, its grid.

Segmentation policy (checked at every keyframe; a keyframe is a scan after the robot moved ``keyframe_distance``
or turned ``keyframe_turn_deg`` since the previous one). A new submap starts at the current keyframe when

1. ``distance``: the robot travelled more than ``max_distance`` metres (odometer path length) since the anchor;
2. ``turn``: its heading in the anchor frame differs from the anchor's by more than ``max_turn_deg``;
3. ``time``: more than ``max_time_s`` seconds passed since the anchor (with at least ``min_distance`` travelled,
   so a robot standing still does not make empty submaps);
4. ``doorway`` (a change of place): since the anchor the robot passed a narrow gap, i.e. at some keyframe the
   free width across the robot (the nearest return beside the base on the left plus that on the right, see
   ``side_width``) was below ``doorway_width``, and now the width is above ``doorway_width`` +
   ``doorway_hysteresis`` (the robot came out the other side) and it travelled at least ``min_distance``.

The anchor frame of a submap is the base pose at its first scan, so the robot's pose there is the identity.

The local occupancy grid is a small vectorised ray caster of its own (``local_grid``): ``holoslam.maps.occupancy``
did not exist when this was written. Every beam is sampled at half-cell steps; samples before the hit count as
free, the hit as occupied (log-odds sums of the counts per cell); beams with no return clear up to
``clear_range``. The free samples are counted by a compiled loop (``_fast.free_counts``) without materialising
them; the grid's extent comes from each beam's first and last sample (samples move monotonically along a beam).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from holoslam import geometry as g
from holoslam.maps.grid import OccupancyGrid
from holoslam.submaps.features import FeatureConfig, ScanFeatures
from holoslam.submaps.localize import IcpConfig
from holoslam.submaps.probgrid import ProbGrid

__all__ = [
    "SegmentConfig", "Submap", "side_width", "split_reason", "local_grid", "voxel_downsample", "voxel_append",
]


@dataclass(frozen=True, slots=True)
class SegmentConfig:
    max_distance: float = 3.0  # m
    max_turn_deg: float = 150.0
    max_time_s: float = 60.0
    min_distance: float = 0.5  # m before a time or doorway split
    doorway_width: float = 1.2  # m
    doorway_hysteresis: float = 0.4  # m
    keyframe_distance: float = 0.2  # m
    keyframe_turn_deg: float = 10.0
    voxel: float = 0.03  # m, decimation of a submap's points
    grid_resolution: float = 0.05  # m
    clear_range: float = 4.0  # m
    icp: IcpConfig = field(default_factory=IcpConfig)
    features: FeatureConfig = field(default_factory=FeatureConfig)


@dataclass(frozen=True, eq=False)
class Submap:
    """One local geometric map. ``scan_stamps_ns`` (K,) and ``aTb`` (K, 3) / ``cov_aTb`` (K, 3, 3) are its
    keyframes' base poses in the anchor frame (the first is the anchor, the identity); ``points`` (M, 2) and
    ``normals`` (M, 2) the decimated scan points in the anchor frame; ``scan_points`` the keyframes' points in
    the base frame; ``features`` H in the anchor frame; ``grid`` its local occupancy grid (anchor frame);
    ``reason`` why it was started ("start", "distance", "turn", "time", "doorway", "scans");
    ``track_stamps_ns`` / ``track_aTb`` the base poses of the scans localised in it but not inserted."""

    index: int
    anchor_stamp_ns: int
    scan_stamps_ns: np.ndarray
    aTb: np.ndarray
    cov_aTb: np.ndarray
    scan_points: tuple[np.ndarray, ...]
    points: np.ndarray
    normals: np.ndarray
    features: ScanFeatures
    grid: OccupancyGrid | ProbGrid | None
    reason: str
    track_stamps_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    track_aTb: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def side_width(b_points: np.ndarray, half_length: float = 0.5) -> float:
    """Free width across the robot: the nearest return beside it on the left plus that on the right, counting
    only points alongside the base (|x| <= ``half_length`` in the base frame, lateral distance |y|); inf when a
    side has no return. Door jambs are caught while the robot is within ``half_length`` of the doorway."""
    p = np.asarray(b_points, dtype=np.float64).reshape(-1, 2)
    beside = np.abs(p[:, 0]) <= half_length
    left = p[beside & (p[:, 1] > 0), 1]
    right = -p[beside & (p[:, 1] < 0), 1]
    if left.size == 0 or right.size == 0:
        return float("inf")
    return float(left.min() + right.min())


def split_reason(
    cfg: SegmentConfig, travelled: float, aTb: np.ndarray, elapsed_ns: int, narrow_seen: bool, width: float
) -> str | None:
    """Which rule of the policy (module docstring) starts a new submap now, or None."""
    if travelled > cfg.max_distance:
        return "distance"
    if abs(float(aTb[2])) > np.radians(cfg.max_turn_deg):
        return "turn"
    if travelled >= cfg.min_distance:
        if elapsed_ns > cfg.max_time_s * 1e9:
            return "time"
        if narrow_seen and width > cfg.doorway_width + cfg.doorway_hysteresis:
            return "doorway"
    return None


def voxel_downsample(points: np.ndarray, normals: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Keep the first point (and its normal) of every occupied voxel."""
    if points.shape[0] == 0:
        return points, normals
    codes = _voxel_codes(points, voxel)
    if codes is None:  # an index beyond 31 bits: voxels as rows (slower)
        codes = np.floor(points / voxel).astype(np.int64)
        _, first = np.unique(codes, axis=0, return_index=True)
    else:
        _, first = np.unique(codes, return_index=True)
    first = np.sort(first)
    return points[first], normals[first]


def _voxel_codes(points: np.ndarray, voxel: float) -> np.ndarray | None:
    """One int64 per voxel of each point (x index * 2^32 + y index), or None when an index needs over 31 bits."""
    keys = np.floor(points / voxel).astype(np.int64)
    if keys.size and np.abs(keys).max() >= 2**31:
        return None
    return keys[:, 0] * 2**32 + keys[:, 1]


def voxel_append(
    points: np.ndarray, normals: np.ndarray, codes: np.ndarray, new_points: np.ndarray, new_normals: np.ndarray,
    voxel: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``voxel_downsample(vstack([points, new_points]), ...)`` for ``points`` that already hold one point per
    voxel, with ``codes`` the sorted voxel codes of ``points`` (empty at the start): the old points are kept as
    they are, a new point only if its voxel is new and it is the first new point in it. Returns (points,
    normals, codes)."""
    new_codes = _voxel_codes(np.asarray(new_points, dtype=np.float64), voxel)
    if new_codes is None or codes.shape[0] != points.shape[0]:  # far from the origin: the general path
        P, N = voxel_downsample(np.vstack([points, new_points]), np.vstack([normals, new_normals]), voxel)
        c = _voxel_codes(P, voxel)
        return P, N, np.sort(c) if c is not None else np.full(0, -1, np.int64)
    _, first = np.unique(new_codes, return_index=True)
    first = np.sort(first)
    c = new_codes[first]
    at = np.searchsorted(codes, c)
    fresh = codes[np.minimum(at, codes.size - 1)] != c if codes.size else np.ones(c.size, dtype=bool)
    first, at, c = first[fresh], at[fresh], c[fresh]
    order = np.argsort(c)
    return (np.vstack([points, new_points[first]]), np.vstack([normals, new_normals[first]]),
            np.insert(codes, at[order], c[order]))


def local_grid(
    aTs: np.ndarray, ranges: list[np.ndarray], angles: list[np.ndarray], resolution: float = 0.05,
    clear_range: float = 4.0, margin: float = 0.5,
) -> OccupancyGrid | None:
    """A log-odds occupancy grid from sensor poses ``aTs`` (K, 3) and each scan's ranges/angles (inf = no
    return). Vectorised: one flat array of ray samples for all beams (x and y kept as separate 1-D arrays)."""
    if len(ranges) == 0:
        return None
    K = len(ranges)
    nb = np.array([r.size for r in ranges])
    pose_of = np.repeat(np.arange(K), nb)
    r = np.concatenate(ranges).astype(np.float64)
    a = np.concatenate(angles).astype(np.float64)
    hit = np.isfinite(r)
    reach = np.where(hit, r, clear_range)
    T = np.asarray(aTs, dtype=np.float64).reshape(-1, 3)[pose_of]
    tx, ty = T[:, 0], T[:, 1]
    ang = T[:, 2] + a
    ca, sa = np.cos(ang), np.sin(ang)
    rh = np.where(hit, r, 0.0)
    step = 0.5 * resolution
    ns = np.ceil(reach / step).astype(np.int64)
    # free samples d = k * step, k = 0, 1, ... while d < reach - resolution (a cell short of the hit): a prefix
    # of each ray's ns samples; its length from a division, corrected by one where rounding put it off
    stop = reach - resolution
    nk = np.clip(np.ceil(stop / step).astype(np.int64), 0, ns)
    nk -= (nk > 0) & ((nk - 1) * step >= stop)
    nk += (nk < ns) & (nk * step < stop)
    occ_x = (tx + rh * ca)[hit]
    occ_y = (ty + rh * sa)[hit]
    # a ray's samples move monotonically along it, so its first (the sensor) and last sample bound them all
    some = nk > 0
    d_last = (nk[some] - 1) * step
    last_x = tx[some] + d_last * ca[some]
    last_y = ty[some] + d_last * sa[some]
    lo = np.array([min(last_x.min(initial=np.inf), occ_x.min(initial=np.inf), tx.min()),
                   min(last_y.min(initial=np.inf), occ_y.min(initial=np.inf), ty.min())]) - margin
    hi = np.array([max(last_x.max(initial=-np.inf), occ_x.max(initial=-np.inf), tx.max()),
                   max(last_y.max(initial=-np.inf), occ_y.max(initial=-np.inf), ty.max())]) + margin
    W = int(np.ceil((hi[0] - lo[0]) / resolution))
    H = int(np.ceil((hi[1] - lo[1]) / resolution))

    def flat(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        c = np.floor((x - lo[0]) / resolution).astype(np.int64)
        rr = np.floor((y - lo[1]) / resolution).astype(np.int64)
        return rr * W + c

    free_n = _free_counts(tx, ty, ca, sa, nk, step, lo, resolution, W, H, flat)
    occ_n = np.bincount(flat(occ_x, occ_y), minlength=H * W) if occ_x.size else np.zeros(H * W, np.int64)
    logodds = 0.85 * occ_n - 0.4 * free_n
    prob = 1.0 / (1.0 + np.exp(-np.clip(logodds, -500.0, 500.0)))  # same values; exp(>709) would overflow
    occ = np.where((free_n + occ_n) > 0, np.round(prob * 100.0), -1).astype(np.int8).reshape(H, W)
    return OccupancyGrid(occ, resolution, float(lo[0]), float(lo[1]))


def _free_counts(tx, ty, ca, sa, nk, step, lo, resolution, W, H, flat) -> np.ndarray:
    """Free samples per cell (H * W,): compiled (``_fast.free_counts``) or, without numba, with the samples."""
    try:
        from holoslam.submaps._fast import free_counts
    except ImportError:  # pragma: no cover - numba is a declared dependency
        ray = np.repeat(np.arange(tx.size), nk)
        d = (np.arange(ray.size) - np.repeat(np.cumsum(nk) - nk, nk)) * step
        return np.bincount(flat(tx[ray] + d * ca[ray], ty[ray] + d * sa[ray]), minlength=H * W)
    return free_counts(np.ascontiguousarray(tx), np.ascontiguousarray(ty), ca, sa, nk, float(step),
                       float(lo[0]), float(lo[1]), float(resolution), W, H)


def transform_normals(aTb: np.ndarray, normals: np.ndarray) -> np.ndarray:
    return np.asarray(normals, dtype=np.float64) @ g.rot2(float(aTb[2])).T
