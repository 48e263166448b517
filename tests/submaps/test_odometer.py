"""The odometer check (holoslam.submaps.odometer): a known bias put on a real robot's odometry is read back, an
unbiased one reads as calibrated, and the report's lines say which."""

from __future__ import annotations

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam.submaps.odometer import OdometerBias, odometer_bias, odometer_text

REALDATA = SHARED / "realdata"


@pytest.fixture(scope="module")
def fr079():
    if not (REALDATA / "fr079.mcap").exists():
        pytest.skip("../shared/realdata is not here")
    from holoslam.io.mcap import read_log

    log, _ = read_log(REALDATA / "fr079.mcap", require=["odometry", "scan"])
    return log


def _check(log, keys_from, odometer_from):
    """The check with ``keys_from``'s odometry at the scans as the keyframes and ``odometer_from``'s odometry."""
    from holoslam.geometry import interpolate_poses

    scans = np.array([s.stamp_ns for s in log.scans], np.int64)
    ks, kT = keys_from.odometry_arrays()
    os_, oT = odometer_from.odometry_arrays()
    return odometer_bias(scans, interpolate_poses(ks, kT, scans), os_, oT)


def test_a_bias_put_on_a_real_robots_odometry_is_read_back(fr079):
    # fr079's own odometry stands for the scans' trajectory (its motion: a real robot's straights and turns), the
    # same odometry with derive.bias_odometry's 5 % and 0.5 deg per metre for the odometer
    from holoslam.derive import bias_odometry

    m = _check(fr079, fr079, bias_odometry(fr079, 1.05, 0.5))
    assert m is not None and m.stretches >= 50
    assert abs(m.scale - 1.05) < 0.003 and abs(m.yaw_deg_per_m - 0.5) < 0.05
    assert m.off and 0 < m.scale_std < 0.003 and 0 < m.yaw_std < 0.1
    same = _check(fr079, fr079, fr079)
    assert same is not None and abs(same.scale - 1.0) < 1e-6 and abs(same.yaw_deg_per_m) < 1e-6 and not same.off
    # the other way round: the odometer 3 % short, turning right
    short = _check(fr079, fr079, bias_odometry(fr079, 0.97, -1.0))
    assert short is not None and abs(short.scale - 0.97) < 0.003 and abs(short.yaw_deg_per_m + 1.0) < 0.05


def test_stretches_where_the_scans_were_blind_along_the_track_are_left_out():
    # 120 m straight at 0.2 m a node with an odometer 4 % long. Along the first 70 m (a bare corridor: the matches
    # blind along the track) the keyframes follow the odometer, 0.208 m a step; then they see the motion again
    n = 600
    t = np.arange(n, dtype=np.int64) * 200_000_000
    odo = np.column_stack([0.208 * np.arange(n), np.zeros(n), np.zeros(n)])
    blind = np.arange(n) < 350
    step = np.where(blind[1:], 0.208, 0.2)
    keys = np.column_stack([np.concatenate([[0.0], np.cumsum(step)]), np.zeros(n), np.zeros(n)])
    diluted = odometer_bias(t, keys, t, odo)  # most stretches read the odometer as right
    assert diluted is not None and abs(diluted.scale - 1.0) < 1e-9
    m = odometer_bias(t, keys, t, odo, blind=blind)
    # a stretch of 2 m holds 10 keyframes, the one across the corridor's end one blind: 24 of the last 25 kept
    assert m is not None and m.stretches == 24 and abs(m.scale - 1.04) < 1e-9
    assert odometer_bias(t, keys, t, odo, blind=np.ones(n, bool)) is None  # nothing left to measure on


def test_too_few_straight_stretches_give_no_measurement():
    # a robot turning on the spot and an arc of a circle: nothing straight to measure on
    t = np.arange(200, dtype=np.int64) * 100_000_000
    th = np.linspace(0, 6 * np.pi, 200)
    arc = np.column_stack([3 * np.sin(th / 3), 3 - 3 * np.cos(th / 3), th / 3])
    assert odometer_bias(t, arc, t, arc) is None
    assert odometer_bias(t, np.zeros((200, 3)), t, np.zeros((200, 3))) is None


def test_the_report_lines_say_how_far_off_and_flag_an_odometer_off_its_calibration():
    ok = OdometerBias(1.004, 0.001, -0.1, 0.05, 40, 80.0).to_dict()
    off = OdometerBias(1.034, 0.005, -3.5, 0.2, 23, 46.6).to_dict()
    assert not ok["off"] and off["off"]
    (line,) = odometer_text(ok)
    assert "0.4 % long" in line and "0.10 deg per metre to the right" in line and "40 straight stretches" in line
    lines = odometer_text(off)
    assert len(lines) == 2 and "3.4 % long" in lines[0] and "wheel radii" in lines[1]
