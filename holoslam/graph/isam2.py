"""Incremental solving with gtsam's iSAM2: the anchor-by-anchor feed (``Method.ISAM2`` and the incremental start)
and the outlier rounds run on the same iSAM2 object (:class:`Isam2Session`).

QR factorisation by default: Cholesky throws on the strongly anisotropic scan-match information of CSAIL / MITb /
FR079. With a relinearisation threshold of 1e-3 the answer is batch LM's to ~1e-6 m on the household log; gtsam's
default 0.1 leaves it millimetres off, which can flip a chi-square decision.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import SolverError
from holoslam.graph.build import BuildOptions, BuiltGraph
from holoslam.graph.keys import MAGNETIC_KEY, anchor_key, landmark_key
from holoslam.graph.options import HEAD, LMK, REL, Factorization, IterationHook, SolveOptions
from holoslam.graph.problem import SlamProblem

__all__ = ["isam2_params", "isam2_feed", "isam2_estimate", "Isam2Session"]


def isam2_estimate(
    problem: SlamProblem, built: BuiltGraph, values: Any, options: SolveOptions, hook: IterationHook | None
) -> tuple[Any, int]:
    """Feed the graph anchor by anchor (see ``_isam2_feed``); returns the estimate and the number of updates."""
    isam, _slots, updates = isam2_feed(problem, built, values, options, hook)
    return isam.calculateEstimate(), updates


def isam2_params(options: SolveOptions) -> Any:
    import gtsam

    params = gtsam.ISAM2Params()
    params.setFactorization(
        "QR" if Factorization(options.isam2_factorization) is Factorization.QR else "CHOLESKY"
    )
    params.setRelinearizeThreshold(float(options.isam2_relinearize_threshold))
    params.relinearizeSkip = int(options.isam2_relinearize_skip)
    return params


def isam2_feed(
    problem: SlamProblem, built: BuiltGraph, values: Any, options: SolveOptions, hook: IterationHook | None
) -> tuple[Any, np.ndarray, int]:
    """Feed the graph anchor by anchor (factors grouped by the latest anchor they involve); each new anchor is
    initialised from the current estimate composed with the first measurement that reaches it from an earlier
    anchor (else with the initial guess's step), each new landmark from its first sighting. Returns the iSAM2
    object, the iSAM2 factor index of each factor of ``built.graph`` and the number of updates."""
    import gtsam

    params = isam2_params(options)
    params.evaluateNonlinearError = hook is not None
    isam = gtsam.ISAM2(params)
    slots = np.full(built.graph.size(), -1, dtype=np.int64)

    rel, lm = problem.relative, problem.landmarks
    init = problem.initial_wTa
    assert init is not None  # set by SlamProblem.__post_init__
    n = problem.num_poses
    order = np.argsort(built.stage, kind="stable")
    stages = built.stage[order]
    bounds = np.searchsorted(stages, np.arange(n + 1), side="left")
    # first measurement reaching each anchor from an earlier one: (earlier anchor, earlier->this pose)
    reach: dict[int, tuple[int, Any]] = {}
    rel_rows = built.index[built.family == REL]
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


class Isam2Session:
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
            if fam == HEAD or fam == LMK or (fam == REL and self.robust_rel[row]):
                self.live[(fam, row)] = (
                    int(slots[f]),
                    self._label(fam, row, labels),
                    self._kernel(fam, opts_build),
                )

    @staticmethod
    def _label(fam: int, row: int, labels: tuple[str, ...]) -> str | None:
        return labels[row] if fam == LMK else None

    @staticmethod
    def _kernel(fam: int, opts: BuildOptions) -> Any:
        return {REL: opts.loop_kernel, HEAD: opts.heading_kernel, LMK: opts.landmark_kernel}[fam]

    def _factors(self, fam: int, rows: np.ndarray, labels: tuple[str, ...], opts: BuildOptions) -> Any:
        from holoslam.graph import factors as fac
        from holoslam.graph.keys import anchor_keys

        p = self.problem
        if fam == REL:
            rel = p.relative
            return fac.between_factors(
                anchor_keys(rel.i[rows]),
                anchor_keys(rel.j[rows]),
                rel.iTj[rows],
                rel.cov_iTj[rows],
                opts.loop_kernel,
            )
        if fam == HEAD:
            hd = p.headings
            return fac.heading_factors(
                anchor_keys(hd.i[rows]),
                hd.yaw[rows],
                hd.sigma[rows],
                MAGNETIC_KEY,
                opts.heading_kernel,
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
            rows = np.flatnonzero(mask & self.robust_rel) if fam == REL else np.flatnonzero(mask)
            kernel = self._kernel(fam, opts)
            for row in rows.tolist():
                want[(fam, row)] = (self._label(fam, row, labels), kernel)
        remove = [key for key, (_slot, lab, ker) in self.live.items() if want.get(key) != (lab, ker)]
        add = [key for key, w in want.items() if key not in self.live or self.live[key][1:] != w]
        removed_slots = [self.live.pop(key)[0] for key in remove]
        graph = gtsam.NonlinearFactorGraph()
        order: list[tuple[int, int]] = []
        for fam in (REL, HEAD, LMK):
            rows = np.array(sorted(r for f, r in add if f == fam), dtype=np.int64)
            if rows.size == 0:
                continue
            if fam == LMK:
                for name in dict.fromkeys(labels[k] for k in rows.tolist()):
                    self.var_of.setdefault(name, len(self.var_of))
            graph.push_back(self._factors(fam, rows, labels, opts))
            order += [(fam, int(r)) for r in rows.tolist()]
        values = gtsam.Values()
        new_names = {
            labels[r]
            for f, r in order
            if f == LMK and not self.isam.valueExists(landmark_key(self.var_of[labels[r]]))
        }
        if new_names:
            lm_rows = np.array([r for (f, r) in want if f == LMK], dtype=np.int64)
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

    def _update(
        self, graph: Any = None, values: Any = None, remove: list[int] | None = None, force: bool = False
    ):
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
        w_lm = np.array([values.atPoint2(landmark_key(self.var_of[m])) for m in names], dtype=float).reshape(
            -1, 2
        )
        theta_m = values.atPose2(MAGNETIC_KEY).theta() if magnetic else None
        return wTa, names, w_lm, theta_m
