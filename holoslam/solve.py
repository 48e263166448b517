"""The only place that runs optimisers: batch Levenberg-Marquardt, incremental iSAM2 (anchor by anchor),
initialisation (problem guess, odometry chain, LAGO, incremental), outlier rejection, moved-object detection and
marginal covariances. Results come back as numpy arrays in plain frozen records.

Outlier scheme (``solve``): (1) optimise with robust kernels on loop closures, landmark sightings and compass
headings (DCS / Cauchy by default); (2) chi-square test each robust-family measurement's Mahalanobis residual at
that solution (the kernels kept the outliers from bending it, so the residual is close to "the measurement
against a solution without it"; a sighting of an object with exactly two active sightings is kept: a pair has no
majority); (3) sightings of one object that split in time into two clusters, each
self-consistent and significantly apart, are a *moved object*: the earlier cluster becomes a second landmark
variable ``"<id>@before"`` and the object is reported with both positions; (4) re-solve without the rejected
measurements, repeat until nothing changes; (5) a last solve with plain Gaussian noise on the accepted
measurements gives the final estimate and honest marginal covariances.

Initialisation (``SolveOptions.initialisation``): the problem's guess, the odometry chain, LAGO, an incremental
iSAM2 pass, or ``AUTO``, which solves from each of ``SolveOptions.auto_candidates`` and keeps the lowest final
error (``Solution.candidates`` lists every start's final error, ``Solution.initialisation`` the winner). No single
start reaches the global optimum everywhere: on MITb LM from the guess, the odometry chain or LAGO stops at
E 385.12 while the incremental start reaches 20.60; on CSAIL all four agree. AUTO costs the sum of its candidates.

``Method.ISAM2`` feeds the graph anchor by anchor (QR factorisation by default: Cholesky throws on the strongly
anisotropic scan-match information of CSAIL / MITb / FR079); ``isam2_final_lm_iterations`` polishes the
incremental estimate with a few batch LM iterations (on Victoria Park, 2 of them land on the batch optimum).
Its outlier rounds (steps 2-5) run on the same iSAM2 object (``_Isam2Session``): rejected measurements' factors
are removed, re-admitted ones added back, a moved object's earlier sightings move to a new landmark variable and
the final Gaussian solve swaps each robust factor for its Gaussian twin, each change one iSAM2 update followed by
relinearising updates until no step exceeds ``isam2_relinearize_threshold``; no batch LM runs (but the polish).
With a threshold of 1e-3 the answer is batch LM's to ~1e-6 m on the household log; gtsam's default 0.1 leaves it
millimetres off, which can flip a chi-square decision.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import GraphError, SolverError
from holoslam.graph.build import FAMILY_CODES, BuildOptions, BuiltGraph, build_graph, initial_values
from holoslam.graph.keys import MAGNETIC_KEY, anchor_key, landmark_key
from holoslam.graph.problem import (
    MeasurementFamily,
    MeasurementRef,
    SlamProblem,
    default_prior,
    odometry_chain,
)

__all__ = [
    "Method",
    "Initialisation",
    "Factorization",
    "CovarianceScope",
    "SolveOptions",
    "MovedObject",
    "Solution",
    "IterationHook",
    "solve",
    "G2oSolveSummary",
    "solve_g2o_file",
]

IterationHook = Callable[[int, float, float], None]
"""Called after each optimiser iteration (LM) or update (iSAM2) with (iteration, error_before, error_after)."""

_REL, _HEAD, _LM = (
    FAMILY_CODES[f]
    for f in (MeasurementFamily.RELATIVE, MeasurementFamily.HEADING, MeasurementFamily.LANDMARK)
)
_DOF = {_REL: 3, _HEAD: 1, _LM: 2}


class Method(str, Enum):
    BATCH = "batch"  # Levenberg-Marquardt over the whole graph
    ISAM2 = "isam2"  # incremental, anchor by anchor


class Initialisation(str, Enum):
    PROBLEM = "problem"  # the problem's initial_wTa (g2o vertices / dead reckoning)
    ODOMETRY = "odometry"  # compose the relative measurements in order
    LAGO = "lago"  # gtsam.lago.initialize on the pose graph (diagonal part of each covariance)
    INCREMENTAL = "incremental"  # an iSAM2 pass, each new pose initialised from the current estimate
    AUTO = "auto"  # try the candidates of SolveOptions.auto_candidates, keep the lowest final error


class Factorization(str, Enum):
    QR = "qr"
    CHOLESKY = "cholesky"


class CovarianceScope(str, Enum):
    NONE = "none"
    ANCHORS = "anchors"
    LANDMARKS = "landmarks"
    ALL = "all"


@dataclass(frozen=True, slots=True)
class SolveOptions:
    method: Method = Method.BATCH
    initialisation: Initialisation = Initialisation.PROBLEM
    build: BuildOptions = BuildOptions()
    fix_first: bool = True  # add a tight prior on anchor 0 when the problem has none
    max_iterations: int = 100
    relative_error_tol: float = 1e-5
    absolute_error_tol: float = 1e-5
    isam2_factorization: Factorization = Factorization.QR
    isam2_relinearize_threshold: float = 0.1
    isam2_relinearize_skip: int = 10  # gtsam default; 2x faster than 1 on Victoria Park, same optimum
    isam2_extra_updates: int = 0  # updates without new factors after the last anchor (relinearise, converge)
    isam2_final_lm_iterations: int = 0  # Method.ISAM2: LM iterations that polish the iSAM2 estimate
    reject_outliers: bool = True
    chi2_probability: float = 0.9999  # a measurement is an outlier beyond this chi2 quantile of its dimension
    max_rounds: int = 4
    final_gaussian: bool = True
    detect_moved: bool = True
    min_moved_sightings: int = 2
    min_move_distance: float = 0.25  # m
    covariances: CovarianceScope = CovarianceScope.NONE
    covariance_anchors: tuple[int, ...] | None = None  # None: all anchors (when covariances asks for anchors)
    # Initialisation.AUTO: solve from each of these starts (a start equal to an earlier one, or that fails, is
    # skipped) and keep the solution with the lowest final error (ties: the earlier candidate)
    auto_candidates: tuple[Initialisation, ...] = (
        Initialisation.PROBLEM,
        Initialisation.ODOMETRY,
        Initialisation.LAGO,
        Initialisation.INCREMENTAL,
    )


@dataclass(frozen=True, eq=False)
class MovedObject:
    """An object whose sightings split in time: at ``w_position_before`` until anchor ``last_anchor_before``,
    at ``w_position_after`` from anchor ``first_anchor_after``."""

    object_id: str
    w_position_before: np.ndarray
    w_position_after: np.ndarray
    last_anchor_before: int
    first_anchor_after: int

    @property
    def distance(self) -> float:
        return float(np.hypot(*(self.w_position_after - self.w_position_before)))


@dataclass(frozen=True, eq=False)
class Solution:
    """The optimised anchors ``wTa`` (N, 3) and landmarks ``w_landmarks`` (L, 2) named by ``landmark_ids``
    (a moved object's earlier position is ``"<id>@before"``), their marginal covariances when asked for (NaN rows
    for anchors not asked for), solver statistics, the rejected measurements, moved objects, and the compass
    bias (yaw_compass - theta_true, radians; None without headings)."""

    wTa: np.ndarray
    cov_wTa: np.ndarray | None
    landmark_ids: tuple[str, ...]
    w_landmarks: np.ndarray
    cov_w_landmarks: np.ndarray | None
    iterations: int
    initial_error: float
    final_error: float
    rejected: tuple[MeasurementRef, ...] = ()
    moved_objects: tuple[MovedObject, ...] = ()
    compass_bias: float | None = None
    method: Method = Method.BATCH
    rounds: int = 1
    seconds: float = 0.0
    pose_ids: np.ndarray | None = None
    initialisation: Initialisation | None = None  # the start used (AUTO: the winning candidate)
    candidates: tuple[tuple[Initialisation, float], ...] = ()  # AUTO: (start, final error; nan = failed)

    def landmark(self, object_id: str) -> np.ndarray:
        try:
            return self.w_landmarks[self.landmark_ids.index(object_id)]
        except ValueError:
            raise GraphError(
                f"no landmark {object_id!r} in the solution; known: {self.landmark_ids}"
            ) from None


# ----------------------------------------------------------------------------------------------- optimisers


def _lm_params(options: SolveOptions, hook: IterationHook | None) -> Any:
    import gtsam

    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(options.max_iterations))
    params.setRelativeErrorTol(float(options.relative_error_tol))
    params.setAbsoluteErrorTol(float(options.absolute_error_tol))
    if hook is not None:
        params.iterationHook = hook
    return params


def _batch(
    graph: Any,
    values: Any,
    options: SolveOptions,
    hook: IterationHook | None,
    errors: list[float] | None = None,
) -> tuple[Any, int]:
    """LM to convergence; appends (initial error, final error) to ``errors`` when given (free: LM has them)."""
    import gtsam

    try:
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, _lm_params(options, hook))
        e0 = opt.error()
        result = opt.optimize()
    except RuntimeError as e:
        raise SolverError(
            f"Levenberg-Marquardt failed: {e}; check that every variable is constrained"
        ) from None
    if errors is not None:
        errors.extend((float(e0), float(opt.error())))
    return result, int(opt.iterations())


def _isam2(
    problem: SlamProblem, built: BuiltGraph, values: Any, options: SolveOptions, hook: IterationHook | None
) -> tuple[Any, int]:
    """Feed the graph anchor by anchor (see ``_isam2_feed``); returns the estimate and the number of updates."""
    isam, _slots, updates = _isam2_feed(problem, built, values, options, hook)
    return isam.calculateEstimate(), updates


def _isam2_params(options: SolveOptions) -> Any:
    import gtsam

    params = gtsam.ISAM2Params()
    params.setFactorization(
        "QR" if Factorization(options.isam2_factorization) is Factorization.QR else "CHOLESKY"
    )
    params.setRelinearizeThreshold(float(options.isam2_relinearize_threshold))
    params.relinearizeSkip = int(options.isam2_relinearize_skip)
    return params


def _isam2_feed(
    problem: SlamProblem, built: BuiltGraph, values: Any, options: SolveOptions, hook: IterationHook | None
) -> tuple[Any, np.ndarray, int]:
    """Feed the graph anchor by anchor (factors grouped by the latest anchor they involve); each new anchor is
    initialised from the current estimate composed with the first measurement that reaches it from an earlier
    anchor (else with the initial guess's step), each new landmark from its first sighting. Returns the iSAM2
    object, the iSAM2 factor index of each factor of ``built.graph`` and the number of updates."""
    import gtsam

    params = _isam2_params(options)
    params.evaluateNonlinearError = hook is not None
    isam = gtsam.ISAM2(params)
    slots = np.full(built.graph.size(), -1, dtype=np.int64)

    rel, lm = problem.relative, problem.landmarks
    init = problem.initial_wTa
    n = problem.num_poses
    order = np.argsort(built.stage, kind="stable")
    stages = built.stage[order]
    bounds = np.searchsorted(stages, np.arange(n + 1), side="left")
    # first measurement reaching each anchor from an earlier one: (earlier anchor, earlier->this pose)
    reach: dict[int, tuple[int, Any]] = {}
    rel_rows = built.index[built.family == _REL]
    for k in rel_rows.tolist():
        i, j = int(rel.i[k]), int(rel.j[k])
        if j > i and j not in reach:
            reach[j] = (i, gtsam.Pose2(*rel.iTj[k]))
        elif i > j and i not in reach:
            reach[i] = (j, gtsam.Pose2(*rel.iTj[k]).inverse())
    # anchors no measurement reaches from an earlier one take the initial guess's step
    steps = geo.between(init[:-1], init[1:]) if n > 1 else np.zeros((0, 3))
    var_seen: set[int] = set()
    magnetic_seen = False
    graph = built.graph
    updates = 0
    # poses are composed in gtsam (one Pose2 per anchor; numpy per-pose calls cost 0.1 ms each)
    prev = gtsam.Pose2(*init[0])  # the current estimate of anchor a - 1 (before the loop: anchor 0's guess)
    for a in range(n):
        new_factors = gtsam.NonlinearFactorGraph()
        new_values = gtsam.Values()
        if a in reach:
            i, iTa = reach[a]
            # the estimate of an older anchor than a - 1 comes from iSAM2
            wTi = prev if i == a - 1 else isam.calculateEstimatePose2(anchor_key(i))
            wTa = wTi.compose(iTa)
        elif a > 0:
            wTa = prev.compose(gtsam.Pose2(*steps[a - 1]))
        else:
            wTa = prev
        new_values.insert(anchor_key(a), pose2=wTa)
        fed = order[bounds[a] : bounds[a + 1]]
        for f in fed.tolist():
            new_factors.push_back(graph.at(f))
            for key in graph.at(f).keys():
                if key == MAGNETIC_KEY and not magnetic_seen:
                    new_values.insert(MAGNETIC_KEY, values.atPose2(MAGNETIC_KEY))
                    magnetic_seen = True
                elif (key >> 56) == ord("l") and key not in var_seen:
                    var_seen.add(key)
                    row = int(built.index[f])  # a sighting's stage is its anchor: lm.i[row] == a
                    new_values.insert(key, wTa.transformFrom(np.asarray(lm.a_position[row], dtype=float)))
        try:
            result = isam.update(new_factors, new_values)
        except RuntimeError as e:
            raise SolverError(
                f"iSAM2 failed at anchor {a}: {e}; try Factorization.QR or a batch solve"
            ) from None
        slots[fed] = np.asarray(result.getNewFactorsIndices(), dtype=np.int64)
        updates += 1
        if hook is not None:
            hook(updates, float(result.getErrorBefore()), float(result.getErrorAfter()))
        if a + 1 < n:
            prev = isam.calculateEstimatePose2(anchor_key(a))
    for _ in range(max(0, int(options.isam2_extra_updates))):
        isam.update()
        updates += 1
    return isam, slots, updates


class _Isam2Session:
    """``Method.ISAM2``'s outlier rounds on the one iSAM2 object the anchor-by-anchor feed built: a round removes
    the factors of rejected measurements and adds those of re-admitted ones (``removeFactorIndices`` of the same
    update), a moved object's earlier sightings are re-added on a new landmark variable, and the final Gaussian
    solve swaps each robust factor for its plain Gaussian twin. iSAM2 drops a variable left without factors and
    gets a fresh initial value when one comes back. After each change, updates with forced relinearisation run
    until no variable's linear step exceeds ``isam2_relinearize_threshold`` (or ``max_iterations`` updates).

    Only the measurement families the outlier scheme tests change: robust-kind relative poses, headings,
    sightings; the prior, the magnetic frame's prior and the Gaussian relative poses stay as fed."""

    def __init__(
        self,
        problem: SlamProblem,
        built: BuiltGraph,
        isam: Any,
        slots: np.ndarray,
        labels: tuple[str, ...],
        robust_rel_rows: np.ndarray,
        opts_build: BuildOptions,
        options: SolveOptions,
        hook: IterationHook | None,
        updates: int = 0,
    ) -> None:
        self.problem, self.isam, self.options, self.hook = problem, isam, options, hook
        self.updates = updates  # iSAM2 updates so far (the feed's): the hook's iteration numbers go on
        self.robust_rel = np.zeros(len(problem.relative), bool)
        self.robust_rel[robust_rel_rows] = True
        self.var_of = {name: v for v, name in enumerate(built.landmark_names)}  # stable landmark variables
        self.live: dict[tuple[int, int], tuple[int, str | None, Any]] = {}
        for f in range(built.graph.size()):
            fam, row = int(built.family[f]), int(built.index[f])
            if fam == _HEAD or fam == _LM or (fam == _REL and self.robust_rel[row]):
                self.live[(fam, row)] = (int(slots[f]), self._label(fam, row, labels), self._kernel(fam, opts_build))

    @staticmethod
    def _label(fam: int, row: int, labels: tuple[str, ...]) -> str | None:
        return labels[row] if fam == _LM else None

    @staticmethod
    def _kernel(fam: int, opts: BuildOptions) -> Any:
        return {_REL: opts.loop_kernel, _HEAD: opts.heading_kernel, _LM: opts.landmark_kernel}[fam]

    def _factors(self, fam: int, rows: np.ndarray, labels: tuple[str, ...], opts: BuildOptions) -> Any:
        from holoslam.graph import factors as fac
        from holoslam.graph.keys import anchor_keys

        p = self.problem
        if fam == _REL:
            rel = p.relative
            return fac.between_factors(
                anchor_keys(rel.i[rows]), anchor_keys(rel.j[rows]), rel.iTj[rows], rel.cov_iTj[rows],
                opts.loop_kernel,
            )
        if fam == _HEAD:
            hd = p.headings
            return fac.heading_factors(
                anchor_keys(hd.i[rows]), hd.yaw[rows], hd.sigma[rows], MAGNETIC_KEY, opts.heading_kernel,
                opts.heading_xy_sigma,
            )
        lm = p.landmarks
        keys = np.array([landmark_key(self.var_of[labels[k]]) for k in rows.tolist()], dtype=np.uint64)
        return fac.landmark_factors(
            anchor_keys(lm.i[rows]), keys, lm.a_position[rows], lm.cov_a_position[rows], opts.landmark_kernel
        )

    def apply(
        self,
        opts: BuildOptions,
        masks: dict[int, np.ndarray],
        labels: tuple[str, ...],
        wTa: np.ndarray,
    ) -> int:
        """Make the iSAM2 graph hold exactly the active measurements with ``opts``' kernels and ``labels``, then
        converge; returns the number of updates."""
        import gtsam

        from holoslam.graph.build import robust_landmark_guess

        want: dict[tuple[int, int], tuple[str | None, Any]] = {}
        for fam, mask in masks.items():
            rows = np.flatnonzero(mask & self.robust_rel) if fam == _REL else np.flatnonzero(mask)
            kernel = self._kernel(fam, opts)
            for row in rows.tolist():
                want[(fam, row)] = (self._label(fam, row, labels), kernel)
        remove = [key for key, (_slot, lab, ker) in self.live.items() if want.get(key) != (lab, ker)]
        add = [key for key, w in want.items() if key not in self.live or self.live[key][1:] != w]
        removed_slots = [self.live.pop(key)[0] for key in remove]
        graph = gtsam.NonlinearFactorGraph()
        order: list[tuple[int, int]] = []
        for fam in (_REL, _HEAD, _LM):
            rows = np.array(sorted(r for f, r in add if f == fam), dtype=np.int64)
            if rows.size == 0:
                continue
            if fam == _LM:
                for name in dict.fromkeys(labels[k] for k in rows.tolist()):
                    self.var_of.setdefault(name, len(self.var_of))
            graph.push_back(self._factors(fam, rows, labels, opts))
            order += [(fam, int(r)) for r in rows.tolist()]
        values = gtsam.Values()
        new_names = {
            labels[r]
            for f, r in order
            if f == _LM and not self.isam.valueExists(landmark_key(self.var_of[labels[r]]))
        }
        if new_names:
            lm_rows = np.array([r for (f, r) in want if f == _LM], dtype=np.int64)
            guess = robust_landmark_guess(self.problem, wTa, lm_rows, labels, new_names)
            for name in sorted(new_names):
                values.insert(landmark_key(self.var_of[name]), np.asarray(guess[name], dtype=float))
        if graph.size() == 0 and not removed_slots:
            return 0
        before = self.updates
        result = self._update(graph, values, removed_slots)
        for key, slot in zip(order, result.getNewFactorsIndices(), strict=True):
            self.live[key] = (int(slot), *want[key])
        self.converge()
        return self.updates - before

    def converge(self) -> int:
        """Updates with forced relinearisation until no variable's step exceeds the relinearisation threshold
        (at most ``max_iterations``); returns how many ran."""
        before = self.updates
        for _ in range(max(1, int(self.options.max_iterations))):
            if self._update(force=True).getVariablesRelinearized() == 0:
                break
        return self.updates - before

    def _update(self, graph: Any = None, values: Any = None, remove: list[int] | None = None, force: bool = False):
        import gtsam

        try:
            result = self.isam.update(
                gtsam.NonlinearFactorGraph() if graph is None else graph,
                gtsam.Values() if values is None else values,
                remove or [],
                force_relinearize=force,
            )
        except RuntimeError as e:
            raise SolverError(f"iSAM2 failed in an outlier round: {e}; try a batch solve") from None
        self.updates += 1
        if self.hook is not None:
            self.hook(self.updates, float(result.getErrorBefore()), float(result.getErrorAfter()))
        return result

    def estimate(self) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, float | None]:
        """Anchors, the landmark names that have a variable and their positions, the magnetic frame's angle."""
        import gtsam

        values = self.isam.calculateEstimate()
        poses = gtsam.utilities.extractPose2(values)  # in key order: m0 (if any) < x0 < x1 < ...
        magnetic = values.exists(MAGNETIC_KEY)
        wTa = np.array(poses[1:] if magnetic else poses, dtype=float).reshape(-1, 3)
        names = tuple(name for name, v in self.var_of.items() if values.exists(landmark_key(v)))
        w_lm = np.array([values.atPoint2(landmark_key(self.var_of[m])) for m in names], dtype=float).reshape(-1, 2)
        theta_m = values.atPose2(MAGNETIC_KEY).theta() if magnetic else None
        return wTa, names, w_lm, theta_m


