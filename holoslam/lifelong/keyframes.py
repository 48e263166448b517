"""The keyframe stage of a joined session, with the held map as its old submaps.

A run's keyframe stage (``holoslam.submaps.revisits``, ``holoslam.graph.nodes``) solves every keyframe (node) as
a pose beside the solved anchors and matches it into the older submaps it revisits: the anchor graph holds each
submap rigid, and the far end of a submap drifts from its anchor by a few centimetres. A joined session has had
that stage against its own submaps only; the joint solve (``joint``) then places its anchors on the stored map,
each submap rigid again. Here the session's nodes are matched into the working stored submaps they revisit too and
solved once more (``solve_nodes``): the new anchors held at the joint solve's poses with its marginal covariances,
the stored anchors at their held poses (``STORED_SIGMAS``), the node matches into the session's own submaps as its
run found them, and the new ones into the stored submaps. The session's trajectory and anchors are then the node
solve's, as a run's are (``optimise.keyframe_anchors``, ``trajectory.node_keyframe_poses``).

A stored submap's keyframes (where the robot stood while building it: what ``match_nodes`` picks old submaps by)
are its session's stored poses hung from its anchor (``StoredTrajectory``), thinned to one per ``KEYFRAME_CELL_M``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SessionKeyframes", "stored_keyframes", "session_keyframes", "world_trajectory", "STORED_SIGMAS",
           "KEYFRAME_CELL_M"]

# sigmas (m, m, rad) of the prior that holds a stored anchor in the node solve: the stored map is held
# (``LifelongConfig.hold_stored``), so as nearly fixed as the node solve's default for an anchor without a
# covariance (1 mm / 0.06 deg, ``solve_nodes``)
STORED_SIGMAS = (1e-3, 1e-3, 1e-3)
# m: a stored submap's keyframes are its session's poses hung from its anchor, one per cell of this size (the
# keyframes only tell which submaps a node stands near: ``RevisitConfig.keyframe_distance_m`` is 6 m); intel in 3
# sessions scored 0.0210 m with 0.25, 0.5 and 1 m alike
KEYFRAME_CELL_M = 0.5


@dataclass(frozen=True, eq=False)
class _Target:
    """A stored submap as ``match_nodes`` reads a submap: its index among the node solve's anchors, its grid and
    its keyframes in its anchor frame."""

    index: int
    grid: Any
    aTb: np.ndarray


@dataclass(frozen=True, eq=False)
class SessionKeyframes:
    """The joined session's node solve: ``wTn`` (N, 3) its nodes in the world at ``stamps_ns``, ``wTa`` (K, 3)
    its anchors (the node at each anchor's stamp), the matches into its own submaps and into the stored ones, and
    how many node-submap pairs were tried in the stored map, and the stage's wall time."""

    stamps_ns: np.ndarray
    wTn: np.ndarray
    wTa: np.ndarray
    own_matches: int
    stored_matches: int
    stored_tried: int
    seconds: float = 0.0


def stored_keyframes(store: Any, stored: tuple) -> list[np.ndarray]:
    """Per ``stored`` submap (``StoredSubmap``, in that order) its keyframes in its anchor frame, (n, 3): its
    session's stored poses hung from its anchor, one per ``KEYFRAME_CELL_M`` cell (module docstring)."""
    out: list[np.ndarray] = [np.zeros((0, 3))] * len(stored)
    by_session: dict[int, list[int]] = {}
    for j, s in enumerate(stored):
        by_session.setdefault(int(s.session_id), []).append(j)
    for sid, rows in sorted(by_session.items()):
        t = store.trajectory(sid)
        k, aTb = np.asarray(t.anchor_idx, np.int64), np.asarray(t.aTb, np.float64).reshape(-1, 3)
        for j in rows:
            mine = aTb[k == int(stored[j].idx)]
            _u, first = np.unique(np.floor(mine[:, :2] / KEYFRAME_CELL_M).astype(np.int64), axis=0, return_index=True)
            out[j] = mine[np.sort(first)]
    return out


def session_keyframes(st: Any, wTa: np.ndarray, cov_wTa: np.ndarray | None, stored: tuple,
                      keyframes: list[np.ndarray], frontend: Any = None) -> SessionKeyframes | None:
    """The node solve of the joined session ``st`` (``pipeline.SlamStages``) with its anchors at ``wTa`` (K, 3)
    (the joint solve's, covariances ``cov_wTa``), matched into the ``stored`` submaps (with grids) that hold
    ``keyframes`` (``stored_keyframes``) near its nodes, with the run's ``FrontEndConfig`` ``frontend``. None when
    the session has no nodes or the keyframe stage is off."""
    import time
    from dataclasses import replace

    from holoslam.graph.nodes import solve_nodes
    from holoslam.relocalise_parts import _grid
    from holoslam.submaps.frontend import FrontEndConfig
    from holoslam.submaps.revisits import NodeMatches, graph_nodes, match_nodes

    fe_cfg = frontend or FrontEndConfig()
    if not fe_cfg.revisits.enabled:
        return None
    nodes = st.revisits.nodes if st.revisits is not None else graph_nodes(st.fe.submaps)
    if not len(nodes):
        return None
    t0 = time.perf_counter()
    own = st.revisits.matches if st.revisits is not None else _no_matches()
    K = len(wTa)
    first = K + fe_cfg.revisits.skip_recent + 1  # stored submap j is anchor first + j: never a node's chain neighbour
    A = np.vstack([np.asarray(wTa, np.float64).reshape(-1, 3), np.zeros((first - K, 3)),
                   np.array([s.wTa for s in stored]).reshape(-1, 3)])
    targets = [_Target(first + j, _grid(s), kf) for j, (s, kf) in enumerate(zip(stored, keyframes, strict=True))
               if len(kf) and _grid(s) is not None]
    rcfg = replace(fe_cfg.revisits, min_score=fe_cfg.revisits.min_score * st.fe.score_scale)
    cross = match_nodes(targets, nodes, A, rcfg, fe_cfg.local.match) if targets else _no_matches()
    used = np.unique(cross.submap)  # the stored anchors a node was matched into: held beside the new ones
    renumber = {int(k): K + n for n, k in enumerate(used.tolist())}
    C = np.broadcast_to(np.diag([1e-6, 1e-6, 1e-6]), (K, 3, 3)) if cov_wTa is None else np.asarray(cov_wTa)
    held = np.broadcast_to(np.diag(np.square(STORED_SIGMAS)), (len(used), 3, 3))
    matches = NodeMatches(
        np.concatenate([own.submap, [renumber[int(k)] for k in cross.submap.tolist()]]).astype(np.int64),
        np.concatenate([own.node, cross.node]).astype(np.int64),
        np.vstack([own.aTb.reshape(-1, 3), cross.aTb.reshape(-1, 3)]),
        np.vstack([own.cov_aTb.reshape(-1, 3, 3), cross.cov_aTb.reshape(-1, 3, 3)]),
        np.concatenate([own.score, cross.score]))
    sol = solve_nodes(nodes, matches, np.vstack([A[:K], A[used]]), np.concatenate([C.reshape(-1, 3, 3), held]),
                      fe_cfg.revisits)
    stamps = np.asarray(st.fe.anchor_stamps_ns, np.int64)
    k = np.clip(np.searchsorted(nodes.stamps_ns, stamps), 0, len(nodes) - 1)
    hit = nodes.stamps_ns[k] == stamps
    wTa_out = np.where(hit[:, None], sol.wTn[k], sol.wTa[:K])
    return SessionKeyframes(nodes.stamps_ns, sol.wTn, wTa_out, len(own), len(cross), int(cross.tried),
                            time.perf_counter() - t0)


def _no_matches() -> Any:
    from holoslam.submaps.revisits import NodeMatches

    return NodeMatches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                       np.zeros(0))


def world_trajectory(st: Any, kf: SessionKeyframes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The session's trajectory in the world from its node solve: the keyframes (and the scans localised between
    them) at the nodes' poses (``trajectory.node_keyframe_poses``), every other stamp between them by the session's
    own trajectory with the correction spread over the gap (``trajectory.optimised_trajectory``). Returns (world
    poses at ``st.traj.stamps_ns``, keyframe stamps, world keyframes)."""
    from holoslam.trajectory import node_keyframe_poses, optimised_trajectory

    key_t, wTk = node_keyframe_poses(st.fe.submaps, kf.stamps_ns, kf.wTn)
    wTb = optimised_trajectory(st.traj.stamps_ns, st.traj.stamps_ns, st.traj.wTb, key_t, wTk)
    return wTb, key_t, wTk
