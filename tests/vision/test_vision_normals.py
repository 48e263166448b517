"""A label's normal from the pose of its corners (``holoslam.vision.locate``: PnP's rotation, with a sigma that
covers the planar pose's flip when the corners cannot tell the two solutions apart) and its robust weighted mean
over readings (``holoslam.vision.normals.mean_direction``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam.sim.label_views import label_corners_o, look_at_label, project_points
from holoslam.vision.camera import PinholeCamera, make_transform, ptz_chain
from holoslam.vision.locate import label_normal, observation_from_pnp, pnp_label
from holoslam.vision.normals import angle_deg, mean_direction


def _camera(f: float) -> PinholeCamera:
    return PinholeCamera(np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]]), np.zeros(5), 640, 480)


def _deg(a: np.ndarray, b: np.ndarray) -> float:
    return angle_deg(a, b)


@pytest.mark.parametrize("yaw,median_max,p95_max", [(30, 0.8, 1.5), (55, 0.5, 0.9)])
def test_the_pnp_normal_of_a_zoomed_label_is_within_a_degree(yaw, median_max, p95_max):
    """A 10 cm label at 2 m through the PTZ zoomed to about 5 px a module (f = 3000 px: 130 px wide at 30 deg, 86
    at 55), 0.5 px of corner noise, 300 draws: the normal's error measured median 0.62 / 0.34 deg, 95th
    percentile 1.14 / 0.63, largest 1.8 / 0.9; its sigma covers the error (below 1.73 sigma: the 95 % radius of
    a 2-D error whose sigma is its total) in 96 % of the draws."""
    cam = _camera(3000.0)
    cTo = look_at_label(2.0, yaw, 10, 0, (0.0, 0.0))
    truth = project_points(cam.K, cTo, label_corners_o(0.1))
    rng = np.random.default_rng(yaw)
    err, sigma = [], []
    for _ in range(300):
        est = pnp_label(truth + rng.normal(0, 0.5, (4, 2)), 0.1, cam, sigma_px=0.5)
        err.append(_deg(est.c_normal, cTo[:3, 2]))
        sigma.append(math.degrees(est.normal_sigma_rad))
    err_a, sigma_a = np.array(err), np.array(sigma)
    assert np.median(err_a) < median_max and np.percentile(err_a, 95) < p95_max and err_a.max() < 2 * p95_max
    assert 0.9 <= float(np.mean(err_a < 1.73 * sigma_a)) <= 1.0
    assert float(np.median(sigma_a)) < 1.2 * median_max  # the sigma is not inflated either


def test_a_flip_the_corners_cannot_tell_apart_raises_the_sigma():
    """A 5 cm label at 2 m without zoom (14 px wide, 15 deg off frontal): exact corners, yet the other IPPE
    solution (the normal mirrored about the line of sight, 30 deg away) fits them within the noise: the sigma
    covers it (half the angle, 15 deg). Zoom alone does not lift it (the same label 150 px wide at f = 6000 px:
    the far edge 1 px shorter than the near one, still within the noise); a label large against its range does
    (10 cm at 1 m, 300 px: 8 px)."""
    cTo = look_at_label(2.0, 15, 0, 0, (0.0, 0.0))
    for cam in (_camera(600.0), _camera(6000.0)):
        est = pnp_label(project_points(cam.K, cTo, label_corners_o(0.05)), 0.05, cam)
        assert _deg(est.c_normal, cTo[:3, 2]) < 1e-3
        assert math.degrees(est.normal_sigma_rad) == pytest.approx(15.0, abs=0.5)
    near = look_at_label(1.0, 15, 0, 0, (0.0, 0.0))
    cam = _camera(3000.0)
    sure = pnp_label(project_points(cam.K, near, label_corners_o(0.1)), 0.1, cam)
    assert math.degrees(sure.normal_sigma_rad) < 1.0


def test_the_normal_needs_no_printed_size():
    cam = _camera(3000.0)
    cTo = look_at_label(1.5, -35, 15, 40, (0.05, -0.02))
    px = project_points(cam.K, cTo, label_corners_o(0.08)) + np.random.default_rng(3).normal(0, 0.3, (4, 2))
    n, sigma = label_normal(px, cam)
    est = pnp_label(px, 0.08, cam)
    # the same normal and sigma up to the iterative PnP's tolerance (1.2e-6 deg apart on an AMD EPYC; a size that
    # mattered would move them by degrees)
    assert _deg(n, est.c_normal) < 1e-3 and sigma == pytest.approx(est.normal_sigma_rad, rel=1e-3)
    assert _deg(n, cTo[:3, 2]) < 1.0


def test_an_observation_carries_the_normal_in_the_base_frame():
    """The PTZ on its mount, panned 40 deg left and tilted 10 deg down, reads a label whose normal points back at
    the robot 25 deg off its line of sight: the observation's ``b_normal`` is the label's z axis in the base."""
    cam = _camera(3000.0)
    bTc = ptz_chain(make_transform(np.eye(3), (0.05, 0.0, 1.10)), math.radians(40), math.radians(10))
    cTo = look_at_label(2.0, 25, 0, 0, (0.0, 0.0))
    px = project_points(cam.K, cTo, label_corners_o(0.1))
    ob = observation_from_pnp(7, "O05", "HL1;O05;cup;s=100", px, 0.1, cam, bTc)
    assert ob.b_normal is not None and _deg(ob.b_normal, bTc[:3, :3] @ cTo[:3, 2]) < 1e-6
    assert 0 < ob.normal_sigma_rad < math.radians(1.0)
    assert np.allclose(ob.b_position, (bTc @ np.r_[cTo[:3, 3], 1.0])[:3], atol=1e-6)


def _unit(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])


def test_the_mean_normal_leaves_a_flipped_reading_out():
    """Five readings within 1 deg of 0 and one flipped to 70 deg, equally certain: the mean stays within 0.3 deg
    of 0 (an unweighted unit-vector mean would be 10 deg off) and the flip is not kept."""
    v = np.array([_unit(a) for a in (-1.0, 0.5, 1.0, -0.5, 0.0, 70.0)])
    m, sigma, kept = mean_direction(v, np.full(6, math.radians(1.0)))
    assert m is not None and _deg(m, _unit(0.0)) < 0.3
    assert kept.tolist() == [True] * 5 + [False]
    assert math.radians(0.3) < sigma < math.radians(1.0)  # five readings of 1 deg: 0.45 deg
    plain = v.mean(axis=0)
    assert _deg(plain, _unit(0.0)) > 9.5


def test_the_mean_normal_weights_readings_by_their_sigma():
    m, sigma, kept = mean_direction(np.array([_unit(0.0), _unit(10.0)]), np.radians([1.0, 3.0]))
    assert m is not None and kept.all()
    # weights 1 and 1/9: the mean at 10 / 10 = 1.0 deg; its sigma the weighted spread (3 deg) over sqrt 2, above
    # the information (0.95 deg): the two disagree more than their sigmas say
    assert math.degrees(math.atan2(m[1], m[0])) == pytest.approx(1.0, abs=0.05)
    assert math.degrees(sigma) == pytest.approx(2.12, abs=0.01)
    m2, _, kept2 = mean_direction(np.array([_unit(0.0), _unit(90.0)]), np.radians([2.0, 1.0]))
    assert m2 is not None and _deg(m2, _unit(90.0)) < 1e-9 and kept2.tolist() == [False, True]
    none, s, k = mean_direction(np.zeros((0, 2)), np.zeros(0))
    assert none is None and math.isnan(s) and k.shape == (0,)
    floor, s1, _ = mean_direction(np.array([_unit(5.0)]), np.array([math.nan]))
    assert floor is not None and math.degrees(s1) == pytest.approx(1.0)  # MIN_SIGMA_DEG for an unknown sigma
