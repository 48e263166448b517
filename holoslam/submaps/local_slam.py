"""Local SLAM: scans -> nodes matched into submaps (seed 002 Eq. 12) -> finished probability-grid submaps.

A scan becomes a **node** when the robot moved ``motion_distance``, turned ``motion_turn_deg`` or waited
``motion_time_s`` since the last node (Cartographer's motion filter, SPEC §8). Its base pose is predicted from
the previous node by the odometry increment (and, when that window scores low, from the laser's own motion:
the last matched pose moved on at the last matched velocity), then matched into the older of the two **active submaps**
(``scanmatch.match_scan``: correlative window, then continuous refinement; a match under ``min_score`` keeps the
prediction, with the dead-reckoning covariance). The node is inserted into both active submaps. A submap is
finished after ``scans_per_submap`` insertions; a new one starts, anchored at the current node, when the newest
active submap holds half that many, so every scan is matched into a map already well filled around it.

The anchor of a new submap n is the current node's base pose; its pose in the submap m it was matched into,
mTn, is the ``scan_match`` relative pose of Eq. 15 (with nTr the identity). Each node's pose covariance in its
submap is the matcher's (score surface) plus a random walk of the map itself, ``map_drift_*`` per metre
travelled since the anchor (a submap is built from matched scans, each with its own small error).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.probgrid import GridBuilder, GridConfig, ProbGrid
from holoslam.submaps.scan_filter import ScanFilterConfig, adaptive_voxel_filter
from holoslam.submaps.scanmatch import MatchConfig, WidePyramid, match_scan

__all__ = ["LocalSlamConfig", "Node", "ActiveSubmap", "LocalSlam"]


@dataclass(frozen=True, slots=True)
class LocalSlamConfig:
    """Local SLAM settings. Motion filter and submap size: Cartographer's published 2D defaults (SPEC §8: 0.2 m,
    1 deg, 5 s; 90 scans per submap), chosen for real laser scanners at 5-40 Hz."""

    grid: GridConfig = field(default_factory=GridConfig)
    match: MatchConfig = field(default_factory=MatchConfig)
    scan_filter: ScanFilterConfig = field(default_factory=ScanFilterConfig)  # the points a scan is matched with
    motion_distance: float = 0.2  # m
    motion_turn_deg: float = 1.0
    motion_time_s: float = 5.0
    scans_per_submap: int = 90
    # m; > 0: each node's grid match refined by point-to-line ICP against the submap's points kept at this spacing.
    # Off by default, by measurement: on the simulated household it takes anchors from 10 to 6 mm, but on real
    # logs (first 300 s, local relation error) ACES goes 3.4 -> 3.7 cm and fr079 2.9 -> 4.3 cm
    polish_voxel: float = 0.0
    min_scans_to_match: int = 3  # a map of fewer scans is too sparse to match into: odometry until then
    match_every_scan: bool = True
    # between nodes the robot turned less than motion_turn_deg by its odometry: a narrower correlative window
    track_angular_window_deg: float = 5.0  # localise the scans between nodes too (a matched pose at every scan stamp)
    map_drift_per_m: float = 0.005  # m of map error per m travelled inside a submap (1 sigma)
    map_drift_deg_per_m: float = 0.05  # deg per m
    # s; a node whose scan follows the last node's by more than this starts afresh ("lost"): the active submaps are
    # finished and a new one is anchored at it, tied to the old ones by the odometry alone with the lost
    # covariance (``FrontEndConfig.lost_sigma_m``), so that only a loop closure can place it. The laser fell silent
    # (a driver restart) or the robot was carried: either way its map of the place it comes back to must not be
    # glued to the old one by a prediction nothing checked. 10 s is twice the motion filter's time (a standing
    # robot's laser yields a node every motion_time_s) and 7x the slowest real laser period met (1.4 Hz)
    lost_gap_s: float = 10.0
    # node matches in a row that fail (score under ``match.min_score`` after the wide search) in a submap they
    # should fit (``min_scans_to_match`` scans, the laser's usual score known) before local SLAM starts afresh as
    # after a gap: the robot was carried with its laser on (picked up, an elevator) and the odometry no longer says
    # where it is. A node whose match fails is not inserted (a scan no match placed must not write walls into the
    # map; inserted, the next scans of a carried robot matched into it: a Freiburg log played twice end to end,
    # the second copy never rejoined). On the shared logs (full rate and 1.4 Hz with half the beams, the
    # household) failed matches came at most 2 in a row; a carried robot's keep failing. 0: never
    lost_after_misses: int = 3
    # m/s^2: the laser's own prediction (the last matched pose moved on at the last matched velocity) is offered to
    # the matcher only while a change of speed at this rate moves it less than the matcher's window
    # (1/2 a dt^2 <= ``match.linear_window``: 0.45 s at 1 m/s^2 and 0.1 m). A wheeled indoor robot accelerates well
    # below 1 m/s^2 (ARIA's Pioneer default is 0.3); a 5 Hz laser's next scan is 0.2 s on, a 1.4 Hz laser's 0.7 s,
    # too far for a constant velocity: on intel at 1.4 Hz, whose stamps come in bursts (a velocity from two stamps
    # 2.3 s apart, the robot's motion between them logged within 10 ms), the laser's prediction put scans 0.5-0.9 m
    # back along corridors
    laser_prediction_accel: float = 1.0


@dataclass(frozen=True, slots=True)
class Node:
    """A matched scan: its stamp, the submap it was matched into and its base pose there (with covariance),
    the scan's points in the base frame, and whether the match was trusted."""

    stamp_ns: int
    submap: int
    aTb: np.ndarray
    cov_aTb: np.ndarray
    b_points: np.ndarray
    score: float
    matched: bool


