"""One graph for the whole store: the working submaps' anchors of every joined session, their relative poses
(within sessions and across them), and the objects' placements seen from them, with the new session's anchors,
relative poses, cross-session laser matches and sightings added, solved again with GTSAM (``holoslam.solve``).

Unknowns: every working anchor's world pose (the stored ones start at their stored values, the new session's at
wTs ∘ sTa) and every placement of an object (``<id>#<n>``: the object at its n-th place in this home) seen from a
working submap. Cross-session laser matches enter as ``cross`` relative poses under the run's loop kernel (Huber) and the
chi-square rounds, as any closure. The gauge: the oldest working anchor keeps its stored pose
(``SolveOptions.fix_first``), so the world frame stays where the first session put it."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["JointGraph", "JointSolution", "joint_problem", "solve_joint"]


@dataclass(frozen=True, eq=False)
class JointGraph:
    """The joint problem and how its anchors map back: ``stored_ids`` (M,) the stored submaps' row ids (anchors
    0..M-1), then the new session's K anchors (M..M+K-1)."""

    problem: Any  # SlamProblem
    stored_ids: np.ndarray
    new_count: int


@dataclass(frozen=True, eq=False)
class JointSolution:
    """The joint solve's anchors (stored, new) with covariances, placements with covariances, and its cost."""

    stored_wTa: np.ndarray
    stored_cov: np.ndarray | None
    new_wTa: np.ndarray
    new_cov: np.ndarray | None
    placements: dict[str, tuple[np.ndarray, np.ndarray | None]]
    seconds: float
    iterations: int
    method: str
    rejected: int


def joint_problem(stored, factors, sightings, new_sTa: np.ndarray, new_relative, new_landmarks,
                  new_placement: dict[str, str], wTs: np.ndarray, cross, placements_init: dict[str, np.ndarray]
                  ) -> JointGraph:
    """The joint ``SlamProblem``: ``stored`` working submaps (``StoredSubmap``), their ``factors`` and
    ``sightings`` (store batches), the new session's anchors ``new_sTa`` in its own frame, its relative poses
    (``RelativePoseMeasurements``, indices into its anchors) and landmark sightings (``LandmarkMeasurements``,
    object ids renamed to placements by ``new_placement``), the session transform ``wTs``, the cross-session
    ``LaserMatch``es, and initial placement positions."""
    from holoslam.graph.problem import LandmarkMeasurements, RelativePoseMeasurements, SlamProblem

    ids = np.array([s.id for s in stored], np.int64)
    M, K = len(ids), len(new_sTa)
    index = {int(k): n for n, k in enumerate(ids.tolist())}
    fi = np.array([index[int(i)] for i in factors.i], np.int64)
    fj = np.array([index[int(j)] for j in factors.j], np.int64)
    ci = np.array([index[m.old] for m in cross], np.int64)
    cj = np.array([M + m.new for m in cross], np.int64)
    relative = RelativePoseMeasurements(
        np.concatenate([fi, np.asarray(new_relative.i) + M, ci]),
        np.concatenate([fj, np.asarray(new_relative.j) + M, cj]),
        np.vstack([factors.iTj.reshape(-1, 3), new_relative.iTj, np.array([m.oTn for m in cross]).reshape(-1, 3)]),
        np.vstack([factors.cov_iTj.reshape(-1, 3, 3), new_relative.cov_iTj,
                   np.array([m.cov_oTn for m in cross]).reshape(-1, 3, 3)]),
        np.concatenate([np.asarray(factors.kind, object), np.asarray(new_relative.kind, object),
                        np.full(len(cross), "cross", object)]))
    si = np.array([index[int(i)] for i in sightings.submap_id], np.int64)
    landmarks = LandmarkMeasurements(
        np.concatenate([si, np.asarray(new_landmarks.i) + M]),
        tuple(sightings.placement) + tuple(new_placement[o] for o in new_landmarks.landmark),
        np.vstack([sightings.a_position.reshape(-1, 2), new_landmarks.a_position]),
        np.vstack([sightings.cov_a_position.reshape(-1, 2, 2), new_landmarks.cov_a_position]),
        np.concatenate([sightings.z, new_landmarks.z]))
    init = np.vstack([np.array([s.wTa for s in stored]).reshape(-1, 3),
                      g.compose(np.broadcast_to(wTs, (K, 3)), new_sTa)])
    problem = SlamProblem(num_poses=M + K, relative=relative, landmarks=landmarks, initial_wTa=init,
                          initial_landmarks=placements_init)
    return JointGraph(problem, ids, K)


def solve_joint(jg: JointGraph, method: str = "batch", covariances: bool = True) -> JointSolution:
    """Solve the joint problem (batch Levenberg-Marquardt or iSAM2 over the whole graph; the run's kernels and
    chi-square rounds; no moved-object splitting: placements are decided before, ``holoslam.lifelong.changes``)."""
    import dataclasses

    from holoslam.choices import Method
    from holoslam.optimise import run_build_options
    from holoslam.solve import CovarianceScope, SolveOptions, solve

    t0 = time.perf_counter()
    opts = SolveOptions(method=Method(method), reject_outliers=True, detect_moved=False,
                        covariances=CovarianceScope.ALL if covariances else CovarianceScope.NONE,
                        build=dataclasses.replace(run_build_options(), robust_kinds=("loop", "cross")))
    sol = solve(jg.problem, opts)
    M = len(jg.stored_ids)
    cov = sol.cov_wTa
    placements = {name: (sol.w_landmarks[k], None if sol.cov_w_landmarks is None else sol.cov_w_landmarks[k])
                  for k, name in enumerate(sol.landmark_ids)}
    return JointSolution(sol.wTa[:M], None if cov is None else cov[:M], sol.wTa[M:], None if cov is None else cov[M:],
                         placements, time.perf_counter() - t0, int(sol.iterations), str(method), len(sol.rejected))
