"""Method.ISAM2 with the outlier scheme: the rounds run on the iSAM2 object (factors removed, re-added, swapped
for their Gaussian twins), never batch LM, the solution says isam2, and the answer is batch LM's."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from graph_worlds import make_world

import holoslam.solve as solve_mod
from holoslam import geometry as geo
from holoslam.graph.problem import HeadingMeasurements, RelativePoseMeasurements
from holoslam.solve import CovarianceScope, Method, SolveOptions, solve

ISAM2 = SolveOptions(method=Method.ISAM2, covariances=CovarianceScope.ALL, isam2_relinearize_threshold=1e-3)


def _clean():
    return make_world(seed=1)


def _moved():
    problem, wTa, objects = make_world(seed=1)
    lm = problem.landmarks
    counts = {n: lm.landmark.count(n) for n in set(lm.landmark)}
    name = max(counts, key=counts.get)
    half = problem.num_poses // 2
    new_w = objects[name] + np.array([1.5, -1.0])
    pos = np.array(lm.a_position)
    for m in range(len(lm)):
        if lm.landmark[m] == name and lm.i[m] >= half:
            a = geo.inverse(wTa[lm.i[m]])
            pos[m] = geo.transform_points(a, new_w[None])[0] + pos[m] - geo.transform_points(a, objects[name][None])[0]
    return replace(problem, landmarks=replace(lm, a_position=pos)), wTa, objects


def _wrong_loops():
    problem, wTa, objects = make_world(seed=1)
    rng = np.random.default_rng(7)
    rel, n = problem.relative, problem.num_poses
    fi = rng.choice(n // 2, 5, replace=False)
    fj = fi + rng.integers(3, n // 2, 5)
    off = np.column_stack([rng.uniform(1.0, 3.0, 5), rng.uniform(-2.0, 2.0, 5), rng.uniform(0.5, 1.5, 5)])
    bad = RelativePoseMeasurements(
        np.concatenate([rel.i, fi]),
        np.concatenate([rel.j, fj]),
        np.concatenate([rel.iTj, geo.compose(geo.between(wTa[fi], wTa[fj]), off)]),
        np.concatenate([rel.cov_iTj, rel.cov_iTj[:5]]),
        np.concatenate([rel.kind, np.full(5, "loop", object)]),
    )
    return replace(problem, relative=bad), wTa, objects


def _compass_disturbance():
    problem, wTa, objects = make_world(seed=4, compass_bias=-1.2)
    hd = problem.headings
    yaw = np.array(hd.yaw)
    yaw[10:14] += 0.6
    return replace(problem, headings=HeadingMeasurements(hd.i, yaw, hd.sigma)), wTa, objects


@pytest.fixture()
def no_batch_lm(monkeypatch):
    def refuse(*_a, **_k):
        raise AssertionError("batch Levenberg-Marquardt ran in an iSAM2 solve")

    monkeypatch.setattr(solve_mod, "_batch", refuse)


@pytest.mark.parametrize("world", [_clean, _moved, _wrong_loops, _compass_disturbance])
def test_isam2_outlier_rounds_give_the_batch_answer(world, monkeypatch):
    problem, _, _ = world()
    batch = solve(problem, replace(ISAM2, method=Method.BATCH))
    with monkeypatch.context() as m:
        m.setattr(solve_mod, "_batch", lambda *a, **k: pytest.fail("batch Levenberg-Marquardt ran in iSAM2"))
        inc = solve(problem, ISAM2)
    assert inc.method is Method.ISAM2 and inc.rounds == batch.rounds
    assert set(inc.rejected) == set(batch.rejected)
    assert [m.object_id for m in inc.moved_objects] == [m.object_id for m in batch.moved_objects]
    assert inc.landmark_ids == batch.landmark_ids
    # batch LM stops at relative / absolute error change 1e-5, iSAM2 when no step exceeds 1e-3: both ~1e-5 m
    assert np.abs(inc.wTa[:, :2] - batch.wTa[:, :2]).max() < 1e-4
    assert np.abs(geo.wrap(inc.wTa[:, 2] - batch.wTa[:, 2])).max() < 1e-4
    assert np.abs(inc.w_landmarks - batch.w_landmarks).max() < 1e-4
    assert inc.final_error == pytest.approx(batch.final_error, rel=1e-6)
    assert np.allclose(inc.cov_wTa, batch.cov_wTa, rtol=1e-3, atol=1e-9)
    if batch.compass_bias is not None:
        assert inc.compass_bias == pytest.approx(batch.compass_bias, abs=1e-4)
    for m_inc, m_b in zip(inc.moved_objects, batch.moved_objects, strict=True):
        assert np.allclose(m_inc.w_position_before, m_b.w_position_before, atol=1e-4)
        assert np.allclose(m_inc.w_position_after, m_b.w_position_after, atol=1e-4)


def test_isam2_rounds_update_the_incremental_solver(no_batch_lm):
    """The rounds are iSAM2 updates after the anchor-by-anchor feed (one update per anchor): more updates than
    anchors, and the wrong loop closures' factors were removed from the iSAM2 graph."""
    problem, _, _ = _wrong_loops()
    updates = []
    sol = solve(problem, ISAM2, iteration_hook=lambda i, a, b: updates.append(i))
    assert sol.method is Method.ISAM2 and sol.rounds >= 2
    assert updates == list(range(1, sol.iterations + 1)) and sol.iterations > problem.num_poses
    n = len(problem.relative)
    assert {r.index for r in sol.rejected} >= set(range(n - 5, n))


def test_isam2_polish_is_the_only_lm(monkeypatch):
    problem, _, _ = _clean()
    ran = []
    real = solve_mod._batch

    def spy(graph, values, options, hook, errors=None, stop=None):
        ran.append(options.max_iterations)
        return real(graph, values, options, hook, errors, stop)

    monkeypatch.setattr(solve_mod, "_batch", spy)
    sol = solve(problem, replace(ISAM2, isam2_final_lm_iterations=2))
    assert ran == [2] and sol.method is Method.ISAM2


@pytest.mark.slow
def test_pipeline_with_isam2_reports_it_and_maps_what_batch_maps(tmp_path):
    from holoslam.pipeline import RunConfig, SolverConfig, SolverMethod, run
    from holoslam.sim import SimConfig, simulate_to_file

    log = tmp_path / "short.mcap"
    simulate_to_file(log, SimConfig(seed=7, duration_s=120.0, image_rate_hz=0.5))
    lm = run(log, RunConfig())
    inc = run(log, RunConfig(solver=SolverConfig(method=SolverMethod.ISAM2)))
    assert lm.report.solver.method == "batch" and inc.report.solver.method == "isam2"
    assert inc.report.solver.rejected_measurements == lm.report.solver.rejected_measurements
    assert inc.report.factors["object_landmark"] > 0  # objects were seen: landmark rounds ran
    # the anchors are the keyframe solve's, seeded by either solver's anchors: 0.11 mm apart at most (measured)
    assert np.abs(inc.wTa[:, :2] - lm.wTa[:, :2]).max() < 2e-4
    assert [o.object_id for o in inc.objects] == [o.object_id for o in lm.objects]
    pos_inc = np.array([o.w_position[:2] for o in inc.objects])
    pos_lm = np.array([o.w_position[:2] for o in lm.objects])
    assert np.abs(pos_inc - pos_lm).max() < 1e-4
    assert inc.report.solver.final_error == pytest.approx(lm.report.solver.final_error, rel=1e-6)