@dataclass(frozen=True, slots=True)
class Break:
    """Local SLAM started afresh: submap ``new`` after submap ``last`` (a gap in the laser, or scans that stopped
    fitting), and ``fix``, the last node matched before it (None when none was): where the robot last was by its
    scans, from which the odometry to the new anchor is shorter than from any anchor."""

    last: int
    new: int
    fix: Node | None


class ActiveSubmap:
    """A submap being filled (mutable; ``finish`` freezes its grid)."""

    def __init__(self, index: int, anchor_stamp_ns: int, cfg: LocalSlamConfig, travelled0: float) -> None:
        self.index, self.anchor_stamp_ns, self.travelled0 = index, anchor_stamp_ns, travelled0
        self.builder = GridBuilder(cfg.grid)
        self.stamps: list[int] = []
        self.aTb: list[np.ndarray] = []
        self.cov: list[np.ndarray] = []
        self.b_points: list[np.ndarray] = []
        self.tracked: list[tuple[int, np.ndarray]] = []  # (stamp, aTb) of scans localised, not inserted
        self.pts = np.zeros((0, 2))  # the inserted scans' points, one per voxel, with normals (ICP polish)
        self.nrm = np.zeros((0, 2))
        self.codes = np.zeros(0, np.int64)
        self.voxel = cfg.polish_voxel

    @property
    def count(self) -> int:
        return self.builder.count

    def insert(self, stamp: int, aTb: np.ndarray, cov: np.ndarray, b_points: np.ndarray,
               ranges: np.ndarray, angles: np.ndarray, bTs: np.ndarray) -> None:
        self.stamps.append(int(stamp))
        self.aTb.append(np.asarray(aTb, np.float64))
        self.cov.append(np.asarray(cov, np.float64))
        self.b_points.append(b_points)
        self.builder.insert(ranges, angles, g.compose(aTb, bTs))
        if self.voxel > 0:
            from holoslam.submaps.localize import scan_normals
            from holoslam.submaps.segment import voxel_append

            n, ok = scan_normals(b_points)
            R = g.rot2(aTb[2])
            self.pts, self.nrm, self.codes = voxel_append(self.pts, self.nrm, self.codes,
                                                          g.transform_points(aTb, b_points[ok]), n[ok] @ R.T,
                                                          self.voxel)

    def grid(self) -> ProbGrid:
        return self.builder.freeze()


