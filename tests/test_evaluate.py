"""holoslam.evaluate: alignment recovers known transforms, errors and coverage behave as defined."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam import geometry as g
from holoslam.evaluate import align_se2, apply_se2, object_errors, trajectory_errors, truth_at

finite = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(x=finite, y=finite, th=st.floats(-3.1, 3.1), seed=st.integers(0, 10_000))
def test_align_recovers_known_transform(x, y, th, seed):
    rng = np.random.default_rng(seed)
    est = rng.uniform(-10, 10, (12, 2))
    T = np.array([x, y, th])
    true = g.transform_points(T, est)
    got = align_se2(est, true)
    np.testing.assert_allclose(got[:2], T[:2], atol=1e-8)
    assert abs(g.wrap(got[2] - th)) < 1e-9


def test_align_is_least_squares_under_noise():
    rng = np.random.default_rng(1)
    est = rng.uniform(-5, 5, (200, 2))
    T = np.array([1.0, -2.0, 0.7])
    true = g.transform_points(T, est) + rng.normal(0, 0.05, est.shape)
    got = align_se2(est, true)
    cost = np.sum((g.transform_points(got, est) - true) ** 2)
    for d in np.eye(3) * 1e-3:  # any small perturbation costs more
        assert np.sum((g.transform_points(got + d, est) - true) ** 2) > cost
        assert np.sum((g.transform_points(got - d, est) - true) ** 2) > cost


def test_align_single_point_is_translation_and_bad_input_raises():
    np.testing.assert_allclose(align_se2(np.array([[1.0, 2.0]]), np.array([[3.0, 5.0]])), [2.0, 3.0, 0.0])
    with pytest.raises(ValueError):
        align_se2(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError):
        align_se2(np.full((2, 2), np.nan), np.zeros((2, 2)))


def test_trajectory_errors_after_alignment_are_zero_for_a_moved_copy():
    rng = np.random.default_rng(2)
    true = np.column_stack([rng.uniform(-5, 5, (30, 2)), rng.uniform(-3, 3, 30)])
    T = np.array([3.0, -1.0, 1.2])
    est = apply_se2(g.inverse(T), true)  # the estimate lives in another world frame
    e = trajectory_errors(est, true)
    assert e.rmse_m < 1e-9 and e.heading_rmse_deg < 1e-7 and e.n == 30
    np.testing.assert_allclose(e.T, T, atol=1e-9)
    raw = trajectory_errors(est, true, align=False)
    assert raw.rmse_m > 0.5


def test_trajectory_errors_values():
    true = np.zeros((4, 3))
    est = np.zeros((4, 3))
    est[1, :2] = [0.3, 0.4]  # 0.5 m off
    est[2, 2] = np.radians(2.0)
    e = trajectory_errors(est, true, align=False)
    assert e.max_m == pytest.approx(0.5)
    assert e.rmse_m == pytest.approx(np.sqrt(0.25 / 4))
    assert e.heading_rmse_deg == pytest.approx(np.sqrt(4.0 / 4))


def _sample_coverage(seed: int, scale: float) -> float:
    """Poses with random body-frame covariances and headings; true = estimate + sampled world-frame error."""
    rng = np.random.default_rng(seed)
    n = 4000
    est = np.column_stack([rng.uniform(-10, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    A = rng.normal(0, 0.1, (n, 3, 3))
    cov_body = A @ np.swapaxes(A, 1, 2) + np.eye(3) * 1e-4
    cov_body[:, 0, 0] *= 9.0  # strongly anisotropic: the frame matters
    L = np.linalg.cholesky(cov_body[:, :2, :2])
    e_body = np.einsum("nij,nj->ni", L, rng.standard_normal((n, 2)))
    R = g.rot2(est[:, 2])
    true = est.copy()
    true[:, :2] += np.einsum("nij,nj->ni", R, e_body)
    return trajectory_errors(est, true, cov_body * scale, align=False).coverage95


def test_coverage_of_sampled_gaussian_is_95_percent_in_the_body_frame():
    c = _sample_coverage(3, 1.0)
    assert abs(c - 0.95) < 0.015
    assert _sample_coverage(3, 0.25) < 0.8  # overconfident covariances are caught


def test_coverage_skips_gauge_pose():
    true = np.zeros((3, 3))
    est = np.zeros((3, 3))
    est[:, 0] = [0.01, 0.0, 0.1]
    cov = np.stack([np.zeros((3, 3)), np.eye(3) * 0.01, np.eye(3) * 0.01])
    e = trajectory_errors(est, true, cov, align=False)
    assert e.n_coverage == 2 and e.coverage95 == pytest.approx(1.0)


def test_object_errors_matching_and_transform():
    T = np.array([1.0, 2.0, np.pi / 2])
    truth = {"a": np.array([1.0, 3.0, 0.5]), "b": np.array([0.0, 2.0, 1.0]), "c": np.array([5.0, 5.0, 0.0])}
    # estimates in the estimate's world frame: inverse-map the truth, perturb b by 0.1 m
    inv = g.inverse(T)
    ids = ["a", "b", "zz", "b@before"]
    est = g.transform_points(inv, np.array([[1.0, 3.0], [0.1, 2.0], [0.0, 0.0], [9.0, 9.0]]))
    o = object_errors(ids, est, truth, T)
    assert o.n_matched == 2
    assert o.errors_m["a"] == pytest.approx(0.0, abs=1e-12)
    assert o.errors_m["b"] == pytest.approx(0.1)
    assert o.missing == ("c",) and o.unexpected == ("zz",)
    assert o.rmse_m == pytest.approx(np.sqrt(0.01 / 2)) and o.max_m == pytest.approx(0.1)
    cov = np.tile(np.eye(2) * 0.03**2, (4, 1, 1))
    o2 = object_errors(ids, est, truth, T, cov)
    assert o2.coverage95 == pytest.approx(0.5)  # a inside, b 3.3 sigma out


def test_truth_at_interpolates_across_wrap():
    t = np.array([0, 1_000_000_000], dtype=np.int64)
    P = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 4.0, -np.pi + 0.1]])
    q = truth_at(np.array([500_000_000, -5, 2_000_000_000]), t, P)
    np.testing.assert_allclose(q[0, :2], [1.0, 2.0])
    assert abs(g.wrap(q[0, 2] - np.pi)) < 1e-12
    np.testing.assert_allclose(q[1], P[0])
    np.testing.assert_allclose(q[2, :2], P[1, :2])
    with pytest.raises(ValueError):
        truth_at(q[:1, 0].astype(np.int64), t[::-1], P)


def test_object_errors_without_estimates_lists_all_missing():
    o = object_errors([], np.zeros((0, 2)), {"a": np.zeros(3)}, np.zeros(3))
    assert o.n_matched == 0 and o.missing == ("a",) and np.isnan(o.rmse_m)
