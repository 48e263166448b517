"""``Initialisation.AUTO``: solve from several starts, keep the lowest final error, and say whether the starts
agree and whether the kept solution explains the measurements.

No single start reaches the global optimum of every graph: on MITb LM from the file's guess (or the odometry
chain, or LAGO) stops at E 385.12 while the chordal start reaches 20.6035; on Victoria Park both stop far off and
only the incremental start (an iSAM2 pass) gets there. The default candidates are the problem's own guess and the
chordal start, chordal first (the problem's own guess first when it already fits the measurements, before any
solve: ``_order``), each followed by LM to convergence. A later candidate runs only when the best
solution so far disagrees with the measurements (``auto_enough_when_fits``): more than ``auto_fallback_beyond``
of them (and at least 5) beyond the chi-square bound ``chi2_probability`` of their dimension, where a consistent
solution leaves 1 - chi2_probability; the report names each start not run and why. A later start whose LM
reaches an earlier start's solution (the same error to the LM tolerance and the same poses to ``auto_agree_*``)
stops there, so agreeing starts cost little more than one solve. The slow incremental start (``auto_fallback``)
runs only when the best of the candidates still disagrees with the measurements.

The solver itself is passed in (:class:`StartRunner`), so this module does not import ``holoslam.solve``.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import GraphError, SolverError
from holoslam.graph.initialise import chordal
from holoslam.graph.options import CovarianceScope, Initialisation, SolveOptions
from holoslam.graph.problem import SlamProblem, odometry_chain
from holoslam.graph.solution import Solution, StartOutcome, StartsReport

__all__ = ["StartRunner", "solve_from_starts", "Start"]

Start = tuple[np.ndarray, dict[str, np.ndarray]]  # anchor poses (N, 3) and landmark positions by id


class StartRunner(Protocol):
    """What ``solve_from_starts`` needs from the solver."""

    def run(
        self, options: SolveOptions, start: Start | None, reference: Solution | None
    ) -> tuple[Solution, Any, bool]:
        """Solve from ``start`` (None: the one ``options.initialisation`` names); stop LM early when it reaches
        ``reference``'s solution. Returns the solution, the solver's state (for ``fit`` and ``finish``) and
        whether LM stopped on reaching the reference."""
        ...

    def fit(self, state: Any) -> tuple[int, int]:
        """(measurements beyond the chi-square bound, measurements tested) at the state's solution."""
        ...

    def finish(self, solution: Solution, state: Any) -> Solution:
        """The solution with the covariances the caller asked for."""
        ...


def _same(a: Start, b: Start) -> bool:
    if not np.allclose(a[0], b[0], rtol=0.0, atol=1e-9) or a[1].keys() != b[1].keys():
        return False
    return all(np.allclose(a[1][k], b[1][k], rtol=0.0, atol=1e-9) for k in a[1])


def _exact(problem: SlamProblem, wTa: np.ndarray, tol: float = 1e-6) -> bool:
    """Does ``wTa`` satisfy every relative measurement (m, rad)? Then it is LAGO's zero-cost solution."""
    rel = problem.relative
    d = geo.between(geo.between(wTa[rel.i], wTa[rel.j]), rel.iTj)
    return bool(np.all(np.abs(d[:, :2]) <= tol) and np.all(np.abs(geo.wrap(d[:, 2])) <= tol))


def _start(
    problem: SlamProblem, cand: Initialisation, seen: list[tuple[Initialisation, Start]]
) -> tuple[Start | None, str]:
    """The start array of a candidate (None: the solver makes it) and, when it is not to be solved, why."""
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    if cand is Initialisation.LAGO:
        a0 = problem.initial_wTa[0]
        if any(np.allclose(s[0][0], a0, rtol=0.0, atol=1e-9) and _exact(problem, s[0]) for _c, s in seen):
            return None, "the graph has no loop: LAGO returns the chain"
        return None, ""
    if cand is Initialisation.INCREMENTAL:
        return None, ""
    if cand is Initialisation.PROBLEM:
        start: Start = (problem.initial_wTa, dict(problem.initial_landmarks))
    elif cand is Initialisation.ODOMETRY:
        start = (odometry_chain(problem.num_poses, problem.relative), dict(problem.initial_landmarks))
    else:
        start = chordal(problem)
    for earlier, s in seen:
        if _same(start, s):
            return start, f"the same start as {earlier.value}"
    return start, ""


