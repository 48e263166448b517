"""Cross-session closures once a session is placed: every few keyframes of every session submap searched in the
stored submaps near it, by the run's own loop search (``holoslam.submaps.loops.LoopSearch``: its windowed branch
and bound around the estimate, its score thresholds, its ambiguity test that refuses a match with a second peak,
its refinement and Eq. 15 for the anchors' relative pose, at most ``max_per_pair`` closures a pair of submaps).

The global matches that verified the join (``holoslam.relocalise``) are few (3-10 a session) and all from the
anchor scans; two sessions of one building need as many closures between them as a run finds between its own
revisits to be aligned to the centimetre (intel, three sessions: 6-10 matches left its sessions 0.2-0.3 m apart).
Here the session's keyframes stand at their placed estimate (``wTs`` ∘ sTa ∘ aTb) and the stored submaps at
their stored poses, as a run's nodes and finished submaps do; the window is the loop search's right after a
closure (``base_window_xy``, ``base_window_deg``: the hypothesis is good to the relocalisation's 0.3 m / 3 deg).
A closure must also agree with the hypothesis within that 0.3 m / 3 deg (``RelocaliseConfig.consistent_*``):
it refines the join, it cannot move it elsewhere. Both hold where the session's matches placed it: a session is
rigid only to its own drift, so further along its path from the submaps that placed it (``path_from``; its own
loop closures are shortcuts), window and agreement grow with that path as the loop search's windows grow with the
travel since a closure (``LoopConfig.window_rate``, ``window_deg_rate``). Aces' second third, placed by its last
submaps, starts 1.3 m from its stored neighbour (the first third's loose end): a 1 m window there found none of
the closures a run finds, and its relations to the first third stayed 1.3 m off."""

from __future__ import annotations

import dataclasses

import numpy as np

from holoslam import geometry as g
from holoslam.relocalise_parts import LaserMatch, RelocaliseConfig, _consistent, _grid

__all__ = ["session_closures", "path_from"]


def path_from(session_sTa: np.ndarray, sources, relative=None) -> np.ndarray:
    """Per session submap, the path length (m) along the session to the nearest submap of ``sources`` (indices):
    the anchors' chain, each step the distance between consecutive anchors, the session's own loop closures
    (``relative``, a ``RelativePoseMeasurements`` of its anchors: kind ``loop``) free, as the run's anchor graph
    weighs them (``AnchorGraph.graph_distance``; its Dijkstra, from a virtual node tied to every source). All zero
    without sources."""
    from holoslam.submaps.anchor_graph import _shortest_paths, _undirected_csr

    sTa = np.asarray(session_sTa, np.float64).reshape(-1, 3)
    n, src = len(sTa), sorted({int(k) for k in sources if 0 <= int(k) < len(sTa)})
    if not src or n < 2:
        return np.zeros(n)
    free = 1e-9  # an edge of no length (a weight of 0 would be no edge)
    i, j = np.arange(n - 1), np.arange(1, n)
    w = np.maximum(np.hypot(*(sTa[1:, :2] - sTa[:-1, :2]).T), free)
    if relative is not None and len(relative.i):
        loop = np.asarray(relative.kind, object) == "loop"
        i = np.concatenate([i, np.asarray(relative.i)[loop]])
        j = np.concatenate([j, np.asarray(relative.j)[loop]])
        w = np.concatenate([w, np.full(int(loop.sum()), free)])
    i, j = np.concatenate([i, np.full(len(src), n)]), np.concatenate([j, src])  # the virtual source: node n
    w = np.concatenate([w, np.full(len(src), free)])
    return _shortest_paths(_undirected_csr(n + 1, i, j, w), n)[0][:n]


def _agreeing(match: LaserMatch, wTs: np.ndarray, cfg: RelocaliseConfig, loops, path_m: float) -> bool:
    """Does the closure ``match`` agree with the session transform ``wTs``, within the hypothesis's tolerance grown
    by the session's drift over ``path_m`` (module docstring)?"""
    grown = dataclasses.replace(cfg, consistent_xy_m=cfg.consistent_xy_m + loops.window_rate * path_m,
                                consistent_deg=cfg.consistent_deg + loops.window_deg_rate * path_m)
    return bool(_consistent(np.asarray(match.wTs)[None], np.asarray(wTs, np.float64)[None], grown)[0, 0])


