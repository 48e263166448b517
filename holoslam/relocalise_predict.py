"""Verification of a relocalisation hypothesis by prediction (``RelocaliseConfig.predict_min_submaps`` and the
settings beside it): each of the largest consistent groups of global matches places the session, and the
further session submaps are matched locally where that placement predicts them, grown outwards one step of the
session's own map at a time."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam import geometry as g
from holoslam.relocalise_parts import (
    Hypothesis,
    LaserMatch,
    RelocaliseConfig,
    _matches_near,
    _spread_cov,
    fit_se2,
    join_agreement,
    laser_groups,
    query_points,
)
from holoslam.submaps.loop_verify import Agreement

__all__ = ["Prediction", "predict", "predicted_hypothesis"]

_DEFAULTS = RelocaliseConfig()  # frozen: the functions' default


@dataclass(frozen=True, eq=False)
class Prediction:
    """One candidate group tested by prediction (``predict``): its matches (``group``), the session transform
    fitted to every placed session submap, where each placed session submap's anchor lies in the world
    (``wTa``: the group's by its global matches, the others by their local matches), the further session
    submaps tried (``tested``: a stored submap near their predicted place), the local matches that placed them
    (``confirmed``) and the map check (None: no verdict)."""

    group: tuple[LaserMatch, ...]
    wTs: np.ndarray
    wTa: dict[int, np.ndarray]
    tested: tuple[int, ...]
    confirmed: tuple[LaserMatch, ...]
    agreement: Agreement | None
    refused: bool

    @property
    def submaps(self) -> int:
        """Further session submaps confirmed (each counted once, whatever its number of local matches)."""
        return len({m.new for m in self.confirmed})

    def text(self) -> str:
        w, a = self.wTs, self.agreement
        check = "" if a is None else (f", map check {a.fraction:.2f} of {a.support + a.conflict} walls"
                                      + (" (refused)" if self.refused else ""))
        return (f"{len(self.group)} matches at ({w[0]:.2f}, {w[1]:.2f}, {math.degrees(w[2]):.1f} deg): "
                f"{self.submaps} of {len(self.tested)} further session submaps confirmed{check}")


def _same_place(a: Prediction, b: Prediction, cfg: RelocaliseConfig) -> bool:
    """Two predictions put one session submap at the same pose (within the consistency): one place reached from
    two groups (neighbouring groups of one place, a few decimetres apart, reach the same local matches)."""
    for k in set(a.wTa) & set(b.wTa):
        d = g.between(a.wTa[k], b.wTa[k])
        if np.hypot(d[0], d[1]) <= cfg.consistent_xy_m and abs(g.wrap(d[2])) <= math.radians(cfg.consistent_deg):
            return True
    return False


def predict(group: tuple[LaserMatch, ...], session_submaps, session_sTa: np.ndarray, stored_submaps,
            cfg: RelocaliseConfig = _DEFAULTS) -> Prediction:
    """A candidate group's predictions, grown outwards: the group's session submaps are placed by their global
    matches; the unplaced session submap nearest (in the session's frame) to a placed one is predicted from it
    (the placed anchor composed with their relative pose in the session) and matched locally there
    (``_matches_near``: a 0.3 m / 3 deg window); a match at ``min_score`` places it, and the next is predicted,
    until none is left to try (each keyframe of ``_keyframe_queries`` is tried; the best placed match places the
    submap). Each prediction spans one step of the session's own map, so a bend between the session and the stored
    map (aces' third session: 3.5 deg where the stored map is bent) does not leave the window. The session
    transform is then the least-squares fit of the placed anchors; the map check (``join_agreement``) runs at it
    around the group's own session submaps."""
    sTa = np.asarray(session_sTa, np.float64).reshape(-1, 3)
    wTa: dict[int, np.ndarray] = {}
    for m in sorted(group, key=lambda m: -m.score):
        wTa.setdefault(m.new, g.compose(m.wTs, sTa[m.new]))
    own = set(wTa)
    queries = {k: _keyframe_queries(session_submaps[k], cfg) for k in range(len(sTa)) if k not in wTa}
    tried: dict[int, int] = {}  # session submap -> the placed one it was last predicted from
    tested: set[int] = set()
    confirmed: list[LaserMatch] = []
    while True:
        placed = np.array(sorted(wTa))
        todo = [k for k in queries if k not in wTa]
        if not todo:
            break
        d = np.hypot(sTa[todo, None, 0] - sTa[None, placed, 0], sTa[todo, None, 1] - sTa[None, placed, 1])
        nearest = placed[np.argmin(d, axis=1)]
        order = [i for i in np.argsort(np.min(d, axis=1), kind="stable").tolist() if tried.get(todo[i]) != nearest[i]]
        if not order:
            break
        k, q = todo[order[0]], int(nearest[order[0]])
        tried[k] = q
        pred = g.compose(wTa[q], g.between(sTa[q], sTa[k]))
        near = [(pts, aTb) for pts, aTb in queries[k]
                if len(pts) >= cfg.min_query_points and _near_stored(g.compose(pred, aTb), stored_submaps, cfg)]
        if near:
            tested.add(k)
        found = [(m, i) for i, (pts, aTb) in enumerate(near)
                 for m in _matches_near(pts, g.compose(pred, aTb), stored_submaps, cfg)]
        if not found or len({i for _, i in found}) < cfg.predict_keyframe_share * len(near):
            continue
        hits = [(m[4], g.compose(m[1], g.inverse(near[i][1])), m[2], m[3], m[0]) for m, i in found]  # to the anchor
        best = max(hits, key=lambda h: h[3])
        wTa[k] = g.compose(best[4], best[1])
        confirmed += [LaserMatch(k, h[0], h[1], h[2], h[3], g.compose(g.compose(h[4], h[1]), g.inverse(sTa[k])))
                      for h in hits]
    keys = sorted(wTa)
    P = np.array([wTa[k] for k in keys])
    wTs = (fit_se2(sTa[keys, :2], P[:, :2]) if len(keys) >= 2 else g.compose(P[0], g.inverse(sTa[keys[0]])))
    a = join_agreement(session_submaps, sTa, stored_submaps, wTs, sorted(own), cfg) if cfg.verify_joins else None
    return Prediction(group, wTs, wTa, tuple(sorted(tested)), tuple(confirmed), a,
                      a is not None and a.verdict(cfg.verify) is False)


def _keyframe_queries(submap, cfg: RelocaliseConfig) -> list[tuple[np.ndarray, np.ndarray]]:
    """What a session submap is predicted with: every ``predict_keyframe_step``-th keyframe's points (base frame)
    and its pose in the anchor frame; a submap without keyframes (or the step 0): its ``query_points`` at the
    anchor."""
    scans = getattr(submap, "scan_points", None)
    if not scans or cfg.predict_keyframe_step <= 0:
        return [(query_points(submap), np.zeros(3))]
    aTb = np.asarray(submap.aTb, np.float64).reshape(-1, 3)
    return [(np.asarray(scans[i], np.float64), aTb[i]) for i in range(0, len(scans), cfg.predict_keyframe_step)]


def _near_stored(wTn: np.ndarray, stored_submaps, cfg: RelocaliseConfig) -> bool:
    anchors = np.array([s.wTa for s in stored_submaps], np.float64).reshape(-1, 3)
    return bool(len(anchors)) and float(np.min(np.hypot(anchors[:, 0] - wTn[0], anchors[:, 1] - wTn[1]))) <= cfg.close_radius_m


def predicted_hypothesis(matches: list[LaserMatch], session_submaps, session_sTa: np.ndarray, stored_submaps,
                         cfg: RelocaliseConfig = _DEFAULTS, refuted: tuple[np.ndarray, ...] = ()
                         ) -> tuple[Hypothesis | None, list[Prediction]]:
    """Verification by prediction (``predict_min_submaps`` and the settings beside it): the largest
    ``predict_candidates`` consistent groups (``laser_groups``, without the ``refuted`` transforms) each
    ``predict``-ed; the one confirmed by most further session submaps is verified when they are at least
    ``predict_min_submaps``, the map check does not refuse it and every other group not refused is confirmed by
    at most ``runner_up_ratio`` of its number. Returns that hypothesis (verified or not; None without groups
    or with the check off) and every candidate's prediction."""
    if cfg.predict_min_submaps <= 0 or cfg.close_per_submap <= 0:
        return None, []
    preds = [predict(gr, session_submaps, session_sTa, stored_submaps, cfg)
             for gr in laser_groups(matches, cfg, refuted, cfg.predict_candidates)]
    live = sorted((p for p in preds if not p.refused), key=lambda p: (-p.submaps, -len(p.group)))
    if not live:
        return None, preds
    best = live[0]
    runner = max((p.submaps for p in live[1:] if not _same_place(p, best, cfg)), default=0)
    ok = best.submaps >= cfg.predict_min_submaps and runner <= cfg.runner_up_ratio * best.submaps
    members = best.group + best.confirmed
    why = (f"{len(best.group)} consistent laser matches from {len({m.new for m in best.group})} session submaps, "
           f"their prediction confirmed by local matches of {best.submaps} further session submaps (of "
           f"{len(best.tested)} placed near a stored submap; {len(best.confirmed)} matches)"
           + ("" if best.agreement is None else
              f"; map check {best.agreement.fraction:.2f} of {best.agreement.support + best.agreement.conflict} walls")
           + f"; the best other group's predictions {runner}")
    if not ok:
        why += (f"; needs {cfg.predict_min_submaps} further submaps and no other group over "
                f"{cfg.runner_up_ratio:g}x")
    M = np.array([m.wTs for m in members], np.float64)
    return Hypothesis(best.wTs, _spread_cov(best.wTs, M, cfg), len(members), ok, why, members), preds
