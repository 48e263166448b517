"""The joint solve holds the stored map (``LifelongConfig.hold_stored``): the stored anchors are their sessions'
keyframe solve, which their stored anchor-level factors cannot reproduce, so a new session is solved onto them
instead of re-solving them from those factors (intel in 3 sessions: x3.07 of the whole log before, README)."""

from __future__ import annotations

import numpy as np

from holoslam.graph.problem import LandmarkMeasurements, RelativePoseMeasurements
from holoslam.lifelong.joint import joint_problem, solve_joint
from holoslam.lifelong.session import LifelongConfig
from holoslam.relocalise import LaserMatch
from holoslam.store.records import StoredFactors, StoredSightings, StoredSubmap

COV = np.diag([0.02**2, 0.02**2, 1e-6])


def _submap(i, wTa):
    return StoredSubmap(i, 1, i, i, np.asarray(wTa, float), None, np.asarray(wTa, float), (0.0, 0.0), 0.05, None)


def _problem(hold: bool):
    """Stored anchors at x = 0 and 4 m (the keyframe solve's); their stored factor says 4.2 m (the anchor-level
    estimate, 0.2 m off); the new session's two anchors, 4 m apart, each matched into one stored submap."""
    stored = (_submap(1, (0.0, 0.0, 0.0)), _submap(2, (4.0, 0.0, 0.0)))
    factors = StoredFactors(np.array([1]), np.array([1]), np.array([1]), np.array([2]), np.array([[4.2, 0.0, 0.0]]),
                            np.array([np.diag([0.05**2, 0.05**2, 1e-6])]), np.array(["scan_match"], object))
    none = StoredSightings(np.zeros(0, np.int64), (), (), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0))
    new_rel = RelativePoseMeasurements(np.array([0]), np.array([1]), np.array([[4.0, 0.0, 0.0]]), np.array([COV]),
                                       np.array(["scan_match"], object))
    new_lm = LandmarkMeasurements(np.zeros(0, np.int64), (), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    cross = (LaserMatch(0, 1, np.zeros(3), COV, 0.8, np.zeros(3)), LaserMatch(1, 2, np.zeros(3), COV, 0.8, np.zeros(3)))
    sTa = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
    return joint_problem(stored, factors, none, sTa, new_rel, new_lm, {}, np.zeros(3), cross, {}, hold_stored=hold)


def test_the_new_session_is_solved_onto_the_held_stored_map():
    held = solve_joint(_problem(True), covariances=False)
    assert np.allclose(held.stored_wTa, [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]], atol=1e-3)
    assert np.allclose(held.new_wTa[:, 0], [0.0, 4.0], atol=0.01)  # on the stored map, where its matches put it
    moved = solve_joint(_problem(False), covariances=False)
    assert moved.stored_wTa[1, 0] > 4.03  # re-solved from its anchor-level factor, the stored map leaves the keyframe solve


def test_the_stored_map_is_held_and_closed_on_densely_by_default():
    lc = LifelongConfig()
    assert lc.hold_stored and lc.dense_closures
