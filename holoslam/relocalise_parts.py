"""Relocalisation's parts (``holoslam.relocalise`` puts them together): its settings, the laser and object
hypotheses from global matches, their grouping by consistency, the map check and the local matches."""


from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.loop_verify import Agreement, VerifyConfig

__all__ = ["RelocaliseConfig", "LaserMatch", "Hypothesis", "Relocalisation", "fit_se2", "object_hypothesis", "precompute_stored", "global_match", "local_matches", "join_agreement", "query_points", "laser_matches", "laser_groups", "laser_hypothesis", "checked_hypothesis"]



@dataclass(frozen=True, slots=True)
class RelocaliseConfig:
    """Relocalisation settings (module docstring)."""

    # mean probability of the points (0.1-0.9) a global match must reach: Cartographer's
    # global_localization_min_score is 0.6; a session submap overlaps a stored one only in part, and its points
    # off the stored submap's explored area score 0.1 (measured on the simulated household: true matches of
    # well-overlapping submaps score 0.55-0.75, a wrong best-of-everything 0.35-0.5)
    min_score: float = 0.55
    # m / deg: two matches agree on the session's transform within these. A refined match is good to a cell or
    # two (0.05 m grids) at the matched submap; a 1 deg error moves a point 10 m from the anchor by 0.17 m, so
    # 0.3 m / 3 deg accepts the matches of one place and refuses those of another (a room 1 m over is 3x out)
    consistent_xy_m: float = 0.3
    consistent_deg: float = 3.0
    min_consistent: int = 3  # Cartographer's relocalisation test: at least 3 cross-trajectory constraints
    min_session_submaps: int = 2  # the consistent matches come from this many session submaps at least
    runner_up_ratio: float = 0.5  # the best inconsistent group may hold at most this fraction of the best's size
    # the laser search stops after a session submap once a verified group holds this many matches (twice the
    # minimum: a margin over the runner-up test); 0 searches every pair
    enough_consistent: int = 6
    # once this many matches agree, a session submap is searched only in the stored submaps near where they put it
    # (each search still global); a single match guides nothing (one wrong match would steer the search)
    guide_support: int = 2
    guide_radius_m: float = 8.0  # m: a submap reaches a few metres (household rooms, the real logs' corridors)
    # searches at most (session submaps x stored submaps); a long session against a large store is cut off here
    # and, without a verified group by then, stays unjoined (the report says how many were searched)
    max_searches: int = 600
    # m: the session submap's anchor is searched over the stored grid and this far beyond it (a robot starts a
    # submap inside what it sees; overlapping submaps hold each other's anchors or nearly)
    window_margin_m: float = 1.0
    # m: the branch and bound uses the points within this range of the session submap's anchor: the angular step
    # is the rotation that moves the farthest point by one cell, so a 30 m laser's far points (the real logs)
    # make 3,700 headings where 8 m (the household laser's range) make 1,000; the refinement uses every point
    search_max_range_m: float = 8.0
    search_voxel_m: float = 0.1  # m: the session submap's points thinned for the branch and bound (2 cells)
    search_min_points: int = 150  # points kept at least by that thinning
    min_query_points: int = 50  # a session submap whose anchor scan has fewer returns is not searched
    depth: int = 7  # the branch and bound's precomputed levels (Cartographer's 7)
    # m: the search is coarse to fine (``holoslam.submaps.global_search``, the loop search's): branch and bound
    # over the stored grid max-pooled to this resolution first (an upper bound of the fine score: a right match
    # is never pruned there), then the full-resolution branch and bound only within coarse_check_xy_m /
    # coarse_check_deg of the coarse best; 0: the full-resolution branch and bound over the whole submap.
    # 0.2 m is the loop search's (LoopConfig.global_resolution_m, measured on aces: 20-70 ms per whole submap
    # instead of 0.3-1.2 s)
    coarse_resolution_m: float = 0.2
    coarse_check_xy_m: float = 1.0  # m: the loop search's global_check_xy (5 coarse cells)
    coarse_check_deg: float = 5.0  # deg: the loop search's global_check_deg (a few coarse angular steps)
    # Once placed, every session submap is matched locally (``local_matches``) into the stored submaps whose
    # anchors lie within close_radius_m of where the hypothesis puts it, the nearest close_per_submap of them: the
    # few global matches that verified the join are too few to align two sessions to the centimetre (3
    # sessions of intel: 6-10 of them, relations across sessions 0.2-0.3 m). A window of the consistency's
    # 0.3 m / 3 deg around the prediction; accepted at min_score and consistent with the hypothesis
    close_radius_m: float = 6.0
    close_per_submap: int = 3
    # The map check of a laser hypothesis (``join_agreement``, the loop search's ``map_agreement``): the session
    # submaps within ``verify.neighbours`` indices of those whose matches agree, laid by the hypothesis onto the
    # stored submaps whose anchors lie within verify_radius_m of theirs; walls must fall on walls, not in space
    # the other side saw free. A hypothesis it refuses is not joined; the next consistent group that passes it
    # and the verification above is (aces' third session: 4 matches one corridor bay along, 0.7-0.9 m off)
    verify_joins: bool = True
    verify_radius_m: float = 10.0  # m: a real log's submap spans 10-30 m (30 m lasers); the household's 5-8 m
    verify: VerifyConfig = field(default_factory=VerifyConfig)  # the loop search's, calibrated on aces
    # Verification by prediction (``predicted_hypothesis``), when the global matches verify no group (too few
    # session submaps, or a runner-up as large): each of the largest predict_candidates consistent groups places
    # the session, the other session submaps' keyframes are matched locally where it puts them, grown outwards
    # (``predict``; ``local_matches``' settings: close_radius_m, close_per_submap, min_score, a 0.3 m / 3 deg window;
    # close_per_submap 0 turns it off), and the map check (``join_agreement``) runs at the fitted transform around the group's own session
    # submaps, as for a verified group (over every placed submap it refused the right place on aces' third
    # session, 0.87: the stored map there is bent by up to 1.1 m against the whole log's run). A group is
    # verified when the local matches of at least predict_min_submaps further session submaps confirm it, the map check does not
    # refuse it and no other group's predictions come within runner_up_ratio of it. 3: the global test's
    # min_consistent, now as submaps placed where the hypothesis said they would be, each a scan from another
    # place; a wrong group's predictions fall where the map does not hold those scans
    predict_min_submaps: int = 3  # 0: no verification by prediction
    # every this many keyframes of a session submap are predicted and matched, not its anchor scan alone (the
    # settling's closures search every third too). On aces' third session the anchor scans confirm at most 2 further
    # submaps of the right place (the others overlap the stored map too little to score 0.55); every third
    # keyframe confirms 9 of it and 3-4 of the wrong places (2-4 m off along the corridor). 0: the anchor scan alone
    predict_keyframe_step: int = 3
    # a session submap confirms a prediction when at least this share of its keyframes predicted near a stored
    # submap match there. Walls match walls: in another building a corridor's keyframes match here and there (the 18
    # sessions of the wrong-building check: up to 16 of 44 session submaps with one keyframe or more matched, at
    # most 2 with 0.5 of them or more); where the stored map holds the place most do (aces' third session, the right
    # place: 0.5-1.0 of them in 5 of its submaps)
    predict_keyframe_share: float = 0.5
    predict_candidates: int = 4  # groups tried, largest first (each a local match per session submap and nearby submap)
    object_inlier_m: float = 0.3  # m: an object this close to its stored place agrees (the "moved" threshold)
    min_object_inliers: int = 3  # objects agreeing with an object hypothesis for it to be verified
    min_pair_separation_m: float = 1.0  # m: two objects nearer fix the heading poorly (5 cm in 1 m = 3 deg)
    # sigmas of the hypothesis's covariance floor (m, m, rad): one grid cell and the consistency's resolution
    floor_sigmas: tuple[float, float, float] = (0.05, 0.05, math.radians(0.5))


