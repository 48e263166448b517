"""The points a scan is matched with: an adaptive voxel filter (Cartographer's ``AdaptiveVoxelFilter``).

A dense laser (1,000-2,000 beams) gives far more points than scan matching needs: the matcher's cost grows with
the points, its accuracy hardly does once the scan's structure is covered. ``adaptive_voxel_filter`` keeps one
point per voxel (the first, in beam order) with the largest voxel edge, up to ``max_length_m``, that still
leaves at least ``min_num_points`` points; a scan of no more than ``min_num_points`` points is kept whole.

Defaults: at least 200 points (Cartographer's 2D ``adaptive_voxel_filter.min_num_points``) and voxels of at
most 2 cm (Cartographer's 0.5 m is tuned for speed, not for the household's millimetres). Measured with
``benchmarks/bench_scan_filter.py`` (a 1,081-beam 40 Hz laser on the simulated household route, 30 s, wall time
of local SLAM and RMS error of consecutive nodes): every point 2.54 s, 1.21 mm; 2 cm 1.87 s, 1.30 mm; 2.5 cm
1.78 s, 1.42 mm; 5 cm (one grid cell) 1.29 s, 1.82 mm; 0.5 m 1.23 s, 2.69 mm (the default over 60 s: 0.91x the
time, 1.26 against 1.18 mm: the gain is modest at 1,000 beams and grows with denser lasers). On fr079 (360 beams) 2 cm maps to
0.0662 m / 0.439 deg against 0.0660 m / 0.442 deg with every point; intel, aces and the simulated household
(180-181 beams) are not filtered."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ScanFilterConfig", "adaptive_voxel_filter"]


@dataclass(frozen=True, slots=True)
class ScanFilterConfig:
    """Adaptive voxel filter of the points a scan is matched with (module docstring)."""

    max_length_m: float = 0.02  # m, the largest voxel edge tried
    min_num_points: int = 200  # points kept at least (Cartographer 2D: 200); 0 turns the filter off

    def __post_init__(self) -> None:
        from holoslam.errors import ConfigError

        if not self.max_length_m > 0 or self.min_num_points < 0:
            raise ConfigError(f"frontend.local.scan_filter: max_length_m must be > 0 and min_num_points >= 0, got "
                              f"{self.max_length_m}, {self.min_num_points}")


def _first_per_voxel(points: np.ndarray, edge: float) -> np.ndarray:
    """Indices (sorted) of the first point in each occupied voxel of edge ``edge``."""
    keys = np.floor(points / edge).astype(np.int64)
    code = keys[:, 0] * np.int64(1 << 32) + keys[:, 1]  # |index| < 2^31 for scans within 10^7 voxels
    _, first = np.unique(code, return_index=True)
    return np.sort(first)


def adaptive_voxel_filter(points: np.ndarray, cfg: ScanFilterConfig = ScanFilterConfig()) -> np.ndarray:
    """The points (N, 2) to match with: ``points`` itself when it has at most ``min_num_points``, else one
    point per voxel of the largest edge (binary search, 1 % of ``max_length_m`` resolution) keeping at least
    ``min_num_points``."""
    pts = np.asarray(points, dtype=np.float64)
    if cfg.min_num_points <= 0 or len(pts) <= cfg.min_num_points:
        return pts
    keep = _first_per_voxel(pts, cfg.max_length_m)
    if len(keep) >= cfg.min_num_points:
        return pts[keep]
    lo, hi = 0.0, cfg.max_length_m  # lo keeps enough (edge 0: every point), hi too few
    best = np.arange(len(pts))
    while hi - lo > 0.01 * cfg.max_length_m:
        mid = 0.5 * (lo + hi)
        k = _first_per_voxel(pts, mid)
        if len(k) >= cfg.min_num_points:
            lo, best = mid, k
        else:
            hi = mid
    return pts[best]
