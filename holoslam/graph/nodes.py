"""The keyframes' poses solved against the old submaps they revisit (Cartographer's node poses, Hess et al. 2016).

After the anchor graph is solved, every keyframe (node, ``holoslam.submaps.revisits.Nodes``) becomes a pose
variable ``n<k>`` beside the anchors ``x<i>``:

- its pose in its host submap, ``aTb`` with the matcher's covariance (which grows with the distance from the
  anchor, ``LocalSlamConfig.map_drift_*``): BetweenFactorPose2(x_host, n_k);
- consecutive nodes' relative pose from those matched poses, 1 sigma = floor + rate x step
  (``RevisitConfig.step_sigma_*``): the trajectory stays smooth where one node is pulled and the next is not;
- each node match into an old submap (``NodeMatches``), Huber-robust: BetweenFactorPose2(x_old, n_k);
- a disputed node (``revisits.disputed_nodes``: the solved anchors place it in two places more than
  ``RevisitConfig.max_shift_m`` apart, a slip of local SLAM inside a submap) has its tie to its host and its steps
  to its neighbours Huber-robust too, so that its matches place it: on intel at 1.4 Hz with 12 % of its returns
  dropped (one draw) its worst relation 0.93 -> 0.32 m, the bench's sparse intel row 0.0272 m / 0.38 m max ->
  0.0266 m / 0.23 m (eight perturbed draws of sparse intel: relations over 0.9 m in 2 against 6; the full-rate
  logs, ACES and fr079 at 1.4 Hz have none disputed);
- each anchor held at its solved pose with its marginal covariance (the anchors' graph already holds the dead
  reckoning, compass, landmarks and closures; a fixed anchor instead was measured worse on intel: 0.0240 against
  0.0211 m relation error, every 3rd node / 3 m / 3 submaps).

Levenberg-Marquardt from the rigid-submap poses. The node poses give the run's trajectory and map; the anchors
(and the objects located in their frames) stay those of the anchor solve, with their covariances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam import geometry as g
from holoslam.graph.factors import NO_KERNEL, Kernel, RobustKernel, between_factors, prior_factors
from holoslam.graph.keys import anchor_keys, node_keys
from holoslam.submaps.revisits import NodeMatches, Nodes, RevisitConfig, disputed_nodes

__all__ = ["NodeSolution", "KeyframeSolve", "solve_nodes"]


@dataclass(frozen=True, eq=False)
class NodeSolution:
    """Every node's solved world pose ``wTn`` (N, 3), the anchors of the node solve ``wTa`` (K, 3), the final
    and initial errors, the iterations and how many nodes were disputed (``revisits.disputed_nodes``)."""

    wTn: np.ndarray
    wTa: np.ndarray
    error: float
    initial_error: float
    iterations: int
    disputed: int = 0


@dataclass(frozen=True, eq=False)
class KeyframeSolve:
    """What the keyframe stage of a run produced: the keyframes, their matches into old submaps, the solution."""

    nodes: Nodes
    matches: NodeMatches
    solution: NodeSolution


def _step_covariances(wTn: np.ndarray, cfg: RevisitConfig) -> tuple[np.ndarray, np.ndarray]:
    d = g.between(wTn[:-1], wTn[1:])
    step = np.hypot(d[:, 0], d[:, 1])
    s_xy = cfg.step_sigma_m + cfg.step_sigma_rate * step
    s_th = math.radians(cfg.step_sigma_deg) + cfg.step_sigma_rate * np.abs(d[:, 2])
    cov = np.zeros((len(d), 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = s_xy**2
    cov[:, 2, 2] = s_th**2
    return d, cov


def solve_nodes(nodes: Nodes, matches: NodeMatches, wTa: np.ndarray, cov_wTa: np.ndarray | None,
                cfg: RevisitConfig | None = None) -> NodeSolution:
    """Solve the node graph (module docstring). ``cov_wTa`` (K, 3, 3) the anchors' marginals (None: 1 mm /
    0.06 deg, the anchors nearly fixed)."""
    import gtsam

    cfg = cfg or RevisitConfig()
    wTa = np.asarray(wTa, np.float64).reshape(-1, 3)
    K, N = len(wTa), len(nodes)
    wTn0 = g.compose(wTa[nodes.host], nodes.aTb) if N else np.zeros((0, 3))
    if N == 0:
        return NodeSolution(wTn0, wTa, 0.0, 0.0, 0)
    C_a = (np.broadcast_to(np.diag([1e-6, 1e-6, 1e-6]), (K, 3, 3)) if cov_wTa is None
           else np.asarray(cov_wTa, np.float64).reshape(K, 3, 3))
    ak, nk = anchor_keys(np.arange(K)), node_keys(np.arange(N))
    huber = Kernel(RobustKernel.HUBER, cfg.huber_k)
    disputed = disputed_nodes(nodes, wTa, cfg.max_shift_m)
    graph = prior_factors(ak, wTa, C_a + np.eye(3) * 1e-10)
    for part, kernel in ((~disputed, NO_KERNEL), (disputed, huber)):  # a disputed node's tie to its host: robust
        if part.any():
            graph.push_back(between_factors(ak[nodes.host[part]], nk[part], nodes.aTb[part],
                                            nodes.cov_aTb[part] + np.eye(3) * 1e-8, kernel))
    if N > 1:
        steps, cov_steps = _step_covariances(wTn0, cfg)
        beside = disputed[:-1] | disputed[1:]  # a step to or from a disputed node: robust
        for part, kernel in ((~beside, NO_KERNEL), (beside, huber)):
            if part.any():
                graph.push_back(between_factors(nk[:-1][part], nk[1:][part], steps[part], cov_steps[part], kernel))
    if len(matches):
        floor = np.diag([cfg.match_floor_m**2, cfg.match_floor_m**2, math.radians(cfg.match_floor_deg) ** 2])
        graph.push_back(between_factors(ak[matches.submap], nk[matches.node], matches.aTb, matches.cov_aTb + floor,
                                        huber))
    values = gtsam.Values()
    for k, p in zip(ak.tolist(), wTa.tolist(), strict=True):
        values.insert(k, gtsam.Pose2(*p))
    for k, p in zip(nk.tolist(), wTn0.tolist(), strict=True):
        values.insert(k, gtsam.Pose2(*p))
    params = gtsam.LevenbergMarquardtParams()
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    e0 = float(graph.error(values))
    result = opt.optimize()
    wTn = np.array([[p.x(), p.y(), p.theta()] for p in map(result.atPose2, nk.tolist())])
    wTa_out = np.array([[p.x(), p.y(), p.theta()] for p in map(result.atPose2, ak.tolist())])
    return NodeSolution(wTn, wTa_out, float(graph.error(result)), e0, int(opt.iterations()), int(disputed.sum()))
