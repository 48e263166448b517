"""Turn a :class:`~holoslam.graph.problem.SlamProblem` into a gtsam factor graph and initial values.

With :mod:`holoslam.graph.factors`, the only place that creates gtsam factors. Each factor of the returned graph
is traced back to its measurement (``BuiltGraph.family`` / ``BuiltGraph.index``), and to the latest anchor it
involves (``BuiltGraph.stage``), which is what the incremental solver feeds anchor by anchor.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from holoslam.errors import GraphError
from holoslam.graph import factors as fac
from holoslam.graph.keys import MAGNETIC_KEY, anchor_keys, landmark_key
from holoslam.graph.problem import MeasurementFamily, SlamProblem

__all__ = ["BuildOptions", "BuiltGraph", "build_graph", "initial_values", "kind_mask", "FAMILY_CODES"]

FAMILY_CODES: dict[MeasurementFamily, int] = {
    MeasurementFamily.RELATIVE: 0,
    MeasurementFamily.HEADING: 1,
    MeasurementFamily.LANDMARK: 2,
    MeasurementFamily.PRIOR: 3,
}
_MAGNETIC_PRIOR_CODE = 4


@dataclass(frozen=True, slots=True)
class BuildOptions:
    """Which robust kernel each family gets. Relative measurements whose kind is in ``robust_kinds`` (loop closures
    by default) get ``loop_kernel``; the others (dead reckoning, odometry, g2o edges) stay Gaussian."""

    loop_kernel: fac.Kernel = fac.Kernel(fac.RobustKernel.DCS, 1.0)
    landmark_kernel: fac.Kernel = fac.Kernel(fac.RobustKernel.DCS, 1.0)
    heading_kernel: fac.Kernel = fac.Kernel(fac.RobustKernel.CAUCHY, 1.0)
    robust_kinds: tuple[str, ...] = ("loop",)
    heading_xy_sigma: float = 1e4

    def without_kernels(self) -> BuildOptions:
        return BuildOptions(
            fac.NO_KERNEL, fac.NO_KERNEL, fac.NO_KERNEL, self.robust_kinds, self.heading_xy_sigma
        )


@dataclass(frozen=True, eq=False)
class BuiltGraph:
    """A gtsam graph plus, per factor, the measurement it came from and the latest anchor it involves."""

    graph: Any
    family: np.ndarray  # (F,) int8 codes of FAMILY_CODES (4 = the magnetic frame's prior)
    index: np.ndarray  # (F,) row in that family's batch
    stage: np.ndarray  # (F,) latest anchor index the factor involves
    landmark_names: tuple[str, ...]  # variable L(k) is landmark_names[k]
    has_magnetic: bool
    sighting_variable: np.ndarray = field(
        default_factory=lambda: np.zeros(0, np.int64)
    )  # per active sighting


def kind_mask(kind: np.ndarray, kinds: tuple[str, ...]) -> np.ndarray:
    """Which measurements have one of ``kinds`` (an object array of kind names; the names present are looked up
    once, not string-converted row by row)."""
    if kind.size == 0:
        return np.zeros(0, bool)
    present = {str(k) for k in set(kind.tolist())}
    wanted = present & {str(k) for k in kinds}
    if not wanted:
        return np.zeros(kind.size, bool)
    if wanted == present:
        return np.ones(kind.size, bool)
    return np.isin(kind.astype(str), sorted(wanted))


def build_graph(
    problem: SlamProblem,
    options: BuildOptions = BuildOptions(),
    relative_mask: np.ndarray | None = None,
    heading_mask: np.ndarray | None = None,
    landmark_mask: np.ndarray | None = None,
    landmark_labels: tuple[str, ...] | None = None,
    theta_magnetic: float = 0.0,
) -> BuiltGraph:
    """All factors of ``problem`` (the masked-in measurements only). ``landmark_labels`` renames sightings (one
    label per sighting; used to split a moved object into two variables)."""
    import gtsam

    rel, hd, lm = problem.relative, problem.headings, problem.landmarks
    rmask = np.ones(len(rel), bool) if relative_mask is None else np.asarray(relative_mask, bool)
    hmask = np.ones(len(hd), bool) if heading_mask is None else np.asarray(heading_mask, bool)
    lmask = np.ones(len(lm), bool) if landmark_mask is None else np.asarray(landmark_mask, bool)
    labels = lm.landmark if landmark_labels is None else tuple(landmark_labels)
    if len(labels) != len(lm):
        raise GraphError(f"landmark_labels has {len(labels)} entries for {len(lm)} sightings")

    graph = gtsam.NonlinearFactorGraph()
    fam: list[np.ndarray] = []
    idx: list[np.ndarray] = []
    stage: list[np.ndarray] = []

    def add(sub: Any, code: int, rows: np.ndarray, st: np.ndarray) -> None:
        graph.push_back(sub)
        fam.append(np.full(rows.size, code, np.int8))
        idx.append(rows.astype(np.int64))
        stage.append(st.astype(np.int64))

    # priors
    if problem.priors:
        rows = np.arange(len(problem.priors))
        pi = np.array([p.i for p in problem.priors])
        add(
            fac.prior_factors(
                anchor_keys(pi),
                np.array([p.wTa for p in problem.priors]),
                np.array([p.cov_wTa for p in problem.priors]),
            ),
            FAMILY_CODES[MeasurementFamily.PRIOR],
            rows,
            pi,
        )
    # relative poses: Gaussian ones and robust ones
    robust = kind_mask(rel.kind, options.robust_kinds)
    for sel, kernel in ((rmask & ~robust, fac.NO_KERNEL), (rmask & robust, options.loop_kernel)):
        rows = np.flatnonzero(sel)
        if rows.size:
            add(
                fac.between_factors(
                    anchor_keys(rel.i[rows]),
                    anchor_keys(rel.j[rows]),
                    rel.iTj[rows],
                    rel.cov_iTj[rows],
                    kernel,
                ),
                FAMILY_CODES[MeasurementFamily.RELATIVE],
                rows,
                np.maximum(rel.i[rows], rel.j[rows]),
            )
    # compass headings through the magnetic frame
    rows = np.flatnonzero(hmask)
    has_magnetic = rows.size > 0
    if has_magnetic:
        add(
            fac.magnetic_frame_prior(MAGNETIC_KEY, theta_magnetic),
            _MAGNETIC_PRIOR_CODE,
            np.zeros(1),
            np.array([hd.i[rows].min()]),
        )
        add(
            fac.heading_factors(
                anchor_keys(hd.i[rows]),
                hd.yaw[rows],
                hd.sigma[rows],
                MAGNETIC_KEY,
                options.heading_kernel,
                options.heading_xy_sigma,
            ),
            FAMILY_CODES[MeasurementFamily.HEADING],
            rows,
            hd.i[rows],
        )
    # landmarks
    rows = np.flatnonzero(lmask)
    names = tuple(dict.fromkeys(labels[k] for k in rows))
    var_of = {n: k for k, n in enumerate(names)}
    sight_var = np.array([var_of[labels[k]] for k in rows], dtype=np.int64)
    if rows.size:
        lkeys = np.array([landmark_key(v) for v in sight_var.tolist()], dtype=np.uint64)
        add(
            fac.landmark_factors(
                anchor_keys(lm.i[rows]),
                lkeys,
                lm.a_position[rows],
                lm.cov_a_position[rows],
                options.landmark_kernel,
            ),
            FAMILY_CODES[MeasurementFamily.LANDMARK],
            rows,
            lm.i[rows],
        )
    if graph.size() == 0:
        raise GraphError("the problem has no measurements to optimise")
    return BuiltGraph(
        graph=graph,
        family=np.concatenate(fam),
        index=np.concatenate(idx),
        stage=np.concatenate(stage),
        landmark_names=names,
        has_magnetic=has_magnetic,
        sighting_variable=sight_var,
    )


def initial_values(
    problem: SlamProblem,
    built: BuiltGraph,
    wTa: np.ndarray | None = None,
    w_landmarks: dict[str, np.ndarray] | None = None,
    theta_magnetic: float | None = None,
    landmark_labels: tuple[str, ...] | None = None,
) -> Any:
    """gtsam Values for every variable of ``built``: anchors from ``wTa`` (default the problem's initial guess),
    landmarks from ``w_landmarks`` / the problem's initial landmarks / their first active sighting, the magnetic
    frame from ``theta_magnetic`` or the circular mean of (anchor heading - compass yaw)."""
    import gtsam

    wTa = problem.initial_wTa if wTa is None else np.asarray(wTa, float)
    assert wTa is not None  # set by SlamProblem.__post_init__
    values = gtsam.Values()
    keys = anchor_keys(np.arange(problem.num_poses))
    # the keyword picks gtsam's Pose2 overload of Values.insert directly (1.2 µs less per pose than letting
    # pybind11 try the vector / matrix / point overloads first)
    insert = values.insert
    if wTa.shape != (problem.num_poses, 3):
        raise GraphError(f"initial poses: expected shape ({problem.num_poses}, 3), got {wTa.shape}")
    poses = map(gtsam.Pose2, wTa[:, 0].tolist(), wTa[:, 1].tolist(), wTa[:, 2].tolist())
    for k, p in zip(keys.tolist(), poses, strict=True):
        insert(k, pose2=p)
    known = dict(problem.initial_landmarks)
    if w_landmarks:
        known.update(w_landmarks)
    lm = problem.landmarks
    labels = lm.landmark if landmark_labels is None else landmark_labels
    lrows = built.index[built.family == FAMILY_CODES[MeasurementFamily.LANDMARK]]
    missing = [n for n in built.landmark_names if n not in known]
    if missing:
        known.update(robust_landmark_guess(problem, wTa, lrows, labels, set(missing)))
    for v, name in enumerate(built.landmark_names):
        values.insert(landmark_key(v), np.asarray(known[name], dtype=float))
    if built.has_magnetic:
        if theta_magnetic is None:
            theta_magnetic = magnetic_from_headings(problem, wTa)
        values.insert(MAGNETIC_KEY, gtsam.Pose2(0.0, 0.0, float(theta_magnetic)))
    return values


def robust_landmark_guess(
    problem: SlamProblem,
    wTa: np.ndarray,
    rows: np.ndarray,
    labels: tuple[str, ...],
    wanted: set[str],
    radius: float = 0.5,
) -> dict[str, np.ndarray]:
    """A world position per landmark id from its sightings under ``wTa``: the mean of the largest group of
    sightings within ``radius`` of one of them (so a misread or misplaced first sighting does not seed it)."""
    lm = problem.landmarks
    rows = np.asarray(rows, dtype=np.int64)
    if rows.size == 0:
        return {}
    T = wTa[lm.i[rows]]
    c, s = np.cos(T[:, 2]), np.sin(T[:, 2])
    ap = lm.a_position[rows]
    p = np.column_stack([T[:, 0] + c * ap[:, 0] - s * ap[:, 1], T[:, 1] + s * ap[:, 0] + c * ap[:, 1]])
    names = np.array([labels[k] for k in rows.tolist()], dtype=object)
    out: dict[str, np.ndarray] = {}
    for name in wanted:
        q = p[names == name]
        if q.shape[0] == 0:
            continue
        near = np.hypot(q[:, None, 0] - q[None, :, 0], q[:, None, 1] - q[None, :, 1]) <= radius
        best = int(np.argmax(near.sum(1)))
        out[name] = q[near[best]].mean(axis=0)
    return out


def magnetic_from_headings(problem: SlamProblem, wTa: np.ndarray) -> float:
    """Circular mean of theta_a - yaw over all headings: the rotation of the magnetic frame (= -compass bias)."""
    hd = problem.headings
    if len(hd) == 0:
        return 0.0
    d = wTa[hd.i, 2] - hd.yaw
    return float(np.arctan2(np.sin(d).mean(), np.cos(d).mean()))