def _lago(problem: SlamProblem, built: BuiltGraph) -> np.ndarray:
    """LAGO on the relative measurements (diagonal part of each covariance), aligned to the initial anchor 0."""
    import gtsam

    from holoslam.graph.factors import between_factors, prior_factors
    from holoslam.graph.keys import anchor_keys

    rel = problem.relative
    rows = built.index[built.family == _REL]
    covd = np.zeros((rows.size, 3, 3))
    d = np.einsum("kii->ki", rel.cov_iTj[rows])
    covd[:, [0, 1, 2], [0, 1, 2]] = d
    g = between_factors(anchor_keys(rel.i[rows]), anchor_keys(rel.j[rows]), rel.iTj[rows], covd)
    g.push_back(prior_factors(anchor_keys(np.array([0])), np.zeros(3), np.diag([1e-8, 1e-8, 1e-10])))
    try:
        v = gtsam.lago.initialize(g)
    except (RuntimeError, IndexError) as e:  # IndexError: gtsam's map::at on some graphs (ais2klinik)
        raise SolverError(f"LAGO initialisation failed: {type(e).__name__}: {e}") from None
    wTa = np.array(problem.initial_wTa, dtype=float)
    for a in range(problem.num_poses):
        k = anchor_key(a)
        if v.exists(k):
            p = v.atPose2(k)
            wTa[a] = (p.x(), p.y(), p.theta())
    align = geo.compose(problem.initial_wTa[0], geo.inverse(wTa[0]))
    return geo.compose(align, wTa)


