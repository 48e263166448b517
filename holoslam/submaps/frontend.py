"""The SLAM front end: a log and object observations -> submaps and a :class:`holoslam.graph.problem.SlamProblem`.

Steps (seed 002 §2, SPEC §4 and §8), each a named function or class:

1. Dead reckoning of the whole run (Eq. 14, compass heading changes with the odometry fallback) gives
   ``wTb`` at every odometry stamp: the prediction of scan matching and the "dead reckoning alone" baseline. Its
   noise model is the log's own odometry covariance when that is a plausible propagated one, else the documented
   defaults (``holoslam.submaps.odometry_noise``); the dead-reckoning relative poses are then calibrated against
   the scan matches between the same anchors (``AnchorGraph.measurements``).
2. Local SLAM (``local_slam.LocalSlam``): scans that pass the motion filter become nodes, matched into the
   older of two active probability-grid submaps (Eq. 12, ``scanmatch``) and inserted into both. Each new
   submap is anchored at a node; its pose in the submap it was matched into is a ``scan_match`` relative pose
   (Eq. 15), beside the ``dead_reckoning`` relative pose between the two anchors' stamps (Eq. 14).
3. Revisits (``loops.LoopSearch``): every few nodes, the finished submaps near the node's current world
   estimate are searched by branch-and-bound in a window that grows with the distance travelled since the
   last closure; a closure is a ``loop`` relative pose (robust kernel in the solver). After each closure the
   anchors are re-estimated through the ``optimize`` callback (the pipeline passes the solver), so windows
   stay small once the map is consistent.
4. Compass yaw at every anchor stamp (raw, with its bias) -> HeadingMeasurements.
5. Landmarks (Eq. 16): an observation at stamp t is put into the anchor frame of the submap active at t, using
   the robot's pose there (nearest earlier node ∘ dead reckoning to t): a_xy = R(theta) b_xy + t, z kept; its
   2x2 covariance is R cov_b R^T + J cov_aTb J^T. An observation before the first scan (the camera may fire
   first) goes to anchor 0 by dead reckoning back from it; only observations outside the odometry's span are
   skipped (counted in ``skipped_observations``).
6. Ambiguous objects: an object seen at least twice whose sightings all disagree with one another (no two
   within ``association_gate`` of each other under their covariances plus ``association_drift`` of the initial
   anchors) cannot be located: its sightings are left out and its id is listed in ``ambiguous_objects``.
   Objects with a consistent majority, or two self-consistent groups (a moved object), go to the solver,
   whose outlier rejection and moved-object detection handle them; each object's initial position is the
   mean of its largest agreeing group (the earliest on a tie).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from holoslam import geometry as g
from holoslam.errors import IngestError
from holoslam.geometry import interpolate_poses
from holoslam.submaps.anchor_graph import AnchorGraph
from holoslam.submaps.deadreckon import DeadReckoningConfig, dead_reckon, interpolate_yaw
from holoslam.submaps.features import FeatureConfig, scans_features
from holoslam.submaps.local_slam import ActiveSubmap, Break, LocalSlam, LocalSlamConfig
from holoslam.submaps.loops import LoopConfig, LoopSearch
from holoslam.submaps.odometer import OdometerCorrection, OdometerCorrectionConfig, OdometerWatch, is_blind
from holoslam.submaps.odometry_noise import OdometryNoise, odometry_noise
from holoslam.submaps.probgrid import GridConfig, ProbGrid
from holoslam.submaps.revisits import RevisitConfig
from holoslam.submaps.segment import Submap, voxel_downsample
from holoslam.types import LogData, ObjectObservation, Scan

if TYPE_CHECKING:
    from holoslam.graph.problem import SlamProblem


__all__ = ["FrontEndConfig", "FrontEnd", "build_problem", "corrected_log", "base_to_laser", "landmark_in_anchor"]


@dataclass(frozen=True, slots=True)
class FrontEndConfig:
    dead_reckoning: DeadReckoningConfig = field(default_factory=DeadReckoningConfig)
    local: LocalSlamConfig = field(default_factory=LocalSlamConfig)
    loops: LoopConfig = field(default_factory=LoopConfig)
    revisits: RevisitConfig = field(default_factory=RevisitConfig)  # keyframes against old submaps, after the solve
    features: FeatureConfig = field(default_factory=FeatureConfig)
    base_frame: str = ""  # "" = the log's base frame (LogData.base_frame: the mapping's, else the odometry's child)
    build_grids: bool = True
    association_drift: float = 0.15  # m, allowance for the initial anchors' drift when comparing sightings
    association_gate: float = 13.8  # chi-square(2) 0.999: two sightings of one object agree below this
    point_voxel: float = 0.05  # m, decimation of a submap's points (features, pictures)
    # features H (Eq. 13) from every k-th node of a submap: consecutive nodes (0.2 m apart) see the same walls,
    # and extracting them from every node was a sixth of the front end's time on real logs
    feature_every_nodes: int = 5
    # the odometry across a break of local SLAM (``LocalSlamConfig.lost_gap_s``: the robot may have been carried):
    # kept as the link's mean, with this much more uncertainty (1 sigma): far more than any loop closure's
    # (centimetres), so that one overrides it, and no more, since beside centimetre scan matches a weaker link leaves
    # the marginal covariances numerically indeterminate (aces kidnapped in its middle: 100 m fails, 30 m / 180 deg
    # and 10 m / 57 deg are solved). The loop search does not rely on it: a window across a break covers everything
    lost_sigma_m: float = 10.0
    lost_sigma_deg: float = 57.3
    # a second pass on corrected odometry when the first finds the odometer off where the scans cannot see motion
    # (``holoslam.optimise.odometer_pass``)
    odometer: OdometerCorrectionConfig = field(default_factory=OdometerCorrectionConfig)


@dataclass(frozen=True, eq=False)
class FrontEnd:
    """Submaps, the SLAM problem, the whole-run dead reckoning (``dr_stamps_ns``, ``dr_wTb``), the anchors'
    stamps, the base->laser pose ``bTs`` used, what was skipped (observations outside the odometry's span or
    at an anchor's origin), and ``ambiguous_objects``: ids whose sightings all disagree (step 7), left out of the problem."""

    submaps: tuple[Submap, ...]
    problem: SlamProblem
    dr_stamps_ns: np.ndarray
    dr_wTb: np.ndarray
    anchor_stamps_ns: np.ndarray
    bTs: np.ndarray
    skipped_observations: int = 0
    loops_tried: int = 0
    ambiguous_objects: tuple[str, ...] = ()
    dead_reckoning_inflation: float = 1.0  # factor applied to the dead-reckoning covariances (AnchorGraph)
    odometry_noise: OdometryNoise | None = None  # the dead-reckoning noise model used: the log's or the defaults
    loop_groups: int = 0  # anchor pairs joined by loop closures (each pair's closures count as one, AnchorGraph)
    dead_reckoning_slips: int = 0  # dead-reckoning segments down-weighted for disagreeing with their scan match
    loop_counts: dict[str, int] = field(default_factory=dict)  # the loop search's outcomes by reason
    # local SLAM started afresh after a gap in the laser (``LocalSlamConfig.lost_gap_s``) or where its scans stopped
    # fitting the map (``LocalSlamConfig.lost_after_misses``)
    breaks: int = 0
    score_scale: float = 1.0  # the loop search's threshold scale at the end (``LoopConfig.score_reference``)
    # the share of local SLAM's matched nodes whose match was blind along the track (``odometer.is_blind``)
    blind_share: float = 0.0
    # the odometer's bias found (by local SLAM's check, ``OdometerWatch``, or after a first pass,
    # ``holoslam.optimise.odometer_pass``), taken off the odometry this front end mapped with (None: the raw
    # odometry); the run's later stages use ``corrected_log``
    odometer_correction: OdometerCorrection | None = None
    # the stamps of those blind matched nodes: the odometer checks leave out the stretches that hold one
    blind_stamps_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    # m: the gap between two neighbouring returns at the laser's median range, and the submaps' grid settings as
    # fitted to the laser (``local_grid_config``: its rate, and whether such gaps were bridged)
    return_gap_m: float = math.nan
    grid: GridConfig = field(default_factory=GridConfig)

    @property
    def bridged_returns(self) -> bool:
        return self.grid.bridge

    @property
    def grid_cell_m(self) -> float:
        return self.grid.resolution

    def blind_at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """Which of ``stamps_ns`` are nodes whose match was blind along the track (bool, same shape)."""
        return np.isin(np.asarray(stamps_ns, np.int64), self.blind_stamps_ns)


def base_to_laser(log: LogData, laser_frame: str, base_frame: str = "") -> np.ndarray:
    """The planar pose (x, y, yaw) of the laser in the base frame ("" = ``log.base_frame``) from the log's
    static transforms (ingestion puts an upside-down laser's scans in a level frame, so yaw is all it takes)."""
    base_frame = base_frame or log.base_frame
    try:
        from holoslam.frames import TransformTree

        tree = TransformTree(log.transforms)
        stamp = log.scans[0].stamp_ns if log.scans else 0
        return np.asarray(tree.planar(base_frame, laser_frame, stamp), dtype=np.float64)
    except ImportError:  # pragma: no cover - frames.py is part of the package now
        pass
    for t in log.transforms:
        if t.parent == base_frame and t.child == laser_frame:
            M = t.matrix()
            return np.array([M[0, 3], M[1, 3], np.arctan2(M[1, 0], M[0, 0])])
    if laser_frame == base_frame:
        return np.zeros(3)
    raise IngestError(f"no transform from {base_frame!r} to the laser frame {laser_frame!r} in {log.source}; "
                      f"the log needs /tf_static {base_frame}->{laser_frame} (a mapping's 'frames: {{base: NAME}}' "
                      "names another base frame)")


def landmark_in_anchor(
    aTb: np.ndarray, cov_aTb: np.ndarray, b_position: np.ndarray, cov_b_position: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """Eq. 16: an object at ``b_position`` (3,) in the base frame -> (a_xy (2,), cov (2x2), z)."""
    T = np.asarray(aTb, dtype=np.float64)
    pb = np.asarray(b_position, dtype=np.float64)
    R = g.rot2(T[2])
    a_xy = g.transform_points(T, pb[None, :2])[0]
    Jxi = np.zeros((2, 3))
    Jxi[:, :2] = R
    Jxi[:, 2] = R @ np.array([-pb[1], pb[0]])
    cov = R @ np.asarray(cov_b_position)[:2, :2] @ R.T + Jxi @ np.asarray(cov_aTb) @ Jxi.T
    return a_xy, 0.5 * (cov + cov.T), float(pb[2])


def _submap_record(sm: ActiveSubmap, cfg: FrontEndConfig, reason: str, grid: ProbGrid | None = None) -> Submap:
    """A finished submap as the record the rest of holoslam reads (keyframes = its nodes); ``grid``: its frozen
    grid when already made."""
    P = np.array(sm.aTb).reshape(-1, 3)
    every = max(1, cfg.feature_every_nodes)
    features = scans_features(P[::every], sm.b_points[::every], cfg.features)
    pts = np.vstack([g.transform_points(T, b) for T, b in zip(P, sm.b_points, strict=True)])
    pts, nrm = voxel_downsample(pts, np.zeros_like(pts), cfg.point_voxel)
    if grid is None and cfg.build_grids:
        grid = sm.grid()
    tr_t = np.array([t for t, _ in sm.tracked], np.int64)
    tr_T = np.array([T for _, T in sm.tracked]).reshape(-1, 3)
    return Submap(sm.index, sm.anchor_stamp_ns, np.array(sm.stamps, np.int64), P, np.array(sm.cov).reshape(-1, 3, 3),
                  tuple(sm.b_points), pts, nrm, features, grid, reason, tr_t, tr_T)


def build_problem(
    log: LogData,
    observations: Sequence[ObjectObservation] | Callable[[], Sequence[ObjectObservation]] = (),
    config: FrontEndConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    optimize: Callable[[object], np.ndarray] | None = None,
) -> FrontEnd:
    """Run the front end over a log (see the module docstring). Raises IngestError when the log lacks
    odometry or scans. ``progress(done, total)`` is called with the scans walked, about every 2% of them.
    ``optimize(problem) -> wTa`` re-estimates the anchors after loop closures (without it the front end keeps
    its chained estimate, and loop windows grow with the distance since the start). ``observations`` may be a
    callable returning them, called once local SLAM is done (the run's vision stage, still running in a
    thread)."""
    cfg = config or FrontEndConfig()
    run = _dead_reckoning(log, cfg)  # step 1
    grid, return_gap = local_grid_config(run.scans, cfg)
    cfg = replace(cfg, local=replace(cfg.local, grid=grid))
    watch = OdometerWatch(cfg.odometer, run.ost, run.opose)  # the odometer checked as local SLAM goes
    correction = None
    try:
        closed, graph, loops = _local_slam(run, cfg, progress, optimize, watch)  # steps 2-3
    except _OdometerOff as off:  # found off while mapping: start again on the corrected odometry
        correction = off.correction
        run = _dead_reckoning(correction.apply(log), cfg)
        watch = OdometerWatch(replace(cfg.odometer, enabled=False), run.ost, run.opose)
        closed, graph, loops = _local_slam(run, cfg, progress, optimize, watch)
    anchors = np.array([sm.anchor_stamp_ns for sm in closed], dtype=np.int64)
    if callable(observations):  # still being made (the vision stage in a thread): needed from step 4 on
        observations = observations()
    problem, skipped, drop = _problem(run, closed, anchors, graph, observations, cfg)  # steps 4-6
    return FrontEnd(tuple(closed), problem, run.dr_stamps_ns, run.dr_wTb, anchors, run.bTs, skipped,
                    loops.tried, tuple(sorted(drop)), graph.dead_reckoning_inflation(), run.noise,
                    len(graph.loop_groups()), len(graph.dead_reckoning_slips()),
                    {**dict(sorted(loops.counts.items())),
                     **{f"{k} search ms": int(1000 * v) for k, v in loops.seconds.items()}},
                    sum(k == "lost" for k in graph.kind), loops.scale, watch.blind_share, correction,
                    watch.blind_stamps_ns, return_gap, grid)


def corrected_log(log: LogData, fe: FrontEnd) -> LogData:
    """The log as the front end mapped it: its odometry corrected when the front end found the odometer off
    (``FrontEnd.odometer_correction``), else ``log`` itself. The trajectory between nodes, the objects' dead
    reckoning and the maps' poses follow the odometry the anchors were solved with."""
    return log if fe.odometer_correction is None else fe.odometer_correction.apply(log)


class _OdometerOff(Exception):
    """Local SLAM's check found the odometer off (``OdometerWatch``): the front end starts again."""

    def __init__(self, correction: OdometerCorrection) -> None:
        super().__init__(f"the odometer is off: {correction.to_dict()}")
        self.correction = correction


@dataclass(frozen=True, eq=False)
class _Run:
    """Step 1's results and the log's arrays the later steps read: odometry ``ost``/``opose``, compass
    ``hst``/``hyaw``/``hsig`` (``have_h``: enough of it to use), dead-reckoning arguments with the compass
    (``hargs``) and without it for short spans (``short``), the scans within the odometry's span, the laser pose
    ``bTs``, the noise model, the whole-run dead reckoning ``dr_wTb`` at ``dr_stamps_ns``, and per scan the
    odometry pose and the distance travelled."""

    ost: np.ndarray
    opose: np.ndarray
    hst: np.ndarray
    hyaw: np.ndarray
    hsig: np.ndarray
    have_h: bool
    hargs: dict
    short: dict
    scans: list
    bTs: np.ndarray
    noise: OdometryNoise
    dr_stamps_ns: np.ndarray
    dr_wTb: np.ndarray
    odo_at_scans: np.ndarray
    travelled: np.ndarray


def _dead_reckoning(log: LogData, cfg: FrontEndConfig) -> _Run:
    """Step 1: the whole-run dead reckoning, starting at the odometry pose of the first scan."""
    if len(log.odometry) < 2:
        raise IngestError(f"{log.source}: the front end needs odometry (/odom), found {len(log.odometry)} records")
    if not log.scans:
        raise IngestError(f"{log.source}: the front end needs laser scans (/scan), found none")
    ost, opose = log.odometry_arrays()
    hst, hyaw, hsig = log.heading_arrays()
    # the dead-reckoning noise model: the log's own odometry covariance when plausible, else the defaults
    noise = odometry_noise(log.odometry, cfg.dead_reckoning)
    dr_cfg = noise.config
    hsig = np.where(np.isfinite(hsig) & (hsig > 0), hsig, dr_cfg.compass_sigma)
    have_h = hst.size >= 2
    hargs: dict[str, Any] = dict(heading_stamps_ns=hst if have_h else None, heading_yaw=hyaw if have_h else None,
                 heading_sigma=hsig if have_h else None, config=dr_cfg)
    short: dict[str, Any] = dict(config=replace(dr_cfg, use_compass=False))
    scans = [s for s in log.scans if ost[0] <= s.stamp_ns <= ost[-1]]
    if not scans:
        raise IngestError(f"{log.source}: no scan lies within the odometry's time span")
    bTs = base_to_laser(log, scans[0].frame_id, cfg.base_frame)
    t_first = int(scans[0].stamp_ns)
    start = interpolate_poses(ost, opose, np.array([t_first]))[0]
    whole = dead_reckon(ost, opose, t_first, int(ost[-1]), start=start, **hargs)
    dr_st, dr_wTb = whole.stamps_ns, whole.aTb
    path_len = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dr_wTb[:, :2], axis=0).T))])
    scan_t = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    odo_at_scans = interpolate_poses(ost, opose, scan_t)
    travelled = np.interp((scan_t - dr_st[0]).astype(float), (dr_st - dr_st[0]).astype(float), path_len)
    return _Run(ost, opose, hst, hyaw, hsig, have_h, hargs, short, scans, bTs, noise, dr_st, dr_wTb, odo_at_scans,
                travelled)


