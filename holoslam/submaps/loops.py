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
against m's grid, and is unambiguous: no pose of the window outside a small box around it
(``ambiguity_exclude_xy``, ``ambiguity_exclude_deg``) scores within ``ambiguity_margin`` of it. Along a
corridor, or between two similar rooms, the best of the window can be an alias metres from the truth with a
flat score surface, and the refinement's covariance (its +-0.5 m surface) does not cover the error; such a
match is dropped (``ambiguity="reject"``) or kept with a covariance spanning the peaks (``"span"``). An
accepted match gives the ``loop`` relative pose of Eq. 15, mTn = mTr ∘ (nTr)^-1, with the refined match's
covariance. Loops enter the graph with a robust kernel (Huber in a run, ``optimise.run_build_options``) and the
final solve's chi-square rounds, so a wrong one that passes here bends the map less. Defaults: Cartographer's
published constraint-builder settings (SPEC §8: +-7 m, +-30 deg, 15 m, score 0.55 / 0.6, depth 7); the
ambiguity test's were measured on the real logs (``LoopConfig``).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.loop_config import LoopConfig
from holoslam.submaps.loop_consistency import LoopConsistency
from holoslam.submaps.loop_verify import map_agreement
from holoslam.submaps.probgrid import ProbGrid
from holoslam.submaps.scan_filter import ScanFilterConfig, adaptive_voxel_filter
from holoslam.submaps.scanmatch import MatchConfig, match_scan

__all__ = ["LoopConfig", "LoopCandidate", "LoopSearch"]


@dataclass(frozen=True, slots=True)
class LoopCandidate:
    old: int
    new: int
    mTn: np.ndarray
    cov_mTn: np.ndarray
    score: float
    window_xy: float
    travelled: float = math.nan  # m, the odometer at the node (closures of nearby nodes cannot vouch for each other)


