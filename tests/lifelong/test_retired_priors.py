"""Retired submaps keep what they saw of unchanged objects: their sightings, fused per placement, enter the joint
graph as sightings from one virtual anchor held by a prior (``joint.retired_priors``, ``joint_problem``)."""

from __future__ import annotations

import numpy as np

from holoslam import geometry as g
from holoslam.graph.problem import LandmarkMeasurements, RelativePoseMeasurements
from holoslam.lifelong.joint import joint_problem, retired_priors, solve_joint
from holoslam.store.records import StoredFactors, StoredSightings, StoredSubmap


def _submap(i, wTa, cov=None):
    return StoredSubmap(i, 1, i, i, np.asarray(wTa, float), cov, np.asarray(wTa, float), (0.0, 0.0), 0.05, 9)


def _sightings(rows):
    """rows: (submap id, placement, world xy, anchor wTa, sigma)"""
    a = np.array([g.transform_points(g.inverse(np.asarray(T, float)), np.asarray(w, float)[None])[0]
                  for _i, _p, w, T, _s in rows]).reshape(-1, 2)
    return StoredSightings(np.array([r[0] for r in rows], np.int64), tuple(r[1].split("#")[0] for r in rows),
                           tuple(r[1] for r in rows), a, np.array([np.eye(2) * r[4] ** 2 for r in rows]),
                           np.full(len(rows), 0.5))


def test_retired_sightings_fuse_by_information_per_placement():
    T1, T2 = (1.0, 2.0, 0.3), (-2.0, 0.5, -1.2)
    subs = (_submap(1, T1), _submap(2, T2, np.diag([1e-4, 1e-4, 1e-6])))
    rows = [(1, "A#1", (3.0, 3.0), T1, 0.01), (1, "A#1", (3.02, 3.0), T1, 0.01),  # one anchor, two sightings
            (2, "A#1", (3.1, 3.0), T2, 0.02), (2, "B#1", (0.0, 5.0), T2, 0.01), (2, "C#2", (9.0, 9.0), T2, 0.01)]
    pri = retired_priors(subs, _sightings(rows), {"A#1", "B#1"})
    assert pri.names == ("A#1", "B#1") and pri.sightings.tolist() == [3, 1]  # C#2 is no longer a live placement
    # anchor 1: mean (3.01, 3) with variance 0.01^2 / 2; anchor 2: (3.1, 3) with 0.02^2 + the anchor's 1e-4 (x, y)
    # and its heading's 1e-6 rad^2 times the lever arm: fused by information
    v1, v2x = 0.01**2 / 2, 0.02**2 + 1e-4
    a2 = g.transform_points(g.inverse(np.array(T2)), np.array([[3.1, 3.0]]))[0]
    lever = np.hypot(*a2)
    assert np.isclose(pri.w_xy[0, 0], (3.01 / v1 + 3.1 / v2x) / (1 / v1 + 1 / v2x), atol=2e-4)
    assert 0.9 * v1 * v2x / (v1 + v2x) < pri.cov_w_xy[0, 0, 0] < v1
    assert np.isclose(pri.cov_w_xy[0, 1, 1], 1 / (1 / v1 + 1 / (0.02**2 + 1e-4 + 1e-6 * lever**2)), rtol=0.35)
    assert np.allclose(pri.w_xy[1], (0.0, 5.0), atol=1e-9)


def test_the_joint_solve_uses_the_retired_sightings():
    """One working anchor at the origin sees A badly (10 cm); the retired anchors saw A well (5 mm each): the
    joint estimate of A follows them, and the working anchors stay where the gauge holds them."""
    stored = (_submap(5, (0.0, 0.0, 0.0)),)
    work = _sightings([(5, "A#1", (2.1, 1.0), (0, 0, 0), 0.1)])
    factors = StoredFactors(*(np.zeros(0, np.int64),) * 4, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, object))
    new_rel = RelativePoseMeasurements(np.array([0]), np.array([1]), np.array([[1.0, 0.0, 0.0]]),
                                       np.array([np.diag([1e-4, 1e-4, 1e-6])]), np.array(["scan_match"], object))
    new_lm = LandmarkMeasurements(np.zeros(0, np.int64), (), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    retired = (_submap(1, (0.0, 0.0, 0.0), np.diag([1e-6, 1e-6, 1e-8])), _submap(2, (1.0, 0.0, 0.5), np.diag([1e-6, 1e-6, 1e-8])))
    pri = retired_priors(retired, _sightings([(1, "A#1", (2.0, 1.0), (0, 0, 0), 0.005),
                                              (2, "A#1", (2.0, 1.0), (1.0, 0.0, 0.5), 0.005)]), {"A#1"})
    from holoslam.relocalise import LaserMatch

    cross = (LaserMatch(0, 5, np.zeros(3), np.diag([1e-4, 1e-4, 1e-6]), 0.8, np.zeros(3)),)
    sTa = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    args = (stored, factors, work, sTa, new_rel, new_lm, {}, np.zeros(3), cross, {"A#1": np.array([2.1, 1.0])})
    without = solve_joint(joint_problem(*args), covariances=False)
    jg = joint_problem(*args, pri)
    assert jg.prior_placements == 1 and jg.problem.num_poses == 4
    with_ = solve_joint(jg, covariances=False)
    assert np.hypot(*(without.placements["A#1"][0] - (2.1, 1.0))) < 0.01
    assert np.hypot(*(with_.placements["A#1"][0] - (2.0, 1.0))) < 0.01
    assert with_.new_wTa.shape == (2, 3) and np.allclose(with_.stored_wTa[0], 0.0, atol=1e-3)


def test_a_stored_part_cut_off_by_retirement_is_held_at_its_stored_pose():
    """Stored anchors 0 and 1 lost the factor between them (the submaps between were retired); the new session
    matches only anchor 0: anchor 1 gets a prior at its stored pose (else it floats and GTSAM's marginals fail)."""
    from holoslam.relocalise import LaserMatch

    stored = (_submap(1, (0.0, 0.0, 0.0)), _submap(2, (5.0, 1.0, 0.4), np.diag([4e-4, 4e-4, 1e-5])))
    factors = StoredFactors(*(np.zeros(0, np.int64),) * 4, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, object))
    none = _sightings([])
    new_rel = RelativePoseMeasurements(np.array([0]), np.array([1]), np.array([[1.0, 0.0, 0.0]]),
                                       np.array([np.diag([1e-4, 1e-4, 1e-6])]), np.array(["scan_match"], object))
    new_lm = LandmarkMeasurements(np.zeros(0, np.int64), (), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    cross = (LaserMatch(0, 1, np.zeros(3), np.diag([1e-4, 1e-4, 1e-6]), 0.8, np.zeros(3)),)
    jg = joint_problem(stored, factors, none, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), new_rel, new_lm, {},
                       np.zeros(3), cross, {})
    pri = {p.i: p for p in jg.problem.priors}
    assert set(pri) == {0, 1} and np.allclose(pri[1].wTa, (5.0, 1.0, 0.4))
    assert np.allclose(pri[1].cov_wTa, np.diag([4e-4, 4e-4, 1e-5]), atol=1e-8)
    js = solve_joint(jg)  # with covariances: no indeterminate anchor
    assert js.covariances_failed == "" and js.stored_cov is not None
    assert np.allclose(js.stored_wTa[1], (5.0, 1.0, 0.4), atol=1e-6)
