"""Sensor noise measured against the configured values, camera readability, and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam.geometry import wrap
from holoslam.sim import SimConfig, simulate_household, simulate_to_file
from holoslam.sim.route import household_trajectory
from holoslam.sim.sensors import (
    MIN_MODULE_PX,
    compass,
    laser_scans,
    magnetic_disturbance,
    odometry,
)
from holoslam.sim.world import reference_household


@pytest.fixture(scope="module")
def world():
    return reference_household()


@pytest.fixture(scope="module")
def traj(world):
    return household_trajectory(world, 240.0, seed=7)


def test_odometer_scale_and_slip_match_the_configuration(traj):
    scale, slip = 0.015, 0.01
    odo = odometry(
        traj.stamps_ns, traj.wTb, np.random.default_rng(11), scale=scale, slip_sigma=slip, slip_event_rate=0.0
    )
    moving = odo.ds_true > 1e-4
    L = odo.ds_true[moving].sum()
    assert L > 40.0
    measured_scale = odo.ds_meas[moving].sum() / L - 1.0
    assert measured_scale == pytest.approx(scale, abs=4 * slip / math.sqrt(L))
    z = (odo.ds_meas[moving] - (1 + scale) * odo.ds_true[moving]) / np.sqrt(odo.ds_true[moving])
    assert z.std() == pytest.approx((1 + scale) * slip, rel=0.08)
    # the integrated pose drifts away from the truth (odometry alone is not enough)
    err = np.hypot(*(odo.odomTb[-1, :2] - (traj.wTb[-1, :2] - traj.wTb[0, :2])))
    assert err > 0.05


def test_odometer_slip_events_happen_at_the_configured_rate(traj):
    rate = 0.5  # per metre, high so that the count is meaningful in a short run
    odo = odometry(
        traj.stamps_ns, traj.wTb, np.random.default_rng(12), scale=0.0, slip_sigma=0.0, slip_event_rate=rate
    )
    moving = odo.ds_true > 1e-4
    ratio = odo.ds_meas[moving] / odo.ds_true[moving]
    events = np.count_nonzero(ratio > 1.4)
    assert np.all((ratio > 1.4) == (ratio >= 1.5 - 1e-9))  # slips over-report 1.5x-3x, others exactly 1
    expected = (rate * odo.ds_true[moving]).sum()  # probability rate * ds per step
    assert abs(events - expected) < 4 * math.sqrt(expected)


def test_odometer_heading_noise_and_drift(traj):
    ts, drift, sig = 0.02, math.radians(0.5), 0.02
    odo = odometry(
        traj.stamps_ns, traj.wTb, np.random.default_rng(13), turn_scale=ts, drift=drift, turn_sigma=sig
    )
    r = odo.dtheta_meas - (1 + ts) * odo.dtheta_true - drift * odo.ds_true
    var = sig**2 * np.abs(odo.dtheta_true) + math.radians(0.2) ** 2 * np.abs(
        odo.ds_true
    )  # default heading_sigma
    ok = var > 1e-10
    z = r[ok] / np.sqrt(var[ok])
    assert z.std() == pytest.approx(1.0, rel=0.08)
    assert abs(z.mean()) < 4 / math.sqrt(ok.sum())
    # reported covariance grows with distance and is a valid covariance
    C = odo.cov_odomTb
    assert C[-1, 0, 0] + C[-1, 1, 1] > C[len(C) // 4, 0, 0] + C[len(C) // 4, 1, 1] > 0
    assert np.all(np.linalg.eigvalsh(C[1:]) > 0)


def test_compass_bias_sigma_and_disturbance(world, traj):
    sigma, bias = math.radians(1.5), math.radians(2.0)
    c = compass(world, traj.stamps_ns, traj.wTb, np.random.default_rng(14), sigma=sigma, bias=bias)
    assert np.all(np.diff(c.stamps_ns) == 100_000_000)
    err = wrap(c.yaw - c.yaw_true - c.disturbance)
    assert err.mean() == pytest.approx(bias, abs=4 * sigma / math.sqrt(len(err)))
    assert err.std() == pytest.approx(sigma, rel=0.08)
    # the disturbance is a few degrees next to the appliances and zero a metre away
    assert magnetic_disturbance(world, np.array([[9.1, 1.55]]))[0] == pytest.approx(math.radians(6.0))
    assert magnetic_disturbance(world, np.array([[3.0, 5.0]]))[0] == 0.0
    near = magnetic_disturbance(world, np.array([[5.2 - 0.5, 3.2]]))[0]
    assert math.radians(0.5) < near < math.radians(4.0)


def test_compass_disturbance_is_measurable_near_the_fridge(world):
    # park the robot 0.4 m from the fridge's source for 20 s: the mean error exceeds the bias by the
    # configured disturbance
    n = 401
    stamps = 1_000_000_000 + np.arange(n, dtype=np.int64) * 50_000_000
    wTb = np.tile([8.7, 1.55, 0.3], (n, 1))
    c = compass(world, stamps, wTb, np.random.default_rng(15), sigma=math.radians(1.5), bias=0.0)
    expected = math.radians(6.0) * (1 - 0.4) ** 2
    assert wrap(c.yaw - c.yaw_true).mean() == pytest.approx(
        expected, abs=4 * math.radians(1.5) / math.sqrt(len(c.yaw))
    )


def test_laser_noise_against_the_ray_cast_at_the_true_pose(world, traj):
    sc = laser_scans(world, traj.stamps_ns, traj.wTb, np.random.default_rng(16), sigma=0.01)
    assert sc.ranges.shape[1] == 181 and sc.ranges.dtype == np.float32
    assert sc.angle_min == pytest.approx(-math.pi / 2) and sc.angle_increment == pytest.approx(math.pi / 180)
    fin = np.isfinite(sc.ranges_true) & np.isfinite(sc.ranges)
    r = sc.ranges[fin].astype(np.float64) - sc.ranges_true[fin]
    assert abs(r.mean()) < 4 * 0.01 / math.sqrt(r.size) + 1e-4
    assert r.std() == pytest.approx(0.01, rel=0.05)
    # 1 mm resolution, and no return means +inf
    assert np.allclose(sc.ranges[fin] * 1000, np.round(sc.ranges[fin] * 1000), atol=1e-2)
    assert np.all(np.isinf(sc.ranges[~np.isfinite(sc.ranges_true)]))
    assert np.nanmax(np.where(np.isfinite(sc.ranges), sc.ranges, np.nan)) <= 8.0


def test_camera_sightings_are_readable_and_decode_from_pixels():
    import cv2
    from pyzbar import pyzbar

    run = simulate_household(SimConfig(seed=4, duration_s=60.0, image_rate_hz=0.5))
    assert len(run.snapshots) >= 5
    for s in run.snapshots:
        img = cv2.imdecode(np.frombuffer(s.jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)
        assert img.shape == (480, 640)
        decoded = sorted(r.data.decode() for r in pyzbar.decode(img))
        assert decoded == sorted(p for p, _ in s.tags)
        assert s.target_id in s.visible_ids
        for payload, corners in s.tags:
            n = 29 if len(payload) <= 42 else 33
            edges = np.linalg.norm(corners - np.roll(corners, -1, 0), axis=1)
            assert edges.min() / n >= MIN_MODULE_PX - 0.2
            assert np.all((corners >= -1) & (corners <= [641, 481]))
        # K follows the zoom
        assert s.K[0, 0] == pytest.approx(525.0 * s.zoom)


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    cfg = SimConfig(seed=9, duration_s=20.0, image_rate_hz=0.5)
    a, b, c = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    sa = simulate_to_file(a, cfg)
    simulate_to_file(b, cfg)
    simulate_to_file(c, SimConfig(seed=10, duration_s=20.0, image_rate_hz=0.5))
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()
    assert sa["messages"]["/odom"] == 401 and sa["bytes"] == a.stat().st_size


def test_config_rejects_nonsense():
    from holoslam.errors import ConfigError

    with pytest.raises(ConfigError, match="duration_s"):
        SimConfig(duration_s=-1)
    with pytest.raises(ConfigError, match="jpeg_quality"):
        SimConfig(jpeg_quality=0)


def test_run_as_records_matches_the_streams():
    from holoslam.sim.records import to_log_data

    run = simulate_household(SimConfig(seed=3, duration_s=30.0, image_rate_hz=0.5))
    data = to_log_data(run)
    stamps, poses = data.odometry_arrays()
    assert np.array_equal(stamps, run.odometry.stamps_ns) and np.allclose(poses, run.odometry.odomTb)
    gs, gp = data.ground_truth_arrays()
    assert np.array_equal(gs, run.stamps_ns) and np.allclose(gp, run.wTb)
    assert len(data.scans) == len(run.scans.stamps_ns) and data.scans[0].valid.any()
    assert len(data.images) == len(data.camera_infos) == len(run.snapshots)
    assert len(data.tags) == sum(len(s.tags) for s in run.snapshots)
    assert [t.child for t in data.transforms if t.static] == ["laser", "ptz_base"]
    last = data.odometry[-1].cov_odomTb
    ros = run.odometry.cov_odomTb[-1]
    assert np.trace(last) == pytest.approx(np.trace(ros)) and np.all(np.linalg.eigvalsh(last) > 0)
    h = data.headings[0]
    assert h.sigma == pytest.approx(math.radians(1.5))


def test_noise_scale_zero_gives_the_truth():
    run = simulate_household(SimConfig(seed=5, duration_s=30.0, image_rate_hz=0).with_noise_scale(0.0))
    assert run.snapshots == ()
    odo = run.odometry
    assert np.array_equal(odo.ds_meas, odo.ds_true) and np.array_equal(odo.dtheta_meas, odo.dtheta_true)
    c = run.compass
    assert np.allclose(wrap(c.yaw - c.yaw_true), 0.0, atol=1e-12)
    fin = np.isfinite(run.scans.ranges_true)
    assert np.allclose(run.scans.ranges[fin], run.scans.ranges_true[fin], atol=5e-4 + 1e-6)
    doubled = SimConfig().with_noise_scale(2.0)
    assert (
        doubled.laser_sigma == 0.02 and doubled.compass_sigma_deg == 3.0 and doubled.seed == SimConfig().seed
    )


def test_one_whole_tour_when_no_duration_is_given(world):
    from holoslam.sim.route import tour_duration_s

    t = tour_duration_s(world, seed=2)
    tr = household_trajectory(world, None, seed=2)
    assert (tr.stamps_ns[-1] - tr.stamps_ns[0]) * 1e-9 == pytest.approx(t, abs=0.05)
    assert set(world.room_of(tr.wTb[:, :2])) == {r.name for r in world.rooms}
    # the robot ends the tour back in the living room, where it started
    assert world.room_of(tr.wTb[-1:, :2]) == ["living_room"]
