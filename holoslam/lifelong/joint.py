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

__all__ = ["JointGraph", "JointSolution", "PlacementPriors", "joint_problem", "retired_priors", "solve_joint",
           "composed_factors", "working_factors"]

# m: the virtual anchor that carries the retired sightings stands this far from the placements' centroid (a
# bearing/range factor from afar is near linear in x/y, so the fused x/y covariance converts with little error)
PRIOR_ANCHOR_OFFSET_M = 100.0


@dataclass(frozen=True, eq=False)
class JointGraph:
    """The joint problem and how its anchors map back: ``stored_ids`` (M,) the stored submaps' row ids (anchors
    0..M-1), then the new session's K anchors (M..M+K-1)."""

    problem: Any  # SlamProblem
    stored_ids: np.ndarray
    new_count: int
    prior_placements: int = 0  # placements given a prior from retired sightings (0: no virtual anchor)


@dataclass(frozen=True, eq=False)
class PlacementPriors:
    """What the retired submaps saw of the placements still in the working graph, fused: per placement its world
    position (P, 2), 2x2 covariance (P, 2, 2) and the number of sightings fused."""

    names: tuple[str, ...]
    w_xy: np.ndarray
    cov_w_xy: np.ndarray
    sightings: np.ndarray

    def __len__(self) -> int:
        return len(self.names)


def retired_priors(retired, sightings, live: set[str]) -> PlacementPriors:
    """The sightings of ``retired`` submaps (``StoredSubmap``s out of the working graph, their anchors frozen at
    their last joint solve) of the placements in ``live``, fused per placement in the world: the sightings of
    one anchor by information in its frame, moved into the world with the anchor's covariance added once (its
    sightings share its pose error), then the anchors' estimates fused by information. Retiring a submap thus
    keeps what its session saw of an unchanged object: every session's sightings stay in the one graph."""
    by_id = {int(s.id): s for s in retired}
    acc: dict[str, list[np.ndarray]] = {}  # placement -> [information, information-weighted xy, count]
    groups: dict[tuple[str, int], list[int]] = {}
    for k, (sid, p) in enumerate(zip(sightings.submap_id.tolist(), sightings.placement, strict=True)):
        if p in live and int(sid) in by_id:
            groups.setdefault((p, int(sid)), []).append(k)
    for (p, sid), rows in groups.items():
        info_a = np.linalg.inv(sightings.cov_a_position[rows])
        L = info_a.sum(axis=0)
        a = np.linalg.solve(L, np.einsum("kab,kb->a", info_a, sightings.a_position[rows]))
        sm = by_id[sid]
        R = g.rot2(float(sm.wTa[2]))
        cov = R @ np.linalg.inv(L) @ R.T
        if sm.cov_wTa is not None:
            J = np.column_stack([R, R @ np.array([-a[1], a[0]])])
            cov = cov + J @ np.asarray(sm.cov_wTa) @ J.T
        w = g.transform_points(np.asarray(sm.wTa, np.float64), a[None])[0]
        info = np.linalg.inv(0.5 * (cov + cov.T))
        e = acc.setdefault(p, [np.zeros((2, 2)), np.zeros(2), np.zeros(1)])
        e[0] += info
        e[1] += info @ w
        e[2] += len(rows)
    names = tuple(sorted(acc))
    cov_w = np.array([np.linalg.inv(acc[n][0]) for n in names]).reshape(-1, 2, 2)
    xy = np.array([c @ acc[n][1] for c, n in zip(cov_w, names, strict=True)]).reshape(-1, 2)
    return PlacementPriors(names, xy, cov_w, np.array([int(acc[n][2][0]) for n in names], np.int64))


# the stored factors a composition runs through: a session's chain (local SLAM's scan matches and the odometry
# beside them), never its loops or the cross-session matches: those enter the joint solve under a robust kernel
# and its chi-square rounds, which a composition would take from a wrong one
CHAIN_KINDS = ("scan_match", "dead_reckoning")


