"""``run_session``: a log run as a new session of a map store (``holoslam run LOG --map STORE -o OUT``).

Steps: the run's SLAM stages in the session's own frame (``pipeline.slam_stages``); relocalisation against the
store (``holoslam.relocalise``: laser and objects, verified); when placed, the object changes
(``changes.classify``, before the solve: a moved object gets a new placement) and the joint solve of the working
graph with the session (``joint``); the session's results moved into the world (anchors from the joint solve,
every pose hung from its anchor, objects at their placements); the maps and the report in the world frame
(``pipeline.finish_run``, with the report's ``session`` object); the stored submaps the session's cover well
retired; everything written to the store in one transaction. The first session founds the world (its own frame);
a session that cannot be placed is stored unjoined, in its own frame, and its run folder stays in that frame."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.lifelong.changes import ChangeConfig, Located, classify, to_world, view_directions
from holoslam.lifelong.frustum import FrustumConfig
from holoslam.lifelong.summary import ObjectChange, SessionSummary
from holoslam.relocalise_parts import RelocaliseConfig, fit_se2, local_matches, query_points
from holoslam.store.records import (
    NewSubmap,
    ObjectState,
    ObjectStatus,
    SessionUpdate,
    StoredTrajectory,
    new_ref,
)

__all__ = ["LifelongConfig", "SessionRun", "run_session", "run_session_data", "place_session"]


@dataclass(frozen=True, slots=True)
class LifelongConfig:
    relocalise: RelocaliseConfig = field(default_factory=RelocaliseConfig)
    changes: ChangeConfig = field(default_factory=ChangeConfig)
    frustum: FrustumConfig = field(default_factory=FrustumConfig)
    joint_method: str = "batch"  # the joint solve: batch (LM) or isam2 (benchmarks/bench_lifelong.py measures both)
    # the cross-session factors once placed: True, the closures of every third keyframe of every session submap by
    # the run's loop search into the stored submaps near it (``crossmatch.session_closures``); False, the anchor
    # scans matched into the 3 nearest stored submaps (``relocalise.local_matches``). With the stored map held
    # (``hold_stored``) the closures bend only the new session onto it; measured on the real logs in 3 sessions
    # (README, before the keyframe stage onto the held map, ``keyframes``): intel x1.38 of the whole log with them,
    # x1.68 with the anchor scans' matches; aces x1.14. (Before
    # the stored map was held, they pulled it too: intel x3.14, aces x1.22.)
    dense_closures: bool = True
    # the stored working anchors pinned at their stored poses in the joint solve (``joint.joint_problem``). They
    # are their sessions' keyframe solve (every scan's matches, ``optimise.keyframe_anchors``), which the stored
    # anchor-level factors cannot reproduce (intel in one piece: 0.019 m with the keyframe solve, 0.029 m from the
    # anchors' factors alone); re-solving them from those factors undid it (intel's first session's own relations
    # 0.024 m -> 0.030 m once the second joined, 0.033 m after the third). Held, the new session is solved onto the
    # map as it stands (as Cartographer's frozen trajectories are); False: the whole working graph moves
    hold_stored: bool = True
    settle: bool = True  # the join settled by its closures' map check (``crossmatch.settle_join``)
    # the join settled by its closures (``crossmatch.settle_join``): a group of closures whose map check over every
    # session submap beats the hypothesis's by this fraction of walls moves it (aces' third session: 0.64 at the
    # global matches' place one corridor bay along, 0.88 at the log's relations' place), at most settle_moves times
    settle_margin: float = 0.1
    settle_moves: int = 2
    settle_refine_margin: float = 0.1  # after a move, a group beating it by this fraction moves it again
    # search closures from every k-th keyframe of each session submap; 0: the loop search's every_nodes (3)
    closure_every_nodes: int = 0
    closures_per_pair: int = 0  # closures kept between a session submap and a stored one; 0: the loop search's (4)
    # the relative poses through retired submaps kept, composed, between the working ones they linked
    # (``joint.composed_factors``); False: dropped with them (the rule before)
    compose_retired: bool = True
    # a stored submap leaves the working graph when the new session's submaps know this fraction of its known
    # cells (it stays in the store's history); the working graph then holds about one visit of each place
    retire_cover: float = 0.9
    # the joined session's keyframe stage run again with the held stored submaps as old submaps beside its own
    # (``keyframes.session_keyframes``): its nodes matched into the stored map and solved, its trajectory and
    # anchors taken from them as a run's are; False: each session submap stays rigid on its joint-solve anchor.
    # Measured on the real logs in 3 sessions (README): intel x1.38 -> x1.11 of the whole log (relations across
    # sessions 1-2 0.046 -> 0.025 m), aces x1.86 -> x1.08 (through the next
    # session's settling, README), fr079 x1.00 -> x1.00; 0.6-6 s a session
    keyframes: bool = True


@dataclass(frozen=True, eq=False)
class SessionRun:
    """A session's run (in the world frame when joined), its summary, and the update written to the store."""

    run: Any  # RunResult
    summary: SessionSummary
    relocalisation: Any  # Relocalisation | None (None for the founding session)
    joint: Any  # JointSolution | None
    update: SessionUpdate
    joint_graph: Any = None  # the JointGraph solved (benchmarks re-solve it by another method)
    stages: Any = None  # the SLAM stages in the session's own frame (pipeline.SlamStages), before the join


