"""The dead-reckoning noise model of a log: its own odometry covariance when plausible, else the defaults; the
front end's calibration of the dead reckoning and of loop closures against the log's scan matches (issue 13)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.submaps.anchor_graph import AnchorGraph
from holoslam.submaps.deadreckon import DeadReckoningConfig
from holoslam.submaps.odometry_noise import odometry_noise


@pytest.fixture(scope="module")
def sim_log():
    from holoslam.sim import SimConfig, simulate_household
    from holoslam.sim.records import to_log_data

    cfg = SimConfig(seed=4, duration_s=60.0, image_rate_hz=0.0)
    return cfg, to_log_data(simulate_household(cfg))


def _with_cov(odometry, f):
    return tuple(dataclasses.replace(o, cov_odomTb=f(o)) for o in odometry)


def test_a_propagated_covariance_gives_the_odometers_own_rates(sim_log):
    cfg, log = sim_log
    n = odometry_noise(log.odometry)
    assert n.source == "log", n.reason
    # the simulated driver propagates slip 0.01 m/sqrt(m) (lateral a tenth of it), turn 0.02 rad/sqrt(rad),
    # heading 0.2 deg/sqrt(m): recovered, and they become the dead-reckoning model's random walks
    want = (cfg.odom_slip_sigma, 0.1 * cfg.odom_slip_sigma, cfg.odom_turn_sigma, math.radians(cfg.odom_heading_sigma_deg))
    np.testing.assert_allclose(n.fitted_sigmas, want, rtol=0.05)
    c = n.config
    assert (c.sigma_s_per_sqrt_m, c.odo_sigma_turn_per_sqrt_rad) == pytest.approx((want[0], want[2]), rel=0.05)
    # what no driver publishes stays the defaults'
    d = DeadReckoningConfig()
    assert (c.sigma_scale, c.odo_sigma_turn_scale, c.odo_sigma_drift_per_m) == (
        d.sigma_scale, d.odo_sigma_turn_scale, d.odo_sigma_drift_per_m)
    # a ten times larger covariance (a worse odometer) gives rates sqrt(10) times larger
    big = odometry_noise(_with_cov(log.odometry, lambda o: 10.0 * o.cov_odomTb))
    np.testing.assert_allclose(np.array(big.fitted_sigmas) / np.array(n.fitted_sigmas), math.sqrt(10), rtol=0.02)
    off = odometry_noise(log.odometry, DeadReckoningConfig(use_log_covariance=False))
    assert off.source == "defaults" and off.config == DeadReckoningConfig(use_log_covariance=False)


@pytest.mark.parametrize(
    "make, why",
    [
        (lambda o: None, "absent"),  # all zeros: the reader gives None
        (lambda o: np.diag([1e-3, 1e-3, 0.03]), "constant"),  # diff_drive_controller's pose_covariance_diagonal
        (lambda o: np.diag([1e-9, 1e-9, 1e-9]), "constant"),  # the tiny placeholder
        (lambda o: np.diag([1e-3, 1e-3, 1e3]), "placeholder"),  # yaw "not estimated"
        (lambda o: np.diag([1e6, 1e6, 1e6]), "placeholder"),
        (lambda o: 1e4 * o.cov_odomTb, "implausible"),  # inflated 10^4 x: 1 m per sqrt(m)
    ],
)
def test_what_ros_drivers_often_publish_falls_back_to_the_defaults(sim_log, make, why):
    _, log = sim_log
    n = odometry_noise(_with_cov(log.odometry, make))
    assert n.source == "defaults" and n.reason.startswith(why), n.reason
    assert n.config == DeadReckoningConfig()


def test_a_covariance_that_grows_but_not_with_the_motion_is_not_used(sim_log):
    _, log = sim_log
    # growing with time while the robot stands or drives alike (a filter's process noise per second)
    t0 = log.odometry[0].stamp_ns
    n = odometry_noise(_with_cov(log.odometry, lambda o: np.diag([1e-4, 1e-4, 1e-5]) * (1 + (o.stamp_ns - t0) * 1e-9)
                                 * (1 + 0.5 * np.sin((o.stamp_ns - t0) * 1e-9))))
    assert n.source == "defaults" and n.reason.startswith("not propagated"), n.reason


def test_the_front_end_uses_the_logs_covariance(sim_log):
    """Before: the parsed covariance was never used (inflating it 100x changed nothing)."""
    from holoslam.submaps.frontend import FrontEndConfig, build_problem

    _, log = sim_log
    cfg = FrontEndConfig(build_grids=False)
    worse = dataclasses.replace(log, odometry=_with_cov(log.odometry, lambda o: 100.0 * o.cov_odomTb))
    a, b = build_problem(log, config=cfg), build_problem(worse, config=cfg)
    assert a.odometry_noise.source == b.odometry_noise.source == "log"
    assert b.odometry_noise.config.sigma_s_per_sqrt_m == pytest.approx(10 * a.odometry_noise.config.sigma_s_per_sqrt_m)
    dr = a.problem.relative.kind == "dead_reckoning"
    ta = np.trace(a.problem.relative.cov_iTj[dr], axis1=1, axis2=2)
    tb = np.trace(b.problem.relative.cov_iTj[dr], axis1=1, axis2=2)
    assert np.median(tb / ta) > 3.0


# ------------------------------------------------------------------------------ calibration in the front end


def _graph(n_pairs=40, dr_sigma=0.02, model_sigma=0.01, slips=(), seed=0):
    """Anchors 1 m apart; each pair has a dead-reckoning relative pose with true error sigma ``dr_sigma`` but a
    model covariance of ``model_sigma``, and a (near-exact) scan match."""
    rng = np.random.default_rng(seed)
    G = AnchorGraph(np.zeros(3))
    for k in range(n_pairs):
        T = np.array([1.0, 0.0, 0.1])
        err = rng.normal(0, dr_sigma, 3) * [1, 1, 0.1]
        if k in slips:
            err[0] += 0.3  # a wheel slipped 30 cm
        G.add(k, k + 1, g.compose(T, err), np.diag([model_sigma**2, model_sigma**2, (0.1 * model_sigma) ** 2]),
              "dead_reckoning")
        G.add(k, k + 1, T, np.eye(3) * 1e-8, "scan_match")
        G.est.append(G.est[-1]), G.travel.append(float(k + 1))
    return G


def test_the_dead_reckoning_is_scaled_to_its_disagreement_with_the_scan_matches():
    G = _graph(n_pairs=400)
    # errors twice the model's sigma: covariances four times too small
    assert G.dead_reckoning_inflation() == pytest.approx(4.0, rel=0.15)
    assert _graph(dr_sigma=0.005).dead_reckoning_inflation() == 1.0  # a pessimistic model is not shrunk
    m = G.measurements()
    dr = m.kind == "dead_reckoning"
    scaled = m.cov_iTj[dr][:, 0, 0] / (0.01**2 + 1e-10)
    assert np.median(scaled) == pytest.approx(G.dead_reckoning_inflation(), rel=1e-9)  # the slips only grow more


def test_a_slipped_segment_is_down_weighted_alone():
    G = _graph(dr_sigma=0.01, slips=(7,))
    slips = G.dead_reckoning_slips()
    rows = [r for r in slips if G.kind[r] == "dead_reckoning"]
    assert rows == [14]  # pair 7's dead reckoning (rows alternate dead reckoning, scan match)
    m = G.measurements()
    assert m.cov_iTj[14, 0, 0] > 100 * m.cov_iTj[12, 0, 0]
    # the slip does not move the typical segments' calibration
    assert G.dead_reckoning_inflation() == pytest.approx(_graph(dr_sigma=0.01).dead_reckoning_inflation(), rel=0.1)


def test_loop_closures_between_one_pair_of_anchors_count_as_one():
    G = _graph(n_pairs=6)
    for _ in range(4):
        G.add(0, 5, np.array([5.0, 0.0, 0.5]), np.eye(3) * 1e-4, "loop")
    G.add(1, 4, np.array([3.0, 0.0, 0.3]), np.eye(3) * 1e-4, "loop")
    m = G.measurements()
    loops = m.kind == "loop"
    np.testing.assert_allclose(m.cov_iTj[loops][:, 0, 0], [4e-4 + 4e-10] * 4 + [1e-4 + 1e-10])
    assert G.loop_groups() == {(0, 5): 4, (1, 4): 1}


def test_small_nnls_is_scipys():
    """The rates' non-negative least squares (every support of 4 columns) gives scipy's answer, active
    constraints included."""
    from scipy.optimize import nnls

    from holoslam.submaps.odometry_noise import _nnls

    rng = np.random.default_rng(3)
    clipped = 0
    for _ in range(200):
        A = rng.normal(size=(30, 4))
        y = rng.normal(size=30)
        want, _ = nnls(A, y)
        clipped += int(np.any(want == 0.0))
        assert np.allclose(_nnls(A, y), want, rtol=1e-9, atol=1e-12)
    assert clipped > 50  # the bounds were active in many of them