class LoopSearch:
    """Holds the finished submaps' precomputed grids and searches nodes against them."""

    def __init__(self, cfg: LoopConfig, match_cfg: MatchConfig) -> None:
        if cfg.ambiguity not in ("reject", "span", "off"):
            raise ValueError(f"LoopConfig.ambiguity must be 'reject', 'span' or 'off', got {cfg.ambiguity!r}")
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
        self.pre_coarse: OrderedDict[int, object] = OrderedDict()  # coarse grids of the global search
        self.last_global: dict[int, float] = {}  # odometer reading at each old submap's last global search
        self.last_global_round = -math.inf  # odometer reading at the last node that ran global searches
        self.consistency = LoopConsistency(cfg.consistency)
        self.breaks: list[int] = []  # submaps where local SLAM started afresh (``add_break``)
        self.counts: dict[str, int] = {}  # searches and their outcomes, by reason (the run report's loop section)
        self.seconds = {"windowed": 0.0, "global": 0.0}  # wall seconds spent in each kind of search
        self.scale = 1.0  # of every score threshold: the local matches' usual score / score_reference, at most 1
        self.ambiguous = 0  # matches with a second peak (rejected or widened, ``LoopConfig.ambiguity``)
        # (old, new, best bnb.Match, its second peaks) of every branch-and-bound match checked, for diagnostics
        self.peaks: list[tuple[int, int, object, list]] = []

    def add_submap(self, index: int, grid: ProbGrid) -> None:
        self.grids[index] = grid

    def add_break(self, index: int) -> None:
        """Local SLAM started afresh at submap ``index`` (its relation to the ones before is the odometry's)."""
        self.breaks.append(index)

    def _parts(self, count: int) -> np.ndarray:
        """(count,) the part of the run of each submap index: the breaks before it."""
        return np.searchsorted(np.sort(np.array(self.breaks, np.int64)), np.arange(count), side="right")

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

    def window(self, graph_distance_m: float, cov_mTr: np.ndarray | None = None,
               mTr: np.ndarray | None = None) -> tuple[float, float, float]:
        """Search window half-widths (x m, y m, rad) in the old submap's frame for a node this far from it in the
        graph (the drift since the last closure) and, when given, with this covariance of its pose ``mTr`` there:
        the larger of the two, uncapped (module docstring)."""
        c = self.cfg
        xy = c.base_window_xy + c.window_rate * graph_distance_m
        th = math.radians(c.base_window_deg + c.window_deg_rate * graph_distance_m)
        if cov_mTr is None or mTr is None:
            return xy, xy, min(th, math.pi)
        wx, wy, wth = self.covariance_window(cov_mTr, mTr)
        return max(xy, wx), max(xy, wy), min(max(th, wth), math.pi)

    def covariance_window(self, cov_mTr: np.ndarray, mTr: np.ndarray) -> tuple[float, float, float]:
        """``window_sigmas`` of the node's covariance relative to the old submap, in the submap's axes."""
        R = g.rot2(float(mTr[2]))
        S = R @ np.asarray(cov_mTr)[:2, :2] @ R.T
        k = self.cfg.window_sigmas
        return (k * math.sqrt(max(S[0, 0], 0.0)), k * math.sqrt(max(S[1, 1], 0.0)),
                min(k * math.sqrt(max(float(cov_mTr[2, 2]), 0.0)), math.pi))

    def _is_global(self, wx: float, wy: float, wth: float) -> bool:
        return max(wx, wy) > self.cfg.max_window_xy or wth > math.radians(self.cfg.max_window_deg) + 1e-12

    def search(self, n: int, nTr: np.ndarray, cov_nTr: np.ndarray, b_pts: np.ndarray, est_wTa: np.ndarray,
               graph_distance: np.ndarray, travelled: float = 0.0, rel_cov: np.ndarray | None = None,
               travel: np.ndarray | None = None,
               bundle: Callable[[], np.ndarray] | None = None) -> list[LoopCandidate]:
        """Loop candidates of node r (pose ``nTr`` in submap n) against the finished submaps;
        ``graph_distance[m]`` is the graph path length from m to n (see the module docstring); ``travelled``
        the odometer reading, which spaces wide searches of one old submap ``wide_search_spacing`` apart (a
        wide window costs ~10 ms; one every couple of metres finds a revisit as surely as one per node).
        ``rel_cov[m]`` (optional): the covariance of anchor n relative to anchor m (n's frame), which widens the
        window to ``window_sigmas`` of it; ``travel[m]`` the odometer at each anchor (the consistency test's
        drift allowance); ``bundle`` makes the points of the node and those behind it (``global_bundle_m``, node
        frame) that the global search matches, called only when a global round runs. Closures of windowed searches are returned at once; those of global ones
        when another agrees (``loop_consistency``)."""
        c = self.cfg
        wTr = g.compose(est_wTa[n], nTr)
        olds = [m for m in self.grids if m < n - c.skip_recent and self.pairs.get((m, n), 0) < c.max_per_pair]
        if not olds:
            return []
        olds_arr = np.array(olds)
        dist = np.hypot(*(est_wTa[olds_arr, :2] - wTr[:2]).T)
        found: list[LoopCandidate] = []
        globals_: list[tuple[int, np.ndarray, float, float, float]] = []
        searched = 0
        search_pts = (adaptive_voxel_filter(b_pts, ScanFilterConfig(c.search_voxel_m, c.search_min_points))
                      if c.search_voxel_m > 0 else b_pts)
        A = g.adjoint(g.inverse(nTr))
        for q in np.argsort(dist, kind="stable").tolist():  # nearest first
            m, d = int(olds_arr[q]), float(dist[q])
            seed = g.between(est_wTa[m], wTr)
            cov_mTr = None if rel_cov is None else A @ rel_cov[m] @ A.T + cov_nTr
            wx, wy, wth = self.window(float(graph_distance[m]), cov_mTr, seed)
            # beyond the caps (by the drift since the last closure or by the covariance): the global search too,
            # within its budget. Neither window is trusted to bound the error there: on fr079 at 1.4 Hz a revisit
            # after 142 m of graph was 13 m / 20 deg off, where the drift window said 8 m and 3 sigma of the
            # covariance 3.4 m / 14 deg; so the global search covers the whole old submap (``_global``)
            if self._is_global(wx, wy, wth):
                globals_.append((m, seed, wx, wy, wth))
            wx, wy = min(wx, c.max_window_xy), min(wy, c.max_window_xy)
            wth = min(wth, math.radians(c.max_window_deg))
            wxy = max(wx, wy)
            if d > c.max_constraint_distance + wxy:
                continue
            if wxy <= c.wide_window_xy and searched >= c.max_searches_per_node:
                continue  # narrow (near in the graph): the nearest few suffice; wide ones are spaced instead
            wide = wxy > c.wide_window_xy
            if wide and travelled - self.last_wide.get(m, -np.inf) < c.wide_search_spacing:
                continue
            if wide:
                self.last_wide[m] = travelled
            searched += not wide
            t0 = time.perf_counter()
            cand = self._windowed(m, n, nTr, cov_nTr, b_pts, search_pts, seed, (wx, wy), wth, wide)
            self.seconds["windowed"] += time.perf_counter() - t0
            if cand is not None:
                found.append(cand)
        if globals_ and travel is not None and travelled - self.last_global_round >= c.global_every_m:
            self.last_global_round = travelled
            g_pts = b_pts if bundle is None else adaptive_voxel_filter(
                bundle(), ScanFilterConfig(c.global_bundle_voxel_m, c.global_bundle_min_points))
            found.extend(self._global_round(n, nTr, cov_nTr, b_pts, g_pts, globals_, est_wTa, travel, travelled))
        return found

    def _count(self, reason: str) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + 1

    def _windowed(self, m: int, n: int, nTr, cov_nTr, b_pts, search_pts, seed, wxy, wth: float,
                  wide: bool) -> LoopCandidate | None:
        """One windowed search (at most max_window_xy / max_window_deg), accepted on its own (``min_score_wide``
        when ``wide``)."""
        c = self.cfg
        min_score = (c.min_score_wide if wide else c.min_score) * self.scale
        margin = c.ambiguity_margin * self.scale
        self.tried += 1
        self._count("windowed searches")
        win = _Window(self._precomputed(m), search_pts, seed, wxy, wth)
        hit = win.best(min_score, margin if c.ambiguity != "off" else -1.0)
        if hit is None:
            self._count("windowed: no match above the score")
            return None
        peaks = []
        if c.ambiguity != "off":  # before the refinement: an ambiguous match is not worth refining
            peaks = win.second_peaks(hit, margin, c.ambiguity_exclude_xy,
                                     math.radians(c.ambiguity_exclude_deg), c.ambiguity_peaks,
                                     first=c.ambiguity == "reject")
            self.peaks.append((m, n, hit, peaks))
            if peaks:
                self.ambiguous += 1
                if c.ambiguity == "reject":
                    self._count("windowed: ambiguous (a second peak)")
                    return None
        cand = self._refined(m, n, nTr, cov_nTr, b_pts, hit, peaks, min_score, float(np.max(wxy)))
        self._count("windowed: accepted" if cand is not None else "windowed: refinement failed")
        if cand is not None:
            self.pairs[(m, n)] = self.pairs.get((m, n), 0) + 1
        return cand

    def _refined(self, m: int, n: int, nTr, cov_nTr, b_pts, hit, peaks, min_score: float,
                 window_xy: float) -> LoopCandidate | None:
        """The branch-and-bound pose refined against m's grid, with the peaks' spread in its covariance."""
        from holoslam.submaps.deadreckon import relative_anchor_pose

        gr = self.grids[m]
        ref = match_scan(gr.prob, gr.origin, gr.resolution, b_pts, hit.aTb, self.refine_cfg)
        if ref.score < min_score or np.hypot(*(ref.aTb[:2] - hit.aTb[:2])) > 2 * gr.resolution:
            return None
        cov_aTb = ref.cov_aTb
        if peaks:
            cov_aTb = spanning_covariance(ref.aTb, cov_aTb, [p.aTb for p in peaks])
        mTn, cov_mTn = relative_anchor_pose(ref.aTb, cov_aTb, nTr, cov_nTr)
        return LoopCandidate(m, n, mTn, cov_mTn, ref.score, window_xy)

    def _coarse(self, m: int):
        """m's grid max-pooled to ``global_resolution_m``, precomputed (cached like ``_precomputed``)."""
        from holoslam.submaps import bnb
        from holoslam.submaps.global_search import pool_grid

        if m in self.pre_coarse:
            self.pre_coarse.move_to_end(m)
            return self.pre_coarse[m]
        gr = self.grids[m]
        f = max(1, int(round(self.cfg.global_resolution_m / gr.resolution)))
        self.pre_coarse[m] = bnb.precompute(pool_grid(gr.prob, f), self.cfg.depth, origin=gr.origin,
                                            res=gr.resolution * f)
        if len(self.pre_coarse) > self.cfg.precomputed_cache:
            self.pre_coarse.popitem(last=False)
        return self.pre_coarse[m]

    def _global_round(self, n: int, nTr, cov_nTr, b_pts, g_pts, targets, est_wTa, travel, travelled: float):
        """Global searches of this node: ``global_per_node`` of the ``targets`` (m, seed, wx, wy, wth), the
        least recently searched first; their closures go through the consistency test."""
        from holoslam.submaps.global_search import clip_window

        c = self.cfg
        targets = [t for t in targets if travelled - self.last_global.get(t[0], -np.inf) >= c.wide_search_spacing
                   and clip_window(t[1], t[2], t[3], self.grids[t[0]].origin, self.grids[t[0]].prob.shape,
                                   self.grids[t[0]].resolution) is not None]
        lost = any(max(t[2], t[3]) >= _LOST_M for t in targets)
        count = c.global_per_node_lost if lost else c.global_per_node
        # lost (after a break of local SLAM): half the round (rounded up) for the submaps a waiting closure puts
        # the node in (nearest first), the rest for the least recently searched; most waiting closures are wrong,
        # and a right one's place is found only by the round robin until then. Not while merely drifting: there
        # a wrong closure's predicted places, searched first, found aliases that agreed with it (fr079 at 1.4 Hz,
        # half the beams: a clique of three wrong closures, 4.5 m mean error, against 0.094 m without)
        near = self._hypothesis_distances(est_wTa, g.compose(est_wTa[n], nTr)) if lost else {}
        targets.sort(key=lambda t: self.last_global.get(t[0], -np.inf))
        first = sorted((t for t in targets if t[0] in near), key=lambda t: near[t[0]])[: (count + 1) // 2]
        chosen = first + [t for t in targets if all(t[0] != f[0] for f in first)][: count - len(first)]
        out: list[LoopCandidate] = []
        for m, seed, wx, wy, wth in chosen:
            self.last_global[m] = travelled
            t0 = time.perf_counter()
            cand = self._global(m, n, nTr, cov_nTr, b_pts, g_pts, seed, wx, wy, wth)
            self.seconds["global"] += time.perf_counter() - t0
            if cand is None:
                continue
            cand = replace(cand, travelled=travelled)
            if c.verify.enabled:
                agree = map_agreement(self.grids, est_wTa, self._parts(len(est_wTa)), m, n, cand.mTn, c.verify)
                if agree.verdict(c.verify) is False:
                    self._count("global: rejected by the map check")
                    continue
            accepted = self.consistency.offer(cand, est_wTa, travel)
            self._count("global: accepted (consistent)" if accepted else "global: waiting for agreement")
            for a in accepted:
                if a is not cand:
                    self._count("global: accepted later (consistent)")
                self.pairs[(a.old, a.new)] = self.pairs.get((a.old, a.new), 0) + 1
            out.extend(accepted)
        return out

    def _hypothesis_distances(self, est_wTa: np.ndarray, wTr: np.ndarray) -> dict[int, float]:
        """Old submap -> distance (m) from its anchor to where one of the ``hypothesis_closures`` most recent
        closures waiting for agreement puts the node (their correction applied to its estimate), for the anchors
        within ``max_constraint_distance``. A right closure's correction holds while the robot drives on through
        the old map, so the submaps it predicts are where the agreeing closures are found; searched in the
        round-robin order instead, kidnapped aces found 4 right closures in 36 submaps x 240 m of rounds and
        no three agreed. A wrong closure's prediction is searched too, and finds no closure that agrees."""
        from holoslam.submaps.loop_consistency import correction

        out: dict[int, float] = {}
        olds = np.array(sorted(self.grids), np.int64)
        pending = self.consistency.pending
        for p in pending[max(0, len(pending) - self.cfg.hypothesis_closures):]:
            wTp = g.compose(correction(est_wTa[p.old], p.mTn, est_wTa[p.new]), wTr)
            d = np.hypot(*(est_wTa[olds, :2] - wTp[:2]).T)
            for m, dm in zip(olds[d <= self.cfg.max_constraint_distance].tolist(),
                             d[d <= self.cfg.max_constraint_distance].tolist(), strict=True):
                out[m] = min(out.get(m, np.inf), dm)
        return out

    def _global(self, m: int, n: int, nTr, cov_nTr, b_pts, g_pts, seed, wx: float, wy: float,
                wth: float) -> LoopCandidate | None:
        """One global search (``global_search``): coarse over the whole of m's grid at every heading (the window
        only chose m as a target: it may be too small, ``search``), fine around the coarse best, second peaks kept
        in the covariance, refinement."""
        from holoslam.submaps.global_search import clip_window, coarse_match

        c = self.cfg
        pre = self._coarse(m)
        clipped = clip_window(seed, _LOST_M, _LOST_M, pre.origin, pre.shape, pre.res)
        if clipped is None:
            self._count("global: window off the submap")
            return None
        self.tried += 1
        self._count("global searches")
        centre, cx, cy = clipped
        coarse = coarse_match(pre, g_pts, centre, cx, cy, math.pi, c.global_coarse_min_score * self.scale,
                              c.global_max_range_m)
        if coarse is None:
            self._count("global: no match above the score")
            return None
        win = _Window(self._precomputed(m), b_pts, coarse.aTb, c.global_check_xy, math.radians(c.global_check_deg))
        min_score, margin = c.global_min_score * self.scale, c.ambiguity_margin * self.scale
        hit = win.best(min_score, margin)
        if hit is None:
            self._count("global: fine match below the score")
            return None
        peaks = win.second_peaks(hit, margin, c.ambiguity_exclude_xy,
                                 math.radians(c.ambiguity_exclude_deg), c.global_ambiguity_peaks)
        if peaks:
            self.ambiguous += 1
            self._count("global: ambiguous, kept with the peaks' spread")
        cand = self._refined(m, n, nTr, cov_nTr, b_pts, hit, peaks, min_score, max(wx, wy))
        if cand is None:
            self._count("global: refinement failed")
        return cand


_LOST_M = 1e5  # m: a window this wide comes from a break of local SLAM (``relative_covariances``), not from drift


class _Window:
    """One branch-and-bound search of a scan against a precomputed submap (``bnb.search``'s candidates and
    algorithm), kept so that the ambiguity search re-uses its discretised points and its top level's bounds:
    a second peak costs only the descent."""

    def __init__(self, pre, b_pts, seed, wxy: float, wth: float) -> None:
        from holoslam.submaps import bnb

        self.pre = pre
        self.cand = bnb._candidates(pre, b_pts, seed, wxy, wth, None)
        n = self.cand.rows.shape[1]
        self.n = n
        self.quant = (pre.q_lo, pre.q_step, float(pre.q_out), float(bnb.OUTSIDE), bnb._SLACK * n)
        self.d_top = bnb._top_level(pre, self.cand.box)
        k = _kernels()
        self.top, self.order = k[0](pre.prob, pre.levels, pre.starts, self.cand.rows, self.cand.cols,
                                    self.cand.box, self.d_top, self.quant)
        a = self.cand.angles
        self.angle_step = abs(float(a[1] - a[0])) if a.size > 1 else math.pi
        self.margin = -1.0  # best()'s margin: the nodes it set aside (aside) and where its top level stopped
        self.aside, self.k_break = np.zeros((0, 5)), 0

    def _descend(self, min_score: float, centres=None, ex=(0, 0), first: bool = False, defer: float = -1.0,
                 resume: bool = False):
        """The kernel's descent above ``min_score`` (mean probability) outside the boxes; ``defer`` >= 0 (score
        units) keeps what it sets aside for a later ``resume`` (see ``_descend_py``)."""
        from holoslam.submaps import bnb

        pre, c = self.pre, self.cand
        seeds, k0 = (self.aside, self.k_break) if resume else (np.zeros((0, 5)), 0)
        s, a, x, y, k_break, aside = _kernels()[1](
            pre.prob, pre.levels, pre.starts, c.rows, c.cols, c.box, self.d_top, self.quant,
            float(min_score) * self.n, self.top, self.order, k0, seeds,
            np.asarray(centres if centres is not None else np.zeros((0, 3)), np.int64).reshape(-1, 3),
            np.asarray(ex, np.int64), first, float(defer) * self.n if defer >= 0 else -1.0)
        if defer >= 0:
            self.aside, self.k_break = aside[np.argsort(-aside[:, 4], kind="stable")], k_break
        return None if a < 0 else bnb._match(self.cand, self.pre.res, a, x, y, s)

    def best(self, min_score: float, margin: float = -1.0):
        """``bnb.search``: the best candidate strictly above ``min_score`` (None if there is none). With
        ``margin`` >= 0 the nodes it prunes within ``margin`` of the best are kept: a second peak search with
        that margin then starts from them instead of from the top (the same result for less work)."""
        self.margin = margin
        # a hair more than the margin: rounding of (best - margin) n can never leave a node out
        return self._descend(min_score, defer=margin + 1e-9 if margin >= 0 else -1.0)

    def indices(self, aTb: np.ndarray) -> tuple[int, int, int]:
        """The candidate (angle, x, y) indices of a pose on the window's lattice."""
        c, res = self.cand, self.pre.res
        a = int(np.argmin(np.abs(g.wrap(c.angles - aTb[2]))))
        return a, int(round((aTb[0] - c.seed[0]) / res)), int(round((aTb[1] - c.seed[1]) / res))

    def second_peaks(self, best, margin: float, exclude_xy: float, exclude_rad: float, count: int = 1,
                     first: bool = False) -> list:
        """Up to ``count`` candidates of the window scoring strictly above ``best.score - margin`` outside
        boxes of +-``exclude_xy`` m (x and y) and +-``exclude_rad`` around ``best`` (a ``bnb.Match`` of this
        window) and around each other: each the exact best outside the boxes so far, or with ``first`` any
        candidate above the threshold (the first the search meets: enough to know that there is one)."""
        ex = (int(math.floor(exclude_xy / self.pre.res + 1e-9)),
              int(math.floor(exclude_rad / self.angle_step + 1e-9)))
        centres = [self.indices(best.aTb)]
        found = []
        for k in range(max(0, int(count))):
            # the first resumes from what best() set aside when it kept that much (it holds every node that can
            # lead to a candidate above best - margin); later ones, with more boxes, start from the top
            resume = k == 0 and 0 <= margin <= self.margin
            p = self._descend(best.score - margin, centres, ex, first, resume=resume)
            if p is None:
                break
            found.append(p)
            centres.append(self.indices(p.aTb))
        return found


def spanning_covariance(aTb: np.ndarray, cov_aTb: np.ndarray, others) -> np.ndarray:
    """The covariance of a match about ``aTb`` when the poses ``others`` are as likely as it: the second moment
    of the equal mixture of all of them about ``aTb`` (errors in ``aTb``'s frame, as ``cov_aTb``) added."""
    d = np.array([g.between(aTb, np.asarray(o, float)) for o in others]).reshape(-1, 3)
    d[:, 2] = g.wrap(d[:, 2])
    return np.asarray(cov_aTb, float) + d.T @ d / (len(d) + 1)


def _top_py(prob, levels, starts, rows, cols, box, d_top, quant):  # pragma: no cover - compiled
    """The bounds of the top level's nodes (``_bnb_fast.branch_and_bound``'s first step) and their order, best
    first: (bounds (A nx ny,), order)."""
    n_ang = rows.shape[0]
    x_lo, x_hi, y_lo, y_hi = box
    w = 1 << d_top
    nx = (x_hi - x_lo) // w + 1
    ny = (y_hi - y_lo) // w + 1
    bb = _bnb_fast._boxes(rows, cols)
    top = np.empty(n_ang * nx * ny, dtype=np.float64)
    for a in range(n_ang):
        for ix in range(nx):
            for iy in range(ny):
                top[(a * nx + ix) * ny + iy] = _bnb_fast._score(prob, levels, starts, d_top, rows, cols, bb, a,
                                                                x_lo + ix * w, y_lo + iy * w, quant)
    return top, np.argsort(-top, kind="mergesort")


def _defer(buf, n, a, x, y, d, bound):  # pragma: no cover - compiled
    """Append the node (a, x, y, level d, bound) to the (capacity, 5) buffer holding n rows (doubled when full)."""
    if n == buf.shape[0]:
        grown = np.empty((2 * buf.shape[0], 5), dtype=np.float64)
        for i in range(n):  # a loop, not grown[:n] = buf[:n]: that slice copy cost 5-9 s of numba's compile
            for c in range(5):
                grown[i, c] = buf[i, c]
        buf = grown
    buf[n, 0], buf[n, 1], buf[n, 2], buf[n, 3], buf[n, 4] = a, x, y, d, bound
    return buf, n + 1


def _workspace(box, d_top, rows, cols, defer):  # pragma: no cover - compiled
    """``_descend_py``'s arrays: the top level's node counts (nx, ny), the scan's cell boxes, the depth-first
    stack (angle, x, y, level, bound), the children scratch (cx, cy, cs) and the set-aside buffer."""
    w = 1 << d_top
    cap = 4 * d_top + 4
    st = (np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64),
          np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.float64))
    return ((box[1] - box[0]) // w + 1, (box[3] - box[2]) // w + 1, _bnb_fast._boxes(rows, cols), st,
            np.empty(4, dtype=np.int64), np.empty(4, dtype=np.int64), np.empty(4, dtype=np.float64),
            np.empty((64 if defer >= 0 else 0, 5), dtype=np.float64))