@dataclass(frozen=True, eq=False)
class _Placed:
    """The session in the world: anchors, covariances, wTs, object states, factors/sightings for the store."""

    wTa: np.ndarray
    cov_wTa: np.ndarray | None
    wTs: np.ndarray
    cov_wTs: np.ndarray | None
    objects: tuple[ObjectState, ...]
    placement: dict[str, str]
    stored_updates: dict[int, tuple[np.ndarray, np.ndarray | None]]
    retire: tuple[int, ...]
    cross: tuple
    joint: Any
    graph: Any = None
    view_s: dict[str, float] = field(default_factory=dict)  # stored objects not located: camera s in view
    images: dict[str, int] = field(default_factory=dict)  # the same: images that held their place readable
    support_left: tuple[str, ...] = ()  # the same: the session's laser saw the thing they were on gone
    # the session's trajectory in the world from its node solve (``keyframes.world_trajectory``: poses at the
    # session's stamps, keyframe stamps, keyframes); None: hung from the anchors rigidly
    traj: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    keyframes: Any = None  # keyframes.SessionKeyframes of a joined session (None: the stage did not run)


def run_session(log_path: str | Path, store_path: str | Path, config: Any = None,
                lifelong: LifelongConfig | None = None, progress: Any = None, store_progress: Any = None
                ) -> SessionRun:
    """Run a log as a new session of the store at ``store_path`` (created when absent); see the module
    docstring. Returns the run (``RunResult``, report with ``session``), not writing a run folder."""
    from holoslam.config import RunConfig
    from holoslam.io.digest import file_sha256
    from holoslam.io.mcap import read_log
    from holoslam.store.db import MapStore
    from holoslam.timing import StageClock

    cfg = config or RunConfig()
    clock = StageClock(progress)
    with MapStore.open(store_path):  # a bad store is a one-line error before the run, not after it
        pass
    with clock.stage("ingest"):
        log, ingest_report = read_log(log_path, mapping=cfg.mapping, require=["odometry", "scan"])
        sha = file_sha256(log_path)
    return run_session_data(log, ingest_report, store_path, Path(log_path).name, sha, cfg, lifelong, clock,
                            store_progress)


def run_session_data(log: Any, ingest_report: Any, store_path: str | Path, log_name: str, log_sha256: str,
                     config: Any = None, lifelong: LifelongConfig | None = None, clock: Any = None,
                     store_progress: Any = None) -> SessionRun:
    """``run_session`` on a log already in memory (``holoslam.io.mcap.read_log``'s records), named
    ``log_name`` with content hash ``log_sha256`` in the store (e.g. a window of a longer log)."""
    from holoslam.config import RunConfig
    from holoslam.pipeline import finish_run, slam_stages
    from holoslam.store.db import MapStore
    from holoslam.timing import StageClock

    cfg = config or RunConfig()
    lc = lifelong or LifelongConfig()
    clock = clock or StageClock(None)
    st = slam_stages(log, cfg, clock)
    with MapStore.open(store_path) as store:
        with clock.stage("session (relocalise, join)"):
            placed, reloc, summary = place_session(store, st, lc, log, cfg.frontend)
            world = _in_world(st, placed, log)
        run = finish_run(log, ingest_report, world, cfg, clock, str(log.source), session=summary)
        update = _update(log_name, log_sha256, log, st, placed, reloc, summary)
        store.add_session(update, store_progress)
    return SessionRun(run, summary, reloc, placed.joint, update, placed.graph, st)


