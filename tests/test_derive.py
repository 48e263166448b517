"""Logs derived from a log (``holoslam.derive``): a log played several times end to end, as a robot carried back
to its start would record it."""

import math

import numpy as np
import pytest

from holoslam import derive
from holoslam import geometry as g
from holoslam.types import GroundTruthPose, LogData, Odometry, Pose2, Scan


def _drive() -> LogData:
    """Three stamps 1 s apart: a robot driving 1 m forward and turning 90 deg, odometry and truth alike."""
    poses = [np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, math.pi / 2])]
    t = [k * 1_000_000_000 for k in range(3)]
    scan = dict(frame_id="laser", angle_min=-1.0, angle_increment=1.0, range_min=0.1, range_max=10.0,
                ranges=np.ones(3), valid=np.ones(3, bool))
    return LogData(source="drive.mcap", odometry=tuple(Odometry(s, Pose2.from_array(p)) for s, p in zip(t, poses, strict=True)),
                   scans=tuple(Scan(stamp_ns=s, **scan) for s in t),
                   ground_truth=tuple(GroundTruthPose(s, Pose2.from_array(p)) for s, p in zip(t, poses, strict=True)))


def test_each_copy_follows_the_last_with_the_odometer_counting_on_and_the_truth_repeating():
    log = _drive()
    twice, span = derive.repeat(log, 2), derive.repeat_span_ns(log)
    assert span == 3_000_000_000  # the scans' 2 s and 1 s between the copies
    assert [s.stamp_ns for s in twice.scans] == [0, 1_000_000_000, 2_000_000_000, 3_000_000_000, 4_000_000_000,
                                                 5_000_000_000]
    odo = np.array([o.odomTb.as_array() for o in twice.odometry])
    # the second copy's odometry starts where the first ended (the carry is not in it) and moves as the first did
    np.testing.assert_allclose(odo[3], odo[2], atol=1e-12)
    np.testing.assert_allclose(g.between(odo[3], odo[4]), g.between(odo[0], odo[1]), atol=1e-12)
    # the truth: the robot is back at its start, and drives the same path again
    truth = np.array([p.wTb.as_array() for p in twice.ground_truth])
    assert [p.stamp_ns for p in twice.ground_truth] == [s.stamp_ns for s in twice.scans]
    np.testing.assert_allclose(truth[3:], truth[:3], atol=1e-12)


def test_a_repeat_needs_a_whole_count_and_odometry():
    with pytest.raises(ValueError, match="times must be an integer"):
        derive.repeat(_drive(), 0)
    with pytest.raises(ValueError, match="no odometry"):
        derive.repeat(LogData(source="drive.mcap", scans=_drive().scans), 2)
