"""The SLAM front end: a log and object observations -> submaps and a :class:`holoslam.graph.problem.SlamProblem`.

Steps (seed 002 §2, SPEC §4):

1. Dead reckoning of the whole run (Eq. 14, compass heading changes with the odometry fallback) gives
   ``wTb`` at every odometry stamp: the seed of everything else and the "dead reckoning alone" baseline.
2. Scans are walked in time order. A keyframe (see ``holoslam.submaps.segment``) is registered by point-to-line
   ICP into the active submap's points, seeded by the odometry increment from the previous keyframe; a failed
   match keeps the seed with the dead-reckoning covariance added. Over such short intervals (a keyframe is
   0.2 m or 10 degrees from the last; a sighting is a few seconds from its keyframe) the odometry's heading
   change is far better than the difference of two compass readings (sqrt(2) x 1.5 deg of white noise), so
   these use dead reckoning without the compass; the compass enters between anchors and as heading factors.
   A keyframe's pose covariance in the anchor frame is its registration's plus the previous keyframe's: the
   map it registered into was placed by the keyframes before it, so their errors carry over (a conservative
   random walk; the registration alone is overconfident by 2-5x in variance against ground truth). The policy of ``segment.py`` decides when a new
   submap starts; its anchor is the base pose at that keyframe.
3. Between consecutive anchors m and n two independent relative poses are emitted: ``dead_reckoning`` (Eq. 14
   from m's anchor to n's anchor stamp, with its analytic covariance) and, when the arrival scan registers into
   submap m, ``scan_match`` (Eq. 15 with nTr = identity, since n's anchor is the arrival pose); its covariance
   is ICP's plus that of the last keyframe of submap m (the map the scan registered into was placed by it).
4. Compass yaw at every anchor stamp (raw, with its bias) -> HeadingMeasurements.
5. Revisits: every ``revisit_every`` keyframes the scan is registered into the older submaps (not the
   previous one, nor one already linked to the current submap) that have a keyframe within ``revisit_radius``
   of the current estimate, the ``max_loop_candidates`` nearest first; a match that passes ICP's quality gate
   and lies within ``max_loop_correction`` of its seed gives a ``loop`` relative pose by Eq. 15,
   mTn = mTr ∘ (nTr)^-1 with nTr the keyframe's pose in its own submap. Its covariance adds the old map's own
   error where the scan matched (the nearest old keyframe's pose covariance) to ICP's; at most one loop links
   a pair of submaps, and the k loops found from one keyframe are each inflated by k (they share that
   keyframe's pose error, so together they count as one measurement).
6. Landmarks (Eq. 16): an observation at stamp t is put into the anchor frame of the submap active at t, using
   the robot's pose there (last keyframe ∘ dead reckoning to t): a_xy = R(theta) b_xy + t, z kept; its 2x2
   covariance is R cov_b R^T + J cov_aTb J^T. An observation before the first scan (the camera may fire first)
   goes to anchor 0 by dead reckoning back from it; only observations outside the odometry's span are skipped
   (counted in ``skipped_observations``).
7. Ambiguous objects: an object seen at least twice whose sightings all disagree with one another (no two
   within ``association_gate`` of each other under their covariances plus ``association_drift`` of the initial
   anchors) cannot be located: no majority says which sighting is right (one misread id or one tag at the wrong
   place among two sightings). Its sightings are left out and its id is listed in ``ambiguous_objects``, rather
   than placing it at an arbitrary one. Objects with a consistent majority, or two self-consistent groups (a
   moved object), go to the solver, whose outlier rejection and moved-object detection handle them; each
   object's initial position is the mean of its largest agreeing group (the earliest on a tie), so a robust
   kernel does not start, and stay, at a wrong sighting.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from holoslam import geometry as g
from holoslam.errors import IngestError
from holoslam.submaps.deadreckon import DeadReckoningConfig, dead_reckon, interpolate_poses, interpolate_yaw
from holoslam.submaps.features import ScanFeatures, extract_features, transform_features
from holoslam.submaps.localize import NearestIndex, register_points, scan_normals
from holoslam.submaps.segment import (
    SegmentConfig,
    Submap,
    local_grid,
    side_width,
    split_reason,
    transform_normals,
    voxel_append,
)
from holoslam.types import LogData, ObjectObservation

__all__ = ["FrontEndConfig", "FrontEnd", "build_problem", "base_to_laser", "landmark_in_anchor"]


@dataclass(frozen=True, slots=True)
class FrontEndConfig:
    dead_reckoning: DeadReckoningConfig = field(default_factory=DeadReckoningConfig)
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    revisit_every: int = 3  # keyframes
    revisit_radius: float = 1.5  # m from the nearest keyframe of an older submap
    max_loop_candidates: int = 3  # the older submaps with the nearest keyframes are tried, at most this many
    max_loop_correction: float = 0.5  # m between a loop's seed and its match
    default_heading_sigma: float = 0.03  # rad, when the log gives none
    base_frame: str = "base_link"
    build_grids: bool = True
    association_drift: float = 0.15  # m, allowance for the initial anchors' drift when comparing sightings
    association_gate: float = 13.8  # chi-square(2) 0.999: two sightings of one object agree below this


@dataclass(frozen=True, eq=False)
class FrontEnd:
    """Submaps, the SLAM problem, the whole-run dead reckoning (``dr_stamps_ns``, ``dr_wTb``), the anchors'
    stamps, the base->laser pose ``bTs`` used, what was skipped (observations outside the odometry's span or
    at an anchor's origin), and ``ambiguous_objects``: ids whose sightings all disagree (step 7), left out of the problem."""

    submaps: tuple[Submap, ...]
    problem: object  # holoslam.graph.problem.SlamProblem
    dr_stamps_ns: np.ndarray
    dr_wTb: np.ndarray
    anchor_stamps_ns: np.ndarray
    bTs: np.ndarray
    skipped_observations: int = 0
    loops_tried: int = 0
    ambiguous_objects: tuple[str, ...] = ()


def base_to_laser(log: LogData, laser_frame: str, base_frame: str = "base_link") -> np.ndarray:
    """The planar pose (x, y, yaw) of the laser in the base frame from the log's static transforms."""
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
                      "the log needs /tf_static base_link->laser")


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


