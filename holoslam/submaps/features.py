"""Scan features H = {point, line, corner, crossing} (seed 002 Eq. 10) from ordered 2-D scan points.

* Lines: the ordered beam end points are cut into runs where consecutive points are farther apart than
  ``gap`` (plus a range-proportional allowance for the beam spacing); each run is split recursively at the
  point farthest from the chord (split-and-merge) until every piece is within ``split_tol`` of its chord; pieces
  with at least ``min_points`` points and ``min_length`` metres get a total-least-squares line (PCA), and
  adjacent collinear pieces are merged. A segment is stored as its end points projected onto the fitted line.
* Corners: two segments with an end of each within ``corner_gap`` (+ ``gap_per_m`` per metre of range, as
  beams spread) of the other meeting at an angle
  between ``corner_min_angle`` and 180 - that angle: the intersection of their lines.
* Crossings: intersections of the extended lines of two non-adjacent segments at an angle of at least
  ``corner_min_angle`` that lie within ``extend`` metres beyond the ends of both segments (a doorway edge, the
  hidden corner behind furniture), excluding points that already are corners.
* Points: small isolated clusters (runs shorter than ``point_max_extent``, e.g. table and chair legs), by their
  centroid.

The rules run compiled, one call per scan (:func:`extract_features`) or per submap (:func:`scans_features`):
``_features_fast``, whose split of the runs is ``_fast.split_pieces``. In Python they were a sixth of the
household run's time under the GIL, holding back the local SLAM beside them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["FeatureConfig", "ScanFeatures", "extract_features", "scans_features", "split_runs", "transform_features"]


@dataclass(frozen=True, slots=True)
class FeatureConfig:
    gap: float = 0.15  # m between consecutive beams of one run
    gap_per_m: float = 0.05  # extra allowance per metre of range (beam spacing)
    split_tol: float = 0.03  # m
    min_points: int = 6
    min_length: float = 0.3  # m
    merge_angle_deg: float = 5.0
    corner_gap: float = 0.2  # m
    corner_min_angle_deg: float = 45.0
    extend: float = 1.0  # m
    point_max_extent: float = 0.12  # m
    point_min_points: int = 2


@dataclass(frozen=True, slots=True)
class ScanFeatures:
    """Features in one frame: ``segments`` (S, 4) x0 y0 x1 y1, ``lines`` (S, 3) unit normal (nx, ny) and
    offset d with n . p = d, ``corners`` (C, 2), ``crossings`` (X, 2), ``points`` (P, 2)."""

    segments: np.ndarray
    lines: np.ndarray
    corners: np.ndarray
    crossings: np.ndarray
    points: np.ndarray


def split_runs(points: np.ndarray, gap: float = 0.15, gap_per_m: float = 0.05) -> list[tuple[int, int]]:
    """[start, end) index ranges of runs of ordered points whose neighbours are close (the features' first
    rule: a gap wider than ``gap`` + ``gap_per_m`` per metre of the farther point's range cuts a run)."""
    from holoslam.submaps._features_fast import _runs

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    starts, ends = _runs(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), float(gap),
                         float(gap_per_m))
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _settings(cfg: FeatureConfig) -> tuple:
    """The kernel's arguments for ``cfg`` (angles as the cosine and sine the rules compare with)."""
    return (float(cfg.gap), float(cfg.gap_per_m), float(cfg.split_tol), int(cfg.min_points), float(cfg.min_length),
            math.cos(math.radians(cfg.merge_angle_deg)), float(cfg.corner_gap),
            math.sin(math.radians(cfg.corner_min_angle_deg)), float(cfg.extend), float(cfg.point_max_extent),
            int(cfg.point_min_points))


def extract_features(points: np.ndarray, config: FeatureConfig | None = None) -> ScanFeatures:
    """Features of one scan's ordered points (M, 2) (beam order, in any frame)."""
    from holoslam.submaps._features_fast import scan_features

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return ScanFeatures(*scan_features(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                                       *_settings(config or FeatureConfig())))


def scans_features(aTb: np.ndarray, scans: Sequence[np.ndarray], config: FeatureConfig | None = None
                   ) -> ScanFeatures:
    """The features of every scan ``scans[k]`` (ordered points (M_k, 2) in frame b_k) in frame a, by the poses
    ``aTb`` (K, 3), stacked in scan order: ``transform_features(aTb[k], extract_features(scans[k]))`` for every
    k, in one compiled call (a submap's features H in its anchor frame)."""
    from holoslam.submaps._features_fast import scans_features as kernel
    from holoslam.warmup import wait_for_kernels

    wait_for_kernels("holoslam.submaps._features_fast")  # a first run's pool compiling it: not twice
    P = np.ascontiguousarray(np.reshape(aTb, (-1, 3)), dtype=np.float64)
    if P.shape[0] == 0:
        return ScanFeatures(np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)))
    pts = [np.asarray(b, dtype=np.float64).reshape(-1, 2) for b in scans]
    start = np.cumsum([0] + [len(b) for b in pts]).astype(np.int64)
    xy = np.vstack(pts)
    return ScanFeatures(*kernel(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]), start, P,
                                *_settings(config or FeatureConfig())))


def transform_features(aTb: np.ndarray, f: ScanFeatures) -> ScanFeatures:
    """The same features expressed in frame a (for putting a scan's features into its submap's anchor frame)."""
    from holoslam import geometry as g

    T = np.asarray(aTb, dtype=np.float64)
    seg = np.column_stack([g.transform_points(T, f.segments[:, :2]), g.transform_points(T, f.segments[:, 2:])])
    R = g.rot2(T[2])
    n = f.lines[:, :2] @ R.T
    d = f.lines[:, 2] + n @ T[:2]
    return ScanFeatures(seg.reshape(-1, 4), np.column_stack([n, d]).reshape(-1, 3),
                        g.transform_points(T, f.corners).reshape(-1, 2),
                        g.transform_points(T, f.crossings).reshape(-1, 2),
                        g.transform_points(T, f.points).reshape(-1, 2))
