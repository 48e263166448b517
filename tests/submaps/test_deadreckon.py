"""Dead reckoning (Eq. 14), its analytic covariance against Monte Carlo, and Eq. 15."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam import geometry as g
from holoslam.geometry import interpolate_poses
from holoslam.submaps.deadreckon import (
    DeadReckoningConfig,
    dead_reckon,
    integrate,
    odometry_increments,
    relative_anchor_pose,
)

finite = st.floats(-5.0, 5.0, allow_nan=False)
angle = st.floats(-3.1, 3.1, allow_nan=False)


def test_eq14_literal_square_by_hand():
    # literal Eq. 14 (heading at the start of each step): 1 m east, turn left, 1 m north, turn left ...
    s = np.array([1.0, 0.0, 1.0, 0.0, 1.0])
    dth = np.array([0.0, math.pi / 2, 0.0, math.pi / 2, 0.0])
    P = integrate(np.zeros(3), s, dth, midpoint=False)
    np.testing.assert_allclose(P[-1], [0.0, 1.0, -math.pi], atol=1e-12)
    np.testing.assert_allclose(P[1], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(P[3], [1.0, 1.0, math.pi / 2], atol=1e-12)


def test_midpoint_is_exact_on_an_arc():
    # a quarter circle of radius 2 in 10 steps: the midpoint rule lands exactly on (2, 2, pi/2)
    n, r = 10, 2.0
    dth = np.full(n, (math.pi / 2) / n)
    chord = 2 * r * np.sin(dth / 2)
    P = integrate(np.zeros(3), chord, dth, midpoint=True)
    np.testing.assert_allclose(P[-1], [r, r, math.pi / 2], atol=1e-12)
    literal = integrate(np.zeros(3), chord, dth, midpoint=False)
    assert np.hypot(*(literal[-1, :2] - [r, r])) > 0.05  # the literal rule is visibly off


@given(x=finite, y=finite, t=angle, steps=st.lists(st.tuples(st.floats(-0.3, 0.3), st.floats(-0.5, 0.5)),
                                                    min_size=1, max_size=20))
@settings(max_examples=60, deadline=None)
def test_integrate_equals_composition_of_increments(x, y, t, steps):
    s = np.array([a for a, _ in steps])
    d = np.array([b for _, b in steps])
    P = integrate(np.array([x, y, t]), s, d)
    T = np.array([x, y, t])
    for a, b in steps:
        T = g.compose(T, np.array([a * math.cos(b / 2), a * math.sin(b / 2), b]))
    np.testing.assert_allclose(P[-1, :2], T[:2], atol=1e-9)
    assert abs(g.wrap(P[-1, 2] - T[2])) < 1e-9


def test_odometry_increments_sign_and_turn():
    poses = np.array([[0, 0, 0], [0.1, 0, 0], [0.05, 0, 0.2], [0.05, 0, 0.2]], float)
    s, d = odometry_increments(poses)
    np.testing.assert_allclose(s, [0.1, -0.05, 0.0])
    np.testing.assert_allclose(d, [0.0, 0.2, 0.0])


def _true_path(n=120, dt_ns=50_000_000, start_ns=10**9):
    """A path with straight parts and turns; with n + 4 and start_ns - 2 dt it extends the default one."""
    k0 = (start_ns - 10**9) // dt_ns
    t = np.arange(n, dtype=np.int64) * dt_ns + start_ns
    v = 0.3 * 0.05  # metres per step
    k = np.arange(n) + k0
    w = np.where((k > 30) & (k < 70), 0.04, 0.0)
    w[k >= 90] = -0.03
    chord = 2 * (v / np.where(w == 0, 1, w)) * np.sin(w / 2)
    chord = np.where(w == 0, v, chord)
    P = integrate(np.zeros(3), chord[:-1], w[:-1])
    i0 = int(np.searchsorted(t, 10**9))  # anchor the path so that the sample at 1 s is (1, 2, 0.3)
    P = g.compose(g.compose(np.array([1.0, 2.0, 0.3]), g.inverse(P[i0])), P)
    return t, P


def _compass(t, P, bias, sigma, rng, period_ns=100_000_000, offset_ns=23_000_000):
    # the true path continues 4 steps beyond the odometry so the compass samples around the last stamp are true
    tt, PP = _true_path(len(t) + 4, start_ns=int(t[0]) - 2 * 50_000_000)
    hs = np.arange(t[0] - offset_ns, t[-1] + period_ns, period_ns, dtype=np.int64)
    yaw = interpolate_poses(tt, PP, hs)[:, 2] + bias + rng.normal(0, sigma, hs.size)
    return hs, g.wrap(yaw)


def test_compass_bias_cancels_and_disturbance_falls_back():
    rng = np.random.default_rng(0)
    t, P = _true_path()
    odo = P.copy()
    odo[:, 2] = g.wrap(odo[:, 2] + np.linspace(0, 0.05, len(t)))  # wheel heading drifts 0.05 rad
    odo_xy = integrate(P[0], *odometry_increments(P))  # same positions
    odo[:, :2] = odo_xy[:, :2]
    hs, yaw = _compass(t, P, bias=0.7, sigma=1e-4, rng=rng)
    # a local magnetic disturbance of +0.3 rad between 2.0 s and 3.5 s after the start
    dist = (hs > t[0] + 2_000_000_000) & (hs < t[0] + 3_500_000_000)
    yaw_d = g.wrap(yaw + 0.3 * dist)
    # a near-perfect compass and a good odometer (the gate's width is their disagreement's sigma: with the default
    # turn walk, 0.02 rad per sqrt(rad), a 1 s window turning 0.8 rad tolerates 0.07 rad)
    cfg = DeadReckoningConfig(compass_sigma=1e-3, odo_sigma_turn_per_sqrt_rad=0.005)
    clean = dead_reckon(t, odo, int(t[0]), int(t[-1]), start=P[0], heading_stamps_ns=hs, heading_yaw=yaw,
                        config=cfg)
    np.testing.assert_allclose(clean.end[:2], P[-1, :2], atol=2e-3)
    assert abs(g.wrap(clean.end[2] - P[-1, 2])) < 2e-3  # the 0.7 rad bias cancelled
    no_compass = dead_reckon(t, odo, int(t[0]), int(t[-1]), start=P[0], config=cfg)
    assert abs(g.wrap(no_compass.end[2] - P[-1, 2])) > 0.04  # odometry heading alone drifts
    dis = dead_reckon(t, odo, int(t[0]), int(t[-1]), start=P[0], heading_stamps_ns=hs, heading_yaw=yaw_d,
                      config=cfg)
    assert not dis.compass_used.all() and dis.compass_used.mean() > 0.5
    ignore_gate = dead_reckon(t, odo, int(t[0]), int(t[-1]), start=P[0], heading_stamps_ns=hs,
                              heading_yaw=yaw_d, config=replace(cfg, gate=1e9))
    err_gate = np.hypot(*(dis.end[:2] - P[-1, :2]))
    err_raw = np.hypot(*(ignore_gate.end[:2] - P[-1, :2]))
    assert err_gate < 0.5 * err_raw  # the fallback kept the disturbance from bending the path


def _mc(cfg, use_compass, runs=1500, seed=1):
    rng = np.random.default_rng(seed)
    t, P = _true_path()
    s_true, d_true = odometry_increments(P)
    cov0 = np.diag([1e-4, 4e-4, 2.5e-4])
    nominal = None
    ends = []
    hs, _ = _compass(t, P, 0.0, 0.0, rng)
    yaw_true = interpolate_poses(t, P, hs)[:, 2]
    an = None
    for k in range(runs + 1):
        noisy = k > 0
        sig_s = np.sqrt(cfg.sigma_s_per_sqrt_m**2 * np.abs(s_true))
        scale = rng.normal(0, cfg.sigma_scale) if noisy else 0.0  # one systematic error per run
        s = s_true * (1 + scale) + (rng.normal(0, 1, s_true.size) * sig_s if noisy else 0)
        var_o = cfg.odo_sigma_turn_per_sqrt_rad**2 * np.abs(d_true) + cfg.odo_sigma_heading_per_sqrt_m**2 * np.abs(s_true)
        turn = rng.normal(0, cfg.odo_sigma_turn_scale) if noisy else 0.0
        drift = rng.normal(0, cfg.odo_sigma_drift_per_m) if noisy else 0.0
        d = d_true + (rng.normal(0, 1, d_true.size) * np.sqrt(var_o) + turn * d_true + drift * np.abs(s_true)
                      if noisy and not use_compass else 0)
        odo = integrate(P[0], s, d)
        yaw = g.wrap(yaw_true + 0.4 + (rng.normal(0, cfg.compass_sigma, hs.size) if noisy else 0))
        xi0 = rng.multivariate_normal(np.zeros(3), cov0) if noisy else np.zeros(3)
        start = g.compose(P[0], xi0)
        r = dead_reckon(t, odo, int(t[0]), int(t[-1]), start=start, cov_start=cov0,
                        heading_stamps_ns=hs if use_compass else None, heading_yaw=yaw, config=cfg)
        if not noisy:
            nominal, an = r.end, r.cov_aTb_end
            assert r.compass_used.all() == use_compass
        else:
            ends.append(g.between(nominal, r.end))
    E = np.array(ends)
    return an, np.cov(E.T)


@pytest.mark.parametrize("use_compass,systematic", [(True, False), (False, False), (True, True), (False, True)])
def test_covariance_matches_monte_carlo(use_compass, systematic):
    k = 1.0 if systematic else 0.0  # with the correlated scale / slip / turn-scale / drift terms or without
    cfg = DeadReckoningConfig(sigma_s_per_sqrt_m=0.02, compass_sigma=0.02, odo_sigma_turn_per_sqrt_rad=0.05,
                              odo_sigma_heading_per_sqrt_m=0.03, sigma_floor_m=0.0, sigma_floor_rad=0.0, gate=1e9,
                              sigma_scale=0.05 * k, odo_sigma_turn_scale=0.05 * k, odo_sigma_drift_per_m=0.05 * k)
    an, mc = _mc(cfg, use_compass)
    sd_an, sd_mc = np.sqrt(np.diag(an)), np.sqrt(np.diag(mc))
    np.testing.assert_allclose(sd_an, sd_mc, rtol=0.08)
    corr_an = an / np.outer(sd_an, sd_an)
    corr_mc = mc / np.outer(sd_mc, sd_mc)
    np.testing.assert_allclose(corr_an, corr_mc, atol=0.08)


def test_eq15_by_hand():
    # robot at (2, 1, 90deg) in m, and at (1, 0, 0) in n: anchor n sits at (2, 0, 90deg) in m
    mTn, cov = relative_anchor_pose(np.array([2.0, 1.0, math.pi / 2]), np.zeros((3, 3)),
                                    np.array([1.0, 0.0, 0.0]), np.diag([0.01, 0.0, 0.0]))
    np.testing.assert_allclose(mTn, [2.0, 0.0, math.pi / 2], atol=1e-12)
    # an x-error of n's localisation moves anchor n along -x of n
    np.testing.assert_allclose(np.diag(cov), [0.01, 0.0, 0.0], atol=1e-12)


@given(a=st.tuples(finite, finite, angle), b=st.tuples(finite, finite, angle))
@settings(max_examples=80, deadline=None)
def test_eq15_invariant(a, b):
    mTr, nTr = np.array(a), np.array(b)
    mTn, cov = relative_anchor_pose(mTr, np.eye(3) * 1e-3, nTr, np.eye(3) * 2e-3)
    back = g.compose(mTn, nTr)
    np.testing.assert_allclose(back[:2], mTr[:2], atol=1e-9)
    assert abs(g.wrap(back[2] - mTr[2])) < 1e-9
    assert abs(g.wrap(mTn[2] - (mTr[2] - nTr[2]))) < 1e-9  # theta_mn = theta_rm - theta_rn
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_systematic_scale_error_grows_linearly_with_distance():
    # a straight 1 m and 4 m drive: with only the correlated scale error the along-track sigma is
    # sigma_scale * distance (independent per-step noise would grow like sqrt(distance / step))
    cfg = DeadReckoningConfig(sigma_floor_m=0.0, sigma_floor_rad=0.0, sigma_s_per_sqrt_m=0.0, sigma_scale=0.015,
                              use_compass=False)
    for L in (1.0, 4.0):
        t = np.arange(0, 201, dtype=np.int64) * 50_000_000
        P = np.column_stack([np.linspace(0, L, t.size), np.zeros(t.size), np.zeros(t.size)])
        r = dead_reckon(t, P, int(t[0]), int(t[-1]), config=cfg)
        assert np.sqrt(r.cov_aTb_end[0, 0]) == pytest.approx(0.015 * L, rel=1e-9)


def test_interpolate_poses_matches_whole_stream_unwrap():
    # interpolate_poses unwraps only the samples around the queries: same result as unwrapping everything
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.integers(1, 100, 500)).astype(np.int64)
    P = np.column_stack([rng.normal(size=(500, 2)).cumsum(0), g.wrap(rng.normal(0, 0.8, 500).cumsum())])
    ts, th = (t - t[0]).astype(float), np.unwrap(P[:, 2])
    for q in (np.array([t[0] - 5]), np.array([t[-1] + 5]), rng.integers(t[0] - 10, t[-1] + 10, 50),
              np.array([t[10]]), np.array([t[10], t[11] - 1])):
        qq = (q - t[0]).astype(float)
        want = np.column_stack([np.interp(qq, ts, P[:, 0]), np.interp(qq, ts, P[:, 1]), np.interp(qq, ts, th)])
        got = interpolate_poses(t, P, q)
        np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-12)
        assert np.all(np.abs(g.wrap(got[:, 2] - want[:, 2])) < 1e-12)


def _straight(L: float, hz: float) -> tuple[np.ndarray, np.ndarray]:
    n = int(round(L / 0.3 * hz)) + 1  # at 0.3 m/s
    t = np.arange(n, dtype=np.int64) * int(round(1e9 / hz))
    return t, np.column_stack([np.linspace(0, L, n), np.zeros(n), np.zeros(n)])


@pytest.mark.parametrize("hz", [5.0, 20.0, 100.0])
def test_the_covariance_does_not_depend_on_the_odometry_rate(hz):
    # every random term is a random walk in the distance driven (or the angle turned), the floor is once per
    # segment: the same 3 m drive gives the same covariance at 5, 20 or 100 Hz (a per-step sigma would not)
    cfg = DeadReckoningConfig(use_compass=False, sigma_lateral_per_sqrt_m=0.004, sigma_scale=0.0,
                              odo_sigma_turn_scale=0.0, odo_sigma_drift_per_m=0.0)
    t, P = _straight(3.0, hz)
    cov = dead_reckon(t, P, int(t[0]), int(t[-1]), config=cfg).cov_aTb_end
    f2, r2 = cfg.sigma_floor_m**2, cfg.sigma_floor_rad**2
    assert cov[0, 0] == pytest.approx(cfg.sigma_s_per_sqrt_m**2 * 3.0 + f2, rel=1e-9)
    # sideways: the lateral walk plus the heading walk's lever arm, integral of (3 - x) over x: 3^3 / 3
    want_yy = cfg.sigma_lateral_per_sqrt_m**2 * 3.0 + cfg.odo_sigma_heading_per_sqrt_m**2 * 9.0 + f2
    assert cov[1, 1] == pytest.approx(want_yy, rel=0.02 if hz == 5.0 else 0.01)
    assert cov[2, 2] == pytest.approx(cfg.odo_sigma_heading_per_sqrt_m**2 * 3.0 + r2, rel=1e-9)
    # standing still: the floor only
    still = dead_reckon(t, np.zeros_like(P), int(t[0]), int(t[-1]), config=cfg).cov_aTb_end
    np.testing.assert_allclose(np.diag(still), [f2, f2, r2], rtol=1e-9)
