"""The run's trajectory stage: the base pose at every odometry and scan stamp, from the optimised anchors, the
keyframes registered in their submaps, and the wheel odometry between them (``RunTrajectory``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["RunTrajectory", "run_trajectory", "keyframe_poses", "node_keyframe_poses", "optimised_trajectory"]


@dataclass(frozen=True, eq=False)
class RunTrajectory:
    """The optimised base trajectory ``wTb`` and the dead-reckoned one at ``stamps_ns`` (every odometry and every
    scan stamp, sorted, unique), and the optimised keyframes ``wTk`` at ``key_stamps_ns`` it hangs from."""

    stamps_ns: np.ndarray  # (N,)
    wTb: np.ndarray  # (N, 3)
    dead_reckoning_wTb: np.ndarray  # (N, 3)
    key_stamps_ns: np.ndarray  # (K,)
    wTk: np.ndarray  # (K, 3)

    def at_scans(self, log: Any) -> np.ndarray:
        """The optimised base pose at each of the log's scans (the occupancy grid's poses), (S, 3)."""
        odom_stamps, odomTb = log.odometry_arrays()
        scan_stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
        return optimised_trajectory(scan_stamps, odom_stamps, odomTb, self.key_stamps_ns, self.wTk)


def run_trajectory(log: Any, fe: Any, sol: Any, nodes: Any = None) -> RunTrajectory:
    """The trajectory of a run from its front end ``fe`` (dead reckoning, submaps) and solution ``sol``; with
    ``nodes`` (a ``holoslam.graph.nodes.KeyframeSolve``) the keyframes are the keyframe solve's."""
    from holoslam.geometry import interpolate_poses

    odom_stamps, odomTb = log.odometry_arrays()
    scan_stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    # a pose at every odometry and every scan stamp, so ground truth stamped by scan (relations) scores it
    stamps = np.union1d(odom_stamps, scan_stamps)
    dr = interpolate_poses(fe.dr_stamps_ns, fe.dr_wTb, stamps)
    if nodes is None:
        key_stamps, wTk = keyframe_poses(fe.submaps, sol.wTa)
    else:
        key_stamps, wTk = node_keyframe_poses(fe.submaps, nodes.nodes.stamps_ns, nodes.solution.wTn)
    # between keyframes (a few tenths of a second) the wheel odometry's own motion is the most faithful
    wTb = optimised_trajectory(stamps, odom_stamps, odomTb, key_stamps, wTk)
    return RunTrajectory(stamps, wTb, dr, key_stamps, wTk)


def optimised_trajectory(
    stamps_ns: np.ndarray,
    dr_stamps_ns: np.ndarray,
    dr_wTb: np.ndarray,
    anchor_stamps_ns: np.ndarray,
    wTa: np.ndarray,
) -> np.ndarray:
    """The base pose at every stamp from optimised reference poses (anchors or keyframes) ``wTa`` at
    ``anchor_stamps_ns``: between references k and k + 1 the pose is wTa_k composed with the dead-reckoned motion
    since it and a share of the odometry's error over the segment, wTb(t) = wTa_k ∘ (drTa_k^-1 ∘ drTb(t)) ∘ a E_k,
    where E_k = (drTa_k^-1 ∘ drTa_k+1)^-1 ∘ (wTa_k^-1 ∘ wTa_k+1) is what the optimised poses correct of the
    odometry between them and a scales its (x, y, theta): the pose runs into wTa_k+1 instead of jumping there.
    Wheel odometry errs a few centimetres and degrees over a 0.7 s scan period (fr079: backwards for seconds where
    the robot drove forwards); between scans at 1.4 Hz, composing from reference k alone left those errors at
    every stamp. Odometry errs as the wheels move, not as time passes, so a is the share of the segment's motion
    done by t (``_motion_shares``: its distance for x and y, its turning for theta; the time's share where the
    odometry did not move): the shared intel log at 1.4 Hz with half its beams, 0.0293 m / 0.959 deg mean relation
    error with the time's share, 0.0272 m / 0.810 deg (its scans are stamped in bursts, the odometry's motion is
    not); at full rate, where the relations are at the references, unchanged. Before the first reference,
    reference 0 is used backwards; after the last, the last forwards."""
    from holoslam.geometry import interpolate_poses

    stamps = np.asarray(stamps_ns, dtype=np.int64)
    key_t = np.asarray(anchor_stamps_ns, dtype=np.int64)
    wTa = np.asarray(wTa, dtype=np.float64).reshape(-1, 3)
    dr_t = interpolate_poses(dr_stamps_ns, dr_wTb, stamps)
    dr_a = interpolate_poses(dr_stamps_ns, dr_wTb, key_t)
    k = np.clip(np.searchsorted(key_t, stamps, side="right") - 1, 0, len(key_t) - 1)
    out = g.compose(wTa[k], g.between(dr_a[k], dr_t))
    inside = (stamps > key_t[k]) & (k + 1 < len(key_t))
    if inside.any():
        ki = k[inside]
        E = g.between(g.between(dr_a[ki], dr_a[ki + 1]), g.between(wTa[ki], wTa[ki + 1]))
        E[:, 2] = g.wrap(E[:, 2])
        a_xy, a_th = _motion_shares(dr_stamps_ns, dr_wTb, stamps[inside], key_t[ki], key_t[ki + 1])
        out[inside] = g.compose(out[inside], E * np.c_[a_xy, a_xy, a_th])
    return out


