"""Factor graphs built from small synthetic worlds: truth recovered within covariance, outliers rejected, moved
objects detected, compass bias recovered, iSAM2 and batch agree."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from graph_worlds import make_world

from holoslam import geometry as geo
from holoslam.errors import GraphError
from holoslam.graph.build import BuildOptions
from holoslam.graph.keys import before_id
from holoslam.graph.problem import (
    HeadingMeasurements,
    LandmarkMeasurements,
    MeasurementFamily,
    MeasurementRef,
    RelativePoseMeasurements,
    SlamProblem,
)
from holoslam.solve import CovarianceScope, Initialisation, Method, SolveOptions, solve


def rmse_xy(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a[:, :2] - b[:, :2]) ** 2, axis=1))))


@pytest.fixture(scope="module")
def clean():
    problem, wTa, objects = make_world(seed=1)
    sol = solve(problem, SolveOptions(covariances=CovarianceScope.ALL))
    return problem, wTa, objects, sol


def test_clean_world_recovers_truth_within_covariance(clean):
    problem, wTa, objects, sol = clean
    assert rmse_xy(sol.wTa, wTa) < 0.35 * rmse_xy(problem.initial_wTa, wTa)
    d = geo.between(sol.wTa, wTa)  # error in the estimate's own frame, as the covariance
    nees = np.einsum("ki,kij,kj->k", d, np.linalg.inv(sol.cov_wTa), d)
    assert 1.0 < nees.mean() < 6.0  # 3 dof: mean 3 when the covariances are honest
    assert np.mean(nees < 7.81) > 0.8  # chi2(3) 95 %
    for name in sol.landmark_ids:
        e = sol.landmark(name) - objects[name]
        c = sol.cov_w_landmarks[sol.landmark_ids.index(name)]
        assert e @ np.linalg.solve(c, e) < 25.0
    assert abs(sol.compass_bias - 0.3) < 4 * 0.03 / np.sqrt(problem.num_poses) + 0.02
    assert len(sol.rejected) <= 2  # 99.9 % tests on ~180 clean measurements
    assert sol.moved_objects == ()
    assert sol.final_error < sol.initial_error


def test_wrong_loop_closures_are_rejected(clean):
    problem, wTa, _, sol_clean = clean
    rng = np.random.default_rng(7)
    rel = problem.relative
    n = problem.num_poses
    fi = rng.choice(n // 2, 5, replace=False)
    fj = fi + rng.integers(3, n // 2, 5)
    fake = geo.compose(
        geo.between(wTa[fi], wTa[fj]),
        np.column_stack([rng.uniform(1.0, 3.0, 5), rng.uniform(-2.0, 2.0, 5), rng.uniform(0.5, 1.5, 5)]),
    )
    bad = RelativePoseMeasurements(
        np.concatenate([rel.i, fi]),
        np.concatenate([rel.j, fj]),
        np.concatenate([rel.iTj, fake]),
        np.concatenate([rel.cov_iTj, rel.cov_iTj[:5]]),
        np.concatenate([rel.kind, np.full(5, "loop", object)]),
    )
    sol = solve(replace(problem, relative=bad))
    injected = {MeasurementRef(MeasurementFamily.RELATIVE, len(rel) + k) for k in range(5)}
    assert injected <= set(sol.rejected)
    assert rmse_xy(sol.wTa, wTa) < 1.2 * rmse_xy(sol_clean.wTa, wTa) + 0.01
    # without the scheme and without kernels the same graph is bent
    plain = solve(
        replace(problem, relative=bad),
        SolveOptions(reject_outliers=False, build=BuildOptions().without_kernels()),
    )
    assert rmse_xy(plain.wTa, wTa) > 3 * rmse_xy(sol.wTa, wTa)


def test_corrupted_landmark_sightings_are_rejected(clean):
    problem, wTa, objects, sol_clean = clean
    rng = np.random.default_rng(3)
    lm = problem.landmarks
    k = rng.choice(len(lm), max(3, len(lm) // 10), replace=False)
    pos = np.array(lm.a_position)
    names = list(lm.landmark)
    half = k.size // 2
    pos[k[:half]] += rng.uniform(0.8, 2.0, (half, 2)) * rng.choice(
        [-1, 1], (half, 2)
    )  # reported at the wrong place
    others = sorted(set(names))
    for m in k[half:]:  # misread ids
        names[m] = others[(others.index(names[m]) + 1) % len(others)]
    bad = LandmarkMeasurements(lm.i, tuple(names), pos, lm.cov_a_position)
    sol = solve(replace(problem, landmarks=bad))
    rejected = {r.index for r in sol.rejected if r.family is MeasurementFamily.LANDMARK}
    assert set(k.tolist()) <= rejected
    assert rmse_xy(sol.wTa, wTa) < 1.2 * rmse_xy(sol_clean.wTa, wTa) + 0.01
    err = max(np.hypot(*(sol.landmark(n) - objects[n])) for n in objects if n in sol.landmark_ids)
    assert err < 0.15


def test_moved_object_is_reported_with_both_positions(clean):
    problem, wTa, objects, _ = clean
    lm = problem.landmarks
    counts = {n: lm.landmark.count(n) for n in set(lm.landmark)}
    name = max(counts, key=counts.get)
    half = problem.num_poses // 2
    new_w = objects[name] + np.array([1.5, -1.0])
    pos = np.array(lm.a_position)
    for m in range(len(lm)):
        if lm.landmark[m] == name and lm.i[m] >= half:
            pos[m] = geo.transform_points(geo.inverse(wTa[lm.i[m]]), new_w[None])[0] + (
                pos[m] - geo.transform_points(geo.inverse(wTa[lm.i[m]]), objects[name][None])[0]
            )
    sol = solve(replace(problem, landmarks=replace(lm, a_position=pos)))
    moved = {m.object_id: m for m in sol.moved_objects}
    assert set(moved) == {name}
    m = moved[name]
    assert np.hypot(*(m.w_position_before - objects[name])) < 0.1
    assert np.hypot(*(m.w_position_after - new_w)) < 0.1
    assert m.last_anchor_before < half <= m.first_anchor_after
    assert np.allclose(sol.landmark(name), m.w_position_after)
    assert before_id(name) in sol.landmark_ids


def test_compass_bias_and_local_disturbance():
    problem, wTa, _ = make_world(seed=4, compass_bias=-1.2)
    hd = problem.headings
    yaw = np.array(hd.yaw)
    yaw[10:14] += 0.6  # a steel cupboard bends the field there
    sol = solve(replace(problem, headings=HeadingMeasurements(hd.i, yaw, hd.sigma)))
    assert abs(geo.wrap(sol.compass_bias + 1.2)) < 0.02
    rejected = {r.index for r in sol.rejected if r.family is MeasurementFamily.HEADING}
    assert set(range(10, 14)) <= rejected
    assert np.max(np.abs(geo.wrap(sol.wTa[:, 2] - wTa[:, 2]))) < 0.05


def test_isam2_and_batch_agree():
    problem, wTa, _ = make_world(seed=2, compass_bias=None)
    opts = SolveOptions(reject_outliers=False, build=BuildOptions().without_kernels())
    batch = solve(problem, opts)
    calls = []
    inc = solve(
        problem,
        replace(opts, method=Method.ISAM2, isam2_extra_updates=3, isam2_relinearize_threshold=0.01),
        iteration_hook=lambda i, a, b: calls.append(i),
    )
    assert len(calls) == problem.num_poses
    assert np.allclose(inc.wTa[:, :2], batch.wTa[:, :2], atol=1e-3)  # sigmas are 3 cm
    assert np.allclose(inc.w_landmarks, batch.w_landmarks, atol=1e-3)
    assert abs(inc.final_error - batch.final_error) < 1e-4 * batch.final_error
    for init in (Initialisation.LAGO, Initialisation.INCREMENTAL, Initialisation.ODOMETRY):
        other = solve(problem, replace(opts, initialisation=init))
        assert abs(other.final_error - batch.final_error) < 1e-6 * batch.final_error + 1e-9


def test_iteration_hook_reports_decreasing_error():
    problem, _, _ = make_world(seed=5, compass_bias=None)
    seen = []
    solve(problem, SolveOptions(reject_outliers=False), iteration_hook=lambda i, a, b: seen.append((i, a, b)))
    assert seen and seen[0][0] == 1
    assert all(b <= a + 1e-9 for _, a, b in seen)


def test_bad_inputs_raise_graph_error():
    with pytest.raises(GraphError, match="positive definite"):
        RelativePoseMeasurements([0], [1], [[1, 0, 0]], [np.diag([1.0, 0.0, 1.0])], "loop")
    rel = RelativePoseMeasurements([0], [5], [[1, 0, 0]], [np.eye(3)], "loop")
    with pytest.raises(GraphError, match="anchor index"):
        SlamProblem(3, rel)
    with pytest.raises(GraphError, match="sigma"):
        HeadingMeasurements([0], [0.1], [0.0])
    with pytest.raises(GraphError, match="no measurements"):
        solve(SlamProblem(2), SolveOptions(fix_first=False))


def test_auto_initialisation_keeps_the_lowest_error_start():
    """A wrong initial guess (the true chain with every heading flipped by ~pi/2 steps) traps LM; AUTO tries the
    other starts and returns the best, reporting every candidate's final error."""
    problem, wTa, _ = make_world(seed=3, compass_bias=None)
    rng = np.random.default_rng(0)
    bad = problem.initial_wTa.copy()
    bad[:, 2] = geo.wrap(bad[:, 2] + rng.choice([-2.5, 2.5], size=bad.shape[0]))
    bad[:, :2] += rng.normal(0.0, 3.0, size=(bad.shape[0], 2))
    bad[0] = problem.initial_wTa[0]
    trapped = replace(problem, initial_wTa=bad)
    opts = SolveOptions(reject_outliers=False, build=BuildOptions().without_kernels())
    auto = solve(trapped, replace(opts, initialisation=Initialisation.AUTO))
    singles = {c: solve(trapped, replace(opts, initialisation=c)).final_error for c in opts.auto_candidates}
    assert auto.final_error == pytest.approx(min(singles.values()), rel=1e-9)
    assert dict(auto.candidates).keys() <= singles.keys()
    assert auto.initialisation in singles and auto.initialisation is not Initialisation.AUTO
    assert auto.final_error < singles[Initialisation.PROBLEM]  # the bad guess is not the best start
    assert rmse_xy(auto.wTa, wTa) < 0.5