@dataclass(frozen=True, eq=False)
class LaserMatch:
    """Session submap ``new`` (index) found in stored submap ``old`` (row id): ``oTn`` the new anchor in the old
    anchor's frame, its covariance, score, and the session transform it implies."""

    new: int
    old: int
    oTn: np.ndarray
    cov_oTn: np.ndarray
    score: float
    wTs: np.ndarray


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """A verified (or not) session transform: ``wTs``, its covariance, the support (matches or objects)."""

    wTs: np.ndarray
    cov_wTs: np.ndarray
    support: int
    verified: bool
    why: str
    members: tuple = ()  # LaserMatch (laser) or object ids (objects) that agree


@dataclass(frozen=True, eq=False)
class Relocalisation:
    """The outcome: ``joined_by`` laser / objects / both / none, the chosen hypothesis (None: not placed),
    both sources' hypotheses, the consistent laser matches (cross-session factors), timings and the reason."""

    joined_by: str
    hypothesis: Hypothesis | None
    laser: Hypothesis | None
    objects: Hypothesis | None
    matches: tuple[LaserMatch, ...]
    searches: int
    seconds: float
    why: str
    all_matches: tuple[LaserMatch, ...] = field(default_factory=tuple)
    cpu_seconds: float = 0.0  # the process's CPU time (a shared machine's wall time reads high)

    @property
    def placed(self) -> bool:
        return self.hypothesis is not None


