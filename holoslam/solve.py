"""The only place that runs optimisers: batch Levenberg-Marquardt, incremental iSAM2 (anchor by anchor), the
robust rounds (outlier rejection, moved objects), several starts (``Initialisation.AUTO``) and marginal
covariances. Results come back as numpy arrays in plain frozen records.

Outlier scheme (``solve``), a loop over one plain solve (as gtsfm's ``run_iterative_robust_ba``): (1) optimise
with robust kernels on loop closures, landmark sightings and compass headings (DCS / Cauchy by default); (2)
chi-square test each robust-family measurement's Mahalanobis residual at that solution (the kernels kept the
outliers from bending it, so the residual is close to "the measurement against a solution without it"; a sighting
of an object with exactly two active sightings is kept: a pair has no majority); (3) sightings of one object that
split in time into two clusters, each self-consistent and significantly apart, are a *moved object*: the earlier
cluster becomes a second landmark variable ``"<id>@before"`` and the object is reported with both positions; (4)
re-solve without the rejected measurements, repeat until nothing changes; (5) a last solve with plain Gaussian
noise on the accepted measurements gives the final estimate and honest marginal covariances.

Initialisation (``SolveOptions.initialisation``): the problem's guess, the odometry chain, LAGO, the chordal start
(:mod:`holoslam.graph.initialise`), an incremental iSAM2 pass, or ``AUTO`` (:mod:`holoslam.graph.starts`): LM
from the chordal start, from the problem's guess only when that solution disagrees with the measurements (the
lower kept), the incremental start only when the kept solution still disagrees; ``Solution.starts`` says what each start reached and whether they agree.

``Method.ISAM2`` feeds the graph anchor by anchor (:mod:`holoslam.graph.isam2`); ``isam2_final_lm_iterations``
polishes the incremental estimate with a few batch LM iterations (on Victoria Park, 2 of them land on the batch
optimum). Its outlier rounds (steps 2-5) run on the same iSAM2 object (``Isam2Session``): rejected measurements'
factors are removed, re-admitted ones added back, a moved object's earlier sightings move to a new landmark
variable and the final Gaussian solve swaps each robust factor for its Gaussian twin; no batch LM runs (but the
polish).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import SolverError
from holoslam.graph.build import BuildOptions, BuiltGraph, build_graph, initial_values
from holoslam.graph.initialise import chordal, lago
from holoslam.graph.isam2 import Isam2Session, isam2_estimate, isam2_feed
from holoslam.graph.keys import MAGNETIC_KEY, anchor_key, before_id, landmark_key
from holoslam.graph.options import (
    DOF,
    HEAD,
    LMK,
    REL,
    CovarianceScope,
    Factorization,
    Initialisation,
    IterationHook,
    Method,
    SolveOptions,
)
from holoslam.graph.outliers import chi2_quantile, detect_moved, in_pairs, residuals
from holoslam.graph.problem import (
    MeasurementFamily,
    MeasurementRef,
    SlamProblem,
    default_prior,
    odometry_chain,
)
from holoslam.graph.solution import MovedObject, Solution, StartOutcome, StartsReport
from holoslam.graph.starts import Start, solve_from_starts

__all__ = [
    "Method",
    "Initialisation",
    "Factorization",
    "CovarianceScope",
    "SolveOptions",
    "MovedObject",
    "StartOutcome",
    "StartsReport",
    "Solution",
    "IterationHook",
    "solve",
    "chi2_quantile",
]


# ----------------------------------------------------------------------------------------------- optimiser


def _lm_params(options: SolveOptions) -> Any:
    import gtsam

    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(options.max_iterations))
    params.setRelativeErrorTol(float(options.relative_error_tol))
    params.setAbsoluteErrorTol(float(options.absolute_error_tol))
    return params


def _batch(
    graph: Any,
    values: Any,
    options: SolveOptions,
    hook: IterationHook | None,
    errors: list[float] | None = None,
    stop: Callable[[Any], bool] | None = None,
) -> tuple[Any, int]:
    """LM to convergence (gtsam's own loop and tests, iteration by iteration, so that ``stop`` can end it early);
    appends (initial error, final error) to ``errors`` when given (free: LM has them)."""
    import gtsam

    params = _lm_params(options)
    rel, abs_, tol = params.getRelativeErrorTol(), params.getAbsoluteErrorTol(), params.getErrorTol()
    try:
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
        e0 = new = opt.error()
        if e0 > tol and params.getMaxIterations() > 0:
            while True:
                current = new
                opt.iterate()
                new = opt.error()
                if hook is not None:
                    hook(int(opt.iterations()), float(current), float(new))
                if (
                    opt.iterations() >= params.getMaxIterations()
                    or gtsam.checkConvergence(rel, abs_, tol, current, new)
                    or not np.isfinite(current)
                    or (stop is not None and stop(opt))
                ):
                    break
    except RuntimeError as e:
        raise SolverError(
            f"Levenberg-Marquardt failed: {e}; check that every variable is constrained"
        ) from None
    if errors is not None:
        errors.extend((float(e0), float(new)))
    return opt.values(), int(opt.iterations())


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


class _Reaches:
    """A stop test: the LM iterate has reached ``reference`` (its error within LM's relative tolerance of the
    reference's, every pose within ``auto_agree_xy`` / ``auto_agree_theta``): from there LM converges to it.
    ``hit`` says whether it stopped LM."""

    def __init__(self, reference: Solution, problem: SlamProblem, built: BuiltGraph, options: SolveOptions):
        self.ref, self.problem, self.built, self.options = reference, problem, built, options
        self.tol = options.relative_error_tol * abs(reference.final_error) + options.absolute_error_tol
        self.hit = False

    def __call__(self, opt: Any) -> bool:
        ref, o = self.ref, self.options
        if abs(opt.error() - ref.final_error) > self.tol:
            return False
        wTa, w_lm, _ = _extract(opt.values(), self.problem, self.built)
        dxy = np.abs(wTa[:, :2] - ref.wTa[:, :2]).max(initial=0.0)
        if w_lm.shape == ref.w_landmarks.shape and w_lm.size:
            dxy = max(dxy, np.abs(w_lm - ref.w_landmarks).max())
        dth = np.abs(geo.wrap(wTa[:, 2] - ref.wTa[:, 2])).max(initial=0.0)
        self.hit = bool(dxy <= o.auto_agree_xy and dth <= o.auto_agree_theta)
        return self.hit


# ------------------------------------------------------------------------------------------ one plain solve


@dataclass(eq=False)
class _State:
    """One solve's current estimate and what is active in it; the robust rounds change it and re-solve."""

    problem: SlamProblem
    options: SolveOptions
    hook: IterationHook | None
    masks: dict[int, np.ndarray]  # REL / HEAD / LMK: which measurements are active
    labels: tuple[str, ...]  # each sighting's landmark variable name
    build: BuildOptions  # the kernels of the current graph
    built: BuiltGraph
    values: Any
    errs: list[float] = field(default_factory=list)  # (initial, final) of each LM run
    iterations: int = 0
    initial_error: float | None = None
    session: Isam2Session | None = None
    reached: bool = False  # the first LM stopped on reaching a reference solution
    wTa: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    w_lm: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    theta_m: float | None = None
    names: tuple[str, ...] = ()

    def extract(self) -> None:
        self.wTa, self.w_lm, self.theta_m = _extract(self.values, self.problem, self.built)
        self.names = (
            self.built.landmark_names
        )  # the landmark variables of the current estimate (rows of w_lm)

    def rebuild(self, build: BuildOptions) -> None:
        """The graph of the active measurements with ``build``'s kernels, valued at the current estimate."""
        self.build = build
        w_prev = dict(zip(self.names, self.w_lm, strict=True))
        m = self.masks
        self.built = build_graph(
            self.problem, build, m[REL], m[HEAD], m[LMK], self.labels, self.theta_m or 0.0
        )
        self.values = initial_values(
            self.problem, self.built, self.wTa, w_prev, self.theta_m, landmark_labels=self.labels
        )

    def resolve(self, build: BuildOptions) -> None:
        """Re-solve with the current masks and labels and ``build``'s kernels: batch LM from the current
        estimate, or (Method.ISAM2) the iSAM2 session's factor swaps."""
        if self.session is not None:
            self.build = build
            self.iterations += self.session.apply(build, self.masks, self.labels, self.wTa)
            self.wTa, self.names, self.w_lm, self.theta_m = self.session.estimate()
            return
        self.rebuild(build)
        self.values, it = _batch(self.built.graph, self.values, self.options, self.hook, self.errs)
        self.iterations += it
        self.extract()


def _with_gauge(problem: SlamProblem, options: SolveOptions) -> SlamProblem:
    if problem.priors or not options.fix_first:
        return problem
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    return replace(problem, priors=(default_prior(0, problem.initial_wTa[0]),))


def _robust_rows(problem: SlamProblem, build: BuildOptions) -> np.ndarray:
    return np.flatnonzero(np.isin(problem.relative.kind.astype(str), list(build.robust_kinds)))


def _start_values(state: _State, start: Start | None) -> Any:
    problem, built = state.problem, state.built
    init = Initialisation(state.options.initialisation)
    w_lm: dict[str, np.ndarray] | None = None
    if start is not None:
        wTa, w_lm = start
    elif init is Initialisation.ODOMETRY:
        wTa = odometry_chain(problem.num_poses, problem.relative)
    elif init is Initialisation.LAGO:
        wTa = lago(problem, built.index[built.family == REL])
    elif init is Initialisation.CHORDAL:
        wTa, w_lm = chordal(problem)
    else:
        assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
        wTa = problem.initial_wTa
    return initial_values(problem, built, wTa, w_lm, landmark_labels=state.labels)


def _first_solve(state: _State, robust: bool, start: Start | None, reference: Solution | None) -> None:
    """Build the graph, make the start, and optimise: LM (after an iSAM2 pass for the incremental start), or the
    anchor-by-anchor iSAM2 feed (then the session that the robust rounds continue on)."""
    problem, options, hook = state.problem, state.options, state.hook
    method = Method(options.method)
    state.values = _start_values(state, start)
    incremental = Initialisation(options.initialisation) is Initialisation.INCREMENTAL
    if incremental or method is Method.ISAM2:
        state.initial_error = float(state.built.graph.error(state.values))
    if incremental and method is Method.BATCH:
        state.values, state.iterations = isam2_estimate(problem, state.built, state.values, options, None)
    if method is Method.BATCH:
        stop = None if reference is None or robust else _Reaches(reference, problem, state.built, options)
        state.values, it = _batch(state.built.graph, state.values, options, hook, state.errs, stop)
        state.iterations += it
        state.reached = stop is not None and stop.hit
        if state.initial_error is None:
            state.initial_error = state.errs[0]
    else:
        isam, slots, state.iterations = isam2_feed(problem, state.built, state.values, options, hook)
        state.values = isam.calculateEstimate()
        if robust:
            robust_rel = _robust_rows(problem, state.build)
            state.session = Isam2Session(
                problem,
                state.built,
                isam,
                slots,
                state.labels,
                robust_rel,
                state.build,
                options,
                hook,
                state.iterations,
            )
            state.iterations += state.session.converge()  # the outlier tests need the converged estimate
            state.values = isam.calculateEstimate()
        elif options.isam2_final_lm_iterations > 0:
            polish = replace(options, max_iterations=int(options.isam2_final_lm_iterations))
            state.values, it_lm = _batch(state.built.graph, state.values, polish, hook, state.errs)
            state.iterations += it_lm
    state.extract()


# ------------------------------------------------------------------------------------------- robust rounds


class _Rounds:
    """Steps 2-5 of the outlier scheme on a solved state: each round tests, changes what is active, re-solves."""

    def __init__(self, state: _State) -> None:
        o, p = state.options, state.problem
        self.state = state
        self.robust_build = state.build
        self.thr = {fam: chi2_quantile(o.chi2_probability, dof) for fam, dof in DOF.items()}
        self.tested = {
            REL: _robust_rows(p, state.build),
            HEAD: np.arange(len(p.headings)),
            LMK: np.arange(len(p.landmarks)),
        }
        self.moved: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.rounds = 1

    def residuals(self, active: bool) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        s = self.state
        rows = {f: r[s.masks[f][r] == active] for f, r in self.tested.items()}
        return residuals(s.problem, s.wTa, s.w_lm, s.names, s.theta_m, s.labels, rows)

    def reject(self) -> bool:
        """Deactivate the active measurements beyond the chi-square bound (not a sighting of a pair)."""
        s, changed = self.state, False
        for fam, (rows, d2) in self.residuals(True).items():
            bad = rows[d2 > self.thr[fam]]
            if fam == LMK and bad.size:
                bad = bad[~in_pairs(s.labels, s.masks[LMK], bad)]
            if bad.size:
                s.masks[fam][bad] = False
                changed = True
        return changed

    def split_moved(self) -> bool:
        """Objects whose rejected sightings form their own place become two variables (``<id>@before``)."""
        s = self.state
        if not (s.options.detect_moved and len(s.problem.landmarks)):
            return False
        changed = False
        found = detect_moved(
            s.problem, s.wTa, s.w_lm, s.names, s.labels, s.masks[LMK], s.options, self.thr[LMK]
        )
        for name, cluster, later, _mean in found:
            if name in self.moved:
                continue
            same = np.array([k for k, lab in enumerate(s.labels) if lab == name and s.masks[LMK][k]])
            before, after = (same, cluster) if later else (cluster, same)
            self.moved[name] = (before, after)
            before_set = set(before.tolist())
            # the earlier place becomes "<id>@before": the id keeps naming where the object is now
            s.labels = tuple(before_id(name) if k in before_set else lab for k, lab in enumerate(s.labels))
            s.masks[LMK][cluster] = True
            changed = True
        return changed

    def run(self) -> None:
        s = self.state
        for _ in range(s.options.max_rounds):
            if not (self.reject() or self.split_moved()):
                break
            self.rounds += 1
            s.resolve(self.robust_build)
        if s.options.final_gaussian:
            gaussian = self.robust_build.without_kernels()
            s.resolve(gaussian)
            self.rounds += 1
            # re-admit what the Gaussian solution explains (a rejection made against a kernel-biased estimate)
            readmit = False
            for fam, (rows, d2) in self.residuals(False).items():
                ok = rows[d2 <= self.thr[fam]]
                if ok.size:
                    s.masks[fam][ok] = True
                    readmit = True
            if readmit:
                s.resolve(gaussian)
                self.rounds += 1
        if s.session is not None:
            # the final graph as the batch path builds it (its landmark numbering), at the iSAM2 estimate: its
            # error, marginals and the optional LM polish
            s.rebuild(s.build)
            if s.options.isam2_final_lm_iterations > 0:
                polish = replace(s.options, max_iterations=int(s.options.isam2_final_lm_iterations))
                s.values, it_lm = _batch(s.built.graph, s.values, polish, s.hook, s.errs)
                s.iterations += it_lm
            s.wTa, s.w_lm, s.theta_m = _extract(s.values, s.problem, s.built)


# ------------------------------------------------------------------------------------------------- results


def _marginals(state: _State, options: SolveOptions) -> tuple[np.ndarray | None, np.ndarray | None]:
    import gtsam

    problem, built = state.problem, state.built
    scope = CovarianceScope(options.covariances)
    if scope is CovarianceScope.NONE:
        return None, None
    try:
        marg = gtsam.Marginals(built.graph, state.values)
    except RuntimeError as e:
        raise SolverError(f"marginal covariances failed: {e}") from None
    cov_wTa = cov_lm = None
    if scope in (CovarianceScope.ANCHORS, CovarianceScope.ALL):
        cov_wTa = np.full((problem.num_poses, 3, 3), np.nan)
        which = range(problem.num_poses) if options.covariance_anchors is None else options.covariance_anchors
        for a in which:
            cov_wTa[a] = marg.marginalCovariance(anchor_key(int(a)))
    if scope in (CovarianceScope.LANDMARKS, CovarianceScope.ALL):
        n_lm = len(built.landmark_names)
        cov_lm = np.array([marg.marginalCovariance(landmark_key(v)) for v in range(n_lm)]).reshape(-1, 2, 2)
    return cov_wTa, cov_lm


def _solution(
    state: _State, rounds: int, moved: dict[str, tuple[np.ndarray, np.ndarray]], t0: float
) -> Solution:
    problem, built, lm = state.problem, state.built, state.problem.landmarks
    method = Method(state.options.method)
    final_error = (
        state.errs[-1] if method is Method.BATCH and state.errs else float(built.graph.error(state.values))
    )
    cov_wTa, cov_lm = _marginals(state, state.options)
    families = (
        (MeasurementFamily.RELATIVE, REL),
        (MeasurementFamily.HEADING, HEAD),
        (MeasurementFamily.LANDMARK, LMK),
    )
    rejected = tuple(
        MeasurementRef(family, int(k))
        for family, code in families
        for k in np.flatnonzero(~state.masks[code])
    )
    var_of = {n: k for k, n in enumerate(built.landmark_names)}
    w_lm = state.w_lm
    moved_objects = tuple(
        MovedObject(
            name,
            w_lm[var_of[before_id(name)]] if before_id(name) in var_of else np.zeros(2),
            w_lm[var_of[name]] if name in var_of else np.zeros(2),
            int(lm.i[before].max()),
            int(lm.i[after].min()),
        )
        for name, (before, after) in moved.items()
    )
    return Solution(
        wTa=state.wTa,
        cov_wTa=cov_wTa,
        landmark_ids=built.landmark_names,
        w_landmarks=w_lm,
        cov_w_landmarks=cov_lm,
        iterations=state.iterations,
        initial_error=float(state.initial_error if state.initial_error is not None else final_error),
        final_error=final_error,
        rejected=rejected,
        moved_objects=moved_objects,
        compass_bias=None if state.theta_m is None else float(geo.wrap(-state.theta_m)),
        method=method,
        rounds=rounds,
        seconds=time.perf_counter() - t0,
        pose_ids=problem.pose_ids,
        initialisation=Initialisation(state.options.initialisation),
    )


def _first_graph(problem: SlamProblem, options: SolveOptions) -> tuple[SlamProblem, bool, BuiltGraph]:
    """The problem with its gauge, whether the robust rounds run, and the graph of every measurement (the same
    for every start: LM does not change it)."""
    problem = _with_gauge(problem, options)
    lm = problem.landmarks
    robust = options.reject_outliers and bool(
        _robust_rows(problem, options.build).size or len(problem.headings) or len(lm)
    )
    build = options.build if robust else options.build.without_kernels()
    return problem, robust, build_graph(problem, build, None, None, None, lm.landmark)


def _solve_one(
    problem: SlamProblem,
    options: SolveOptions,
    hook: IterationHook | None,
    start: Start | None = None,
    reference: Solution | None = None,
    first: tuple[SlamProblem, bool, BuiltGraph] | None = None,
) -> tuple[Solution, _State]:
    """One start: a plain solve, then (with outlier rejection) the robust rounds as a loop over it. ``first``:
    what :func:`_first_graph` gives (shared by the starts of AUTO)."""
    t0 = time.perf_counter()
    problem, robust, built = first or _first_graph(problem, options)
    lm = problem.landmarks
    build = options.build if robust else options.build.without_kernels()
    masks = {
        REL: np.ones(len(problem.relative), bool),
        HEAD: np.ones(len(problem.headings), bool),
        LMK: np.ones(len(lm), bool),
    }
    state = _State(problem, options, hook, masks, lm.landmark, build, built, None)
    _first_solve(state, robust, start, reference)
    if not robust:
        return _solution(state, 1, {}, t0), state
    rounds = _Rounds(state)
    rounds.run()
    return _solution(state, rounds.rounds, rounds.moved, t0), state


class _Runner:
    """The solver as :func:`holoslam.graph.starts.solve_from_starts` drives it."""

    def __init__(self, problem: SlamProblem, options: SolveOptions, hook: IterationHook | None) -> None:
        self.problem, self.options, self.hook = problem, options, hook
        self.first: tuple[SlamProblem, bool, BuiltGraph] | None = None

    def run(
        self, options: SolveOptions, start: Start | None, reference: Solution | None
    ) -> tuple[Solution, _State, bool]:
        if self.first is None:
            self.first = _first_graph(self.problem, options)
        sol, state = _solve_one(self.problem, options, self.hook, start, reference, self.first)
        return sol, state, state.reached

    def fit(self, state: _State) -> tuple[int, int]:
        """Active measurements beyond the chi-square bound of their dimension at the state's solution."""
        p = state.problem
        rows = {f: np.flatnonzero(state.masks[f]) for f in (REL, HEAD, LMK)}
        res = residuals(p, state.wTa, state.w_lm, state.names, state.theta_m, state.labels, rows)
        q = self.options.chi2_probability
        beyond = sum(int(np.count_nonzero(d2 > chi2_quantile(q, DOF[f]))) for f, (_r, d2) in res.items())
        return beyond, sum(int(r.size) for r in rows.values())

    def finish(self, solution: Solution, state: _State) -> Solution:
        if CovarianceScope(self.options.covariances) is CovarianceScope.NONE:
            return solution
        cov_wTa, cov_lm = _marginals(state, self.options)
        return replace(solution, cov_wTa=cov_wTa, cov_w_landmarks=cov_lm)


def solve(
    problem: SlamProblem,
    options: SolveOptions = SolveOptions(),  # noqa: B008 (a frozen dataclass)
    iteration_hook: IterationHook | None = None,
) -> Solution:
    """Optimise a SLAM problem (see the module docstring for the outlier scheme). With
    ``Initialisation.AUTO`` the whole solve runs from each candidate start and the lowest final error wins."""
    if Initialisation(options.initialisation) is Initialisation.AUTO:
        return solve_from_starts(problem, options, _Runner(problem, options, iteration_hook))
    return _solve_one(problem, options, iteration_hook)[0]
