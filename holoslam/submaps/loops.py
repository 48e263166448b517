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
(``ambiguity_exclude_xy``, ``ambiguity_exclude_deg``) scores within ``ambiguity_margin`` of it, on the window's
lattice or (where the compass's agreement with dead reckoning bounds the window), for its second peaks within
``ambiguity_lattice_slack`` more, refined like the match (the lattice samples each place with its own rounding of
the points: a rival it scores lower may refine as well). Along a
corridor, or between two similar rooms, the best of the window can be an alias metres from the truth with a
flat score surface, and the refinement's covariance (its +-0.5 m surface) does not cover the error; such a
match is dropped (``ambiguity="reject"``) or kept with a covariance spanning the peaks (``"span"``). Beyond the
window, a corridor's periodic aliases (a room's width along it) are sought along the match's least certain axis,
and a match with such peaks keeps their spread along it (``holoslam.submaps.periodic``). An
accepted match gives the ``loop`` relative pose of Eq. 15, mTn = mTr ∘ (nTr)^-1, with the refined match's
covariance. Loops enter the graph with a robust kernel (Huber in a run, ``optimise.run_build_options``) and the
final solve's chi-square rounds, so a wrong one that passes here bends the map less. Defaults: Cartographer's
published constraint-builder settings (SPEC §8: +-7 m, +-30 deg, 15 m, score 0.55 / 0.6, depth 7); the
ambiguity test's were measured on the real logs (``LoopConfig``).
"""

from __future__ import annotations

import math
import os
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.bnb_window import SearchWindow, spanning_covariance
from holoslam.submaps.loop_config import LoopConfig
from holoslam.submaps.loop_consistency import LoopConsistency
from holoslam.submaps.loop_verify import map_agreement
from holoslam.submaps.loop_windows import agreement_bound, beyond_ellipse, drift_windows, is_global
from holoslam.submaps.periodic import periodic_peaks
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


class _Job(NamedTuple):
    """One windowed search of a node: the old submap, the seed (the node's estimate in it), the window's
    half-widths (x m, y m; heading rad) as capped, whether it is wide, whether a weak match may be offered, whether
    it reaches across a break of local SLAM, and the drift window's half-widths (before dead reckoning's
    disagreement widened it, capped alike: ``LoopConfig.widened_needs_agreement``)."""

    m: int
    seed: np.ndarray
    wxy: tuple[float, float]
    wth: float
    wide: bool
    weak: bool
    across: bool
    drift_xy: tuple[float, float]


class LoopSearch:
    """Holds the finished submaps' precomputed grids and searches nodes against them."""

    def __init__(self, cfg: LoopConfig, match_cfg: MatchConfig) -> None:
        if cfg.ambiguity not in ("reject", "span", "off"):
            raise ValueError(f"LoopConfig.ambiguity must be 'reject', 'span' or 'off', got {cfg.ambiguity!r}")
        if not (math.isfinite(cfg.disagreement_window) and cfg.disagreement_window >= 0):
            raise ValueError(f"LoopConfig.disagreement_window must be a finite number >= 0, got {cfg.disagreement_window!r}")
        if not (cfg.periodic_search_m >= 0 and cfg.periodic_exclude_m >= 0 and math.isfinite(cfg.periodic_search_m)):
            raise ValueError("LoopConfig.periodic_search_m and periodic_exclude_m must be finite numbers >= 0 (search 0: "
                             f"off), got {cfg.periodic_search_m!r}, {cfg.periodic_exclude_m!r}")
        if not (cfg.disagreement_window_blind_share >= 0):  # inf allowed: never
            raise ValueError("LoopConfig.disagreement_window_blind_share must be a number >= 0 (above 1: never), got "
                             f"{cfg.disagreement_window_blind_share!r}")
        if not (cfg.far_from_seed > 0):  # inf allowed: never
            raise ValueError(f"LoopConfig.far_from_seed must be a number > 0 (inf: off), got {cfg.far_from_seed!r}")
        if not (cfg.solo_max_offset_m > 0):  # inf allowed: never
            raise ValueError("LoopConfig.solo_max_offset_m must be a number > 0 (m; inf: off), got "
                             f"{cfg.solo_max_offset_m!r}")
        if not (cfg.disagreement_window_max_hz >= 0):  # inf allowed: always
            raise ValueError("LoopConfig.disagreement_window_max_hz must be a number >= 0 (inf: always), got "
                             f"{cfg.disagreement_window_max_hz!r}")
        if not (math.isfinite(cfg.ambiguity_lattice_slack) and cfg.ambiguity_lattice_slack >= 0
                and isinstance(cfg.ambiguity_refined_peaks, int) and cfg.ambiguity_refined_peaks >= 0):
            raise ValueError("LoopConfig.ambiguity_lattice_slack must be a finite number >= 0 (0: off) and "
                             "ambiguity_refined_peaks an integer >= 0, got "
                             f"{cfg.ambiguity_lattice_slack!r}, {cfg.ambiguity_refined_peaks!r}")
        self.cfg = cfg
        # the refinement against an old map starts from the branch-and-bound pose; its window (for the score
        # surface, hence the covariance) is wide enough to show a corridor's ambiguity along its length; Gauss-Newton's
        # refinement, as local SLAM's
        self.refine_cfg = MatchConfig(
            linear_window=0.5, angular_window_deg=3.0, translation_delta_weight=1e3, rotation_delta_weight=1e3, occupied_weight=match_cfg.occupied_weight,
            translation_weight=match_cfg.translation_weight, rotation_weight=match_cfg.rotation_weight,
            iterations=match_cfg.iterations, kappa=match_cfg.kappa, min_score=0.0)
        self.grids: dict[int, ProbGrid] = {}
        self.pre: OrderedDict[int, object] = OrderedDict()
        self.pairs: dict[tuple[int, int], int] = {}
        self.last_wide: dict[int, float] = {}
        self.last_weak: dict[int, float] = {}  # odometer reading at each old submap's last low-floor search
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
        the larger of the two, uncapped (module docstring). One row of ``windows``."""
        cov = None if cov_mTr is None or mTr is None else np.asarray(cov_mTr, float)[None]
        wx, wy, wth = self.windows(np.array([graph_distance_m], float), cov,
                                   None if cov is None else np.asarray(mTr, float)[None])
        return float(wx[0]), float(wy[0]), float(wth[0])

    def windows(self, graph_distance_m: np.ndarray, cov_mTr: np.ndarray | None = None,
                mTr: np.ndarray | None = None,
                disagreement: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``window`` of M old submaps at once: graph distances (M,), covariances (M, 3, 3) of the node's poses
        ``mTr`` (M, 3) in them; (wx, wy, wth), each (M,). The covariance part is ``window_sigmas`` of the node's
        covariance relative to the old submap, in the submap's axes. ``disagreement`` (m (M,), rad (M,)): how far
        the estimate of the node's submap relative to each old one lies from dead reckoning's alone; the window is
        at most the base window plus ``agreement_factor`` times it (``LoopConfig``)."""
        return agreement_bound(self.cfg, drift_windows(self.cfg, graph_distance_m, cov_mTr, mTr), disagreement)

    def _is_global(self, wx: float, wy: float, wth: float) -> bool:
        return is_global(self.cfg, wx, wy, wth)

    def search(self, n: int, nTr: np.ndarray, cov_nTr: np.ndarray, b_pts: np.ndarray, est_wTa: np.ndarray,
               graph_distance: np.ndarray, travelled: float = 0.0, rel_cov: np.ndarray | None = None,
               travel: np.ndarray | None = None,
               bundle: Callable[[], np.ndarray] | None = None,
               disagreement: tuple[np.ndarray, np.ndarray] | None = None,
               compass: bool = True) -> list[LoopCandidate]:
        """Loop candidates of node r (pose ``nTr`` in submap n) against the finished submaps;
        ``graph_distance[m]`` is the graph path length from m to n (see the module docstring); ``travelled``
        the odometer reading, which spaces wide searches of one old submap ``wide_search_spacing`` apart (a
        wide window costs ~10 ms; one every couple of metres finds a revisit as surely as one per node).
        ``rel_cov[m]`` (optional): the covariance of anchor n relative to anchor m (n's frame), which widens the
        window to ``window_sigmas`` of it; ``travel[m]`` the odometer at each anchor (the consistency test's
        drift allowance); ``bundle`` makes the points of the node and those behind it (``global_bundle_m``, node
        frame) that the global search matches, called only when a global round runs; ``disagreement`` (m (N,), rad
        (N,), per anchor: ``AnchorGraph.dead_reckoning_disagreement``) bounds the windows where dead reckoning
        agrees with the estimate, or widens them to it when its heading is the odometry's (``compass`` False:
        ``LoopConfig.disagreement_window``). Closures of windowed searches are returned at once; those of global
        ones when another agrees (``loop_consistency``)."""
        from holoslam.warmup import wait_for_kernels

        wait_for_kernels("holoslam.submaps")  # a first run's pool compiling the branch and bound: not twice
        c = self.cfg
        wTr = g.compose(est_wTa[n], nTr)
        olds = [m for m in self.grids if m < n - c.skip_recent and self.pairs.get((m, n), 0) < c.max_per_pair]
        if not olds:
            return []
        olds_arr = np.array(olds)
        dist = np.hypot(*(est_wTa[olds_arr, :2] - wTr[:2]).T)
        found: list[LoopCandidate] = []
        jobs: list[_Job] = []
        globals_: list[tuple[int, np.ndarray, float, float, float]] = []
        searched = 0
        search_pts = (adaptive_voxel_filter(b_pts, ScanFilterConfig(c.search_voxel_m, c.search_min_points))
                      if c.search_voxel_m > 0 else b_pts)
        A = g.adjoint(g.inverse(nTr))
        order = np.argsort(dist, kind="stable")  # nearest first
        olds_arr, dist = olds_arr[order], dist[order]
        seeds = g.between(np.asarray(est_wTa[olds_arr], float), np.broadcast_to(wTr, (len(olds_arr), 3)))
        covs = None if rel_cov is None else np.einsum("ij,mjk,lk->mil", A, rel_cov[olds_arr], A) + cov_nTr
        dis = None if disagreement is None else (disagreement[0][olds_arr], disagreement[1][olds_arr])
        # the node's heading sigma relative to each old submap: a global match may turn the estimate by at most
        # ``global_heading_sigmas`` of it (``LoopConfig``)
        sig_th = None if covs is None else np.sqrt(np.maximum(covs[:, 2, 2], 0.0))
        loose = self.windows(np.asarray(graph_distance, float)[olds_arr], covs, None if covs is None else seeds)
        win = agreement_bound(c, loose, dis, compass)
        bounded = (win[0] < loose[0]) | (win[1] < loose[1]) | (win[2] < loose[2])  # narrowed by the agreement
        for q, (m, d, wx, wy, wth) in enumerate(zip(olds_arr.tolist(), dist.tolist(), *(w.tolist() for w in win),
                                                    strict=True)):
            seed = seeds[q].copy()
            # beyond the caps (by the drift since the last closure or by the covariance): the global search too,
            # within its budget. Neither window is trusted to bound the error there: on fr079 at 1.4 Hz a revisit
            # after 142 m of graph was 13 m / 20 deg off, where the drift window said 8 m and 3 sigma of the
            # covariance 3.4 m / 14 deg; so the global search covers the whole old submap (``_global``)
            if self._is_global(wx, wy, wth):
                gate = wth if sig_th is None or c.global_heading_sigmas <= 0 else min(
                    wth, c.global_heading_sigmas * float(sig_th[q]))
                globals_.append((m, seed, wx, wy, gate))
            across = max(wx, wy) >= _LOST_M  # reached only across a break of local SLAM
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
            # a weak match (``agree_min_score``) counts only with others from nodes min_separation_m apart: one
            # low-floor search of an old submap per that much travel (the lower floor prunes less: ~4x the cost)
            weak = (c.agree_min_score > 0 and self.scale < 1.0 and travel is not None and not across
                    and travelled - self.last_weak.get(m, -np.inf) >= c.consistency.min_separation_m)
            if weak:
                self.last_weak[m] = travelled
            drift_xy = (min(float(loose[0][q]), c.max_window_xy), min(float(loose[1][q]), c.max_window_xy))
            jobs.append(_Job(m, seed, (wx, wy), wth, wide, weak, across, drift_xy))
            if bounded[q]:
                self._count("windowed: window narrowed by dead reckoning's agreement")
        # the windows are bounded by the compass's agreement (a measured bound of the estimate's error, not a drift
        # allowance): a match within its own peak's box of their edge is rejected too (``LoopConfig.reject_on_edge``),
        # and the lattice's near rivals are refined (``LoopConfig.ambiguity_lattice_slack``)
        band = compass and disagreement is not None and c.agreement_factor > 0
        found.extend(self._windowed_all(jobs, n, nTr, cov_nTr, b_pts, search_pts, est_wTa, travel, travelled, band))
        if globals_ and travel is not None and travelled - self.last_global_round >= c.global_every_m:
            self.last_global_round = travelled
            g_pts = b_pts if bundle is None else adaptive_voxel_filter(
                bundle(), ScanFilterConfig(c.global_bundle_voxel_m, c.global_bundle_min_points))
            found.extend(self._global_round(n, nTr, cov_nTr, b_pts, g_pts, globals_, est_wTa, travel, travelled))
        return found

    def _count(self, reason: str) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + 1

    def _windowed_all(self, jobs: list[_Job], n: int, nTr, cov_nTr, b_pts, search_pts, est_wTa, travel,
                      travelled: float, band: bool = False) -> list[LoopCandidate]:
        """The windowed searches of one node, at most ``max_window_xy`` / ``max_window_deg``, each accepted on its
        own (``min_score_wide`` when ``wide``) unless ``_must_agree``. They are independent:
        run in threads (the branch-and-bound and the matcher are compiled kernels that release the GIL), and
        counted and kept in the order given, so the result does not depend on the threads."""
        if not jobs:
            return []
        pres = [self._precomputed(job.m) for job in jobs]  # here: the cache's order is the searches' order
        t0 = time.perf_counter()

        def one(q: int):
            j = jobs[q]
            return self._window_match(pres[q], j.m, j.seed, j.wxy, j.wth, j.wide, j.weak, n, nTr, cov_nTr, b_pts,
                                      search_pts, band)

        outs = list(_threads().map(one, range(len(jobs)))) if len(jobs) > 1 else [one(0)]
        self.seconds["windowed"] += time.perf_counter() - t0
        found = []
        for job, (cand, reason, hit, peaks) in zip(jobs, outs, strict=True):
            self.tried += 1
            self._count("windowed searches")
            if peaks is not None:
                self.peaks.append((job.m, n, hit, peaks))
                self.ambiguous += bool(peaks)
            kind = None
            if cand is not None and reason == "windowed: accepted":
                reason, kind = self._must_agree(job, hit.aTb, band) or (reason, None)
            elif cand is not None and reason.endswith("offered for agreement"):
                kind = "windowed weak"
            self._count(reason)
            if cand is not None and kind is not None:
                if travel is not None:  # without the anchors' odometer no agreement can be judged: dropped
                    found.extend(self._agreed(replace(cand, travelled=travelled), est_wTa, travel, kind))
            elif cand is not None:
                self.pairs[(job.m, n)] = self.pairs.get((job.m, n), 0) + 1
                found.append(cand)
        return found

    def _must_agree(self, job: _Job, aTb: np.ndarray, band: bool = False) -> tuple[str, str] | None:
        """Why a match its window accepts must be offered for agreement instead, and the kind it is counted under
        there ((reason, kind)), or None: it stands on its own. ``band``: the window is the compass's agreement
        bound (``_window_match``)."""
        # across a break of local SLAM the window stands on no estimate (the robot may have been carried):
        # a match there is a hypothesis like a global one, and needs the others' agreement. Accepted on its own,
        # intel at 1.4 Hz kidnapped at two thirds took two aliases 14 m / 94-101 deg off: never joined
        if job.across:
            return "windowed across a break: offered for agreement", "windowed across a break"
        if beyond_ellipse(aTb, job.seed, job.wxy, self.cfg.far_from_seed):
            return "windowed, beyond its window's ellipse: offered for agreement", "windowed weak"
        # one scan saying the map is metres off: a hypothesis (``LoopConfig.solo_max_offset_m``), unless the
        # compass's agreement bounds the window (``band``)
        moved = math.hypot(float(aTb[0]) - float(job.seed[0]), float(aTb[1]) - float(job.seed[1]))
        if not band and moved > self.cfg.solo_max_offset_m:
            return "windowed, far from its seed: offered for agreement", "windowed far"
        widened = job.wxy[0] > job.drift_xy[0] or job.wxy[1] > job.drift_xy[1]  # never with a compass
        if (self.cfg.widened_needs_agreement and widened
                and beyond_ellipse(aTb, job.seed, job.drift_xy, self.cfg.far_from_seed)):
            return "windowed, beyond its drift window: offered for agreement", "windowed widened"
        return None

    def _agreed(self, cand: LoopCandidate, est_wTa, travel, kind: str) -> list[LoopCandidate]:
        """``cand`` through the map check and the consistency test: the closures accepted now (module docstring
        of ``loop_consistency``), counted under ``kind``."""
        c = self.cfg
        parts = self._parts(len(est_wTa))  # the map check's and the consistency test's
        if c.verify.enabled:
            verify = c.verify.scaled(self.scale)  # a sparse laser's walls agree less (``VerifyConfig``)
            agree = map_agreement(self.grids, est_wTa, parts, cand.old, cand.new, cand.mTn, verify)
            if agree.verdict(verify) is False:
                self._count(f"{kind}: rejected by the map check")
                return []
        accepted = self.consistency.offer(cand, est_wTa, travel, parts)
        self._count(f"{kind}: accepted (consistent)" if accepted else f"{kind}: waiting for agreement")
        if self.consistency.rivalled:
            self._count(f"{kind}: waiting, a rival clique as certain")
        for a in accepted:
            if a is not cand:
                self._count(f"{kind}: accepted later (consistent)")
            self.pairs[(a.old, a.new)] = self.pairs.get((a.old, a.new), 0) + 1
        return accepted

    def _window_match(self, pre, m: int, seed, wxy, wth: float, wide: bool, weak_ok: bool, n: int, nTr, cov_nTr,
                      b_pts, search_pts, band: bool = False) -> tuple[LoopCandidate | None, str, Any, list | None]:
        """One windowed search against m's precomputed grids ``pre``: (the closure or None, the outcome's
        reason, the best match, its second peaks (None when not sought)); ``weak_ok``: down to the agreement
        floor (``agree_min_score``); ``band`` (the window is the compass's agreement bound): a match whose own
        peak box reaches the window's edge is rejected too, not only one on it (``LoopConfig.reject_on_edge``),
        and the lattice's near rivals are refined (``LoopConfig.ambiguity_lattice_slack``). Reads the search's
        state only."""
        c = self.cfg
        min_score = (c.min_score_wide if wide else c.min_score) * self.scale
        weak_floor = min(c.agree_min_score * self.scale, min_score) if weak_ok else 0.0
        margin = c.ambiguity_margin * self.scale
        win = SearchWindow(pre, search_pts, seed, wxy, wth)
        # the refined rivals' search (below; in a window the compass's agreement bounds) reaches
        # ``ambiguity_lattice_slack`` further: best() keeps what it prunes within that, so both searches resume
        rivals_sought = band and c.ambiguity == "reject" and c.ambiguity_lattice_slack > 0
        wider = margin + c.ambiguity_lattice_slack * self.scale if rivals_sought else margin
        hit = win.best(weak_floor if weak_floor > 0 else min_score, wider if c.ambiguity != "off" else -1.0)
        if hit is None:
            return None, "windowed: no match above the score", None, None
        box = (c.ambiguity_exclude_xy, math.radians(c.ambiguity_exclude_deg)) if band else (0.0, 0.0)
        if c.reject_on_edge and win.on_edge(hit, *box):
            return None, "windowed: best on the window's edge", hit, None
        weak = hit.score <= min_score  # above the agreement floor only: accepted only with others that agree
        if weak:
            min_score = weak_floor
        peaks = None
        if c.ambiguity != "off":  # before the refinement: an ambiguous match is not worth refining
            peaks = win.second_peaks(hit, margin, c.ambiguity_exclude_xy,
                                     math.radians(c.ambiguity_exclude_deg), c.ambiguity_peaks,
                                     first=c.ambiguity == "reject")
            if peaks and c.ambiguity == "reject":
                return None, "windowed: ambiguous (a second peak)", hit, peaks
        ref = self._refine(m, b_pts, hit, min_score)
        if ref is None:
            return None, "windowed: refinement failed", hit, peaks
        if rivals_sought:
            rivals = self._refined_rivals(win, m, b_pts, hit, ref, margin, wider)
            if rivals:
                return None, "windowed: ambiguous (a second peak, refined)", hit, rivals
        cand = self._candidate(m, n, nTr, cov_nTr, b_pts, ref, peaks or [], float(np.max(wxy)))
        return cand, "windowed: weak, offered for agreement" if weak else "windowed: accepted", hit, peaks

    def _refined_rivals(self, win: SearchWindow, m: int, b_pts, hit, best, margin: float, wider: float) -> list:
        """The second peaks of ``win`` that the lattice scores within ``wider`` of ``hit`` and that, refined
        like the best (to ``best``, a ``scanmatch`` result), score within ``margin`` of it outside the best's own
        box: a rival the lattice's sampling hid (``LoopConfig.ambiguity_lattice_slack``)."""
        c = self.cfg
        ex_xy, ex_rad = c.ambiguity_exclude_xy, math.radians(c.ambiguity_exclude_deg)
        out = []
        for p in win.second_peaks(hit, wider, ex_xy, ex_rad, c.ambiguity_refined_peaks):
            ref = self._continuous(m, b_pts, p.aTb)
            off = np.abs(ref.aTb[:2] - best.aTb[:2])
            turn = abs(g.wrap(ref.aTb[2] - best.aTb[2]))
            if ref.score > best.score - margin and (off.max() > ex_xy or turn > ex_rad):
                out.append(p)
        return out

    def _continuous(self, m: int, b_pts, aTb):
        """The continuous matcher (``refine_cfg``) of ``b_pts`` against m's grid from the pose ``aTb``."""
        gr = self.grids[m]
        return match_scan(gr.prob, gr.origin, gr.resolution, b_pts, aTb, self.refine_cfg)

    def _refine(self, m: int, b_pts, hit, min_score: float):
        """The branch-and-bound pose ``hit`` refined against m's grid by the continuous matcher (None when it
        scores under ``min_score`` or moves more than two cells: not the lattice's peak)."""
        ref = self._continuous(m, b_pts, hit.aTb)
        if ref.score < min_score or np.hypot(*(ref.aTb[:2] - hit.aTb[:2])) > 2 * self.grids[m].resolution:
            return None
        return ref

    def _candidate(self, m: int, n: int, nTr, cov_nTr, b_pts, ref, peaks, window_xy: float) -> LoopCandidate:
        """The closure of a refined match ``ref``, with the peaks' spread in its covariance."""
        from holoslam.submaps.deadreckon import relative_anchor_pose

        gr = self.grids[m]
        cov_aTb = ref.cov_aTb
        spread = [p.aTb for p in peaks]
        c = self.cfg
        if c.periodic_search_m > 0:  # a corridor's periodic aliases beyond the window (``holoslam.submaps.periodic``)
            along = periodic_peaks(gr.prob, gr.origin, gr.resolution, gr.p_min, b_pts, ref.aTb, cov_aTb,
                                   c.ambiguity_margin * self.scale, c.periodic_search_m, c.periodic_exclude_m)
            if along:
                self._count("periodic along its axis, kept with the peaks' spread")
                spread += along
        if spread:
            cov_aTb = spanning_covariance(ref.aTb, cov_aTb, spread)
        mTn, cov_mTn = relative_anchor_pose(ref.aTb, cov_aTb, nTr, cov_nTr)
        return LoopCandidate(m, n, mTn, cov_mTn, ref.score, window_xy)

    def _coarse(self, m: int):
        """m's grid max-pooled to ``global_resolution_m``, precomputed (cached like ``_precomputed``)."""
        from holoslam.submaps import bnb
        from holoslam.submaps.global_search import pool_factor, pool_grid

        if m in self.pre_coarse:
            self.pre_coarse.move_to_end(m)
            return self.pre_coarse[m]
        gr = self.grids[m]
        f = pool_factor(self.cfg.global_resolution_m, gr.resolution)
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
        # the searches are independent: run in threads (compiled kernels without the GIL), their grids made
        # here first, and counted and offered for agreement in the order chosen, as one after the other would be
        grids = [(self._coarse(t[0]), self._precomputed(t[0])) for t in chosen]
        t0 = time.perf_counter()

        def one(q: int):
            m, seed, wx, wy, wth = chosen[q]
            return self._global(*grids[q], m, n, nTr, cov_nTr, b_pts, g_pts, seed, wx, wy, wth)

        outs = list(_threads().map(one, range(len(chosen)))) if len(chosen) > 1 else [one(0)] if chosen else []
        self.seconds["global"] += time.perf_counter() - t0
        out: list[LoopCandidate] = []
        for (m, *_), (cand, reasons) in zip(chosen, outs, strict=True):
            self.last_global[m] = travelled
            for reason in reasons:
                self._count(reason)
            if reasons[:1] == ["global searches"]:
                self.tried += 1
            self.ambiguous += "global: ambiguous, kept with the peaks' spread" in reasons
            if cand is not None:
                out.extend(self._agreed(replace(cand, travelled=travelled), est_wTa, travel, "global"))
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

    def _global(self, pre, pre_fine, m: int, n: int, nTr, cov_nTr, b_pts, g_pts, seed, wx: float,
                wy: float, wth: float = math.pi) -> tuple[LoopCandidate | None, list[str]]:
        """One global search (``global_search``) against m's coarse and fine grids (``pre``, ``pre_fine``):
        coarse over the whole of m's grid at every heading (the window only chose m as a target: it may be too
        small, ``search``), fine around the coarse best, second peaks kept in the covariance, refinement; a match
        turned from the ``seed`` by more than the window's heading ``wth`` is dropped
        (``global_within_heading_window``), and one further from it than ``global_window_ratio`` times the window
        (``global_ambiguous_window_ratio`` when it has second peaks). The closure or None, and the outcome's
        reasons to count; reads the search's state only."""
        from holoslam.submaps.global_search import clip_window, coarse_match

        c = self.cfg
        clipped = clip_window(seed, _LOST_M, _LOST_M, pre.origin, pre.shape, pre.res)
        if clipped is None:
            return None, ["global: window off the submap"]
        reasons = ["global searches"]
        centre, cx, cy = clipped
        coarse = coarse_match(pre, g_pts, centre, cx, cy, math.pi, c.global_coarse_min_score * self.scale,
                              c.global_max_range_m)
        if coarse is None:
            return None, reasons + ["global: no match above the score"]
        win = SearchWindow(pre_fine, b_pts, coarse.aTb, c.global_check_xy, math.radians(c.global_check_deg))
        min_score, margin = c.global_min_score * self.scale, c.ambiguity_margin * self.scale
        hit = win.best(min_score, margin)
        if hit is None:
            return None, reasons + ["global: fine match below the score"]
        if c.global_within_heading_window and abs(g.wrap(hit.aTb[2] - seed[2])) > wth:
            return None, reasons + ["global: turned beyond the heading window"]
        peaks = win.second_peaks(hit, margin, c.ambiguity_exclude_xy,
                                 math.radians(c.ambiguity_exclude_deg), c.global_ambiguity_peaks)
        ratio = max(abs(hit.aTb[0] - seed[0]) / max(wx, 1e-9), abs(hit.aTb[1] - seed[1]) / max(wy, 1e-9))
        if ratio > (c.global_ambiguous_window_ratio if peaks else c.global_window_ratio):
            return None, reasons + ["global: ambiguous beyond the window" if peaks else "global: beyond the window"]
        if peaks:
            reasons.append("global: ambiguous, kept with the peaks' spread")
        ref = self._refine(m, b_pts, hit, min_score)
        if ref is None:
            return None, reasons + ["global: refinement failed"]
        return self._candidate(m, n, nTr, cov_nTr, b_pts, ref, peaks, max(wx, wy)), reasons


_POOL: tuple[int, ThreadPoolExecutor] | None = None  # (the process that made it, the pool)


def _threads() -> ThreadPoolExecutor:
    """The threads the windowed and the global searches of a node share (made on first use; up to 4, one per
    core). A process forked from one that had them (a batch's worker processes) makes its own: a pool's threads
    do not survive a fork, and the copied pool would wait for them forever."""
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1)),
                                                 thread_name_prefix="holoslam-loops"))
    return _POOL[1]


_LOST_M = 1e5  # m: a window this wide comes from a break of local SLAM (``relative_covariances``), not from drift