_STILL = 1e-6  # m or rad of odometry motion over a segment below which it did not move (its error shared by time)


def _motion_shares(dr_stamps_ns: np.ndarray, dr_wTb: np.ndarray, t: np.ndarray, t0: np.ndarray,
                   t1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The share of the odometry's distance and of its turning between stamps ``t0`` and ``t1`` (each (Q,)) done
    by ``t`` (Q,), t0 <= t <= t1: ((Q,), (Q,)); the time's share where it did not move (``_STILL``)."""
    st = np.asarray(dr_stamps_ns, np.int64)
    poses = np.asarray(dr_wTb, np.float64).reshape(-1, 3)
    ts = (st - st[0]).astype(np.float64)
    step = np.diff(poses, axis=0)
    arcs = (np.r_[0.0, np.cumsum(np.hypot(step[:, 0], step[:, 1]))], np.r_[0.0, np.cumsum(np.abs(g.wrap(step[:, 2])))])
    q, q0, q1 = ((np.asarray(x, np.int64) - st[0]).astype(np.float64) for x in (t, t0, t1))
    by_time = (q - q0) / np.maximum(q1 - q0, 1.0)
    shares = []
    for arc in arcs:
        a, a0, a1 = (np.interp(x, ts, arc) for x in (q, q0, q1))
        moved = a1 - a0 > _STILL
        shares.append(np.where(moved, (a - a0) / np.where(moved, a1 - a0, 1.0), by_time))
    return shares[0], shares[1]


def keyframe_poses(submaps: Sequence[Any], wTa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every submap keyframe's base pose in the world, sorted by stamp: wTb = wTa_k ∘ aTb (the keyframes are
    registered in their submap by scan matching, so they are more accurate than dead reckoning between anchors),
    with the scans localised in a submap without being inserted (``Submap.track_*``)."""
    stamps = [np.concatenate([np.asarray(sm.scan_stamps_ns, np.int64), np.asarray(sm.track_stamps_ns, np.int64)])
              for sm in submaps]
    rel = [np.vstack([np.reshape(sm.aTb, (-1, 3)), np.reshape(sm.track_aTb, (-1, 3))]) for sm in submaps]
    poses = [g.compose(np.broadcast_to(wTa[sm.index], r.shape), r) for sm, r in zip(submaps, rel, strict=True)]
    if not stamps:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    return _first_per_stamp(stamps, poses)


def node_keyframe_poses(submaps: Sequence[Any], node_stamps_ns: np.ndarray, wTn: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``keyframe_poses`` from solved node poses ``wTn`` at ``node_stamps_ns`` (``holoslam.graph.nodes``): the
    keyframes are the nodes; a scan localised in a submap without being inserted is placed in the submap's frame
    as the solved poses of the keyframes of that submap before and after it put the frame, wTs_k = wTn_k ∘ aTn_k^-1,
    interpolated at its stamp (``geometry.interpolate_poses``; the first or last keyframe's beyond them): wTb =
    wTs(t) ∘ aTb (the frame as the earlier keyframe alone put it left fr079 at 0.4404 deg mean relation error,
    0.4392 with both)."""
    node_t = np.asarray(node_stamps_ns, np.int64)
    stamps, poses = [node_t], [np.asarray(wTn, np.float64).reshape(-1, 3)]
    for sm in submaps:
        tt = np.asarray(sm.track_stamps_ns, np.int64)
        if not tt.size:
            continue
        kt = np.asarray(sm.scan_stamps_ns, np.int64)
        n = np.clip(np.searchsorted(node_t, kt), 0, len(node_t) - 1)
        # the submap's frame as each keyframe's solved pose puts it, interpolated at the tracked scans' stamps
        wTs = g.compose(poses[0][n], g.inverse(np.reshape(sm.aTb, (-1, 3))))
        stamps.append(tt)
        poses.append(g.compose(g.interpolate_poses(kt, wTs, tt), np.reshape(sm.track_aTb, (-1, 3))))
    return _first_per_stamp(stamps, poses)


def _first_per_stamp(stamps: list[np.ndarray], poses: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The poses sorted by stamp, the first given kept where stamps repeat (a node in two submaps: its host's)."""
    s, p = np.concatenate(stamps), np.concatenate(poses).reshape(-1, 3)
    order = np.argsort(s, kind="stable")
    s, p = s[order], p[order]
    keep = np.concatenate([[True], np.diff(s) > 0]) if len(s) else np.zeros(0, bool)
    return s[keep], p[keep]