def _seed(seeds, j):  # pragma: no cover - compiled
    """Row j of the seeds (angle, x, y, level, bound) as a stack entry."""
    return int(seeds[j, 0]), int(seeds[j, 1]), int(seeds[j, 2]), int(seeds[j, 3]), seeds[j, 4]


def _top_node(k, nx, ny, x_lo, y_lo, d_top, top):  # pragma: no cover - compiled
    """Top-level node k (angle-major, then x, then y) as a stack entry (angle, x, y, level, bound)."""
    w = 1 << d_top
    a, rem = divmod(k, nx * ny)
    return a, x_lo + (rem // ny) * w, y_lo + (rem % ny) * w, d_top, top[k]


def _descend_py(prob, levels, starts, rows, cols, box, d_top, quant, best0, top, order, k0, seeds, centres, ex,
                first, defer):  # pragma: no cover - compiled
    """The rest of ``_bnb_fast.branch_and_bound`` (depth first, best child first): first from the nodes
    ``seeds`` (m, 5: angle, x, y, level, bound), then from the top level's nodes ``order[k0:]`` until their bound
    falls to the best. With no seeds, k0 = 0 and no boxes: the same nodes in the same order as
    branch_and_bound, hence the same result.

    Boxes cut out: no candidate within +-ex[0] offsets (x and y) and +-ex[1] angle indices of any of ``centres``
    (k, 3: angle, x, y) is returned, and a node whose block lies inside one box is dropped (the bounds of the
    others are still upper bounds: the result is exact). ``first``: return the first candidate above best0 met
    instead of the best. ``defer`` >= 0: every node or candidate set aside with a bound above (best at the time -
    defer) is returned, so that a search for anything above (final best - defer) can start from them and from
    ``order[k_break:]`` instead of from the top (each node is set aside with a bound <= the best at the time, which
    never exceeds the final best). Returns (sum, a, x, y, k_break, set-aside nodes (m', 5)); a = -1 when nothing
    outside the boxes beats best0 (strictly)."""
    x_lo, x_hi, y_lo, y_hi = box
    nx, ny, bb, st, cx, cy, cs, buf = _workspace(box, d_top, rows, cols, defer)
    nd = 0
    best, ba, bx, by = best0, -1, 0, 0
    k_break = order.size
    for kk in range(-seeds.shape[0], order.size - k0):
        if kk < 0:  # a seed
            st[0][0], st[1][0], st[2][0], st[3][0], st[4][0] = _seed(seeds, kk + seeds.shape[0])
            if st[4][0] <= best:
                continue
        else:
            k = order[k0 + kk]
            if top[k] <= best:
                k_break = k0 + kk
                break
            st[0][0], st[1][0], st[2][0], st[3][0], st[4][0] = _top_node(k, nx, ny, x_lo, y_lo, d_top, top)
        sp = 1
        while sp > 0:
            sp -= 1
            a, x, y, d = st[0][sp], st[1][sp], st[2][sp], st[3][sp]
            if st[4][sp] <= best:
                if defer >= 0 and st[4][sp] > best - defer:
                    buf, nd = _defer(buf, nd, a, x, y, d, st[4][sp])
                continue
            span = (1 << d) - 1
            cut = False
            for c in range(centres.shape[0]):
                if (abs(a - centres[c, 0]) <= ex[1] and x >= centres[c, 1] - ex[0]
                        and x + span <= centres[c, 1] + ex[0] and y >= centres[c, 2] - ex[0]
                        and y + span <= centres[c, 2] + ex[0]):
                    cut = True
                    break
            if cut:
                continue
            if d == 0:
                if defer >= 0 and ba >= 0 and best > st[4][sp] - defer:  # the best so far, set aside
                    buf, nd = _defer(buf, nd, ba, bx, by, 0, best)
                best, ba, bx, by = st[4][sp], a, x, y
                if first:
                    return best, ba, bx, by, k_break, buf[:nd]
                continue
            if defer < 0:
                sp, _ = _bnb_fast._push_children(prob, levels, starts, rows, cols, bb, a, x, y, d, box, quant,
                                                 best, st, sp, cx, cy, cs)
                continue
            # _bnb_fast._push_children, setting aside the children it drops
            h = 1 << (d - 1)
            ns = 0
            for dx in range(2):
                if x + dx * h > x_hi:
                    break
                for dy in range(2):
                    if y + dy * h > y_hi:
                        break
                    sc = _bnb_fast._score(prob, levels, starts, d - 1, rows, cols, bb, a, x + dx * h, y + dy * h,
                                          quant)
                    if sc > best:
                        q = ns
                        while q > 0 and cs[q - 1] > sc:
                            cx[q], cy[q], cs[q] = cx[q - 1], cy[q - 1], cs[q - 1]
                            q -= 1
                        cx[q], cy[q], cs[q] = x + dx * h, y + dy * h, sc
                        ns += 1
                    elif sc > best - defer:
                        buf, nd = _defer(buf, nd, a, x + dx * h, y + dy * h, d - 1, sc)
            for q in range(ns):
                st[0][sp], st[1][sp], st[2][sp], st[3][sp], st[4][sp] = a, cx[q], cy[q], d - 1, cs[q]
                sp += 1
    return best, ba, bx, by, k_break, buf[:nd]


_bnb_fast: Any = None  # holoslam.submaps._bnb_fast once _kernels() has run (the compiled functions call into it)
_KERNELS = None


def _kernels():
    """(``_top_py``, ``_descend_py``) compiled with numba on first use (this module does not import numba:
    the front end's other users of it load it lazily too); cached on disk like ``_bnb_fast``."""
    global _bnb_fast, _KERNELS
    if _KERNELS is None:
        import numba as nb

        from holoslam._jit import JIT
        from holoslam.submaps import _bnb_fast as fast

        _bnb_fast = fast
        jit = nb.njit(**JIT)
        global _defer, _workspace, _seed, _top_node
        # called by _descend_py: compiled first, as the globals it reads
        _defer, _workspace, _seed, _top_node = jit(_defer), jit(_workspace), jit(_seed), jit(_top_node)
        _KERNELS = (jit(_top_py), jit(_descend_py))
    return _KERNELS
