"""The run's trajectory between optimised keyframes (``holoslam.trajectory.optimised_trajectory``) and the
scans localised between them (``node_keyframe_poses``)."""

from types import SimpleNamespace

import numpy as np

from holoslam import geometry as g
from holoslam.trajectory import node_keyframe_poses, optimised_trajectory


def _drive(n: int = 201, dt_ns: int = 50_000_000):
    """A robot driving an arc of radius 2.5 m at 0.5 m/s; its odometry reads 8 % short and turns 10 % too little."""
    t = np.arange(n, dtype=np.int64) * dt_ns
    th = 0.2 * t * 1e-9
    true = np.c_[2.5 * np.sin(th), 2.5 * (1 - np.cos(th)), th]
    step = g.between(true[:-1], true[1:]) * np.array([0.92, 0.92, 0.9])
    odo = [true[0]]
    for d in step:
        odo.append(g.compose(odo[-1], d))
    return t, true, np.array(odo)


def test_between_keyframes_the_pose_runs_into_the_next_instead_of_jumping():
    t, true, odo = _drive()
    key = np.arange(0, len(t), 14)  # keyframes every 0.7 s (a 1.4 Hz laser), exact
    wTb = optimised_trajectory(t, t, odo, t[key], true[key])
    np.testing.assert_allclose(wTb[key], true[key], atol=1e-9)  # the keyframes themselves are kept
    err = np.hypot(*(wTb[:, :2] - true[:, :2]).T)
    # composing from the last keyframe alone leaves the odometry's error over up to 0.7 s: 2-3 cm here
    alone = np.array([g.compose(true[key][j], g.between(odo[key][j], odo[i]))
                      for i, j in enumerate(np.clip(np.searchsorted(key, np.arange(len(t)), side="right") - 1, 0,
                                                    len(key) - 1))])
    err_alone = np.hypot(*(alone[:, :2] - true[:, :2]).T)
    inside = slice(0, key[-1] + 1)
    assert err_alone[inside].max() > 0.02
    assert err[inside].max() < 0.001  # the odometry's error spread over each 0.7 s: a fraction of a millimetre
    heading = np.abs(g.wrap(wTb[:, 2] - true[:, 2]))
    assert heading[: key[-1]].max() < np.radians(0.1)


def test_before_the_first_and_after_the_last_keyframe_the_odometry_carries_the_pose():
    t, true, odo = _drive()
    key = np.array([40, 100])
    wTb = optimised_trajectory(t, t, odo, t[key], true[key])
    after = g.compose(true[100], g.between(odo[100], odo[150]))
    before = g.compose(true[40], g.between(odo[40], odo[10]))
    np.testing.assert_allclose(wTb[150], after, atol=1e-9)
    np.testing.assert_allclose(wTb[10], before, atol=1e-9)


def test_a_scan_tracked_between_two_keyframes_follows_both_of_their_solved_poses():
    # a submap with keyframes at 0 and 1 s; the node solve moved the second 4 cm and 0.6 deg relative to where the
    # submap's frame put it (what the solve corrects of local SLAM between them). A scan localised (not inserted) at
    # 0.75 s takes three quarters of that correction, instead of hanging from the first keyframe alone
    aTk = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
    sm = SimpleNamespace(scan_stamps_ns=np.array([0, 1_000_000_000]), aTb=aTk,
                         track_stamps_ns=np.array([750_000_000]), track_aTb=np.array([[0.375, 0.0, 0.0]]))
    wTs = np.array([2.0, 1.0, 0.3])  # the submap's frame as the first keyframe's solved pose puts it
    fix = np.array([0.04, 0.0, np.radians(0.6)])
    wTn = np.array([g.compose(wTs, aTk[0]), g.compose(g.compose(wTs, fix), aTk[1])])
    stamps, poses = node_keyframe_poses([sm], sm.scan_stamps_ns, wTn)
    assert stamps.tolist() == [0, 750_000_000, 1_000_000_000]
    expected = g.compose(g.compose(wTs, 0.75 * fix), sm.track_aTb[0])
    np.testing.assert_allclose(poses[1], expected, atol=1e-12)
    hung_from_first = g.compose(wTs, sm.track_aTb[0])
    assert np.hypot(*(poses[1][:2] - hung_from_first[:2])) > 0.025