def fit_se2(s_xy: np.ndarray, w_xy: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Least-squares wTs with w = R s + t over point pairs (weighted Kabsch/Umeyama in 2D, no scale)."""
    s = np.asarray(s_xy, np.float64).reshape(-1, 2)
    w = np.asarray(w_xy, np.float64).reshape(-1, 2)
    wt = np.ones(len(s)) if weights is None else np.asarray(weights, np.float64)
    wt = wt / wt.sum()
    ms, mw = wt @ s, wt @ w
    a, b = s - ms, w - mw
    c = float(np.sum(wt * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    d = float(np.sum(wt * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])))
    th = math.atan2(d, c)
    t = mw - g.rot2(th) @ ms
    return np.array([t[0], t[1], g.wrap(th)])


def _spread_cov(wTs: np.ndarray, members: np.ndarray, cfg: RelocaliseConfig) -> np.ndarray:
    """The hypothesis's covariance: the members' spread about it (body frame) over their number, plus the floor."""
    d = g.between(np.broadcast_to(wTs, members.shape), members).reshape(-1, 3)
    d[:, 2] = g.wrap(d[:, 2])
    n = max(len(d), 1)
    spread = (d.T @ d) / n / n if len(d) > 1 else np.zeros((3, 3))
    return spread + np.diag(np.square(cfg.floor_sigmas))


# ---------------------------------------------------------------------------------------------- objects


def object_hypothesis(session_xy: dict[str, np.ndarray], world_xy: dict[str, np.ndarray],
                      cfg: RelocaliseConfig = RelocaliseConfig()) -> Hypothesis | None:
    """The session transform from objects known to both (module docstring); None with fewer than two usable."""
    common = sorted(set(session_xy) & set(world_xy))
    if len(common) < 2:
        return None
    S = np.array([session_xy[k] for k in common], np.float64)
    W = np.array([world_xy[k] for k in common], np.float64)
    best: tuple[int, float, np.ndarray] | None = None
    for a, b in combinations(range(len(common)), 2):
        if np.hypot(*(S[a] - S[b])) < cfg.min_pair_separation_m or np.hypot(*(W[a] - W[b])) < cfg.min_pair_separation_m:
            continue
        T = fit_se2(S[[a, b]], W[[a, b]])
        r = np.hypot(*(g.transform_points(T, S) - W).T)
        n, cost = int(np.sum(r < cfg.object_inlier_m)), float(np.sum(np.minimum(r, cfg.object_inlier_m)))
        if best is None or (n, -cost) > (best[0], -best[1]):
            best = (n, cost, T)
    if best is None:
        return None
    T = best[2]
    for _ in range(3):  # refit over the inliers until they settle
        r = np.hypot(*(g.transform_points(T, S) - W).T)
        inl = r < cfg.object_inlier_m
        if inl.sum() < 2:
            break
        T = fit_se2(S[inl], W[inl])
    r = np.hypot(*(g.transform_points(T, S) - W).T)
    inl = r < cfg.object_inlier_m
    n = int(inl.sum())
    # covariance: the residuals' spread over the inliers, propagated as a translation sigma and, over the
    # inliers' extent, a heading sigma
    sig = max(float(np.sqrt(np.mean(r[inl] ** 2))) if n else cfg.object_inlier_m, cfg.floor_sigmas[0])
    extent = max(float(np.max(np.hypot(*(S[inl] - S[inl].mean(0)).T))) if n else 1.0, 0.5)
    cov = np.diag([sig**2 / max(n, 1), sig**2 / max(n, 1), (sig / extent) ** 2 / max(n - 1, 1)])
    ok = n >= cfg.min_object_inliers
    why = (f"{n} of {len(common)} objects known to the store agree within {cfg.object_inlier_m} m" +
           ("" if ok else f" (needs {cfg.min_object_inliers})"))
    return Hypothesis(T, cov, n, ok, why, tuple(k for k, i in zip(common, inl, strict=True) if i))


# ---------------------------------------------------------------------------------------------- laser


def precompute_stored(stored, cfg: RelocaliseConfig) -> tuple:
    """A stored submap's branch-and-bound grids: (full resolution, coarse or None) (``coarse_resolution_m``)."""
    from holoslam.submaps import bnb
    from holoslam.submaps.global_search import pool_factor, pool_grid

    fine = bnb.precompute(stored.prob, cfg.depth, origin=stored.origin, res=stored.resolution)
    f = pool_factor(cfg.coarse_resolution_m, float(stored.resolution))
    coarse = None if f <= 1 else bnb.precompute(pool_grid(stored.prob, f), cfg.depth, origin=stored.origin,
                                                res=float(stored.resolution) * f)
    return fine, coarse


def global_match(stored, points: np.ndarray, cfg: RelocaliseConfig, pre=None):
    """The pose of a session submap (its ``points`` (M, 2) in its anchor frame) in a stored submap (``prob``,
    ``origin``, ``resolution`` in the stored anchor's frame), searched over the whole stored submap and every
    heading: branch and bound on points thinned to ``search_voxel_m`` (``holoslam.submaps.bnb``), refined by
    the continuous matcher on every point. Returns (oTn (3,), cov (3, 3), score) or None. The one place that
    calls the global search: another global search (a dedicated one over whole maps) replaces this body."""
    from holoslam.submaps import bnb
    from holoslam.submaps.scan_filter import ScanFilterConfig, adaptive_voxel_filter
    from holoslam.submaps.scanmatch import MatchConfig, match_scan

    prob, origin, res = stored.prob, stored.origin, float(stored.resolution)
    fine, coarse = pre if pre is not None else precompute_stored(stored, cfg)
    h, w = prob.shape
    half = np.array([w * res / 2.0, h * res / 2.0])
    centre = np.array(origin) + half
    pts = np.asarray(points, np.float64)
    near = pts[np.hypot(pts[:, 0], pts[:, 1]) <= cfg.search_max_range_m]
    pts = adaptive_voxel_filter(near if len(near) >= cfg.search_min_points else pts,
                                ScanFilterConfig(cfg.search_voxel_m, cfg.search_min_points))
    win = (float(half[0]) + cfg.window_margin_m, float(half[1]) + cfg.window_margin_m)
    seed = np.array([centre[0], centre[1], 0.0])
    if coarse is None:
        hit = bnb.search(fine, pts, seed, win, math.pi, cfg.min_score)
    else:
        c = bnb.search(coarse, pts, seed, win, math.pi, cfg.min_score)
        hit = None if c is None else bnb.search(fine, pts, c.aTb, cfg.coarse_check_xy_m,
                                                math.radians(cfg.coarse_check_deg), cfg.min_score)
    if hit is None:
        return None
    # a search around a hypothesis, not tracking from odometry: the window's best seeds the refinement (seed_margin 0)
    refine = MatchConfig(linear_window=0.5, angular_window_deg=3.0, translation_delta_weight=1e3,
                         rotation_delta_weight=1e3, min_score=0.0, seed_margin=0.0)
    ref = match_scan(prob, origin, res, np.asarray(points, np.float64), hit.aTb, refine)
    if ref.score < cfg.min_score or np.hypot(*(ref.aTb[:2] - hit.aTb[:2])) > 2 * res:
        return None
    return ref.aTb, ref.cov_aTb, float(ref.score)


def local_matches(session_submaps, session_sTa: np.ndarray, stored_submaps, wTs: np.ndarray,
                  cfg: RelocaliseConfig = RelocaliseConfig()) -> list[LaserMatch]:
    """Cross-session matches once the session is placed by ``wTs`` (``close_radius_m`` and the settings beside
    it): each session submap's anchor scan registered by the continuous matcher around its predicted pose in the
    nearest stored submaps."""
    out: list[LaserMatch] = []
    for k, sm in enumerate(session_submaps):
        for m in _matches_near(query_points(sm), g.compose(wTs, session_sTa[k]), stored_submaps, cfg):
            implied = g.compose(g.compose(m[0], m[1]), g.inverse(session_sTa[k]))
            if _consistent(implied[None], np.asarray(wTs)[None], cfg)[0, 0]:
                out.append(LaserMatch(k, m[4], m[1], m[2], m[3], implied))
    return out


def _matches_near(q: np.ndarray, wTn: np.ndarray, stored_submaps, cfg: RelocaliseConfig) -> list[tuple]:
    """Scan ``q`` (a session submap's anchor scan) registered by the continuous matcher around ``wTn`` (its anchor's
    predicted pose) in the ``close_per_submap`` stored submaps nearest it within ``close_radius_m``, a window of
    ``consistent_xy_m`` / ``consistent_deg``: (wTa of the stored submap, aTn, cov, score, stored id) of those
    at ``min_score`` at least."""
    from holoslam.submaps.scanmatch import MatchConfig, match_scan

    if cfg.close_per_submap <= 0 or len(q) < cfg.min_query_points or not len(stored_submaps):
        return []
    mc = MatchConfig(linear_window=cfg.consistent_xy_m, angular_window_deg=cfg.consistent_deg, min_score=0.0,
                     seed_margin=0.0)  # the placement is a hypothesis: its window's best seeds the refinement
    anchors = np.array([s.wTa for s in stored_submaps], np.float64).reshape(-1, 3)
    d = np.hypot(anchors[:, 0] - wTn[0], anchors[:, 1] - wTn[1])
    out = []
    for j in np.argsort(d, kind="stable")[: cfg.close_per_submap].tolist():
        st = stored_submaps[j]
        if d[j] > cfg.close_radius_m or st.prob is None:
            break
        m = match_scan(st.prob, st.origin, float(st.resolution), q, g.compose(g.inverse(anchors[j]), wTn), mc)
        if m.score >= cfg.min_score:
            out.append((anchors[j], m.aTb, m.cov_aTb, float(m.score), int(st.id)))
    return out


def _grid(submap):
    """A submap's ``ProbGrid`` (a session's ``Submap.grid`` or a stored one's prob / known), None without one."""
    from holoslam.submaps.probgrid import ProbGrid

    gr = getattr(submap, "grid", None)
    if isinstance(gr, ProbGrid):
        return gr
    if getattr(submap, "prob", None) is not None:
        return ProbGrid(np.asarray(submap.prob, np.float32), tuple(submap.origin), float(submap.resolution),
                        known=submap.known)
    return None


def join_agreement(session_submaps, session_sTa: np.ndarray, stored_submaps, wTs: np.ndarray, near: list[int],
                   cfg: RelocaliseConfig = RelocaliseConfig()) -> Agreement | None:
    """The map check of the session placed by ``wTs``: the session submaps within ``cfg.verify.neighbours``
    indices of those in ``near`` (the ones whose matches agree), each at wTs ∘ sTa, against the stored submaps
    whose anchors lie within ``verify_radius_m`` of theirs, at their stored poses: the loop search's
    ``map_agreement`` (walls on walls against walls in the other side's free space, both ways). None when
    either side has no grid (no verdict)."""
    from holoslam.submaps.loop_verify import map_agreement

    K = cfg.verify.neighbours
    new = sorted({q for k in near for q in range(k - K, k + K + 1) if 0 <= q < len(session_submaps)})
    new = [q for q in new if _grid(session_submaps[q]) is not None]
    if not new:
        return None
    wTn = g.compose(np.broadcast_to(np.asarray(wTs, np.float64), (len(new), 3)), np.asarray(session_sTa)[new])
    anchors = np.array([s.wTa for s in stored_submaps], np.float64).reshape(-1, 3)
    d = np.min(np.hypot(anchors[:, None, 0] - wTn[None, :, 0], anchors[:, None, 1] - wTn[None, :, 1]), axis=1)
    old = [j for j in np.argsort(d, kind="stable").tolist()
           if d[j] <= cfg.verify_radius_m and _grid(stored_submaps[j]) is not None]
    if not old:
        return None
    # map_agreement's indices: the old side around a pivot m (|q - m| <= its neighbours), the new side just before
    # n, both sides in one frame (the world: m and n at the identity, mTn the identity)
    P, Q = len(old), len(new)
    m, n = P, 2 * P + 1 + Q
    grids = {q: _grid(stored_submaps[j]) for q, j in enumerate(old)}
    grids.update({2 * P + 1 + q: _grid(session_submaps[k]) for q, k in enumerate(new)})
    est = np.zeros((n + 1, 3))
    est[:P] = anchors[old]
    est[2 * P + 1:n] = wTn
    part = np.zeros(n + 1, np.int64)
    part[2 * P + 1:] = 1
    vcfg = dataclasses.replace(cfg.verify, neighbours=max(P, Q))
    return map_agreement(grids, est, part, m, n, np.zeros(3), vcfg)


def query_points(submap) -> np.ndarray:
    """What a session submap is searched with: the scan taken at its anchor (its first keyframe's points, in the
    anchor frame), as a loop closure searches one scan. A scan sees from one place what a stored submap of that
    place holds; the submap's own points reach beyond any one stored submap's explored area, and on the real logs
    (30 m lasers, partial overlaps) those points scoring 0.1 kept every match under the score. A record without
    scans (a stored submap: ``points`` is its anchor scan) gives its ``points``."""
    scans = getattr(submap, "scan_points", None)
    if scans:
        return g.transform_points(np.asarray(submap.aTb, np.float64).reshape(-1, 3)[0], np.asarray(scans[0], float))
    return np.asarray(submap.points, np.float64).reshape(-1, 2)


def laser_matches(session_submaps, session_sTa: np.ndarray, stored_submaps,
                  cfg: RelocaliseConfig = RelocaliseConfig(), guide: Hypothesis | None = None
                  ) -> tuple[list[LaserMatch], int]:
    """Every session submap (``query_points``: its anchor scan; the fullest first) against every stored submap (``StoredSubmap`` with
    grids): the matches above ``min_score`` and the number of searches. The search stops early once the matches
    hold a verified group of ``enough_consistent`` (``laser_hypothesis``). ``guide``: a hypothesis (the objects')
    that chooses where to search from the start (``_candidates``)."""

    out: list[LaserMatch] = []
    searches = 0
    pre: dict[int, tuple] = {}
    queries = [query_points(sm) for sm in session_submaps]
    order = sorted(range(len(session_submaps)), key=lambda k: -len(queries[k]))
    for k in order:
        if len(queries[k]) < cfg.min_query_points:
            continue
        for st in _candidates(stored_submaps, guide, session_sTa[k], cfg):
            if searches >= cfg.max_searches:
                break
            if st.id not in pre:
                pre[st.id] = precompute_stored(st, cfg)
            searches += 1
            m = global_match(st, queries[k], cfg, pre[st.id])
            if m is None:
                continue
            oTn, cov, score = m
            wTs = g.compose(g.compose(st.wTa, oTn), g.inverse(session_sTa[k]))
            out.append(LaserMatch(k, st.id, oTn, cov, score, wTs))
        h = laser_hypothesis(out, cfg)
        if cfg.enough_consistent and h is not None and h.verified and h.support >= cfg.enough_consistent:
            # stop only for a group the map check does not refuse (the check runs here, not after every submap)
            h, _refused = checked_hypothesis(out, session_submaps, session_sTa, stored_submaps, cfg)
            if h is not None and h.verified and h.support >= cfg.enough_consistent:
                break
        if h is not None and h.support >= cfg.guide_support:
            guide = h
    return out, searches


def _candidates(stored_submaps, guide: Hypothesis | None, sTa: np.ndarray, cfg: RelocaliseConfig) -> list:
    """The stored submaps a session submap is searched in: all of them, or, once ``guide_support`` matches agree
    on a transform, those whose anchor lies within ``guide_radius_m`` of where it puts the session submap, nearest
    first. Each search is still global (whole submap, every heading): the guide only chooses where to look."""
    if guide is None:
        return list(stored_submaps)
    p = g.compose(guide.wTs, sTa)[:2]
    d = np.array([np.hypot(*(np.asarray(s.wTa[:2]) - p)) for s in stored_submaps])
    return [stored_submaps[i] for i in np.argsort(d, kind="stable") if d[i] <= cfg.guide_radius_m]


def _consistent(a: np.ndarray, b: np.ndarray, cfg: RelocaliseConfig) -> np.ndarray:
    """Pairwise agreement of session transforms a (N, 3) and b (M, 3): (N, M) bool."""
    dxy = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    dth = np.abs(g.wrap(a[:, None, 2] - b[None, :, 2]))
    return (dxy <= cfg.consistent_xy_m) & (dth <= math.radians(cfg.consistent_deg))


def _group(T: np.ndarray, cfg: RelocaliseConfig) -> list[int]:
    """The largest set of pairwise consistent transforms, greedily: seeded by the transform with most consistent
    others, members added in order of their own support while consistent with every member so far."""
    C = _consistent(T, T, cfg)
    support = C.sum(axis=1)
    best: list[int] = []
    for s in np.argsort(-support, kind="stable")[: min(len(T), 20)].tolist():
        members = [s]
        for k in np.argsort(-support, kind="stable").tolist():
            if k != s and C[s, k] and all(C[k, m] for m in members):
                members.append(k)
        if len(members) > len(best):
            best = members
    return best


def _mean_wTs(matches) -> np.ndarray:
    """The score-weighted mean of the matches' session transforms (headings about the first's)."""
    M = np.array([m.wTs for m in matches], np.float64).reshape(-1, 3)
    w = np.array([m.score for m in matches], np.float64)
    th0 = M[0, 2]
    return np.array([*(w @ M[:, :2] / w.sum()), g.wrap(th0 + float(w @ g.wrap(M[:, 2] - th0) / w.sum()))])


def _not_refuted(matches: list[LaserMatch], refuted: tuple[np.ndarray, ...], cfg: RelocaliseConfig
                 ) -> list[LaserMatch]:
    if not refuted or not matches:
        return list(matches)
    R = np.array(refuted).reshape(-1, 3)
    return [m for m in matches if not _consistent(np.asarray(m.wTs)[None], R, cfg).any()]


def laser_groups(matches: list[LaserMatch], cfg: RelocaliseConfig = RelocaliseConfig(),
                 refuted: tuple[np.ndarray, ...] = (), most: int | None = None) -> list[tuple[LaserMatch, ...]]:
    """The matches' consistent groups, largest first: the largest (``_group``), then the largest of the matches
    that agree with none of its members, and so on (the first two are ``laser_hypothesis``'s group and
    runner-up); at most ``most``. Matches that agree with a ``refuted`` transform are left out."""
    matches = _not_refuted(matches, refuted, cfg)
    T = np.array([m.wTs for m in matches], np.float64).reshape(-1, 3)
    rest = list(range(len(T)))
    out: list[tuple[LaserMatch, ...]] = []
    while rest and (most is None or len(out) < most):
        members = [rest[i] for i in _group(T[rest], cfg)]
        out.append(tuple(matches[k] for k in members))
        rest = [k for k in rest if not _consistent(T[k : k + 1], T[members], cfg).any()]
    return out


def laser_hypothesis(matches: list[LaserMatch], cfg: RelocaliseConfig = RelocaliseConfig(),
                     refuted: tuple[np.ndarray, ...] = ()) -> Hypothesis | None:
    """The verified laser hypothesis of the matches (module docstring), or the best unverified one, or None.
    ``refuted``: session transforms the map check refused; the matches that agree with one of them are left out
    (they neither support a hypothesis nor count as its runner-up)."""
    matches = _not_refuted(matches, refuted, cfg)
    if not matches:
        return None
    T = np.array([m.wTs for m in matches])
    members = _group(T, cfg)
    rest = [k for k in range(len(T)) if not _consistent(T[k : k + 1], T[members], cfg).any()]
    runner = len(_group(T[rest], cfg)) if rest else 0
    M = T[members]
    wTs = _mean_wTs([matches[k] for k in members])
    n_new = len({matches[k].new for k in members})
    ok = (len(members) >= cfg.min_consistent and n_new >= cfg.min_session_submaps
          and runner <= cfg.runner_up_ratio * len(members))
    why = (f"{len(members)} consistent laser matches from {n_new} session submaps (of {len(matches)} matches; "
           f"the best other group {runner})")
    if not ok:
        why += (f"; needs {cfg.min_consistent} from {cfg.min_session_submaps} submaps and no other group over "
                f"{cfg.runner_up_ratio:g}x its size")
    return Hypothesis(wTs, _spread_cov(wTs, M, cfg), len(members), ok, why, tuple(matches[k] for k in members))


def checked_hypothesis(matches: list[LaserMatch], session_submaps, session_sTa: np.ndarray, stored_submaps,
                       cfg: RelocaliseConfig = RelocaliseConfig()) -> tuple[Hypothesis | None, list[str]]:
    """``laser_hypothesis`` with the map check (``join_agreement``, ``verify_joins``): a verified group the check
    refuses is set aside and the next is tried, so long as one is verified. Returns the hypothesis (verified and
    not refused, or the best unverified one, or None) and a note per refused group."""
    h, notes, _refuted = _checked(matches, session_submaps, session_sTa, stored_submaps, cfg)
    return h, notes


def _checked(matches: list[LaserMatch], session_submaps, session_sTa: np.ndarray, stored_submaps,
             cfg: RelocaliseConfig) -> tuple[Hypothesis | None, list[str], tuple[np.ndarray, ...]]:
    """``checked_hypothesis`` and the session transforms the map check refused."""
    refuted: list[np.ndarray] = []
    notes: list[str] = []
    while True:
        h = laser_hypothesis(matches, cfg, tuple(refuted))
        if h is None or not h.verified or not cfg.verify_joins:
            return h, notes, tuple(refuted)
        near = sorted({m.new for m in h.members})
        a = join_agreement(session_submaps, session_sTa, stored_submaps, h.wTs, near, cfg)
        if a is None or a.verdict(cfg.verify) is not False:
            tail = "" if a is None else f"; map check {a.fraction:.2f} of {a.support + a.conflict} walls"
            return dataclasses.replace(h, why=h.why + tail), notes, tuple(refuted)
        notes.append(f"refused by the map check ({a.fraction:.2f} of {a.support + a.conflict} walls agree, needs "
                     f"{cfg.verify.min_agreement:g}): {h.support} matches at ({h.wTs[0]:.2f}, {h.wTs[1]:.2f}, "
                     f"{math.degrees(h.wTs[2]):.1f} deg)")
        refuted.append(h.wTs)


def _agree(a: Hypothesis, b: Hypothesis, cfg: RelocaliseConfig) -> bool:
    return bool(_consistent(a.wTs[None], b.wTs[None], cfg)[0, 0])