def local_grid_config(scans: Sequence[Scan], cfg: FrontEndConfig) -> tuple[GridConfig, float]:
    """The submaps' grid settings for this laser: the odds updates scaled to its scan rate (``GridConfig.for_rate``)
    and its returns bridged where neighbouring ones lie farther apart than a cell (``GridConfig.for_beams``); and
    that gap (m, at the median range; nan without returns)."""
    grid = cfg.local.grid.for_rate(scan_rate_hz(np.array([s.stamp_ns for s in scans], np.int64)))
    step, median = beam_step_and_range(scans, grid.max_range)
    return grid.for_beams(step, median), step * median


def _local_slam(
    run: _Run, cfg: FrontEndConfig, progress: Callable[[int, int], None] | None,
    optimize: Callable[[object], np.ndarray] | None, watch: OdometerWatch,
) -> tuple[list[Submap], AnchorGraph, LoopSearch]:
    """Steps 2-3: local SLAM over the scans and the revisit search; returns the finished submaps (by index), the
    relative-pose graph between their anchors and the loop search (its counts). ``watch`` checks the odometer on
    the matched nodes (raises ``_OdometerOff`` when it finds it off). ``cfg.local.grid`` is used as it is
    (``build_problem`` fits it to the laser: ``local_grid_config``)."""
    slam = LocalSlam(cfg.local, run.bTs)
    loops = LoopSearch(cfg.loops, cfg.local.match)
    graph = AnchorGraph(run.dr_wTb[0])
    records: list[Future[Submap]] = []
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="holoslam-submaps") as worker:

        def finish(done: list[ActiveSubmap]) -> None:
            """Finished submaps (their growing grids are dropped here: only the cropped ones are kept): the grid
            to the loop search at once, the record's features and points in the worker, which runs while this
            thread is in the compiled kernels (they release the GIL); the same records either way."""
            for sm in done:
                grid = sm.grid() if cfg.build_grids else None
                records.append(worker.submit(_submap_record, sm, cfg, "scans", grid))
                if isinstance(grid, ProbGrid):  # None without build_grids
                    loops.add_submap(sm.index, grid)

        _walk_scans(run, cfg, progress, optimize, slam, loops, graph, finish, watch)
        slam.close()
        finish(slam.pop_finished())
    return sorted((r.result() for r in records), key=lambda sm: sm.index), graph, loops