def _session_objects(st: Any) -> dict[str, tuple[np.ndarray, np.ndarray, Any]]:
    return {o.object_id: (np.asarray(o.w_position[:2], np.float64),
                          np.nan_to_num(np.asarray(o.cov_w_position)[:2, :2], nan=1e-2) + np.eye(2) * 1e-8, o)
            for o in st.objects}


def place_session(store: Any, st: Any, lc: LifelongConfig, log: Any = None, frontend: Any = None
                  ) -> tuple[_Placed, Any, SessionSummary]:
    """Relocalise the session and join it (module docstring); nothing written yet. ``log``: the session's log
    (its images tell where the camera looked: ``frustum``; None judges "gone" by time in view alone);
    ``frontend``: the run's ``FrontEndConfig`` (the cross-session closures use its loop search)."""
    from holoslam.relocalise import relocalise

    sessions = store.sessions()
    sid = (max((s.id for s in sessions), default=0)) + 1
    sTa = np.asarray(st.sol.wTa, np.float64)
    sobj = _session_objects(st)
    if not any(s.joined for s in sessions):
        placed = _founding(st, sTa, sobj)
        return placed, None, _summary(store, sid, placed, None, founded=True, n_seen=0)
    stored = store.submaps(working=True, grids=True)
    latest = store.latest_objects()
    world_obj = {k: v.w_xy for k, v in latest.items() if v.status != ObjectStatus.GONE and v.w_xy is not None}
    reloc = relocalise(st.fe.submaps, sTa, {k: v[0] for k, v in sobj.items()}, stored, world_obj, lc.relocalise)
    if not reloc.placed:
        placed = _unjoined(st, sTa, sobj)
        return placed, reloc, _summary(store, sid, placed, reloc, founded=False, n_seen=0)
    reloc, closures = _settled(st, sTa, stored, reloc, lc, frontend)
    placed = _join(store, st, sTa, sobj, stored, latest, reloc, lc, log, closures, frontend)
    n_seen = sum(o.status == ObjectStatus.SEEN for o in placed.objects)
    return placed, reloc, _summary(store, sid, placed, reloc, founded=False, n_seen=n_seen)


def _founding(st: Any, sTa: np.ndarray, sobj: dict) -> _Placed:
    """The first joined session: its frame is the world; each object with the side it was seen from (the view
    tests of later sessions, ``changes`` and ``frustum``, need it as for an object of any other session)."""
    cov = None if st.sol.cov_wTa is None else np.asarray(st.sol.cov_wTa)
    views = _located(st, sobj, np.zeros(3), None)
    objs = tuple(ObjectState(k, o.object_type, o.payload, ObjectStatus.NEW, xy, float(o.w_position[2]), c,
                             int(o.sightings), f"{k}#1", view=views[k].view, normal=views[k].normal,
                             normal_sigma_rad=views[k].normal_sigma_rad) for k, (xy, c, o) in sobj.items())
    return _Placed(sTa, cov, np.zeros(3), None, objs, {k: f"{k}#1" for k in sobj}, {}, (), (), None)


def _unjoined(st: Any, sTa: np.ndarray, sobj: dict) -> _Placed:
    cov = None if st.sol.cov_wTa is None else np.asarray(st.sol.cov_wTa)
    objs = tuple(ObjectState(k, o.object_type, o.payload, ObjectStatus.UNPLACED, xy, float(o.w_position[2]), c,
                             int(o.sightings), "") for k, (xy, c, o) in sobj.items())
    return _Placed(sTa, cov, np.zeros(3), None, objs, {}, {}, (), (), None)


def _robot_world(st: Any, wTs: np.ndarray) -> np.ndarray:
    return g.compose(np.broadcast_to(wTs, st.traj.wTb.shape), st.traj.wTb)[:, :2]