def test_isam2_final_lm_iterations_polish():
    problem, _, _ = make_world(seed=4, compass_bias=None)
    opts = SolveOptions(reject_outliers=False, build=BuildOptions().without_kernels(), method=Method.ISAM2)
    raw = solve(problem, opts)
    polished = solve(problem, replace(opts, isam2_final_lm_iterations=2))
    batch = solve(problem, replace(opts, method=Method.BATCH))
    assert polished.final_error <= raw.final_error + 1e-12
    assert polished.final_error == pytest.approx(batch.final_error, rel=1e-6)


def _keep_rows(lm: LandmarkMeasurements, keep: np.ndarray, a_position: np.ndarray) -> LandmarkMeasurements:
    return LandmarkMeasurements(
        lm.i[keep], tuple(lm.landmark[k] for k in keep), a_position[keep], lm.cov_a_position[keep]
    )


def test_disagreeing_pair_is_kept_and_averaged(clean):
    """An object seen exactly twice whose sightings disagree beyond chi2 has no majority: both stay and it sits
    at their mean (rejecting one kept, on sim/s11/x2, the sighting that was 9 cm off)."""
    problem, wTa, objects, _ = clean
    lm = problem.landmarks
    counts = {n: lm.landmark.count(n) for n in set(lm.landmark)}
    name = max(counts, key=counts.get)
    rows = [k for k in range(len(lm)) if lm.landmark[k] == name]
    first, last = rows[0], rows[-1]
    keep = np.array([k for k in range(len(lm)) if lm.landmark[k] != name or k in (first, last)])
    shift_w = np.array([0.5, 0.0])  # 10 sigma of one sighting: each pair member's residual is ~25 > 18.4
    pos = np.array(lm.a_position)
    pos[last] += geo.rot2(wTa[lm.i[last], 2]).T @ shift_w
    sol = solve(replace(problem, landmarks=_keep_rows(lm, keep, pos)))
    rejected = {int(keep[r.index]) for r in sol.rejected if r.family is MeasurementFamily.LANDMARK}
    assert not rejected & {first, last}
    assert np.hypot(*(sol.landmark(name) - (objects[name] + shift_w / 2))) < 0.1
    assert sol.moved_objects == ()