def composed_factors(factors, working_ids: np.ndarray, kinds: tuple[str, ...] = CHAIN_KINDS):
    """The relative poses that retirement would drop, kept: for every connected part of retired submaps (linked
    by stored factors), the working submaps it touches are chained (each to the next, in id order) by the
    composition of the stored factors of ``kinds`` along the most certain path through the retired ones (per pair
    of submaps the factor of least position variance; covariances propagated to first order). A ``StoredFactors`` of kind
    ``composed`` between working ids. Without them, a session whose middle was retired falls apart into pieces
    held only by the cross-session matches (or, cut off, by a prior at their stored poses)."""
    import networkx as nx

    from holoslam.store.records import StoredFactors

    working = {int(k) for k in np.asarray(working_ids).tolist()}
    best: dict[tuple[int, int], tuple[float, np.ndarray, np.ndarray]] = {}
    for i, j, T, C, kind in zip(factors.i.tolist(), factors.j.tolist(), factors.iTj, factors.cov_iTj,
                                factors.kind, strict=True):
        if i == j or (i in working and j in working) or str(kind) not in kinds:
            continue
        a, b, T, C = (i, j, T, C) if i < j else (j, i, g.inverse(T), _inv_cov(T, C))
        w = float(C[0, 0] + C[1, 1])
        if (a, b) not in best or w < best[(a, b)][0]:
            best[(a, b)] = (w, np.asarray(T, np.float64), np.asarray(C, np.float64))
    G = nx.Graph()
    for (a, b), (w, _T, _C) in best.items():
        G.add_edge(a, b, weight=max(w, 1e-12))
    retired = G.subgraph([v for v in G if v not in working])
    rows: list[tuple[int, int, np.ndarray, np.ndarray]] = []
    for part in nx.connected_components(retired):
        touch = sorted({u for v in part for u in G[v] if u in working})
        H = G.subgraph(set(part) | set(touch))
        for a, b in zip(touch, touch[1:], strict=False):
            try:
                path = nx.shortest_path(H, a, b, weight="weight")
            except nx.NetworkXNoPath:
                continue
            if any(v in working for v in path[1:-1]):
                continue  # through another working submap: the chain to it is composed on its own
            T, C = np.zeros(3), np.zeros((3, 3))
            for u, v in zip(path, path[1:], strict=False):
                _w, E, CE = best[(min(u, v), max(u, v))]
                if u > v:
                    E, CE = g.inverse(E), _inv_cov(E, CE)
                T, C = g.propagate_compose(T, C, E, CE)
            rows.append((a, b, T, C))
    n = len(rows)
    return StoredFactors(np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                         np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], np.int64),
                         np.array([r[2] for r in rows]).reshape(-1, 3), np.array([r[3] for r in rows]).reshape(-1, 3, 3),
                         np.array(["composed"] * n, dtype=object))


def working_factors(factors, working_ids: np.ndarray, compose: bool = True):
    """The stored factors between working submaps, with (``compose``) the ``composed_factors`` through retired
    ones."""
    from holoslam.store.records import StoredFactors

    keep = set(np.asarray(working_ids).tolist())
    sel = np.array([int(i) in keep and int(j) in keep for i, j in zip(factors.i, factors.j, strict=True)], bool)
    parts = [StoredFactors(*(np.asarray(a)[sel] for a in (factors.id, factors.session_id, factors.i, factors.j,
                                                            factors.iTj, factors.cov_iTj, factors.kind)))]
    if compose:
        parts.append(composed_factors(factors, working_ids))
    return StoredFactors(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                           ("id", "session_id", "i", "j", "iTj", "cov_iTj", "kind")))


def _inv_cov(T: np.ndarray, C: np.ndarray) -> np.ndarray:
    J = g.inverse_jacobian(np.asarray(T, np.float64))
    return J @ np.asarray(C, np.float64) @ J.T


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
    covariances_failed: str = ""  # why GTSAM gave no marginal covariances ("" when it did, or none were asked)


def joint_problem(stored, factors, sightings, new_sTa: np.ndarray, new_relative, new_landmarks,
                  new_placement: dict[str, str], wTs: np.ndarray, cross, placements_init: dict[str, np.ndarray],
                  priors: PlacementPriors | None = None, hold_stored: bool = False) -> JointGraph:
    """The joint ``SlamProblem``: ``stored`` working submaps (``StoredSubmap``), their ``factors`` and
    ``sightings`` (store batches), the new session's anchors ``new_sTa`` in its own frame, its relative poses
    (``RelativePoseMeasurements``, indices into its anchors) and landmark sightings (``LandmarkMeasurements``,
    object ids renamed to placements by ``new_placement``), the session transform ``wTs``, the cross-session
    ``LaserMatch``es, initial placement positions, and the placements' ``priors`` from retired submaps
    (``retired_priors``): sightings from one virtual anchor (index M+K) held at its pose by a tight prior, as the
    oldest working anchor is (the gauge). ``hold_stored``: every stored anchor pinned at its stored pose as the
    gauge is (``default_prior``), so only the new session's anchors and the placements move
    (``LifelongConfig.hold_stored`` says why)."""
    from holoslam.graph.problem import (
        LandmarkMeasurements,
        PosePrior,
        RelativePoseMeasurements,
        SlamProblem,
        default_prior,
    )

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
    pri: tuple[PosePrior, ...] = (tuple(default_prior(n, init[n]) for n in range(M)) if hold_stored
                                  else _orphan_priors(stored, relative, M + K))
    n_prior = 0
    live = set(landmarks.landmark)
    if priors is not None and len(priors):
        keep = [k for k, n in enumerate(priors.names) if n in live]
        if keep:
            vT = np.array([*(priors.w_xy[keep].mean(axis=0) - [PRIOR_ANCHOR_OFFSET_M, 0.0]), 0.0])
            landmarks = LandmarkMeasurements(
                np.concatenate([landmarks.i, np.full(len(keep), M + K)]),
                landmarks.landmark + tuple(priors.names[k] for k in keep),
                np.vstack([landmarks.a_position, priors.w_xy[keep] - vT[:2]]),
                np.vstack([landmarks.cov_a_position, priors.cov_w_xy[keep]]),
                np.concatenate([landmarks.z, np.full(len(keep), np.nan)]))
            init = np.vstack([init, vT])
            pri = (default_prior(0, init[0]), *pri, default_prior(M + K, vT))
            n_prior = len(keep)
    if pri and pri[0].i != 0:
        pri = (default_prior(0, init[0]), *pri)  # the gauge stays the oldest working anchor's
    problem = SlamProblem(num_poses=len(init), relative=relative, landmarks=landmarks, initial_wTa=init,
                          initial_landmarks=placements_init, priors=pri)
    return JointGraph(problem, ids, K, n_prior)