def _located(st: Any, sobj: dict, wTs: np.ndarray, cov_wTs: np.ndarray | None,
             cfg: ChangeConfig | None = None) -> dict[str, Located]:
    """The session's objects in the world under the relocalisation's wTs, with the side each was seen from and
    its label's normal (``facing.session_normals``)."""
    from holoslam.lifelong.facing import session_normals

    w = {k: to_world(xy, c, wTs, cov_wTs) for k, (xy, c, _o) in sobj.items()}
    obs = st.seen.observations
    views = view_directions(np.array([o.stamp_ns for o in obs], np.int64), tuple(o.object_id for o in obs),
                            st.traj.stamps_ns, _robot_world(st, wTs), {k: v[0] for k, v in w.items()})
    normals = session_normals(obs, st.traj.stamps_ns, g.compose(np.broadcast_to(wTs, st.traj.wTb.shape), st.traj.wTb),
                              (cfg or ChangeConfig()).normal_max_tilt_deg)
    reads: dict[str, list[int]] = {}
    for ob in obs:
        reads.setdefault(ob.object_id, []).append(int(ob.stamp_ns))
    return {k: Located(k, w[k][0], w[k][1], float(o.w_position[2]), int(o.sightings), views.get(k),
                       o.object_type, o.payload, tuple(sorted(reads.get(k, ()))),
                       *normals.get(k, (None, float("nan")))) for k, (_xy, _c, o) in sobj.items()}


def _placements(statuses: dict[str, str], latest: dict[str, ObjectState], all_placements: set[str]
                ) -> dict[str, str]:
    out = {}
    for oid, s in statuses.items():
        if s == ObjectStatus.SEEN and latest[oid].placement:
            out[oid] = latest[oid].placement
        elif s in (ObjectStatus.MOVED, ObjectStatus.NEW):
            used = [p.rsplit("#", 1)[1] for p in all_placements if p.rsplit("#", 1)[0] == oid]
            out[oid] = f"{oid}#{1 + max((int(u) for u in used if u.isdigit()), default=0)}"
    return out


def _unseen_images(latest: dict[str, ObjectState], located: dict, log: Any, st: Any, wTs: np.ndarray,
                   merged: Any, cfg: Any) -> dict[str, int] | None:
    """Per stored object not located, the session's images that held its place readable (``frustum``); None
    when the log has no images with camera transforms."""
    from holoslam.lifelong.frustum import camera_views, covering_images, world_cameras

    views = camera_views(log) if log is not None else None
    if views is None or not len(views):
        return None
    wTb = g.compose(np.broadcast_to(wTs, st.traj.wTb.shape), st.traj.wTb)
    wTc = world_cameras(views, st.traj.stamps_ns, wTb)
    out = {}
    for k, o in latest.items():
        if k in located or o.status == ObjectStatus.GONE or o.w_xy is None or not np.isfinite(o.z):
            continue
        out[k] = covering_images(np.array([o.w_xy[0], o.w_xy[1], o.z]), o.view, o.payload, views, wTc, merged,
                                 cfg, o.normal, o.normal_sigma_rad)
    return out


def _support_left(latest: dict[str, ObjectState], located: dict, own: Any, merged: Any, cfg: ChangeConfig
                  ) -> tuple[str, ...]:
    """The stored objects not located whose support the session's laser (``own``: its grid in the world) saw
    gone (``support``)."""
    from holoslam.lifelong.support import support_left

    todo = {k: o.w_xy for k, o in latest.items()
            if k not in located and o.status != ObjectStatus.GONE and o.w_xy is not None}
    return tuple(k for k, xy in todo.items() if support_left(merged, own, xy, cfg.moved_m, cfg.p_occupied,
                                                             cfg.support_min_cells, cfg.support_seen_share))