def test_moved_object_seen_once_before_is_an_outlier_not_a_move(clean):
    """The sim misses (s10/s11, O06): one sighting before the move and two or more after. One sighting cannot
    tell a move from a bad sighting (corrupt10% shifts single sightings 1-2 m), so it is rejected, not reported
    as a move; the object is placed where it is now."""
    problem, wTa, objects, _ = clean
    lm = problem.landmarks
    counts = {n: lm.landmark.count(n) for n in set(lm.landmark)}
    name = max(counts, key=counts.get)
    half = problem.num_poses // 2
    rows = [k for k in range(len(lm)) if lm.landmark[k] == name]
    before = [k for k in rows if lm.i[k] < half]
    after = [k for k in rows if lm.i[k] >= half]
    assert len(before) >= 2 and len(after) >= 2
    new_w = objects[name] + np.array([0.6, 0.5])
    pos = np.array(lm.a_position)
    for k in after:
        pos[k] += geo.rot2(wTa[lm.i[k], 2]).T @ (new_w - objects[name])
    keep = np.array([k for k in range(len(lm)) if k not in before[1:]])
    sol = solve(replace(problem, landmarks=_keep_rows(lm, keep, pos)))
    rejected = {int(keep[r.index]) for r in sol.rejected if r.family is MeasurementFamily.LANDMARK}
    assert before[0] in rejected
    assert sol.moved_objects == ()
    assert np.hypot(*(sol.landmark(name) - new_w)) < 0.1
    # the same world with a second sighting before the move is reported as a move
    keep2 = np.array([k for k in range(len(lm)) if k not in before[2:]])
    sol2 = solve(replace(problem, landmarks=_keep_rows(lm, keep2, pos)))
    assert [m.object_id for m in sol2.moved_objects] == [name]