class _RunningMedian:
    """The median of the last ``size`` values appended (``np.median``'s value), kept sorted as they come."""

    def __init__(self, size: int) -> None:
        self._last: deque[float] = deque(maxlen=size)
        self._sorted: list[float] = []

    def __len__(self) -> int:
        return len(self._last)

    def append(self, value: float) -> None:
        if len(self._last) == self._last.maxlen:
            del self._sorted[bisect.bisect_left(self._sorted, self._last[0])]
        self._last.append(float(value))
        bisect.insort(self._sorted, float(value))

    def median(self) -> float:
        s, n = self._sorted, len(self._sorted)
        return s[n // 2] if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2.0


class LocalSlam:
    """Walks scans one by one (``add``) and hands out finished submaps (``finished``)."""

    def __init__(self, cfg: LocalSlamConfig, bTs: np.ndarray) -> None:
        self.cfg = cfg
        self.bTs = np.asarray(bTs, np.float64)
        self.active: list[ActiveSubmap] = []
        self.finished: list[ActiveSubmap] = []  # handed out (and forgotten) by pop_finished
        self.anchor_stamps: dict[int, int] = {}  # every submap's anchor stamp, by index
        self.nodes: list[Node] = []
        self.next_index = 0
        self._last_odo: np.ndarray | None = None
        self._last_stamp = 0
        self._turn = math.radians(cfg.motion_turn_deg)
        self._scores = _RunningMedian(200)
        self._track_cfg = replace(cfg.match, angular_window_deg=cfg.track_angular_window_deg)
        self._pyramid = WidePyramid()  # the wide search's pyramid of the host's grid, while it is unchanged
        self.arrivals: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # (m, n, mTn, cov) of new anchors
        self.breaks: list[Break] = []  # submaps started afresh (``lost_gap_s``, ``lost_after_misses``)
        # the laser's own motion: the last matched pose (host frame, host index, stamp) and the body-frame
        # velocity between the last two (m/s, m/s, rad/s), the alternative to a wheel odometry that is wrong
        self._last_fix: tuple[int, int, np.ndarray] | None = None
        self._twist = np.zeros(3)
        # the nodes whose matches failed in a row (``lost_after_misses``): index in ``nodes``, odometry pose, ranges,
        # angles, odometer; left out of the map until a match succeeds (forgotten) or a break re-homes them
        self._missed: list[tuple[int, np.ndarray, np.ndarray, np.ndarray, float]] = []
        # the last node's match covariance (its score surface's, before the submap's drift is added); None when
        # the last node was not matched
        self.last_match_cov: np.ndarray | None = None

    def wants(self, stamp: int, odo: np.ndarray) -> bool:
        """The motion filter: is a scan at ``stamp`` with odometry pose ``odo`` a new node?"""
        if self._last_odo is None:
            return True
        d = g.between(self._last_odo, odo)
        return bool(np.hypot(d[0], d[1]) >= self.cfg.motion_distance or abs(d[2]) >= self._turn
                    or (stamp - self._last_stamp) >= self.cfg.motion_time_s * 1e9)

    def add(self, stamp: int, odo: np.ndarray, cov_odo_step: Callable[[], np.ndarray], s_points: np.ndarray,
            ranges: np.ndarray, angles: np.ndarray, travelled: float) -> Node:
        """Match a node's scan (``s_points`` in the sensor frame; ``ranges``/``angles`` for insertion) and
        insert it. ``odo`` is the odometry pose at the stamp and ``cov_odo_step`` the covariance of the odometry
        increment since the last node, asked for only when the match is not trusted."""
        b_pts = g.transform_points(self.bTs, s_points)
        self.last_match_cov = None
        if self.active and self.nodes and stamp - self._last_stamp > self.cfg.lost_gap_s * 1e9:
            self._lose()
        if not self.active:
            self._start(stamp, travelled)
            node = Node(int(stamp), self.active[0].index, np.zeros(3), np.zeros((3, 3)), b_pts, 1.0, True)
        else:
            host = self.active[0]
            last = self.nodes[-1]
            pred = self._predict(host, odo)
            m = (self._match(host, adaptive_voxel_filter(b_pts, self.cfg.scan_filter), pred,
                             alternative=self._laser_predict(host, stamp))
                 if host.count >= self.cfg.min_scans_to_match else None)
            drift = self._drift(travelled - host.travelled0)
            if m is not None and m.ok:
                self._missed.clear()
                self.last_match_cov = m.cov_aTb
                node = Node(int(stamp), host.index, self._polish(host, b_pts, m.aTb), m.cov_aTb + drift, b_pts,
                            m.score, True)
                self._fix(host, stamp, node.aTb)
            else:
                prev_cov = last.cov_aTb if last.submap == host.index else np.zeros((3, 3))
                node = Node(int(stamp), host.index, pred, prev_cov + cov_odo_step() + drift, b_pts,
                            0.0 if m is None else m.score, False)
                if m is not None and self.cfg.lost_after_misses and len(self._scores) >= 20:
                    self._missed.append((len(self.nodes), np.asarray(odo, np.float64), ranges, angles, travelled))
                    self._keep(node, odo, stamp)  # placed by the odometry, not inserted
                    if len(self._missed) >= self.cfg.lost_after_misses:
                        self._rehome()
                    return self.nodes[-1]
        self._insert(node, ranges, angles, travelled)
        return self._keep(node, odo, stamp)

    def _rehome(self) -> None:
        """The scans fit nowhere near the odometry ``lost_after_misses`` times in a row: carried. Start afresh at
        the first of those nodes, each of them placed in the new submap by the odometry since it and inserted."""
        first, o1, _, _, t1 = self._missed[0]
        self._lose()
        self._start(self.nodes[first].stamp_ns, t1)
        index = self.active[0].index
        for i, odo_i, ranges, angles, travelled in self._missed:
            old = self.nodes[i]
            self.nodes[i] = Node(old.stamp_ns, index, g.between(o1, odo_i),
                                 np.zeros((3, 3)) if i == first else old.cov_aTb, old.b_points,
                                 1.0 if i == first else old.score, i == first)  # the first is the new anchor
            self._insert(self.nodes[i], ranges, angles, travelled)
        self._missed.clear()

    def _keep(self, node: Node, odo: np.ndarray, stamp: int) -> Node:
        self.nodes.append(node)
        self._last_odo, self._last_stamp = np.asarray(odo, np.float64), int(stamp)
        return node

    def track(self, stamp: int, odo: np.ndarray, s_points: np.ndarray) -> None:
        """Localise a scan that is not a node (the motion filter let it pass) in the host submap, without
        inserting it: every scan gets a matched pose (``ActiveSubmap.tracked``), not an odometry guess."""
        if not self.active or not self.nodes:
            return
        host = self.active[0]
        if host.count < self.cfg.min_scans_to_match:
            return
        pred = self._predict(host, odo)
        b_pts = adaptive_voxel_filter(g.transform_points(self.bTs, s_points), self.cfg.scan_filter)
        m = self._match(host, b_pts, pred, self._track_cfg, self._laser_predict(host, stamp))
        if m.ok:
            host.tracked.append((int(stamp), m.aTb))
            self._fix(host, stamp, m.aTb)

    def _in_host(self, host: ActiveSubmap, index: int, aTb: np.ndarray) -> np.ndarray | None:
        """A pose in submap ``index``'s frame moved into the host's frame (None: no known relation)."""
        if index == host.index:
            return aTb
        try:
            return g.compose(g.inverse(self._arrival(index, host.index)), aTb)
        except KeyError:
            return None

    def _laser_predict(self, host: ActiveSubmap, stamp: int) -> np.ndarray | None:
        """The pose at ``stamp`` from the laser alone: the last matched pose moved on at the last velocity (None
        when that is too far on for a constant velocity, ``laser_prediction_accel``)."""
        if self._last_fix is None:
            return None
        t, index, aTb = self._last_fix
        dt = (stamp - t) * 1e-9
        if 0.5 * self.cfg.laser_prediction_accel * dt * dt > self.cfg.match.linear_window:
            return None
        prev = self._in_host(host, index, aTb)
        return None if prev is None else g.compose(prev, self._twist * dt)

    def _fix(self, host: ActiveSubmap, stamp: int, aTb: np.ndarray) -> None:
        """Record a matched pose and the body-frame velocity since the last one."""
        if self._last_fix is not None:
            t, index, prev = self._last_fix
            prev_h = self._in_host(host, index, prev)
            dt = (stamp - t) * 1e-9
            self._twist = (g.between(prev_h, aTb) / dt if prev_h is not None and 0 < dt <= self.cfg.motion_time_s
                           else np.zeros(3))
        self._last_fix = (int(stamp), host.index, np.asarray(aTb, np.float64))

    def _match(self, host: ActiveSubmap, b_pts: np.ndarray, pred: np.ndarray, cfg: MatchConfig | None = None,
               alternative: np.ndarray | None = None):
        """Match into the host; the running median of recent scores tells the matcher what is usual."""
        usual = self._scores.median() if len(self._scores) >= 20 else None
        self._pyramid.key = (host.index, host.count)  # the host's grid changes only when a scan is inserted
        m = match_scan(host.builder.prob, host.builder.origin, host.builder.res, b_pts, pred,
                       cfg or self.cfg.match, expected_score=usual, pyramid=self._pyramid,
                       alternative_aTb=alternative, known=host.builder.known)
        if m.ok:
            self._scores.append(m.score)
        return m

    def _predict(self, host: ActiveSubmap, odo: np.ndarray) -> np.ndarray:
        """The base pose in the host's frame predicted from the last node by the odometry increment."""
        last = self.nodes[-1]
        # the last node in the host's frame (it may have been matched into the submap finished just before)
        prev = self._in_host(host, last.submap, last.aTb)
        assert prev is not None and self._last_odo is not None  # the host started at a node; set by the first node
        return g.compose(prev, g.between(self._last_odo, odo))

    def bundle(self, node, length_m: float) -> np.ndarray:
        """The points of ``node`` and of the nodes of its submap within ``length_m`` of path behind it, in the
        node's base frame (local SLAM's poses: accurate to centimetres over a few metres)."""
        host = next((sm for sm in self.active if sm.index == node.submap), None)
        if host is None or not host.aTb:
            return node.b_points
        poses = np.array(host.aTb)
        step = np.hypot(*np.diff(poses[::-1, :2], axis=0).T)
        keep = int(np.searchsorted(np.cumsum(step), length_m, side="right")) + 1
        bTa = g.inverse(node.aTb)
        parts = [g.transform_points(g.compose(bTa, poses[-1 - q]), host.b_points[-1 - q]) for q in range(keep)]
        return np.vstack(parts)

    def usual_score(self) -> float | None:
        """The median score of the last 200 trusted matches (None before 20): how full this laser fills the grids."""
        return self._scores.median() if len(self._scores) >= 20 else None

    def close(self) -> None:
        """Finish every active submap (end of the log)."""
        while self.active:
            self.finished.append(self.active.pop(0))

    # -- internals ---------------------------------------------------------------------------------------
    def _drift(self, dist: float) -> np.ndarray:
        d = max(dist, 0.0)
        return np.diag([(self.cfg.map_drift_per_m * d) ** 2] * 2
                       + [math.radians(self.cfg.map_drift_deg_per_m * d) ** 2])

    def _arrival(self, m: int, n: int) -> np.ndarray:
        """mTn: the anchor of submap n in the frame of submap m, where it was started."""
        for mm, nn, mTn, _ in reversed(self.arrivals):
            if mm == m and nn == n:
                return mTn
        raise KeyError((m, n))

    def _polish(self, host: ActiveSubmap, b_pts: np.ndarray, aTb: np.ndarray) -> np.ndarray:
        """The grid match refined by point-to-line ICP against the host's points (``polish_voxel`` > 0): a
        grid match is biased by up to half a cell where walls meet cell boundaries, the points are not. Kept
        only when ICP passes its quality gate and moves the pose less than a cell."""
        if host.voxel <= 0 or len(host.pts) < 50:
            return aTb
        from holoslam.submaps.localize import register_points

        reg = register_points(b_pts, host.pts, host.nrm, aTb)
        if reg.ok and np.hypot(*(reg.aTb[:2] - aTb[:2])) < self.cfg.grid.resolution:
            return reg.aTb
        return aTb

    def _lose(self) -> None:
        """Finish the active submaps; the next node starts a new one, tied to them only by a break."""
        last = self.active[-1].index
        fix = next((nd for nd in reversed(self.nodes) if nd.matched), None)
        self.close()
        self.breaks.append(Break(last, self.next_index, fix))
        self._last_fix, self._twist = None, np.zeros(3)

    def pop_finished(self) -> list[ActiveSubmap]:
        """The submaps finished since the last call (the caller keeps what it needs of them)."""
        out, self.finished = self.finished, []
        return out

    def _start(self, stamp: int, travelled: float) -> None:
        self.anchor_stamps[self.next_index] = int(stamp)
        self.active.append(ActiveSubmap(self.next_index, int(stamp), self.cfg, travelled))
        self.next_index += 1

    def _insert(self, node: Node, ranges: np.ndarray, angles: np.ndarray, travelled: float) -> None:
        host = self.active[0]
        for sm in self.active:
            if sm is host:
                aTb, cov = node.aTb, node.cov_aTb
            else:  # the younger active submap: its anchor is a node of the host, rigidly
                hTs = self._arrival(host.index, sm.index)
                aTb = g.between(hTs, node.aTb)
                cov = node.cov_aTb
            sm.insert(node.stamp_ns, aTb, cov, node.b_points, ranges, angles, self.bTs)
        half = max(1, self.cfg.scans_per_submap // 2)
        if self.active[-1].count >= half and len(self.active) < 2:
            self._start(node.stamp_ns, travelled)
            new = self.active[-1]
            # the new submap's anchor is this node: mTn = its pose in the host
            self.arrivals.append((host.index, new.index, node.aTb.copy(), node.cov_aTb.copy()))
            new.insert(node.stamp_ns, np.zeros(3), np.zeros((3, 3)), node.b_points, ranges, angles, self.bTs)
        if host.count >= self.cfg.scans_per_submap:
            self.finished.append(self.active.pop(0))