def session_closures(session_submaps, session_sTa: np.ndarray, stored_submaps, wTs: np.ndarray, frontend=None,
                     every_nodes: int | None = None, cfg: RelocaliseConfig | None = None,
                     already=(), per_pair: int = 0, path_m: np.ndarray | None = None) -> list[LaserMatch]:
    """The cross-session closures of a placed session (module docstring): ``LaserMatch``es (new: session submap
    index, old: stored submap id, oTn: the new anchor in the old one). ``frontend``: the run's
    ``FrontEndConfig`` (its loop search and matcher settings; the defaults when None); ``every_nodes``: search
    from every k-th keyframe of a submap (the loop search's ``every_nodes`` when None); ``already``: the
    closures the join holds (``LaserMatch``es), counted against ``max_per_pair`` as the loop search counts its own;
    ``per_pair`` > 0 replaces that ``max_per_pair``; ``path_m`` (per session submap, ``path_from``): the path from
    the submaps that placed the session, over which windows and agreement grow (zero when None)."""
    from holoslam.submaps.frontend import FrontEndConfig
    from holoslam.submaps.loops import LoopSearch

    fe = frontend or FrontEndConfig()
    cfg = cfg or RelocaliseConfig()
    step = max(1, int(every_nodes if every_nodes is not None else fe.loops.every_nodes))
    loops = fe.loops if per_pair <= 0 else dataclasses.replace(fe.loops, max_per_pair=int(per_pair))
    search = LoopSearch(loops, fe.local.match)
    olds = [j for j, s in enumerate(stored_submaps) if _grid(s) is not None]
    for j in olds:
        search.add_submap(j, _grid(stored_submaps[j]))
    if not olds:
        return []
    M = len(stored_submaps)
    first = M + fe.loops.skip_recent + 1  # the session's submap k is node index first + k, past every stored one
    sTa = np.asarray(session_sTa, np.float64).reshape(-1, 3)
    est = np.zeros((first + len(sTa), 3))
    est[:M] = np.array([s.wTa for s in stored_submaps], np.float64).reshape(-1, 3)
    est[first:] = g.compose(np.broadcast_to(np.asarray(wTs, np.float64), sTa.shape), sTa)
    row = {int(s.id): j for j, s in enumerate(stored_submaps)}
    for m in already:
        if int(m.old) in row:
            key = (row[int(m.old)], first + int(m.new))
            search.pairs[key] = search.pairs.get(key, 0) + 1
    path = np.zeros(len(sTa)) if path_m is None else np.asarray(path_m, np.float64)
    out: list[LaserMatch] = []
    for k, sm in enumerate(session_submaps):
        distance = np.full(len(est), path[k])  # the graph distance to every old submap: through the join
        scans = getattr(sm, "scan_points", None)
        if not scans:
            continue
        aTb, cov = np.asarray(sm.aTb, np.float64).reshape(-1, 3), np.asarray(sm.cov_aTb, np.float64)
        for r in range(0, len(scans), step):
            for c in search.search(first + k, aTb[r], cov[r], np.asarray(scans[r], np.float64), est, distance):
                st = stored_submaps[c.old]
                implied = g.compose(g.compose(np.asarray(st.wTa, np.float64), c.mTn), g.inverse(sTa[k]))
                m = LaserMatch(k, int(st.id), c.mTn, c.cov_mTn, float(c.score), implied)
                if _agreeing(m, wTs, cfg, fe.loops, float(path[k])):
                    out.append(m)
    return out


def settle_join(session_submaps, session_sTa: np.ndarray, stored_submaps, hypothesis, frontend=None,
                cfg: RelocaliseConfig | None = None, margin: float = 0.1, moves: int = 2,
                every_nodes: int | None = None, refine_margin: float | None = None, per_pair: int = 0,
                relative=None):
    """The join checked against its neighbourhood once placed: the session's closures (``session_closures``,
    searched in the loop search's windows around the hypothesis) grouped by the transform each implies
    (``laser_hypothesis``'s groups: 0.3 m / 3 deg, at least ``min_consistent`` from ``min_session_submaps``
    submaps), and every group's transform and the hypothesis's laid onto the stored map with every session
    submap (``join_agreement``). A group whose map agreement beats the hypothesis's by ``margin`` (a fraction of
    walls) replaces it, and the closures are searched again around it (at most ``moves`` times). The few global
    matches of a corridor can all agree on a place one bay along (aces' third session: 4 matches 1.2 m off;
    the session's 21 submaps agree on 0.64 of their walls there and 0.88 at the place the log's relations
    give); a session's many keyframes, each matched in a window, find the right bay.

    ``relative``: the session's own relative poses (its loop closures shorten ``path_from``).

    Returns (the hypothesis kept or moved, the closures consistent with it, a note of the moves)."""
    from holoslam.relocalise import join_agreement, laser_hypothesis
    from holoslam.submaps.frontend import FrontEndConfig

    cfg = cfg or RelocaliseConfig()
    loops = (frontend or FrontEndConfig()).loops
    wide = dataclasses.replace(cfg, consistent_xy_m=1e9, consistent_deg=360.0)  # every closure, grouped below
    every = list(range(len(session_submaps)))
    h = hypothesis
    notes: list[str] = []
    for move in range(moves + 1):
        placed = [int(m.new) for m in h.members if isinstance(m, LaserMatch)]
        path = path_from(session_sTa, placed, relative)
        closures = session_closures(session_submaps, session_sTa, stored_submaps, h.wTs, frontend, every_nodes, wide,
                                    already=h.members if move == 0 else (), per_pair=per_pair, path_m=path)
        here = [m for m in closures if _agreeing(m, h.wTs, cfg, loops, float(path[m.new]))]
        a = join_agreement(session_submaps, session_sTa, stored_submaps, h.wTs, every, cfg)
        if a is None or move == moves:
            return h, here, "; ".join(notes)
        best, best_a, refuted = None, a.fraction, [h.wTs]
        while True:
            g_h = laser_hypothesis(closures, dataclasses.replace(cfg, runner_up_ratio=1.0), tuple(refuted))
            if g_h is None or not g_h.verified:
                break
            refuted.append(g_h.wTs)
            ga = join_agreement(session_submaps, session_sTa, stored_submaps, g_h.wTs, every, cfg)
            need = margin if move == 0 or refine_margin is None else refine_margin
            if ga is not None and ga.fraction >= best_a + need and (best is None or ga.fraction > best[1]):
                best = (g_h, ga.fraction)
        if best is None:
            return h, here, "; ".join(notes)
        d = g.between(h.wTs, best[0].wTs)
        notes.append(f"moved {np.hypot(d[0], d[1]):.2f} m / {np.degrees(d[2]):.1f} deg by {best[0].support} "
                     f"closures from {len({m.new for m in best[0].members})} submaps (the map check over every "
                     f"session submap {a.fraction:.2f} -> {best[1]:.2f})")
        h = dataclasses.replace(best[0], why=hypothesis.why + "; " + notes[-1])
    return h, here, "; ".join(notes)