def _difference(a: Solution, b: Solution) -> tuple[float, float]:
    """Largest position (anchors and landmarks, m) and heading (rad) difference of two solutions."""
    dxy = float(np.abs(a.wTa[:, :2] - b.wTa[:, :2]).max(initial=0.0))
    if a.landmark_ids == b.landmark_ids and a.w_landmarks.size:
        dxy = max(dxy, float(np.abs(a.w_landmarks - b.w_landmarks).max()))
    elif a.landmark_ids != b.landmark_ids:
        dxy = math.inf
    dth = float(np.abs(geo.wrap(a.wTa[:, 2] - b.wTa[:, 2])).max(initial=0.0))
    return dxy, dth


class _Search:
    """The candidates tried so far and the best solution among them."""

    def __init__(self, problem: SlamProblem, options: SolveOptions, runner: StartRunner) -> None:
        self.problem, self.options, self.runner = problem, options, runner
        self.plain = replace(options, covariances=CovarianceScope.NONE)
        # (start, solution or None when it failed, seconds, failure, the earlier start whose solution it reached)
        self.raw: list[tuple[Initialisation, Solution | None, float, str, Initialisation | None]] = []
        self.skipped: list[tuple[Initialisation, str]] = []
        self.seen: list[tuple[Initialisation, Start]] = []
        self.best: tuple[Initialisation, Solution, Any] | None = None
        self._fit: tuple[Any, tuple[int, int, int]] | None = None

    def tried(self, cand: Initialisation) -> bool:
        return any(c is cand for c, *_ in self.raw) or any(c is cand for c, _ in self.skipped)

    def run(self, cand: Initialisation) -> None:
        t0 = time.perf_counter()
        try:
            start, skip = _start(self.problem, cand, self.seen)
            if skip:
                self.skipped.append((cand, skip))
                return
            if start is not None:
                self.seen.append((cand, start))
            ref = self.best[1] if self.best is not None else None
            sol, state, reached = self.runner.run(replace(self.plain, initialisation=cand), start, ref)
        except (SolverError, GraphError) as e:
            self.raw.append((cand, None, time.perf_counter() - t0, str(e), None))
            return
        by = self.best[0] if reached and self.best is not None else None
        self.raw.append((cand, sol, time.perf_counter() - t0, "", by))
        if self.best is None or sol.final_error < self.best[1].final_error * (1.0 - 1e-9):
            self.best = (cand, sol, state)

    def fit(self) -> tuple[int, int, int]:
        """(measurements beyond the chi-square bound, measurements tested, the most allowed) at the best solution
        so far (computed once per best)."""
        assert self.best is not None
        if self._fit is None or self._fit[0] is not self.best[2]:
            beyond, total = self.runner.fit(self.best[2])
            limit = max(5, int(self.options.auto_fallback_beyond * total))
            self._fit = (self.best[2], (beyond, total, limit))
        return self._fit[1]

    def enough(self) -> str:
        """Why the remaining candidates need not run (``auto_enough_when_fits`` and the best solution so far fits
        the measurements), else ''."""
        if self.best is None or not self.options.auto_enough_when_fits:
            return ""
        beyond, total, limit = self.fit()
        if beyond > limit:
            return ""
        return (
            f"the {self.best[0].value} start's solution already fits the measurements: {beyond} of {total} "
            f"beyond the chi-square bound, at most {limit} allowed"
        )

    def outcomes(self) -> tuple[StartOutcome, ...]:
        assert self.best is not None
        kept = self.best[1]
        out = []
        for cand, sol, secs, failure, reached in self.raw:
            if sol is None:
                out.append(StartOutcome(cand, math.nan, seconds=secs, failure=failure))
                continue
            dxy, dth = _difference(sol, kept)
            out.append(StartOutcome(cand, sol.final_error, sol.iterations, secs, dxy, dth, reached))
        return tuple(out)

    def agree(self, outcomes: tuple[StartOutcome, ...]) -> bool | None:
        """Every start that ran ended at the kept solution's error (to ``auto_agree_error``): one minimum. Their
        poses may still differ by LM's slack in a flat valley (w10000: 2.2 m at the same 144.867), which the
        outcomes report."""
        assert self.best is not None
        ran = [o for o in outcomes if o.ok]
        if len(ran) < 2:
            return None
        o, e_kept = self.options, self.best[1].final_error
        return all(
            abs(s.final_error - e_kept) <= o.auto_agree_error * abs(e_kept) + o.absolute_error_tol
            for s in ran
        )


