"""Revisits: loop closures between a node and older, finished submaps, found however far odometry has drifted.

For a node r of submap n at the current world estimate wTr, every finished submap m (not n's own neighbours in
the chain) whose anchor lies within ``max_constraint_distance`` of wTr is searched by branch-and-bound over its
precomputed multi-resolution grids (``bnb``, Hess et al. 2016) in a window around the estimate mTr that grows
with the uncertainty of that estimate: ``window_xy = min(max_window_xy, base + rate * d)``, d the length of the
shortest path from m to n in the graph found so far, chain edges weighing the distance the robot travelled
between their anchors and closures nothing (the relative pose of m and n is as uncertain as the drift along
the best-constrained way from one to the other; drift of odometry plus scan matching is a few per cent of the
distance on real robots). The estimate is re-optimised after every closure. A match counts when
its score (mean probability of the points) reaches ``min_score`` (``min_score_wide`` for windows beyond
``wide_window_xy``: a wide search has more chances of a wrong match), is refined by the continuous matcher
against m's grid, and gives the ``loop`` relative pose of Eq. 15, mTn = mTr ∘ (nTr)^-1, with the refined
match's covariance. Loops enter the graph with a robust kernel (DCS in ``solve``), so a wrong one that passes
here does not bend the map. Defaults: Cartographer's published constraint-builder settings (SPEC §8: +-7 m,
+-30 deg, 15 m, score 0.55 / 0.6, depth 7).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.probgrid import ProbGrid
from holoslam.submaps.scanmatch import MatchConfig, match_scan

__all__ = ["LoopConfig", "LoopCandidate", "LoopSearch"]


@dataclass(frozen=True, slots=True)
class LoopConfig:
    every_nodes: int = 3  # search from every k-th node (Cartographer samples 30 % of pairs)
    max_constraint_distance: float = 15.0  # m between the node and an old submap's anchor
    base_window_xy: float = 1.0  # m, window half-width right after a closure
    window_rate: float = 0.05  # m of window per m travelled since the last closure
    max_window_xy: float = 7.0  # m
    base_window_deg: float = 10.0
    window_deg_rate: float = 1.0  # deg per m travelled since the last closure
    max_window_deg: float = 30.0
    min_score: float = 0.55
    min_score_wide: float = 0.6
    wide_window_xy: float = 3.0  # m
    depth: int = 7
    skip_recent: int = 2  # the submaps this many before the current one are its chain neighbours
    max_per_pair: int = 4  # closures kept between one old submap and one new submap
    wide_search_spacing: float = 2.0  # m travelled between two wide searches of one old submap
    precomputed_cache: int = 64  # submaps whose max-pooled grids stay in memory (a few ms to rebuild one)
    max_searches_per_node: int = 3  # narrow searches per node, nearest old submaps first (cost where many overlap)


@dataclass(frozen=True, slots=True)
class LoopCandidate:
    old: int
    new: int
    mTn: np.ndarray
    cov_mTn: np.ndarray
    score: float
    window_xy: float


class LoopSearch:
    """Holds the finished submaps' precomputed grids and searches nodes against them."""

    def __init__(self, cfg: LoopConfig, match_cfg: MatchConfig) -> None:
        self.cfg = cfg
        # the refinement against an old map starts from the branch-and-bound pose; its window (for the score
        # surface, hence the covariance) is wide enough to show a corridor's ambiguity along its length
        self.refine_cfg = MatchConfig(
            linear_window=0.5, angular_window_deg=3.0, translation_delta_weight=1e3, rotation_delta_weight=1e3, occupied_weight=match_cfg.occupied_weight,
            translation_weight=match_cfg.translation_weight, rotation_weight=match_cfg.rotation_weight,
            iterations=match_cfg.iterations, kappa=match_cfg.kappa, min_score=0.0)
        self.grids: dict[int, ProbGrid] = {}
        self.pre: OrderedDict[int, object] = OrderedDict()
        self.pairs: dict[tuple[int, int], int] = {}
        self.last_wide: dict[int, float] = {}
        self.tried = 0

    def add_submap(self, index: int, grid: ProbGrid) -> None:
        self.grids[index] = grid

    def _precomputed(self, m: int):
        from holoslam.submaps import bnb

        if m in self.pre:
            self.pre.move_to_end(m)
            return self.pre[m]
        gr = self.grids[m]
        self.pre[m] = bnb.precompute(gr.prob, self.cfg.depth, origin=gr.origin, res=gr.resolution)
        if len(self.pre) > self.cfg.precomputed_cache:  # least recently searched out: memory stays bounded
            self.pre.popitem(last=False)
        return self.pre[m]

    def window(self, graph_distance_m: float) -> tuple[float, float]:
        """Search window half-widths (m, rad) for a pair this far apart in the graph."""
        c = self.cfg
        xy = min(c.max_window_xy, c.base_window_xy + c.window_rate * graph_distance_m)
        deg = min(c.max_window_deg, c.base_window_deg + c.window_deg_rate * graph_distance_m)
        return xy, math.radians(deg)

    def search(self, n: int, nTr: np.ndarray, cov_nTr: np.ndarray, b_pts: np.ndarray, est_wTa: np.ndarray,
               graph_distance: np.ndarray, travelled: float = 0.0) -> list[LoopCandidate]:
        """Loop candidates of node r (pose ``nTr`` in submap n) against the finished submaps;
        ``graph_distance[m]`` is the graph path length from m to n (see the module docstring); ``travelled``
        the odometer reading, which spaces wide searches of one old submap ``wide_search_spacing`` apart (a
        wide window costs ~10 ms; one every couple of metres finds a revisit as surely as one per node)."""
        from holoslam.submaps import bnb

        c = self.cfg
        wTr = g.compose(est_wTa[n], nTr)
        olds = [m for m in self.grids if m < n - c.skip_recent and self.pairs.get((m, n), 0) < c.max_per_pair]
        if not olds:
            return []
        olds_arr = np.array(olds)
        dist = np.hypot(*(est_wTa[olds_arr, :2] - wTr[:2]).T)
        found: list[LoopCandidate] = []
        searched = 0
        for q in np.argsort(dist, kind="stable").tolist():  # nearest first
            m, d = int(olds_arr[q]), float(dist[q])
            wxy, wth = self.window(float(graph_distance[m]))
            if d > c.max_constraint_distance + wxy:
                continue
            if wxy <= c.wide_window_xy and searched >= c.max_searches_per_node:
                continue  # narrow (near in the graph): the nearest few suffice; wide ones are spaced instead
            wide = wxy > c.wide_window_xy
            if wide and travelled - self.last_wide.get(m, -np.inf) < c.wide_search_spacing:
                continue
            if wide:
                self.last_wide[m] = travelled
            min_score = c.min_score_wide if wide else c.min_score
            seed = g.between(est_wTa[m], wTr)
            self.tried += 1
            searched += not wide
            hit = bnb.search(self._precomputed(m), b_pts, seed, wxy, wth, min_score)
            if hit is None:
                continue
            gr = self.grids[m]
            ref = match_scan(gr.prob, gr.origin, gr.resolution, b_pts, hit.aTb, self.refine_cfg)
            if ref.score < min_score or np.hypot(*(ref.aTb[:2] - hit.aTb[:2])) > 2 * gr.resolution:
                continue
            from holoslam.submaps.deadreckon import relative_anchor_pose

            mTn, cov_mTn = relative_anchor_pose(ref.aTb, ref.cov_aTb, nTr, cov_nTr)
            found.append(LoopCandidate(m, n, mTn, cov_mTn, ref.score, wxy))
            self.pairs[(m, n)] = self.pairs.get((m, n), 0) + 1
        return found