def _join(store: Any, st: Any, sTa: np.ndarray, sobj: dict, stored: tuple, latest: dict, reloc: Any,
          lc: LifelongConfig, log: Any = None, closures: tuple = (), frontend: Any = None) -> _Placed:
    """The joined session: object changes, the joint solve, the session transform it implies, retirements."""
    from holoslam.lifelong.joint import joint_problem, retired_priors, solve_joint, working_factors
    from holoslam.lifelong.merge import merge_submaps, overlay
    from holoslam.lifelong.support import session_grid

    h = reloc.hypothesis
    ids = np.array([s.id for s in stored], np.int64)
    merged = merge_submaps(np.array([s.wTa for s in stored]), [(s.prob, s.known, s.origin, s.resolution)
                                                                for s in stored], [s.session_id for s in stored])
    located = _located(st, sobj, h.wTs, h.cov_wTs, lc.changes)
    view_s: dict[str, float] = {}
    own = session_grid(st.fe.submaps, sTa, h.wTs)
    # the lines of sight of the view tests cross the home as it stands today: where the session's laser saw a
    # cell, its observation replaces the store's (a chair carried away no longer hides what stood behind it)
    sight = overlay(merged, own)
    images = _unseen_images(latest, located, log, st, h.wTs, sight, lc.frustum)
    left = _support_left(latest, located, own, merged, lc.changes)
    statuses = classify(latest, located, st.traj.stamps_ns, _robot_world(st, h.wTs), sight, lc.changes, view_s,
                        images, left)
    sightings = store.sightings(ids)
    # every placement the store ever gave (retired submaps' sightings included): a new one never reuses a name
    placement = _placements(statuses, latest, store.placements())
    lm = _kept_landmarks(st)
    for oid in set(lm.landmark) - set(placement):  # a landmark without an object record: a fresh placement
        placement[oid] = f"{oid}#new{len(placement)}"
    init = {p: latest[k].w_xy for k, p in placement.items() if k in latest and latest[k].w_xy is not None
            and statuses.get(k) == ObjectStatus.SEEN}
    init.update({placement[k]: v.w_xy for k, v in located.items() if placement[k] not in init})
    live = set(sightings.placement) | {placement[o] for o in lm.landmark}
    retired = tuple(s for s in store.submaps(working=False) if s.retired_by is not None)
    priors = retired_priors(retired, store.sightings(np.array([s.id for s in retired], np.int64)), live)
    cross = tuple(reloc.matches) + tuple(closures)
    jg = joint_problem(stored, working_factors(store.factors(), ids, lc.compose_retired), sightings, sTa, st.fe.problem.relative, lm, placement, h.wTs,
                       cross, init, priors, lc.hold_stored)
    js = solve_joint(jg, lc.joint_method)
    kf, traj = _onto_map(store, st, stored, js, frontend) if lc.keyframes else (None, None)
    wTa = js.new_wTa if kf is None else kf.wTa
    wTs = fit_se2(sTa[:, :2], wTa[:, :2]) if len(sTa) >= 2 else g.compose(wTa[0], g.inverse(sTa[0]))
    objs = _object_states(statuses, located, latest, placement, js, lc.changes)
    retire = _retire(stored, js, st, lc.retire_cover)
    # held stored anchors keep their pose and covariance (a pinned anchor's marginal is only the pin's)
    updates = {} if lc.hold_stored else {
        int(k): (js.stored_wTa[n], None if js.stored_cov is None else js.stored_cov[n])
        for n, k in enumerate(ids.tolist())}
    return _Placed(wTa, js.new_cov, wTs, h.cov_wTs, objs, placement, updates, retire, cross, js, jg,
                   view_s, images or {}, left, traj, kf)


def _onto_map(store: Any, st: Any, stored: tuple, js: Any, frontend: Any) -> tuple[Any, Any]:
    """The joined session's keyframe stage against its own and the held stored submaps
    (``keyframes.session_keyframes``) and its world trajectory from it; (None, None) when it has no nodes."""
    from holoslam.lifelong.keyframes import session_keyframes, stored_keyframes, world_trajectory

    kf = session_keyframes(st, js.new_wTa, js.new_cov, stored, stored_keyframes(store, stored), frontend)
    return (None, None) if kf is None else (kf, world_trajectory(st, kf))