# sigmas (m, m, rad) of the prior that holds a stored anchor cut off from the rest by retirement, when its stored
# covariance is unknown: a grid cell and the relocalisation's resolution (RelocaliseConfig.floor_sigmas)
ORPHAN_SIGMAS = (0.05, 0.05, 0.0087)


def _orphan_priors(stored, relative, n: int) -> tuple:
    """Priors on the stored anchors that retirement cut off from the oldest working anchor's part of the graph
    (their relative poses led to submaps now retired): one per cut-off part, on its oldest anchor, at its stored
    pose with its stored covariance. Without it such a part floats, held by object sightings at most."""
    import networkx as nx

    from holoslam.graph.problem import PosePrior

    G = nx.Graph()
    G.add_nodes_from(range(n))
    G.add_edges_from(zip(np.asarray(relative.i).tolist(), np.asarray(relative.j).tolist(), strict=True))
    out = []
    for comp in nx.connected_components(G):
        k = min(comp)
        if 0 in comp or k >= len(stored):
            continue
        s = stored[k]
        cov = np.diag(np.square(ORPHAN_SIGMAS)) if s.cov_wTa is None else np.asarray(s.cov_wTa) + np.eye(3) * 1e-9
        out.append(PosePrior(k, np.asarray(s.wTa, np.float64), cov))
    return tuple(out)


def solve_joint(jg: JointGraph, method: str = "batch", covariances: bool = True) -> JointSolution:
    """Solve the joint problem (batch Levenberg-Marquardt or iSAM2 over the whole graph; the run's kernels and
    chi-square rounds; no moved-object splitting: placements are decided before, ``holoslam.lifelong.changes``).
    When GTSAM finds the solved system too poorly conditioned for marginal covariances (an anchor held only by
    down-weighted closures), the solve is kept without them (``covariances_failed`` says why; covariances None)."""
    import dataclasses

    from holoslam.choices import Method
    from holoslam.errors import SolverError
    from holoslam.optimise import run_build_options
    from holoslam.solve import CovarianceScope, SolveOptions, solve

    t0 = time.perf_counter()
    opts = SolveOptions(method=Method(method), reject_outliers=True, detect_moved=False,
                        covariances=CovarianceScope.ALL if covariances else CovarianceScope.NONE,
                        build=dataclasses.replace(run_build_options(), robust_kinds=("loop", "cross")))
    failed = ""
    try:
        sol = solve(jg.problem, opts)
    except SolverError as e:
        if "marginal covariances failed" not in str(e):
            raise
        failed = str(e).split("\n")[0].strip() + " " + " ".join(str(e).split("\n")[1:3]).strip()
        sol = solve(jg.problem, dataclasses.replace(opts, covariances=CovarianceScope.NONE))
    M = len(jg.stored_ids)
    cov = sol.cov_wTa
    placements = {name: (sol.w_landmarks[k], None if sol.cov_w_landmarks is None else sol.cov_w_landmarks[k])
                  for k, name in enumerate(sol.landmark_ids)}
    K = jg.new_count
    return JointSolution(sol.wTa[:M], None if cov is None else cov[:M], sol.wTa[M:M + K],
                         None if cov is None else cov[M:M + K],
                         placements, time.perf_counter() - t0, int(sol.iterations), str(method), len(sol.rejected),
                         failed)