class _Open:
    """The submap being built."""

    def __init__(self, index: int, stamp: int, reason: str, cfg: SegmentConfig, travelled0: float) -> None:
        self.index, self.stamp, self.reason, self.cfg = index, stamp, reason, cfg
        self.stamps: list[int] = []
        self.poses: list[np.ndarray] = []
        self.covs: list[np.ndarray] = []
        self.bpts: list[np.ndarray] = []
        self.ranges: list[np.ndarray] = []
        self.angles: list[np.ndarray] = []
        self.pts = np.zeros((0, 2))
        self.nrm = np.zeros((0, 2))
        self.codes = np.zeros(0, dtype=np.int64)  # voxel codes of pts (segment.voxel_append)
        self.feats: list[ScanFeatures] = []
        self.narrow = False
        self.travelled0 = travelled0

    def add(self, stamp, aTb, cov, bpts, bnrm, ranges, angles, bTs) -> None:
        self.stamps.append(int(stamp))
        self.poses.append(np.asarray(aTb, float))
        self.covs.append(np.asarray(cov, float))
        self.bpts.append(bpts)
        self.ranges.append(ranges)
        self.angles.append(angles)
        p = g.transform_points(aTb, bpts)
        n = transform_normals(aTb, bnrm)
        self.pts, self.nrm, self.codes = voxel_append(self.pts, self.nrm, self.codes, p, n, self.cfg.voxel)
        self.feats.append(transform_features(aTb, extract_features(bpts, self.cfg.features)))

    def close(self, bTs: np.ndarray, build_grid: bool) -> Submap:
        f = self.feats
        feats = ScanFeatures(*(np.vstack([getattr(x, k) for x in f]) for k in
                               ("segments", "lines", "corners", "crossings", "points")))
        P = np.array(self.poses)
        grid = None
        if build_grid:
            aTs = g.compose(P, np.broadcast_to(bTs, P.shape))
            grid = local_grid(aTs, self.ranges, self.angles, self.cfg.grid_resolution, self.cfg.clear_range)
        return Submap(self.index, self.stamp, np.array(self.stamps, np.int64), P, np.array(self.covs),
                      tuple(self.bpts), self.pts, self.nrm, feats, grid, self.reason)