def _settled(st: Any, sTa: np.ndarray, stored: tuple, reloc: Any, lc: LifelongConfig, frontend: Any
             ) -> tuple[Any, tuple]:
    """The placed session's join settled (``LifelongConfig.settle``: the relocalisation with its hypothesis moved
    or not, ``crossmatch.settle_join``, and the global matches that agree with it) and the cross-session factors
    beside them (``LifelongConfig.dense_closures``: the settling's closures, or the anchor scans' local matches)."""
    from holoslam.lifelong.crossmatch import settle_join
    from holoslam.relocalise_parts import _consistent

    closures: tuple = ()
    if lc.settle or lc.dense_closures:
        h2, found, note = settle_join(st.fe.submaps, sTa, stored, reloc.hypothesis, frontend, lc.relocalise,
                                      lc.settle_margin if lc.settle else 1e9, lc.settle_moves,
                                      lc.closure_every_nodes or None, lc.settle_refine_margin,
                                      lc.closures_per_pair, st.fe.problem.relative)
        closures = tuple(found)
        if h2 is not reloc.hypothesis:
            T = np.array([m.wTs for m in reloc.all_matches]).reshape(-1, 3)
            ok = _consistent(T, h2.wTs[None], lc.relocalise)[:, 0]
            reloc = dataclasses.replace(reloc, hypothesis=h2, why=f"{reloc.why}; {note}",
                                        matches=tuple(m for m, k in zip(reloc.all_matches, ok, strict=True) if k))
    if lc.dense_closures:
        return reloc, closures
    have = {(m.new, m.old) for m in reloc.matches}
    return reloc, tuple(m for m in local_matches(st.fe.submaps, sTa, stored, reloc.hypothesis.wTs, lc.relocalise)
                        if (m.new, m.old) not in have)


def _kept_landmarks(st: Any) -> Any:
    """The session's landmark sightings its own solve kept (the rejected ones were misreads or outliers)."""
    from holoslam.graph.problem import MeasurementFamily

    lm = st.fe.problem.landmarks
    rejected = {r.index for r in st.sol.rejected if r.family is MeasurementFamily.LANDMARK}
    keep = np.array([k not in rejected for k in range(len(lm))], bool)
    return lm.select(keep) if len(lm) else lm


def _object_states(statuses: dict[str, str], located: dict[str, Located], latest: dict[str, ObjectState],
                   placement: dict[str, str], js: Any, cfg: ChangeConfig | None = None
                   ) -> tuple[ObjectState, ...]:
    """The session's object states: a gone object keeps its stored place, side and normal; a located one gets
    the joint solve's position, and its label's normal: the session's, averaged with the stored one when it was
    seen at its place (``facing.updated_normal``)."""
    from holoslam.lifelong.facing import updated_normal

    out = []
    for oid, s in sorted(statuses.items()):
        if s == ObjectStatus.GONE:
            old = latest[oid]
            out.append(ObjectState(oid, old.kind, old.payload, s, old.w_xy, old.z, old.cov_w_xy, 0, old.placement,
                                   view=old.view, normal=old.normal, normal_sigma_rad=old.normal_sigma_rad))
            continue
        loc = located[oid]
        xy, cov = js.placements.get(placement[oid], (loc.w_xy, loc.cov_w_xy))
        cov = loc.cov_w_xy if cov is None else cov
        d = cd = None
        if s == ObjectStatus.MOVED:
            old = latest[oid]
            oxy, ocov = js.placements.get(old.placement, (old.w_xy, old.cov_w_xy))
            ocov = old.cov_w_xy if ocov is None else ocov
            d, cd = np.asarray(xy) - np.asarray(oxy), np.asarray(cov) + np.asarray(ocov)
        normal, sigma = loc.normal, loc.normal_sigma_rad
        if s == ObjectStatus.SEEN and oid in latest:
            normal, sigma = updated_normal(latest[oid].normal, latest[oid].normal_sigma_rad, normal, sigma,
                                           (cfg or ChangeConfig()).normal_agree_deg)
        out.append(ObjectState(oid, loc.kind, loc.payload, s, np.asarray(xy), loc.z, np.asarray(cov), loc.sightings,
                               placement[oid], d, cd, loc.view, normal=normal, normal_sigma_rad=sigma))
    return tuple(out)


def _retire(stored: tuple, js: Any, st: Any, cover: float) -> tuple[int, ...]:
    """Stored submaps whose known cells the new session's submaps know for at least ``cover`` of them."""
    from holoslam.lifelong.merge import merge_submaps

    subs = [sm for sm in st.fe.submaps if sm.grid is not None and sm.grid.known is not None]
    if not subs or not cover < 1.0 + 1e-9:
        return ()
    new = merge_submaps(js.new_wTa[[sm.index for sm in subs]],
                        [(sm.grid.prob, sm.grid.known, sm.grid.origin, sm.grid.resolution) for sm in subs],
                        [0] * len(subs), margin_m=0.0)
    out = []
    for n, s in enumerate(stored):
        r, c = np.nonzero(s.known)
        if r.size == 0:
            continue
        a = np.column_stack([s.origin[0] + (c + 0.5) * s.resolution, s.origin[1] + (r + 0.5) * s.resolution])
        w = g.transform_points(js.stored_wTa[n], a)
        cc = np.floor((w[:, 0] - new.origin[0]) / new.resolution).astype(np.int64)
        rr = np.floor((w[:, 1] - new.origin[1]) / new.resolution).astype(np.int64)
        H, W = new.known.shape
        inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        hit = np.zeros(len(w), bool)
        hit[inside] = new.known[rr[inside], cc[inside]]
        if hit.mean() >= cover:
            out.append(int(s.id))
    return tuple(out)


