"""The laser mounting check (holoslam.submaps.mounting): a wheeled robot cannot move sideways, so the scan-matched
laser poses tell how far ahead of the robot's turning centre the laser sits, whatever the log's transform says."""

from __future__ import annotations

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.submaps.mounting import WARN_M, laser_ahead_of_turning_centre

LASER_AHEAD_M = 0.12  # where the laser truly is, ahead of the midpoint of the drive wheels


def _drive(seconds=300.0, hz=5.0, seed=0):
    """A differential-drive robot (the wheels' midpoint moves along its heading) wandering at indoor speeds:
    (stamps_ns, wTc) of its turning centre at the scan stamps."""
    rng = np.random.default_rng(seed)
    n = int(seconds * hz)
    dt = 1.0 / hz
    v = np.clip(0.3 + 0.2 * np.cumsum(rng.normal(0, 0.05, n)), 0.0, 0.6)  # m/s
    w = 0.6 * np.sin(np.arange(n) * dt / 7.0) + rng.normal(0, 0.2, n)  # rad/s
    steps = np.column_stack([v * dt * np.sinc(w * dt / (2 * np.pi)), v * dt * np.sinc(w * dt / (2 * np.pi))
                             * np.tan(w * dt / 2), w * dt])  # the arc's chord in the start frame
    wTc = np.zeros((n, 3))
    for k in range(1, n):
        wTc[k] = g.compose(wTc[k - 1], steps[k])
    return (np.arange(n) * dt * 1e9).astype(np.int64), wTc


def _laser_poses(wTc, noise_m=0.003, noise_deg=0.15, seed=1):
    rng = np.random.default_rng(seed)
    wTl = g.compose(wTc, np.array([LASER_AHEAD_M, 0.0, 0.0]))
    return wTl + np.column_stack([rng.normal(0, noise_m, (len(wTl), 2)), rng.normal(0, np.radians(noise_deg), len(wTl))])


def test_the_chord_of_the_simulated_drive_leans_by_half_the_turn():
    """The fixture itself: the turning centre never moves sideways beyond its arc."""
    _t, wTc = _drive()
    d = g.between(wTc[:-1], wTc[1:])
    np.testing.assert_allclose(d[:, 1], d[:, 0] * np.tan(d[:, 2] / 2), atol=1e-12)


@pytest.mark.parametrize("tf_x", [LASER_AHEAD_M, 0.0, -0.04])
def test_the_laser_is_placed_from_the_motion_whatever_the_transform_says(tf_x):
    """Base poses from noisy laser poses (3 mm, 0.15 deg) and a transform that may be wrong: the laser is found
    0.12 m ahead of the turning centre within 5 mm, inside three standard errors, and the report's flag is raised
    exactly when the transform puts base_link more than WARN_M from that centre."""
    stamps, wTc = _drive()
    bTs = np.array([tf_x, 0.05, 0.0])  # a sideways offset is allowed (and not observable)
    wTb = g.compose(_laser_poses(wTc), g.inverse(bTs))
    m = laser_ahead_of_turning_centre(stamps, wTb, bTs)
    assert m is not None and m.turns > 500
    assert abs(m.laser_x_m - LASER_AHEAD_M) < 0.005
    assert abs(m.laser_x_m - LASER_AHEAD_M) < 3 * m.laser_x_std_m + 1e-3
    assert m.laser_x_std_m < 0.003
    assert m.centre_in_base_x_m == pytest.approx(tf_x - LASER_AHEAD_M, abs=0.005)
    assert m.base_off_centre == (abs(tf_x - LASER_AHEAD_M) > WARN_M)


def test_a_laser_behind_the_turning_centre_has_a_negative_offset():
    stamps, wTc = _drive(seed=3)
    wTl = g.compose(wTc, np.array([-0.05, 0.0, 0.0]))
    m = laser_ahead_of_turning_centre(stamps, wTl, np.zeros(3))
    assert m is not None and m.laser_x_m == pytest.approx(-0.05, abs=0.002)


def test_a_few_wrong_matches_do_not_move_the_estimate():
    """One scan pair in fifty thrown 10 cm sideways (a wrong match): the Huber weights keep the estimate."""
    stamps, wTc = _drive(seed=4)
    wTl = _laser_poses(wTc)
    wrong = np.arange(5, len(wTl), 50)
    wTl[wrong] = g.compose(wTl[wrong], np.array([0.0, 0.10, 0.0]))
    m = laser_ahead_of_turning_centre(stamps, wTl, np.zeros(3))
    assert m is not None and abs(m.laser_x_m - LASER_AHEAD_M) < 0.006


def test_a_robot_that_hardly_turns_gives_no_answer():
    stamps = np.arange(400, dtype=np.int64) * 200_000_000
    wTb = np.column_stack([np.arange(400) * 0.06, np.zeros(400), np.full(400, 0.3)])
    assert laser_ahead_of_turning_centre(stamps, wTb, np.zeros(3)) is None
    assert laser_ahead_of_turning_centre(stamps[:1], wTb[:1], np.zeros(3)) is None


def test_gaps_in_the_log_are_left_out():
    """A pair of scans two seconds apart is not an arc: without the gap rule the estimate moves."""
    stamps, wTc = _drive(seed=5)
    stamps = stamps.copy()
    stamps[700:] += 2_000_000_000
    wTl = g.compose(wTc, np.array([LASER_AHEAD_M, 0.0, 0.0]))
    wTl[700:] = g.compose(np.array([0.0, 0.5, 0.0]), wTl[700:])  # the robot moved on during the gap
    m = laser_ahead_of_turning_centre(stamps, wTl, np.zeros(3))
    assert m is not None and m.pairs == len(stamps) - 2 and abs(m.laser_x_m - LASER_AHEAD_M) < 0.002