def _walk_scans(
    run: _Run, cfg: FrontEndConfig, progress: Callable[[int, int], None] | None,
    optimize: Callable[[object], np.ndarray] | None, slam: LocalSlam, loops: LoopSearch, graph: AnchorGraph,
    finish: Callable[[list[ActiveSubmap]], None], watch: OdometerWatch,
) -> None:
    """``_local_slam``'s walk over the scans: each node to local SLAM, new anchors into the graph, finished
    submaps to ``finish``, and the loop search of every ``every_nodes``-th node (``_search_due``)."""
    ost, opose, travelled = run.ost, run.opose, run.travelled
    n_arrivals, n_breaks, last_t, n_nodes = 0, 0, int(run.scans[0].stamp_ns), 0
    lost = np.diag([cfg.lost_sigma_m ** 2] * 2 + [np.radians(cfg.lost_sigma_deg) ** 2])
    every = max(1, -(-len(run.scans) // 50))
    last_search: tuple[int, float, float] | None = None  # the node count, odometer and heading at the last search
    # dead reckoning's disagreement with the estimate: the compass's bound on the windows, or without one the
    # disagreement window's floor on a slow laser (``LoopConfig.disagreement_window_max_hz``) or, on a faster one,
    # once local SLAM's matches were blind often enough (``_blind_enough``)
    widen = (cfg.loops.disagreement_window > 0
             and scan_rate_hz(np.array([sc.stamp_ns for sc in run.scans], np.int64))
             <= cfg.loops.disagreement_window_max_hz)
    for k, scan in enumerate(run.scans):
        if progress is not None and k % every == 0:
            progress(k, len(run.scans))
        t = int(scan.stamp_ns)
        if np.count_nonzero(scan.valid) < cfg.local.match.min_points:
            continue
        if not slam.wants(t, run.odo_at_scans[k]):
            if cfg.local.match_every_scan:
                slam.track(t, run.odo_at_scans[k], scan.points())
            continue
        def cov_odo_step(lt: int = last_t, t: int = t) -> np.ndarray:
            return dead_reckon(ost, opose, lt, t, **run.short).cov_aTb_end

        node = slam.add(t, run.odo_at_scans[k], cov_odo_step,
                        scan.points(), np.where(scan.valid, scan.ranges, np.inf).astype(np.float64),
                        scan.angles, float(travelled[k]))
        last_t, n_nodes = t, n_nodes + 1
        new = sorted([(n, m, mTn, cov, None) for m, n, mTn, cov in slam.arrivals[n_arrivals:]]
                     + [(b.new, b.last, None, None, b) for b in slam.breaks[n_breaks:]], key=lambda e: e[0])
        for n, m, mTn, cov_mTn, brk in new:
            dr = dead_reckon(ost, opose, slam.anchor_stamps[m], slam.anchor_stamps[n], **run.hargs)
            if brk is not None:  # a break: odometry since the last matched node, as uncertain as the building
                h, hTn, cov_hTn = _across_break(run, brk, m, dr, slam.anchor_stamps[n])
                graph.add(h, n, hTn, cov_hTn + lost, "lost")
                loops.add_break(n)
                est_mTn = g.between(graph.est[m], g.compose(graph.est[h], hTn))
            else:  # an arrival: its scan match in m
                est_mTn = np.asarray(mTn)
                graph.add(m, n, dr.end, dr.cov_aTb_end, "dead_reckoning")
                graph.add(m, n, est_mTn, cov_mTn, "scan_match")
            graph.add_anchor(m, est_mTn, dr.end, float(travelled[k]), brk is not None)
        n_arrivals, n_breaks = len(slam.arrivals), len(slam.breaks)
        if slam.last_match_cov is not None and watch.add(  # a matched node, and the odometer's check due
                t, node.submap, node.aTb, is_blind(slam.last_match_cov, cfg.odometer.blind_ratio)):
            fix = watch.check(np.array(graph.est))
            if fix is not None:
                raise _OdometerOff(fix)
        finish(slam.pop_finished())
        here = (n_nodes, float(travelled[k]), float(run.odo_at_scans[k][2]))
        widen = widen or _blind_enough(cfg.loops, watch)  # once on, on: the drift let in stays in the estimate
        if loops.grids and _search_due(cfg.loops, here, last_search):
            last_search = here
            usual = slam.usual_score()
            loops.scale = 1.0 if usual is None else min(1.0, usual / cfg.loops.score_reference)
            found = loops.search(node.submap, node.aTb, node.cov_aTb, node.b_points, np.array(graph.est),
                                 graph.graph_distance(node.submap), float(travelled[k]),
                                 graph.relative_covariances(node.submap), np.array(graph.travel),
                                 partial(slam.bundle, node, cfg.loops.global_bundle_m),
                                 graph.dead_reckoning_disagreement(node.submap)
                                 if run.have_h or widen else None, run.have_h)
            for c in found:
                graph.add(c.old, c.new, c.mTn, c.cov_mTn, "loop")
            if found and graph.disagree(found, cfg.loops.resolve_min_d2):
                graph.reoptimise(optimize)


def _across_break(run: _Run, brk: Break, m: int, dr_mn, anchor_ns: int) -> tuple[int, np.ndarray, np.ndarray]:
    """The break's link to its new anchor: (h, hTn, its covariance before the break's own uncertainty). From the
    last node matched before the break (in submap h), the odometry since it: seconds of odometry where the
    odometry from anchor m (``dr_mn``, the fallback when no node matched) spans the whole submap, minutes of it
    whose drift would place a part of the run that no loop closure rejoins (the log ends) metres and tens of
    degrees off (intel at 1.4 Hz with a biased odometer: 5.9 m / 43 deg from anchor m, 70 s back)."""
    fix = brk.fix
    if fix is None:
        return m, dr_mn.end, dr_mn.cov_aTb_end
    dr = dead_reckon(run.ost, run.opose, fix.stamp_ns, anchor_ns, **run.hargs)
    return fix.submap, *g.propagate_compose(fix.aTb, fix.cov_aTb, dr.end, dr.cov_aTb_end)


#: matched nodes before local SLAM's blind share is judged for the disagreement window (the odometer check's own
#: wait, ``OdometerCorrectionConfig``): a log's first minute is no sample of it (intel's first 100 nodes are 8 %
#: blind, its whole log 0.9 %)
_BLIND_SHARE_NODES = 500


def _blind_enough(cfg: LoopConfig, watch: OdometerWatch) -> bool:
    """Whether local SLAM's matches so far were blind along the track often enough for the disagreement window
    (``LoopConfig.disagreement_window_blind_share``), judged from ``_BLIND_SHARE_NODES`` matched nodes on."""
    return (cfg.disagreement_window > 0 and watch.nodes >= _BLIND_SHARE_NODES
            and watch.blind_share >= cfg.disagreement_window_blind_share)


def _search_due(cfg: LoopConfig, here: tuple[int, float, float], last: tuple[int, float, float] | None) -> bool:
    """Whether the node at ``here`` (node count, odometer m, odometry heading rad) searches for loops, the last
    search's node at ``last`` (None before the first): every ``every_nodes``-th node, and with ``every_m`` /
    ``every_deg`` set, only once the robot moved or turned that much since ``last``."""
    if here[0] % cfg.every_nodes:
        return False
    if last is None or (cfg.every_m <= 0 and cfg.every_deg <= 0):
        return True
    moved = cfg.every_m > 0 and here[1] - last[1] >= cfg.every_m
    turned = cfg.every_deg > 0 and abs(g.wrap(here[2] - last[2])) >= math.radians(cfg.every_deg)
    return moved or turned


def _problem(
    run: _Run, closed: list[Submap], anchors: np.ndarray, graph: AnchorGraph, observations: Sequence[ObjectObservation],
    cfg: FrontEndConfig,
) -> tuple[SlamProblem, int, set[str]]:
    """Steps 4-6: compass headings and landmarks at the anchors, ambiguous objects left out, and the SLAM
    problem (its poses: the submaps' anchors at ``anchors``); returns it with the observations skipped and the
    ambiguous objects' ids."""
    from holoslam.graph.problem import HeadingMeasurements, LandmarkMeasurements, SlamProblem

    N = len(closed)
    headings = _headings(run.hst, run.hyaw, run.hsig, anchors) if run.have_h else None
    li, lid, lxy, lcov, lz, skipped = _landmarks(observations, closed, anchors, run.ost, run.opose, run.short)
    init = np.array(graph.est).reshape(N, 3)
    drop, init_lm = _object_consensus(init, li, lid, lxy, lcov, cfg)
    if drop:
        keep = [k for k, name in enumerate(lid) if name not in drop]
        li, lid, lxy, lcov, lz = ([seq[k] for k in keep] for seq in (li, lid, lxy, lcov, lz))
    landmarks = (LandmarkMeasurements(np.array(li, np.int64), tuple(lid), np.array(lxy).reshape(-1, 2),
                                      np.array(lcov).reshape(-1, 2, 2), np.array(lz))
                 if li else LandmarkMeasurements.empty())
    problem = SlamProblem(num_poses=N, relative=graph.measurements(),
                          headings=headings if headings is not None else HeadingMeasurements.empty(),
                          landmarks=landmarks, initial_wTa=init, initial_landmarks=init_lm, stamps_ns=anchors)
    return problem, skipped, drop


def scan_rate_hz(stamps_ns: np.ndarray, span: int = 10) -> float:
    """The laser's scan rate (Hz): the inverse of the median period over ``span`` consecutive scans, which
    neither stops (a gap) nor bursts of stamps (intel's log stamps scans in bursts 1 ms apart) move; 0 for fewer
    than span + 1 scans."""
    t = np.asarray(stamps_ns, np.int64)
    if len(t) <= span:
        return 0.0
    period = float(np.median((t[span:] - t[:-span]).astype(np.float64))) / span / 1e9
    return 1.0 / period if period > 0 else 0.0


def beam_step_and_range(scans: Sequence[Scan], max_range_m: float, samples: int = 500) -> tuple[float, float]:
    """The laser's beam spacing (rad, the median ``angle_increment``) and the median range of its returns (m,
    those within ``max_range_m``) over at most ``samples`` scans spread evenly over the log; nan without returns."""
    if not scans:
        return math.nan, math.nan
    pick = [scans[i] for i in np.unique(np.linspace(0, len(scans) - 1, min(samples, len(scans))).astype(np.int64))]
    step = float(np.median([abs(s.angle_increment) for s in pick]))
    ranges = np.concatenate([s.ranges[s.valid & (s.ranges <= max_range_m)] for s in pick])
    return step, float(np.median(ranges)) if ranges.size else math.nan


def _headings(hst, hyaw, hsig, anchors):
    """Step 4: compass yaw at the anchor stamps inside the compass's span."""
    from holoslam.graph.problem import HeadingMeasurements

    yaw, idx, w = interpolate_yaw(hst, hyaw, anchors)
    inside = (anchors >= hst[0]) & (anchors <= hst[-1])
    sig = np.sqrt(np.sum(w * hsig[idx] ** 2, axis=1))
    return HeadingMeasurements(np.nonzero(inside)[0], g.wrap(yaw[inside]), sig[inside])


def _landmarks(observations, closed, anchors, ost, opose, short):
    """Step 5 (Eq. 16): every observation in the anchor frame of the submap active at its stamp."""
    li, lid, lxy, lcov, lz = [], [], [], [], []
    skipped = 0
    for ob in sorted(observations, key=lambda o: o.stamp_ns):
        k = int(np.searchsorted(anchors, ob.stamp_ns, side="right")) - 1
        if ob.stamp_ns > ost[-1] or ob.stamp_ns < ost[0]:
            skipped += 1
            continue
        if k < 0:  # before the first scan (odometry covers it): dead reckoning backwards from anchor 0
            sm = closed[0]
            back = dead_reckon(ost, opose, int(ob.stamp_ns), int(sm.scan_stamps_ns[0]), **short)
            Ji = g.inverse_jacobian(back.end)
            aTb, cov_aTb = g.propagate_compose(
                sm.aTb[0], sm.cov_aTb[0], g.inverse(back.end), Ji @ back.cov_aTb_end @ Ji.T
            )
            k = 0
        else:
            sm = closed[k]
            q = int(np.searchsorted(sm.scan_stamps_ns, ob.stamp_ns, side="right")) - 1
            dr = dead_reckon(ost, opose, int(sm.scan_stamps_ns[q]), int(ob.stamp_ns), start=sm.aTb[q],
                             cov_start=sm.cov_aTb[q], **short)
            aTb, cov_aTb = dr.end, dr.cov_aTb_end
        xy, c2, z = landmark_in_anchor(aTb, cov_aTb, ob.b_position, ob.cov_b_position)
        if np.hypot(*xy) < 1e-3:
            skipped += 1
            continue
        li.append(k)
        lid.append(ob.object_id)
        lxy.append(xy)
        lcov.append(c2)
        lz.append(z)
    return li, lid, lxy, lcov, lz, skipped


def _object_consensus(
    init_wTa, li, lid, lxy, lcov, cfg: FrontEndConfig
) -> tuple[set[str], dict[str, np.ndarray]]:
    """Per object, which sightings agree under the initial anchors (module docstring, step 7): the ambiguous
    objects, and each object's initial position: the information-weighted mean of the sighting that most
    others agree with (the earliest on a tie) and those that agree with it (not simply the first sighting,
    which may be the wrong one and would hold a robust kernel at the wrong place)."""
    by: dict[str, list[int]] = {}
    for k, name in enumerate(lid):
        by.setdefault(name, []).append(k)
    ambiguous: set[str] = set()
    init: dict[str, np.ndarray] = {}
    for name, ks in by.items():
        T = init_wTa[np.array([li[k] for k in ks])]
        R = g.rot2(T[:, 2])
        w = np.einsum("nij,nj->ni", R, np.array([lxy[k] for k in ks])) + T[:, :2]
        C = R @ np.array([lcov[k] for k in ks]) @ np.swapaxes(R, 1, 2)
        d = w[:, None, :] - w[None, :, :]
        S = C[:, None] + C[None, :] + np.eye(2) * cfg.association_drift**2
        m2 = np.einsum("abi,abi->ab", d, np.linalg.solve(S, d[..., None])[..., 0])
        agree = m2 < cfg.association_gate
        support = agree.sum(axis=1)  # includes itself
        if len(ks) >= 2 and support.max() == 1:
            ambiguous.add(name)
            continue
        members = agree[int(np.argmax(support))]
        info = np.linalg.inv(C[members])
        init[name] = np.linalg.solve(info.sum(axis=0), np.einsum("kij,kj->i", info, w[members]))
    return ambiguous, init