# ------------------------------------------------------------------------------------------- extraction


def _extract(
    values: Any, problem: SlamProblem, built: BuiltGraph
) -> tuple[np.ndarray, np.ndarray, float | None]:
    import gtsam

    poses = gtsam.utilities.extractPose2(values)  # every Pose2 in key order: m0 (if any) < x0 < x1 < ...
    wTa = np.array(poses[1:] if built.has_magnetic else poses, dtype=float).reshape(-1, 3)
    if wTa.shape[0] != problem.num_poses:
        raise SolverError(f"the solution has {wTa.shape[0]} anchor poses, expected {problem.num_poses}")
    w_lm = np.array(
        [values.atPoint2(landmark_key(v)) for v in range(len(built.landmark_names))], dtype=float
    ).reshape(-1, 2)
    theta_m = values.atPose2(MAGNETIC_KEY).theta() if built.has_magnetic else None
    return wTa, w_lm, theta_m


# ------------------------------------------------------------------------------------ outliers and moves


def _residuals(
    problem: SlamProblem,
    wTa: np.ndarray,
    w_lm: np.ndarray,
    names: tuple[str, ...],
    theta_m: float | None,
    labels: tuple[str, ...],
    rows_by_family: dict[int, np.ndarray],
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Mahalanobis squared residual of the given measurement rows at a solution: {family: (rows, d2)}.
    A sighting whose landmark variable is not in ``names`` gets an infinite residual."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    rel = problem.relative
    rows = rows_by_family.get(_REL, np.zeros(0, np.int64))
    if rows.size:
        pred = geo.between(wTa[rel.i[rows]], wTa[rel.j[rows]])
        r = geo.between(rel.iTj[rows], pred)
        out[_REL] = (rows, np.einsum("ki,kij,kj->k", r, np.linalg.inv(rel.cov_iTj[rows]), r))
    hd = problem.headings
    rows = rows_by_family.get(_HEAD, np.zeros(0, np.int64))
    if rows.size and theta_m is not None:
        r = geo.wrap(wTa[hd.i[rows], 2] - theta_m - hd.yaw[rows])
        out[_HEAD] = (rows, np.square(r / hd.sigma[rows]))
    lm = problem.landmarks
    rows = rows_by_family.get(_LM, np.zeros(0, np.int64))
    if rows.size:
        var_of = {n: k for k, n in enumerate(names)}
        v = np.array([var_of.get(labels[k], -1) for k in rows.tolist()])
        wl = np.where((v >= 0)[:, None], w_lm[np.maximum(v, 0)] if len(names) else 0.0, 0.0)
        pred = geo.transform_points(geo.inverse(wTa[lm.i[rows]]), wl)
        r = pred - lm.a_position[rows]
        d2 = np.einsum("ki,kij,kj->k", r, np.linalg.inv(lm.cov_a_position[rows]), r)
        out[_LM] = (rows, np.where(v >= 0, d2, np.inf))
    return out


def chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square quantile for 1, 2 or 3 degrees of freedom (closed-form CDFs, bisection)."""
    if dof == 2:
        return -2.0 * math.log1p(-probability)

    def cdf(x: float) -> float:
        e = math.erf(math.sqrt(x / 2.0))
        return e if dof == 1 else e - math.sqrt(2.0 * x / math.pi) * math.exp(-x / 2.0)

    if dof not in (1, 3):
        raise ValueError(f"chi2_quantile supports 1-3 degrees of freedom, not {dof}")
    lo, hi = 0.0, 200.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < probability else (lo, mid)
    return 0.5 * (lo + hi)


def _world_sightings(
    problem: SlamProblem, wTa: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    lm = problem.landmarks
    T = wTa[lm.i[rows]]
    p = np.stack([geo.transform_points(T[k], lm.a_position[rows[k]][None])[0] for k in range(rows.size)])
    R = geo.rot2(T[:, 2])
    cov = R @ lm.cov_a_position[rows] @ np.swapaxes(R, 1, 2)
    return p, cov


def _cluster(p: np.ndarray, cov: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of points and the per-point chi2 inlier mask (one refit without outliers)."""
    info = np.linalg.inv(cov)
    mask = np.ones(p.shape[0], bool)
    mean = np.zeros(2)
    for _ in range(2):
        I = info[mask].sum(0)
        mean = np.linalg.solve(I, np.einsum("kij,kj->i", info[mask], p[mask]))
        r = p - mean
        mask_new = np.einsum("ki,kij,kj->k", r, info, r) <= thr
        if mask_new.sum() < 1 or np.array_equal(mask_new, mask):
            break
        mask = mask_new
    return mean, mask


def _in_pairs(labels: tuple[str, ...], active: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Which of the sighting ``rows`` belong to a landmark with exactly two active sightings. Such a pair that
    disagrees has no majority: rejecting either one is a coin toss (on sim/s11/x2 it kept the sighting 9 cm off
    and dropped the one 2 cm off), so both stay and the landmark sits at their information-weighted mean. Pairs
    far apart do not get here: the front end leaves out objects whose sightings all disagree."""
    lab = np.asarray(labels)
    names, counts = np.unique(lab[active], return_counts=True)
    return np.isin(lab[rows], names[counts == 2])


def _detect_moved(
    problem: SlamProblem,
    wTa: np.ndarray,
    w_lm: np.ndarray,
    names: tuple[str, ...],
    labels: tuple[str, ...],
    active: np.ndarray,
    options: SolveOptions,
    thr: float,
) -> list[tuple[str, np.ndarray, bool, np.ndarray]]:
    """Objects whose rejected sightings form their own place: at least ``min_moved_sightings`` rejected sightings
    of one id that agree with each other (chi2), lie ``min_move_distance`` or more from the id's estimate, and
    are all later (or all earlier) than every accepted sighting of that id. Returns (object id, the cluster's
    rows, whether the cluster is the later one, its mean world position)."""
    lm = problem.landmarks
    var_of = {n: k for k, n in enumerate(names)}
    found = []
    out_rows: dict[str, list[int]] = {}
    for k in np.flatnonzero(~active).tolist():
        out_rows.setdefault(labels[k], []).append(k)
    m = max(1, options.min_moved_sightings)
    for name, rows_l in out_rows.items():
        if len(rows_l) < m or "@" in name or name not in var_of:
            continue
        rows_in = np.array([k for k in range(len(lm)) if active[k] and labels[k] == name])
        if rows_in.size == 0:
            continue
        rows = np.array(rows_l)
        p, cov = _world_sightings(problem, wTa, rows)
        mean, inl = _cluster(p, cov, thr)
        cluster = rows[inl]
        if cluster.size < m or np.hypot(*(mean - w_lm[var_of[name]])) < options.min_move_distance:
            continue
        a_c, a_in = lm.i[cluster], lm.i[rows_in]
        if a_c.min() > a_in.max():
            found.append((name, cluster, True, mean))
        elif a_c.max() < a_in.min():
            found.append((name, cluster, False, mean))
    return found


# ---------------------------------------------------------------------------------------------- solve


def _with_gauge(problem: SlamProblem, options: SolveOptions) -> SlamProblem:
    if problem.priors or not options.fix_first:
        return problem
    return replace(problem, priors=(default_prior(0, problem.initial_wTa[0]),))


def _initial_wTa(problem: SlamProblem, built: BuiltGraph, options: SolveOptions) -> np.ndarray:
    init = Initialisation(options.initialisation)
    if init is Initialisation.ODOMETRY:
        return odometry_chain(problem.num_poses, problem.relative)
    if init is Initialisation.LAGO:
        return _lago(problem, built)
    return problem.initial_wTa


def solve(
    problem: SlamProblem, options: SolveOptions = SolveOptions(), iteration_hook: IterationHook | None = None
) -> Solution:
    """Optimise a SLAM problem (see the module docstring for the outlier scheme). With
    ``Initialisation.AUTO`` the whole solve runs from each candidate start and the lowest final error wins."""
    if Initialisation(options.initialisation) is Initialisation.AUTO:
        return _solve_auto(problem, options, iteration_hook)
    t0 = time.perf_counter()
    problem = _with_gauge(problem, options)
    method = Method(options.method)
    lm = problem.landmarks
    rmask = np.ones(len(problem.relative), bool)
    hmask = np.ones(len(problem.headings), bool)
    lmask = np.ones(len(lm), bool)
    labels = lm.landmark
    robust_build = options.build
    robust_any = options.reject_outliers and (
        np.isin(problem.relative.kind.astype(str), list(robust_build.robust_kinds)).any()
        or len(problem.headings) > 0
        or len(lm) > 0
    )

    built = build_graph(
        problem, robust_build if robust_any else robust_build.without_kernels(), rmask, hmask, lmask, labels
    )
    wTa0 = _initial_wTa(problem, built, options)
    values = initial_values(problem, built, wTa0, landmark_labels=labels)
    errs: list[float] = []  # (initial, final) of each LM run
    initial_error: float | None = None
    if Initialisation(options.initialisation) is Initialisation.INCREMENTAL or method is Method.ISAM2:
        initial_error = float(built.graph.error(values))
    if Initialisation(options.initialisation) is Initialisation.INCREMENTAL and method is Method.BATCH:
        values, it0 = _isam2(problem, built, values, options, None)
    else:
        it0 = 0
    robust_rel = np.flatnonzero(np.isin(problem.relative.kind.astype(str), list(robust_build.robust_kinds)))
    polish = replace(options, max_iterations=int(options.isam2_final_lm_iterations))
    session: _Isam2Session | None = None  # Method.ISAM2 with outlier rounds: they run on the same iSAM2 object
    if method is Method.ISAM2:
        isam, slots, iterations = _isam2_feed(problem, built, values, options, iteration_hook)
        values = isam.calculateEstimate()
        if robust_any:
            session = _Isam2Session(
                problem, built, isam, slots, labels, robust_rel, robust_build, options, iteration_hook, iterations
            )
            iterations += session.converge()  # the outlier tests need the converged estimate, as after LM
            values = isam.calculateEstimate()
        elif options.isam2_final_lm_iterations > 0:
            values, it_lm = _batch(built.graph, values, polish, iteration_hook, errs)
            iterations += it_lm
    else:
        values, iterations = _batch(built.graph, values, options, iteration_hook, errs)
        if initial_error is None:
            initial_error = errs[0]
    iterations += it0
    wTa, w_lm, theta_m = _extract(values, problem, built)
    names = built.landmark_names  # the landmark variables of the current estimate (rows of w_lm)

    moved: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
    rounds = 1
    if robust_any:
        thr = {fam: chi2_quantile(options.chi2_probability, dof) for fam, dof in _DOF.items()}
        masks = {_REL: rmask, _HEAD: hmask, _LM: lmask}
        tested = {_REL: robust_rel, _HEAD: np.arange(len(problem.headings)), _LM: np.arange(len(lm))}
        final_build = robust_build

        def residuals(active: bool) -> dict[int, tuple[np.ndarray, np.ndarray]]:
            rows = {f: r[masks[f][r] == active] for f, r in tested.items()}
            return _residuals(problem, wTa, w_lm, names, theta_m, labels, rows)

        def resolve(opts_build: BuildOptions) -> None:
            """Re-solve with the current masks, labels and ``opts_build``'s kernels: batch LM from the current
            estimate, or (Method.ISAM2) the iSAM2 session's factor swaps."""
            nonlocal built, values, iterations, wTa, w_lm, theta_m, names, final_build
            final_build = opts_build
            if session is not None:
                iterations += session.apply(opts_build, masks, labels, wTa)
                wTa, names, w_lm, theta_m = session.estimate()
                return
            w_prev = dict(zip(names, w_lm, strict=True))
            built = build_graph(problem, opts_build, rmask, hmask, lmask, labels, theta_m or 0.0)
            values = initial_values(problem, built, wTa, w_prev, theta_m, landmark_labels=labels)
            values, it = _batch(built.graph, values, options, iteration_hook, errs)
            iterations += it
            wTa, w_lm, theta_m = _extract(values, problem, built)
            names = built.landmark_names

        for _ in range(options.max_rounds):
            res = residuals(True)
            changed = False
            for fam, (rows, d2) in res.items():
                bad = rows[d2 > thr[fam]]
                if fam == _LM and bad.size:
                    bad = bad[~_in_pairs(labels, lmask, bad)]
                if bad.size:
                    masks[fam][bad] = False
                    changed = True
            if not changed and options.detect_moved and len(lm):
                for name, cluster, later, _mean in _detect_moved(
                    problem, wTa, w_lm, names, labels, lmask, options, thr[_LM]
                ):
                    if name in moved:
                        continue
                    same = [k for k in range(len(lm)) if labels[k] == name and lmask[k]]
                    before = np.array(same) if later else cluster
                    after = cluster if later else np.array(same)
                    moved[name] = (before, after, np.zeros(2), np.zeros(2))
                    before_set = set(before.tolist())
                    # the earlier place becomes "<id>@before": the id keeps naming where the object is now
                    labels = tuple(
                        f"{name}@before" if k in before_set else lab for k, lab in enumerate(labels)
                    )
                    lmask[cluster] = True
                    changed = True
            if not changed:
                break
            rounds += 1
            resolve(robust_build)
        if options.final_gaussian:
            resolve(robust_build.without_kernels())
            rounds += 1
            # re-admit what the Gaussian solution explains (a rejection made against a kernel-biased estimate)
            readmit = False
            for fam, (rows, d2) in residuals(False).items():
                ok = rows[d2 <= thr[fam]]
                if ok.size:
                    masks[fam][ok] = True
                    readmit = True
            if readmit:
                resolve(robust_build.without_kernels())
                rounds += 1
        if session is not None:
            # the final graph as the batch path builds it (its landmark numbering), at the iSAM2 estimate: its
            # error, marginals and the optional LM polish
            w_prev = dict(zip(names, w_lm, strict=True))
            built = build_graph(problem, final_build, rmask, hmask, lmask, labels, theta_m or 0.0)
            values = initial_values(problem, built, wTa, w_prev, theta_m, landmark_labels=labels)
            if options.isam2_final_lm_iterations > 0:
                values, it_lm = _batch(built.graph, values, polish, iteration_hook, errs)
                iterations += it_lm
            wTa, w_lm, theta_m = _extract(values, problem, built)
    final_error = errs[-1] if method is Method.BATCH and errs else float(built.graph.error(values))

    cov_wTa, cov_lm = _marginals(built, values, problem, options, len(built.landmark_names))
    rejected = tuple(
        [MeasurementRef(MeasurementFamily.RELATIVE, int(k)) for k in np.flatnonzero(~rmask)]
        + [MeasurementRef(MeasurementFamily.HEADING, int(k)) for k in np.flatnonzero(~hmask)]
        + [MeasurementRef(MeasurementFamily.LANDMARK, int(k)) for k in np.flatnonzero(~lmask)]
    )
    var_of = {n: k for k, n in enumerate(built.landmark_names)}
    moved_objects = tuple(
        MovedObject(
            name,
            w_lm[var_of[f"{name}@before"]] if f"{name}@before" in var_of else ma,
            w_lm[var_of[name]] if name in var_of else mb,
            int(lm.i[before].max()),
            int(lm.i[after].min()),
        )
        for name, (before, after, ma, mb) in moved.items()
    )
    return Solution(
        wTa=wTa,
        cov_wTa=cov_wTa,
        landmark_ids=built.landmark_names,
        w_landmarks=w_lm,
        cov_w_landmarks=cov_lm,
        iterations=iterations,
        initial_error=initial_error,
        final_error=final_error,
        rejected=rejected,
        moved_objects=moved_objects,
        compass_bias=None if theta_m is None else float(geo.wrap(-theta_m)),
        method=method,
        rounds=rounds,
        seconds=time.perf_counter() - t0,
        pose_ids=problem.pose_ids,
        initialisation=Initialisation(options.initialisation),
    )


def _solve_auto(problem: SlamProblem, options: SolveOptions, hook: IterationHook | None) -> Solution:
    """Initialisation.AUTO: the global optimum is not guaranteed from any single start (SPEC §7: MITb needs the
    incremental start, Victoria Park too, LAGO helps city10000), so solve from each candidate and keep the lowest
    final error. A candidate whose start equals an earlier one (the odometry chain of a file without vertices is
    its initial guess) is not solved twice; one that fails (LAGO on a graph it cannot handle) is skipped. LAGO is
    not run when an earlier start already satisfies every relative measurement with anchor 0 where LAGO puts it
    (a pose graph without loops, e.g. the odometry tree of Victoria Park or cityTrees10000): LAGO's least squares
    would return that same start."""
    t0 = time.perf_counter()
    best: Solution | None = None
    tried: list[tuple[Initialisation, float]] = []
    starts: list[np.ndarray] = []
    errors: list[str] = []
    rel = problem.relative

    def exact(wTa: np.ndarray, tol: float = 1e-6) -> bool:
        """Does ``wTa`` satisfy every relative measurement (m, rad)? Then it is LAGO's zero-cost solution."""
        d = geo.between(geo.between(wTa[rel.i], wTa[rel.j]), rel.iTj)
        return bool(np.all(np.abs(d[:, :2]) <= tol) and np.all(np.abs(geo.wrap(d[:, 2])) <= tol))

    for cand in dict.fromkeys(Initialisation(c) for c in options.auto_candidates):
        if cand is Initialisation.AUTO:
            continue
        if cand is Initialisation.LAGO and any(
            np.allclose(s[0], problem.initial_wTa[0], rtol=0.0, atol=1e-9) and exact(s) for s in starts
        ):
            continue
        if cand in (Initialisation.PROBLEM, Initialisation.ODOMETRY):
            start = problem.initial_wTa if cand is Initialisation.PROBLEM else None
            if start is None:
                start = odometry_chain(problem.num_poses, problem.relative)
            if any(np.allclose(start, s, rtol=0.0, atol=1e-9) for s in starts):
                continue
            starts.append(start)
        try:
            sol = solve(problem, replace(options, initialisation=cand), hook)
        except (SolverError, GraphError) as e:
            tried.append((cand, float("nan")))
            errors.append(f"{cand.value}: {e}")
            continue
        tried.append((cand, sol.final_error))
        if best is None or sol.final_error < best.final_error * (1.0 - 1e-9):
            best = sol
    if best is None:
        raise SolverError("every initialisation failed: " + "; ".join(errors))
    return replace(best, seconds=time.perf_counter() - t0, candidates=tuple(tried))


def _marginals(
    built: BuiltGraph, values: Any, problem: SlamProblem, options: SolveOptions, n_landmarks: int
) -> tuple[np.ndarray | None, np.ndarray | None]:
    import gtsam

    scope = CovarianceScope(options.covariances)
    if scope is CovarianceScope.NONE:
        return None, None
    try:
        marg = gtsam.Marginals(built.graph, values)
    except RuntimeError as e:
        raise SolverError(f"marginal covariances failed: {e}") from None
    cov_wTa = cov_lm = None
    if scope in (CovarianceScope.ANCHORS, CovarianceScope.ALL):
        cov_wTa = np.full((problem.num_poses, 3, 3), np.nan)
        which = range(problem.num_poses) if options.covariance_anchors is None else options.covariance_anchors
        for a in which:
            cov_wTa[a] = marg.marginalCovariance(anchor_key(int(a)))
    if scope in (CovarianceScope.LANDMARKS, CovarianceScope.ALL):
        cov_lm = np.array([marg.marginalCovariance(landmark_key(v)) for v in range(n_landmarks)]).reshape(
            -1, 2, 2
        )
    return cov_wTa, cov_lm


# ------------------------------------------------------------------------------------------- g2o files


@dataclass(frozen=True, slots=True)
class G2oSolveSummary:
    """What ``solve_g2o_file`` did: sizes, iterations, errors, times (read / build+solve / write)."""

    in_path: str
    out_path: str | None
    num_poses: int
    num_landmarks: int
    num_factors: int
    iterations: int
    initial_error: float
    final_error: float
    seconds_read: float
    seconds_solve: float
    seconds_write: float
    skipped: tuple[str, ...] = field(default_factory=tuple)
    initialisation: str = "problem"  # the start used (with AUTO: the winner)
    candidates: tuple[tuple[str, float], ...] = ()  # AUTO: (start, final error; nan = failed)


def solve_g2o_file(
    in_path: str | Path,
    out_path: str | Path | None = None,
    method: Method = Method.BATCH,
    initialisation: Initialisation = Initialisation.PROBLEM,
    noise: Any = None,
    options: SolveOptions | None = None,
    iteration_hook: IterationHook | None = None,
) -> tuple[G2oSolveSummary, Solution]:
    """Read a 2D g2o / TORO / iSAM graph, optimise it with its first pose fixed (or the FIX vertices) and no robust
    kernels, and write the optimised graph as g2o (when ``out_path`` is given)."""
    from holoslam.graph.problem import problem_from_g2o
    from holoslam.io.g2o import G2oGraph, TextNoise, read_g2o, write_g2o

    t0 = time.perf_counter()
    g = read_g2o(in_path, noise=TextNoise.GTSAM_AUTO if noise is None else noise)
    problem = problem_from_g2o(g, fix_first=True)
    t1 = time.perf_counter()
    opts = options or SolveOptions(
        method=method,
        initialisation=initialisation,
        reject_outliers=False,
        detect_moved=False,
        final_gaussian=False,
        build=BuildOptions().without_kernels(),
    )
    sol = solve(problem, opts, iteration_hook)
    t2 = time.perf_counter()
    if out_path is not None:
        lm_ids = np.array([int(n) for n in sol.landmark_ids], dtype=np.int64)
        out = G2oGraph(
            vertex_ids=problem.pose_ids,
            vertex_poses=sol.wTa,
            point_ids=lm_ids,
            point_positions=sol.w_landmarks,
            edge_i=g.edge_i,
            edge_j=g.edge_j,
            edge_measured=g.edge_measured,
            edge_cov=g.edge_cov,
            landmark_pose=g.landmark_pose,
            landmark_id=g.landmark_id,
            landmark_measured=g.landmark_measured,
            landmark_cov=g.landmark_cov,
            fixed_ids=g.fixed_ids if g.fixed_ids.size else problem.pose_ids[:1],
        )
        write_g2o(out, out_path)
    t3 = time.perf_counter()
    nf = len(problem.relative) + len(problem.landmarks) + len(problem.priors)
    return (
        G2oSolveSummary(
            in_path=str(in_path),
            out_path=None if out_path is None else str(out_path),
            num_poses=problem.num_poses,
            num_landmarks=len(sol.landmark_ids),
            num_factors=nf,
            iterations=sol.iterations,
            initial_error=sol.initial_error,
            final_error=sol.final_error,
            seconds_read=t1 - t0,
            seconds_solve=t2 - t1,
            seconds_write=t3 - t2,
            skipped=tuple(f"{s.tag} x{s.count} (first at line {s.first_line})" for s in g.skipped),
            initialisation=(sol.initialisation or Initialisation(opts.initialisation)).value,
            candidates=tuple((c.value, e) for c, e in sol.candidates),
        ),
        sol,
    )
