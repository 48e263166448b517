"""holoslam.evaluate.placement_difference: the join of two parts of a trajectory measured against a reference
run, on synthetic poses with a known misplacement."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.evaluate import placement_difference

S = 1_000_000_000


def _reference(n: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A wandering reference trajectory, one pose per 0.1 s."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack([np.full(n, 0.3), np.zeros(n), rng.normal(0, 0.15, n)])
    P = np.zeros((n, 3))
    for i in range(1, n):
        P[i] = g.compose(P[i - 1], steps[i])
    return np.arange(n, dtype=np.int64) * (S // 10), P


def _about(centre: np.ndarray, dxy: np.ndarray, dth: float) -> np.ndarray:
    """The transform rotating by ``dth`` about ``centre`` and then shifting by ``dxy``."""
    c = np.asarray(centre, float)
    return np.array([*(c - g.rot2(dth) @ c + dxy), dth])


def test_known_misplacement_of_the_second_part_is_measured_in_any_frame():
    t, ref = _reference()
    first, second = t < 150 * S // 10, t >= 250 * S // 10  # a gap in the middle, as in a kidnap
    centre = ref[second, :2].mean(axis=0)
    wrong = _about(centre, np.array([0.06, -0.08]), math.radians(0.7))  # 0.1 m and 0.7 deg at its centroid
    est = ref.copy()
    est[second] = g.compose(np.broadcast_to(wrong, est[second].shape), est[second])
    est[~first & ~second] += [30.0, 5.0, 1.0]  # the gap's poses are wildly off and must not count
    for frame in (np.zeros(3), np.array([-120.0, 45.0, 2.5])):  # the estimate's world frame is arbitrary
        moved = g.compose(np.broadcast_to(frame, est.shape), est)
        d = placement_difference(t, moved, t, ref, first, second)
        assert d.translation_m == pytest.approx(0.1, abs=1e-9)
        assert d.rotation_deg == pytest.approx(0.7, abs=1e-9)
        assert d.n_first == first.sum() and d.n_second == second.sum()
        assert d.rms_first_m < 1e-9 and d.rms_second_m < 1e-9
        np.testing.assert_allclose(g.compose(d.T_first, frame), np.zeros(3), atol=1e-9)  # undoes the frame


def test_a_rigidly_moved_trajectory_is_joined_exactly_and_noise_only_adds_a_little():
    t, ref = _reference(seed=3)
    first, second = t < 200 * S // 10, t >= 200 * S // 10
    est = g.compose(np.broadcast_to(np.array([5.0, -2.0, -1.2]), ref.shape), ref)
    assert placement_difference(t, est, t, ref, first, second).translation_m < 1e-9
    noisy = est + np.random.default_rng(1).normal(0, [0.02, 0.02, 0.0], est.shape)
    d = placement_difference(t, noisy, t, ref, first, second)
    assert 0.0 < d.translation_m < 0.01 and d.rotation_deg < 0.1
    assert d.rms_first_m == pytest.approx(0.02 * math.sqrt(2), rel=0.2)


def test_pairs_by_nearest_stamp_within_max_dt_and_rejects_empty_parts():
    t, ref = _reference()
    first, second = t < 100 * S // 10, t >= 300 * S // 10
    shifted = t + 3_000_000  # 3 ms later than the reference's stamps
    with pytest.raises(ValueError, match="first part"):
        placement_difference(shifted, ref, t, ref, first, second)  # max_dt 0: nothing paired
    d = placement_difference(shifted, ref, t, ref, first, second, max_dt_ns=5_000_000)
    assert d.n_first == first.sum() and d.translation_m < 1e-9
    with pytest.raises(ValueError, match="second part"):
        placement_difference(t, ref, t, ref, first, np.zeros_like(second))
