"""Logs derived from a log (``holoslam.derive``): a log played several times end to end, as a robot carried back
to its start would record it; a biased odometer."""

import math

import numpy as np
import pytest

from holoslam import derive
from holoslam import geometry as g
from holoslam.types import GroundTruthPose, LogData, Odometry, Pose2, Scan, Transform


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


def test_a_biased_odometer_drives_its_steps_longer_and_turns_with_the_distance():
    log = _drive()
    tf = Transform(stamp_ns=2_000_000_000, parent="odom", child="base_link", translation=(1.0, 0.0, 0.0),
                   rotation_xyzw=(0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)), static=False)
    log = LogData(source=log.source, odometry=log.odometry, scans=log.scans, ground_truth=log.ground_truth,
                  transforms=(tf,))
    same = derive.bias_odometry(log, 1.0, 0.0)
    np.testing.assert_allclose([o.odomTb.as_array() for o in same.odometry],
                               [o.odomTb.as_array() for o in log.odometry], atol=1e-12)
    biased = derive.bias_odometry(log, 1.05, 2.0)
    odo = np.array([o.odomTb.as_array() for o in biased.odometry])
    # the 1 m step is 1.05 m and turns by 2.1 deg; the turn in place adds no bias: 90 deg more
    np.testing.assert_allclose(odo[1], [1.05, 0.0, math.radians(2.1)], atol=1e-12)
    np.testing.assert_allclose(odo[2], [1.05, 0.0, math.radians(92.1)], atol=1e-12)
    # the odometry frame's transform at the last stamp moved with the pose there; the scans and truth unchanged
    (moved,) = biased.transforms
    assert moved.translation[:2] == pytest.approx((1.05, 0.0), abs=1e-12)
    assert 2 * math.atan2(moved.rotation_xyzw[2], moved.rotation_xyzw[3]) == pytest.approx(math.radians(92.1))
    assert biased.scans == log.scans and biased.ground_truth == log.ground_truth
    with pytest.raises(ValueError, match="scale must be"):
        derive.bias_odometry(log, 0.0, 0.0)


def test_the_real_log_benchmarks_wobble_scales_the_odometer_alone():
    """benchmarks/bench_realdata.py's ``drift@S``: the odometer scaled by S, no heading drift (how far a log's
    figure moves with a change no calibration would notice); names outside 0.5 < S < 1.5 are refused."""
    import argparse

    from repo_paths import REPO, benchmark_module

    from holoslam.io.mcap import read_log

    bench = benchmark_module("bench_realdata")
    log, _ = read_log(REPO / "datasets" / "household_small.mcap", require=["odometry", "scan"])
    wobbled, at = bench.variant_log(log, "drift@1.002")
    assert at is None

    def path(lg):
        _st, P = lg.odometry_arrays()
        return float(np.hypot(*np.diff(P[:, :2], axis=0).T).sum()), P[-1, 2] - P[0, 2]

    (d0, h0), (d1, h1) = path(log), path(wobbled)
    assert d1 / d0 == pytest.approx(1.002, abs=1e-9) and h1 == pytest.approx(h0, abs=1e-9)
    assert bench.variant_name("sparse_drift@0.998") == "sparse_drift@0.998"
    for bad in ("drift@3", "drift@x", "full@1.002"):
        with pytest.raises(argparse.ArgumentTypeError):
            bench.variant_name(bad)


def test_the_real_log_benchmarks_short_laser_cuts_the_returns_beyond_its_range():
    """benchmarks/bench_realdata.py's ``short`` / ``short@R``: every return beyond 8 m (R m) becomes a no-return,
    the rest of the log unchanged; ranges outside 0.5 < R < 100 are refused."""
    import argparse

    from repo_paths import REPO, benchmark_module

    from holoslam.io.mcap import read_log

    bench = benchmark_module("bench_realdata")
    log, _ = read_log(REPO / "datasets" / "household_small.mcap", require=["odometry", "scan"])
    for name, reach in (("short", bench.SHORT_RANGE_M), ("short@2.5", 2.5)):
        short, at = bench.variant_log(log, name)
        assert at is None and len(short.scans) == len(log.scans) and short.odometry == log.odometry
        before = np.concatenate([s.ranges[s.valid] for s in log.scans])
        after = np.concatenate([s.ranges[s.valid] for s in short.scans])
        assert after.max() <= reach and after.size == np.count_nonzero(before <= reach)
    assert (before > 2.5).any()  # the household's laser reaches beyond 2.5 m: the cut did something
    assert bench.variant_name("short@5") == "short@5"
    for bad in ("short@0.2", "short@x", "sparse@5"):
        with pytest.raises(argparse.ArgumentTypeError):
            bench.variant_name(bad)


def test_dropped_returns_take_their_share_of_the_returns_the_same_ones_for_the_same_seed():
    """``derive.drop_returns``: each return a no-return with the given probability, independently; the ranges, the
    stamps and the beams already without a return untouched; the same seed, the same holes; shares outside [0, 1]
    refused. The bench's ``holes`` (12 %, the held-out hospital laser's share) and ``sparse_holes@F``."""
    import argparse

    from repo_paths import REPO, benchmark_module

    from holoslam.io.mcap import read_log

    log, _ = read_log(REPO / "datasets" / "household_small.mcap", require=["odometry", "scan"])
    before = np.concatenate([s.valid for s in log.scans])
    holed = derive.drop_returns(log, 0.25, seed=3)
    after = np.concatenate([s.valid for s in holed.scans])
    assert not (after & ~before).any()  # no beam without a return gained one
    share = 1.0 - after.sum() / before.sum()
    n = before.sum()
    assert abs(share - 0.25) < 4 * math.sqrt(0.25 * 0.75 / n)  # binomial: within 4 sigma of the share
    assert all(np.array_equal(a.ranges, b.ranges) and a.stamp_ns == b.stamp_ns
               for a, b in zip(log.scans, holed.scans, strict=True))
    again = np.concatenate([s.valid for s in derive.drop_returns(log, 0.25, seed=3).scans])
    other = np.concatenate([s.valid for s in derive.drop_returns(log, 0.25, seed=4).scans])
    assert np.array_equal(after, again) and not np.array_equal(after, other)
    assert np.array_equal(np.concatenate([s.valid for s in derive.drop_returns(log, 0.0).scans]), before)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="fraction must be"):
            derive.drop_returns(log, bad)
    bench = benchmark_module("bench_realdata")
    sparse_holed, at = bench.variant_log(log, "sparse_holes@0.5")
    sparse, _ = bench.variant_log(log, "sparse")
    assert at is None and [s.stamp_ns for s in sparse_holed.scans] == [s.stamp_ns for s in sparse.scans]
    kept = np.concatenate([s.valid for s in sparse_holed.scans]).sum()
    assert 0.4 < kept / np.concatenate([s.valid for s in sparse.scans]).sum() < 0.6
    assert bench.variant_name("holes@0.3") == "holes@0.3"
    for bad in ("holes@1.5", "holes@x"):
        with pytest.raises(argparse.ArgumentTypeError):
            bench.variant_name(bad)