def _summary(store: Any, sid: int, p: _Placed, reloc: Any, founded: bool, n_seen: int) -> SessionSummary:
    changes = []
    for o in p.objects:
        if o.status in (ObjectStatus.MOVED, ObjectStatus.GONE, ObjectStatus.NEW) and o.w_xy is not None:
            d = None if o.displacement is None else [float(v) for v in o.displacement]
            changes.append(ObjectChange(o.object_id, o.status, float(o.w_xy[0]), float(o.w_xy[1]),
                                        None if d is None else float(np.hypot(d[0], d[1])), d,
                                        None if o.cov_displacement is None else np.asarray(o.cov_displacement).tolist()))
    joined = founded or (reloc is not None and reloc.placed)
    counts = store.counts()
    js = p.joint
    joint = {} if js is None else {"method": js.method, "seconds": round(js.seconds, 4), "iterations": js.iterations,
                                   "anchors": int(len(js.stored_wTa) + len(js.new_wTa)), "rejected": js.rejected,
                                   "covariances_failed": js.covariances_failed,
                                   "cross_factors": len(p.cross)}
    if p.keyframes is not None:  # the keyframe stage onto the held map (``keyframes.session_keyframes``)
        joint.update(keyframe_matches_own=p.keyframes.own_matches, keyframe_matches_stored=p.keyframes.stored_matches,
                     keyframe_tried_stored=p.keyframes.stored_tried, keyframe_s=round(p.keyframes.seconds, 3))
    return SessionSummary(
        store=str(store.path), session_id=sid, joined=joined, joined_by=("none" if reloc is None else reloc.joined_by),
        founded=founded, relocalisation_s=0.0 if reloc is None else round(reloc.seconds, 4),
        why="the first session: its frame is the world" if reloc is None else reloc.why,
        wTs=[float(v) for v in p.wTs] if joined else None,
        laser_matches=0 if reloc is None else len(reloc.matches),
        laser_searches=0 if reloc is None else reloc.searches, objects_seen=n_seen, changes=changes, joint=joint,
        working_submaps=counts["working_submaps"] - len(p.retire) + (len(p.wTa) if joined else 0),
        retired_submaps=counts["submaps"] - counts["working_submaps"] + len(p.retire),
        relocalisation_cpu_s=0.0 if reloc is None else round(reloc.cpu_seconds, 4),
        unseen_in_view_s=dict(sorted(p.view_s.items())), unseen_in_images=dict(sorted(p.images.items())),
        unseen_support_left=sorted(p.support_left))