def _start_fits(problem: SlamProblem, options: SolveOptions) -> bool:
    """Whether the problem's own start already fits its measurements (``_Search.fit``'s test, before any solve):
    at most ``auto_fallback_beyond`` of them (and at least 5) beyond the chi-square bound. Asked of pose graphs
    only (relative poses alone: a heading's or a landmark's residual needs the solve's compass bias and
    landmark guesses)."""
    from holoslam.graph.outliers import chi2_quantile

    rel = problem.relative
    if problem.initial_wTa is None or len(rel) == 0 or len(problem.headings) or len(problem.landmarks):
        return False
    W = problem.initial_wTa
    r = geo.between(rel.iTj, geo.between(W[rel.i], W[rel.j]))
    r[:, 2] = geo.wrap(r[:, 2])
    d2 = np.einsum("ki,kij,kj->k", r, np.linalg.inv(rel.cov_iTj), r)
    beyond = int(np.count_nonzero(d2 > chi2_quantile(options.chi2_probability, 3)))
    return beyond <= max(5, int(options.auto_fallback_beyond * len(rel)))


def _order(problem: SlamProblem, options: SolveOptions) -> list[Initialisation]:
    """``options.auto_candidates`` in the order to run them: the problem's own start first when it already fits
    the measurements (``_start_fits``; a relaxation is for starts far from any consistent configuration: the
    chordal start then only costs its set-up, ~0.05 s of intel's 0.1 s solve). A start that does not fit keeps
    its place: LM from it may stop in a fitting local minimum (ais2klinik's file guess: 94 of 16,727
    measurements beyond the bound, 33 allowed; LM from it stops at 86.6012, the chordal start's at 86.4071)."""
    order: list[Initialisation] = [c for c in dict.fromkeys(Initialisation(c) for c in options.auto_candidates)
                                   if c is not Initialisation.AUTO]
    if (options.auto_enough_when_fits and Initialisation.PROBLEM in order and order[0] is not Initialisation.PROBLEM
            and _start_fits(problem, options)):
        order.remove(Initialisation.PROBLEM)
        order.insert(0, Initialisation.PROBLEM)
    return order


def solve_from_starts(problem: SlamProblem, options: SolveOptions, runner: StartRunner) -> Solution:
    """Solve from each of ``options.auto_candidates`` (``_order``; then ``auto_fallback`` when the best does not
    fit the measurements) and return the lowest final error with a :class:`StartsReport`."""
    t0 = time.perf_counter()
    search = _Search(problem, options, runner)
    for cand in _order(problem, options):
        why = search.enough()
        if why:
            search.skipped.append((cand, why))
        else:
            search.run(cand)
    if search.best is None:
        failures = "; ".join(f"{c.value}: {why}" for c, _s, _t, why, _r in search.raw if why)
        raise SolverError("every initialisation failed: " + (failures or "no start to try"))
    beyond, total, limit = search.fit()
    fallback = None if options.auto_fallback is None else Initialisation(options.auto_fallback)
    ran = False
    if fallback not in (None, Initialisation.AUTO) and beyond > limit and not search.tried(fallback):
        search.run(fallback)
        ran = True
        beyond, total, limit = search.fit()
    kept, best, state = search.best
    outcomes = search.outcomes()
    report = StartsReport(
        outcomes, kept, search.agree(outcomes), beyond, total, limit, fallback, ran, tuple(search.skipped)
    )
    final = runner.finish(best, state)
    return replace(
        final,
        seconds=time.perf_counter() - t0,
        candidates=tuple((o.initialisation, o.final_error) for o in outcomes),
        starts=report,
    )