def build_problem(
    log: LogData,
    observations: Sequence[ObjectObservation] = (),
    config: FrontEndConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FrontEnd:
    """Run the front end over a log (see the module docstring). Raises IngestError when the log lacks
    odometry or scans. ``progress(done, total)`` is called with the scans walked, about every 2% of them."""
    from holoslam.graph.problem import (
        HeadingMeasurements,
        LandmarkMeasurements,
        RelativePoseMeasurements,
        SlamProblem,
    )

    cfg = config or FrontEndConfig()
    scfg = cfg.segment
    if len(log.odometry) < 2:
        raise IngestError(f"{log.source}: the front end needs odometry (/odom), found {len(log.odometry)} records")
    if not log.scans:
        raise IngestError(f"{log.source}: the front end needs laser scans (/scan), found none")
    ost, opose = log.odometry_arrays()
    hst, hyaw, hsig = log.heading_arrays()
    hsig = np.where(np.isfinite(hsig) & (hsig > 0), hsig, cfg.default_heading_sigma)
    have_h = hst.size >= 2
    hargs = dict(heading_stamps_ns=hst if have_h else None, heading_yaw=hyaw if have_h else None,
                 heading_sigma=hsig if have_h else None, config=cfg.dead_reckoning)
    # short intervals (keyframe to keyframe, keyframe to a sighting): odometry headings only (step 2)
    short = dict(config=replace(cfg.dead_reckoning, use_compass=False))
    scans = [s for s in log.scans if ost[0] <= s.stamp_ns <= ost[-1]]
    if not scans:
        raise IngestError(f"{log.source}: no scan lies within the odometry's time span")
    bTs = base_to_laser(log, scans[0].frame_id, cfg.base_frame)
    # 1. whole-run dead reckoning, starting at the odometry pose of the first scan
    t_first = int(scans[0].stamp_ns)
    start = interpolate_poses(ost, opose, np.array([t_first]))[0]
    whole = dead_reckon(ost, opose, t_first, int(ost[-1]), start=start, **hargs)
    dr_st, dr_wTb = whole.stamps_ns, whole.aTb
    path_len = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dr_wTb[:, :2], axis=0).T))])

    def dr_at(t: int) -> np.ndarray:
        return interpolate_poses(dr_st, dr_wTb, np.array([t]))[0]

    def travelled_at(t: int) -> float:
        return float(np.interp(float(t - dr_st[0]), (dr_st - dr_st[0]).astype(float), path_len))

    rel_i, rel_j, rel_T, rel_cov, rel_kind = [], [], [], [], []

    def add_rel(i, j, T, cov, kind):
        rel_i.append(i), rel_j.append(j), rel_T.append(np.asarray(T, float)), rel_kind.append(kind)
        rel_cov.append(np.asarray(cov, float) + np.eye(3) * 1e-10)

    closed: list[Submap] = []
    est_wTa: list[np.ndarray] = [dr_at(t_first)]
    cur = _Open(0, t_first, "start", scfg, 0.0)
    last_kf_t, last_kf_pose, last_kf_cov = None, None, None
    kf_count = 0
    loops_tried = 0
    linked: set[tuple[int, int]] = set()  # (old, current) submap pairs that already have a loop
    every = max(1, -(-len(scans) // 50))  # at most 50 calls
    kf_turn = np.radians(scfg.keyframe_turn_deg)
    # the odometry at every scan, once: a cheap test that rules out most scans as keyframes before the exact one
    odo_at_scans = interpolate_poses(ost, opose, np.array([s.stamp_ns for s in scans], dtype=np.int64))
    last_kf_k, win_kf, win0, win = -1, -1, 0, np.zeros(0, dtype=bool)
    closed_kf_w: list[np.ndarray] = []  # keyframe positions of the closed submaps in the world (step 5)
    kf_start = [0]  # where each closed submap's keyframes start in their concatenation
    old_index: dict[int, NearestIndex] = {}  # nearest-point indexes of closed submaps, built on first revisit
    for k_scan, scan in enumerate(scans):
        if progress is not None and k_scan % every == 0:
            progress(k_scan, len(scans))
        t = int(scan.stamp_ns)
        valid = scan.valid
        if np.count_nonzero(valid) < scfg.icp.min_points:
            continue
        if last_kf_t is not None:  # not a keyframe: nothing else of the scan is needed
            if win_kf != last_kf_k or not win0 <= k_scan < win0 + win.size:
                win_kf, win0 = last_kf_k, k_scan
                win = _may_be_keyframes(odo_at_scans[last_kf_k], odo_at_scans[k_scan:k_scan + 64], scfg)
            if not win[k_scan - win0]:
                continue
            odo_pair = interpolate_poses(ost, opose, np.array([last_kf_t, t]))
            dT = g.between(odo_pair[0], odo_pair[1])
            if np.hypot(dT[0], dT[1]) < scfg.keyframe_distance and abs(dT[2]) < kf_turn:
                continue
        r_ok, a_ok = scan.ranges[valid].astype(np.float64), scan.angles[valid]
        s_pts = np.column_stack([r_ok * np.cos(a_ok), r_ok * np.sin(a_ok)])
        bpts = g.transform_points(bTs, s_pts)
        snrm, nok = scan_normals(s_pts)
        bnrm = transform_normals(bTs, snrm)
        ranges = np.where(valid, scan.ranges, np.inf).astype(np.float64)
        angles = scan.angles
        if last_kf_t is None:  # the very first scan anchors submap 0
            cur.add(t, np.zeros(3), np.eye(3) * 1e-12, bpts, bnrm, ranges, angles, bTs)
            last_kf_k, last_kf_t, last_kf_pose, last_kf_cov = k_scan, t, np.zeros(3), np.zeros((3, 3))
            continue
        kf_count += 1
        seed = g.compose(last_kf_pose, dT)
        reg = register_points(bpts[nok], cur.pts, cur.nrm, seed, scfg.icp)
        if reg.ok:
            aTb, cov = reg.aTb, reg.cov_aTb + last_kf_cov
        else:
            dr = dead_reckon(ost, opose, last_kf_t, t, start=last_kf_pose, cov_start=last_kf_cov, **short)
            aTb, cov = seed, dr.cov_aTb_end
        width = side_width(bpts)
        if width < scfg.doorway_width:
            cur.narrow = True
        reason = split_reason(scfg, travelled_at(t) - cur.travelled0, aTb, t - cur.stamp, cur.narrow, width)
        if reason is None:
            cur.add(t, aTb, cov, bpts, bnrm, ranges, angles, bTs)
            last_kf_k, last_kf_t, last_kf_pose, last_kf_cov = k_scan, t, aTb, cov
        else:
            # 3. a new anchor at this keyframe: dead reckoning and (if it registered) scan match, Eq. 15
            m, n = cur.index, cur.index + 1
            dr = dead_reckon(ost, opose, cur.stamp, t, **hargs)
            add_rel(m, n, dr.end, dr.cov_aTb_end, "dead_reckoning")
            if reg.ok:
                # the map the arrival scan registered into was placed by the earlier keyframes: their pose
                # error in the anchor frame (that of the last one) adds to the registration's own
                mTn, cov_mTn = _eq15(reg.aTb, reg.cov_aTb + cur.covs[-1], np.zeros(3), np.zeros((3, 3)))
                add_rel(m, n, mTn, cov_mTn, "scan_match")
                best = mTn
            else:
                best = dr.end
            closed.append(cur.close(bTs, cfg.build_grids))
            closed_kf_w.append(g.transform_points(est_wTa[m], closed[-1].aTb[:, :2]))
            kf_start.append(kf_start[-1] + closed_kf_w[-1].shape[0])
            est_wTa.append(g.compose(est_wTa[m], best))
            cur = _Open(n, t, reason, scfg, travelled_at(t))
            cur.add(t, np.zeros(3), np.eye(3) * 1e-12, bpts, bnrm, ranges, angles, bTs)
            last_kf_k, last_kf_t, last_kf_pose, last_kf_cov = k_scan, t, np.zeros(3), np.zeros((3, 3))
            aTb, cov = np.zeros(3), np.zeros((3, 3))
        # 5. revisits
        if kf_count % cfg.revisit_every == 0 and len(closed) >= 2:
            wTr = g.compose(est_wTa[cur.index], aTb)
            found: list[tuple[int, np.ndarray, np.ndarray]] = []
            # the older submaps (not the previous one, nor one linked already) whose anchor is near and that
            # have a keyframe within revisit_radius: every closed submap at once
            n_old = cur.index - 1
            kf_w = np.vstack(closed_kf_w[:n_old])  # their keyframes in the world (est_wTa of closed ones is fixed)
            dmin = np.minimum.reduceat(np.hypot(*(kf_w - wTr[:2]).T), kf_start[:n_old])
            near_anchor = np.hypot(*(np.array(est_wTa[:n_old])[:, :2] - wTr[:2]).T) <= (cfg.revisit_radius
                                                                                       + scfg.max_distance)
            ok = near_anchor & (dmin <= cfg.revisit_radius)
            cands = [(float(dmin[i]), i) for i in np.flatnonzero(ok).tolist() if (i, cur.index) not in linked]
            for _, oi in sorted(cands)[: cfg.max_loop_candidates]:
                old = closed[oi]
                loops_tried += 1
                seed_m = g.between(est_wTa[old.index], wTr)
                if oi not in old_index:
                    old_index[oi] = NearestIndex(old.points, scfg.icp.block)
                lr = register_points(bpts[nok], old.points, old.normals, seed_m, scfg.icp, old_index[oi])
                if not lr.ok or np.hypot(*(lr.aTb[:2] - seed_m[:2])) > cfg.max_loop_correction:
                    continue
                # plus the old map's own error where the scan matched: its nearest keyframe's pose covariance
                near = int(np.argmin(np.hypot(*(old.aTb[:, :2] - lr.aTb[:2]).T)))
                mTn, cov_mTn = _eq15(lr.aTb, lr.cov_aTb + old.cov_aTb[near], aTb, cov)
                found.append((old.index, mTn, cov_mTn))
                linked.add((old.index, cur.index))
            # the loops of one keyframe share its pose error in the current submap (and overlapping old maps
            # share points): k of them are not k independent measurements; inflating each by k keeps their
            # combined information at that of one (covariance intersection's conservative bound)
            for m_old, mTn, cov_mTn in found:
                add_rel(m_old, cur.index, mTn, cov_mTn * len(found), "loop")
    closed.append(cur.close(bTs, cfg.build_grids))
    anchors = np.array([s.anchor_stamp_ns for s in closed], dtype=np.int64)
    N = len(closed)
    # 4. compass headings per anchor
    if have_h:
        yaw, idx, w = interpolate_yaw(hst, hyaw, anchors)
        inside = (anchors >= hst[0]) & (anchors <= hst[-1])
        sig = np.sqrt(np.sum(w * hsig[idx] ** 2, axis=1))
        headings = HeadingMeasurements(np.nonzero(inside)[0], g.wrap(yaw[inside]), sig[inside])
    else:
        headings = HeadingMeasurements.empty()
    # 6. landmarks (Eq. 16)
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
        li.append(k), lid.append(ob.object_id), lxy.append(xy), lcov.append(c2), lz.append(z)
    init = np.array(est_wTa).reshape(N, 3)
    drop, init_lm = _object_consensus(init, li, lid, lxy, lcov, cfg)
    if drop:
        keep = [k for k, name in enumerate(lid) if name not in drop]
        li, lid, lxy, lcov, lz = ([seq[k] for k in keep] for seq in (li, lid, lxy, lcov, lz))
    landmarks = (LandmarkMeasurements(np.array(li, np.int64), tuple(lid), np.array(lxy).reshape(-1, 2),
                                      np.array(lcov).reshape(-1, 2, 2), np.array(lz))
                 if li else LandmarkMeasurements.empty())
    relative = (RelativePoseMeasurements(np.array(rel_i), np.array(rel_j), np.array(rel_T), np.array(rel_cov),
                                         np.array(rel_kind, dtype=object))
                if rel_i else RelativePoseMeasurements.empty())
    problem = SlamProblem(num_poses=N, relative=relative, headings=headings, landmarks=landmarks,
                          initial_wTa=init, initial_landmarks=init_lm, stamps_ns=anchors)
    return FrontEnd(tuple(closed), problem, dr_st, dr_wTb, anchors, bTs, skipped, loops_tried,
                    tuple(sorted(drop)))


def _may_be_keyframes(kf_odo: np.ndarray, odo: np.ndarray, scfg: SegmentConfig, margin: float = 1e-6) -> np.ndarray:
    """Which scans with odometry poses ``odo`` (N, 3) may be keyframes after the keyframe at ``kf_odo``: those
    whose motion from it is not below both keyframe thresholds by more than ``margin`` (m, rad). The poses here
    are interpolated once for all scans, which differs from the exact per-pair interpolation of
    ``build_problem`` by rounding only (~1e-12), so a False is certain and a True gets the exact test."""
    dT = g.between(np.broadcast_to(kf_odo, odo.shape), odo)
    return ((np.hypot(dT[:, 0], dT[:, 1]) >= scfg.keyframe_distance - margin)
            | (np.abs(dT[:, 2]) >= np.radians(scfg.keyframe_turn_deg) - margin))


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


def _eq15(mTr, cov_mTr, nTr, cov_nTr):
    from holoslam.submaps.deadreckon import relative_anchor_pose

    return relative_anchor_pose(mTr, cov_mTr, nTr, cov_nTr)