def _rehang(stamps_ns: np.ndarray, poses: np.ndarray, anchor_stamps_ns: np.ndarray, sTa: np.ndarray,
            wTa: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses of the session frame hung from their anchors (the latest at or before each stamp): (world poses,
    anchor index, pose in the anchor frame)."""
    k = np.clip(np.searchsorted(anchor_stamps_ns, stamps_ns, side="right") - 1, 0, len(sTa) - 1)
    aTb = g.between(sTa[k], poses)
    return g.compose(wTa[k], aTb), k, aTb


def _in_world(st: Any, p: _Placed, log: Any) -> Any:
    """The SLAM stages' results moved into the world: anchors as placed, trajectory and keyframes hung from
    them, dead reckoning and other landmarks by wTs, objects at their placements."""
    from holoslam.pipeline import SlamStages

    sTa = np.asarray(st.sol.wTa, np.float64)
    anchors = np.asarray(st.fe.anchor_stamps_ns, np.int64)
    if p.traj is None:
        wTb = _rehang(st.traj.stamps_ns, st.traj.wTb, anchors, sTa, p.wTa)[0]
        key_t, wTk = st.traj.key_stamps_ns, _rehang(st.traj.key_stamps_ns, st.traj.wTk, anchors, sTa, p.wTa)[0]
    else:
        wTb, key_t, wTk = p.traj
    dr = g.compose(np.broadcast_to(p.wTs, st.traj.dead_reckoning_wTb.shape), st.traj.dead_reckoning_wTb)
    traj = dataclasses.replace(st.traj, wTb=wTb, key_stamps_ns=key_t, wTk=wTk, dead_reckoning_wTb=dr)
    R = g.rot2(float(p.wTs[2]))
    wl = g.transform_points(p.wTs, st.sol.w_landmarks.reshape(-1, 2)) if len(st.sol.w_landmarks) else st.sol.w_landmarks
    cl = None if st.sol.cov_w_landmarks is None else R @ st.sol.cov_w_landmarks @ R.T
    sol = dataclasses.replace(st.sol, wTa=p.wTa, cov_wTa=p.cov_wTa if p.cov_wTa is not None else st.sol.cov_wTa,
                              w_landmarks=wl, cov_w_landmarks=cl)
    by_id = {o.object_id: o for o in p.objects}
    objects = []
    for o in st.objects:
        s = by_id.get(o.object_id)
        if s is None or s.w_xy is None or s.status == ObjectStatus.UNPLACED:
            objects.append(o)
            continue
        cov = np.array(o.cov_w_position, np.float64)
        cov[:2, :2] = s.cov_w_xy
        objects.append(dataclasses.replace(o, w_position=np.array([s.w_xy[0], s.w_xy[1], o.w_position[2]]),
                                           cov_w_position=cov))
    return SlamStages(st.fe, sol, st.seen, st.revisits, traj, tuple(objects))


def _update(log_name: str, sha: str, log: Any, st: Any, p: _Placed, reloc: Any, summary: SessionSummary
            ) -> SessionUpdate:
    """The store update of the session (one transaction)."""
    sTa = np.asarray(st.sol.wTa, np.float64)
    anchors = np.asarray(st.fe.anchor_stamps_ns, np.int64)
    subs = tuple(NewSubmap(k, int(sm.anchor_stamp_ns), p.wTa[k], None if p.cov_wTa is None else p.cov_wTa[k], sTa[k],
                           sm.grid.prob, sm.grid.origin, sm.grid.resolution, query_points(sm), sm.grid.known)
                 for k, sm in enumerate(st.fe.submaps))
    rel = st.fe.problem.relative
    cross = p.cross
    fi = np.concatenate([[new_ref(i) for i in rel.i.tolist()], [m.old for m in cross]]).astype(np.int64)
    fj = np.concatenate([[new_ref(j) for j in rel.j.tolist()], [new_ref(m.new) for m in cross]]).astype(np.int64)
    fT = np.vstack([rel.iTj, np.array([m.oTn for m in cross]).reshape(-1, 3)])
    fC = np.vstack([rel.cov_iTj, np.array([m.cov_oTn for m in cross]).reshape(-1, 3, 3)])
    kinds = tuple(str(k) for k in rel.kind) + ("cross",) * len(cross)
    lm = _kept_landmarks(st) if p.placement else st.fe.problem.landmarks.select(np.zeros(0, np.int64))
    lm_keep = [k for k, o in enumerate(lm.landmark) if o in p.placement]
    lm = lm.select(np.array(lm_keep, np.int64))
    _w, k, aTb = _rehang(st.traj.stamps_ns, st.traj.wTb, anchors, sTa, p.wTa)
    if p.traj is not None:  # the node solve's world poses, hung from the session's world anchors
        aTb = g.between(p.wTa[k], p.traj[0])
    traj = StoredTrajectory(st.traj.stamps_ns, k.astype(np.int32), aTb, st.traj.wTb)
    return SessionUpdate(
        log_name, sha, int(st.traj.stamps_ns[0]), int(st.traj.stamps_ns[-1]), summary.joined, summary.joined_by,
        p.wTs, p.cov_wTs, summary.relocalisation_s, summary.to_dict(), subs, fi, fj, fT, fC, kinds,
        np.array([new_ref(i) for i in lm.i.tolist()], np.int64), tuple(lm.landmark),
        tuple(p.placement[o] for o in lm.landmark), lm.a_position, lm.cov_a_position, np.asarray(lm.z),
        p.objects, traj, p.stored_updates, p.retire, expected_id=summary.session_id)
