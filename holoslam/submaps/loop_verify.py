"""The map check of a global loop closure: do the maps around the two ends agree where they overlap?

A global match is found with a few metres of scans (``global_search``), and in a building of repeated rooms and
corridor junctions a few metres can fit in several places: on the Freiburg ``aces`` log, kidnapped, the global
search proposes aliases 28 m and 48 m from the truth whose scores (0.53-0.67) equal or beat the right match's
(0.53-0.61). What tells them apart is the larger neighbourhood: the submaps built just before the node (tens of
metres of scans, placed by the estimate, which is accurate over that span) laid onto the submaps around the old
one at the match's pose. Where both know a cell, walls must fall on walls, not in the middle of a room the other
side saw empty. Measured there (every candidate of two kidnapped runs, global rounds every 3 m and every 1 m;
right = within 0.6 m of the good run's closure; four submaps a side):

========================  =====================================================
candidates                agreement (walls on walls / walls on either)
========================  =====================================================
right (8)                 0.96-1.00 (one more, 0.46 m off: 0.71)
aliases 18-43 m off (9)   0.33-0.81
========================  =====================================================

The test is symmetric (the new maps' walls against the old maps and the old maps' walls against the new), uses
only what each side saw (an unknown cell is no evidence either way), and allows ``tolerance_m`` of disagreement
in position (the estimate's local drift and the grids' 5 cm cells). A candidate with little overlap passes with no
verdict: the consistency of several closures (``loop_consistency``) still has to accept it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.probgrid import ProbGrid

__all__ = ["VerifyConfig", "Agreement", "map_agreement"]


@dataclass(frozen=True, slots=True)
class VerifyConfig:
    """Settings of the map check (module docstring)."""

    enabled: bool = True
    neighbours: int = 4  # finished submaps a side: those just before the new one, those around the old one
    occupied_p: float = 0.6  # a wall: a cell at least 0.6 (two hits more than misses at Cartographer's 0.55 / 0.49)
    # known free: a cell a beam crossed ~20 times more than it held a return (odds 0.49 / 0.51 a miss); at 0.4
    # (~10) right matches showed 0.82-0.99 (doors, people, the estimate's drift), at 0.3 0.96-1.00, aliases alike
    free_p: float = 0.3
    tolerance_m: float = 0.1  # m: a wall within this of a wall agrees (two 5 cm cells: local drift, cell size)
    # the fraction of overlapping walls that must agree: right matches 0.96-1.00, aliases 0.33-0.81 (docstring).
    # Measured on full-rate lasers; the loop search scales it as it scales its scores (``LoopConfig.score_reference``,
    # ``scaled``): a sparse laser's walls are less certain where the two sides meet. On aces at 1.4 Hz with half
    # the beams, kidnapped, the right global matches agreed 0.56-0.85 at their poses (0.63-0.95 at the full run's),
    # all under 0.9, and the parts were never joined (48 m off); aliases 0.29-0.80: the check alone cannot tell
    # them apart there, the consistency test's clique of closures from places metres apart does
    min_agreement: float = 0.9
    min_cells: int = 30  # cells of overlap below which the check gives no verdict (a match at a map's edge)

    def scaled(self, scale: float) -> VerifyConfig:
        """The check with ``min_agreement`` times ``scale`` (the loop search's score scale, at most 1)."""
        return replace(self, min_agreement=self.min_agreement * min(1.0, scale))


@dataclass(frozen=True, slots=True)
class Agreement:
    """Walls of one side on walls of the other (``support``) and on cells the other saw free (``conflict``)."""

    support: int
    conflict: int

    @property
    def fraction(self) -> float:
        return self.support / max(1, self.support + self.conflict)

    def verdict(self, cfg: VerifyConfig) -> bool | None:
        """True / False when the overlap is large enough to tell, None otherwise."""
        if self.support + self.conflict < cfg.min_cells:
            return None
        return self.fraction >= cfg.min_agreement


@dataclass(frozen=True, slots=True)
class _Masks:
    wall: np.ndarray  # (rows, cols) bool: a wall within the tolerance
    free: np.ndarray  # (rows, cols) bool: known free, no wall within the tolerance
    walls_xy: np.ndarray  # (K, 2) the centres of the wall cells (grid frame)
    origin: tuple[float, float]
    res: float


def _masks(grid: ProbGrid, cfg: VerifyConfig) -> _Masks:
    import cv2

    wall = grid.prob >= cfg.occupied_p
    r = max(0, int(round(cfg.tolerance_m / grid.resolution)))
    near = cv2.dilate(wall.view(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)).astype(bool) if r else wall
    known = grid.known if grid.known is not None else grid.prob > grid.p_min
    free = known & (grid.prob <= cfg.free_p) & ~near
    rr, cc = np.nonzero(wall)
    xy = np.c_[grid.origin[0] + (cc + 0.5) * grid.resolution, grid.origin[1] + (rr + 0.5) * grid.resolution]
    return _Masks(near, free, xy, grid.origin, grid.resolution)


def _count(points: np.ndarray, mask: _Masks) -> tuple[np.ndarray, np.ndarray]:
    """Per point (grid frame): on a wall, in known free space."""
    c = np.floor((points[:, 0] - mask.origin[0]) / mask.res).astype(np.int64)
    r = np.floor((points[:, 1] - mask.origin[1]) / mask.res).astype(np.int64)
    ok = (r >= 0) & (c >= 0) & (r < mask.wall.shape[0]) & (c < mask.wall.shape[1])
    on_wall, on_free = np.zeros(len(points), bool), np.zeros(len(points), bool)
    on_wall[ok], on_free[ok] = mask.wall[r[ok], c[ok]], mask.free[r[ok], c[ok]]
    return on_wall, on_free


def _side_against(walls: Sequence[tuple[np.ndarray, np.ndarray]], others: Sequence[tuple[_Masks, np.ndarray]]):
    """Walls (points, pose in the common frame) of one side against the other side's masks (mask, pose)."""
    support = conflict = 0
    for xy, cTa in walls:
        if not len(xy):
            continue
        pts = g.transform_points(cTa, xy)
        wall = np.zeros(len(pts), bool)
        free = np.zeros(len(pts), bool)
        for mask, cTb in others:
            w, f = _count(g.transform_points(g.inverse(cTb), pts), mask)
            wall |= w
            free |= f
        support += int(wall.sum())
        conflict += int((free & ~wall).sum())  # free in one old map and a wall in none
    return support, conflict


def map_agreement(grids: Mapping[int, ProbGrid], est_wTa: np.ndarray, part: np.ndarray, m: int, n: int,
                  mTn: np.ndarray, cfg: VerifyConfig) -> Agreement:
    """The agreement of the finished submaps just before n with those around m (``cfg.neighbours`` a side, of
    the same part of the run as their end: ``part[k]`` counts the breaks of local SLAM before submap k), each
    side placed by the estimate ``est_wTa`` and the two sides joined by the candidate ``mTn``."""
    K = cfg.neighbours
    new = [q for q in grids if n - K <= q < n and part[q] == part[n]]
    old = [q for q in grids if abs(q - m) <= K and part[q] == part[m] and (not new or q < min(new))]
    if not new or not old:
        return Agreement(0, 0)
    mTw = g.inverse(est_wTa[m])
    nTw = g.inverse(est_wTa[n])
    # the common frame: m's; old submap q at est mTq, new submap q at mTn ∘ nTq
    old_pose = {q: g.compose(mTw, est_wTa[q]) for q in old}
    new_pose = {q: g.compose(mTn, g.compose(nTw, est_wTa[q])) for q in new}
    masks = {q: _masks(grids[q], cfg) for q in old + new}
    s1, c1 = _side_against([(masks[q].walls_xy, new_pose[q]) for q in new], [(masks[q], old_pose[q]) for q in old])
    s2, c2 = _side_against([(masks[q].walls_xy, old_pose[q]) for q in old], [(masks[q], new_pose[q]) for q in new])
    return Agreement(s1 + s2, c1 + c2)
