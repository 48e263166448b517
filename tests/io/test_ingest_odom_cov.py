"""nav_msgs/Odometry pose covariance is in the parent (odom) frame; holoslam's Odometry.cov_odomTb is in the
body frame: ingestion rotates the x/y block by R(theta)^T (and the writer back by R(theta))."""

from __future__ import annotations

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.io.mcap import read_log, rotate_cov_xy
from holoslam.io.mcap_write import ros2_message, write_ros2_log
from holoslam.types import Odometry, Pose2


def _J(phi):
    J = np.eye(3)
    J[:2, :2] = g.rot2(phi)
    return J


@pytest.mark.parametrize("phi", [0.0, 0.3, np.pi / 2, -2.5])
def test_rotate_cov_xy_matches_jacobian_form(phi):
    rng = np.random.default_rng(int(abs(phi) * 100))
    A = rng.normal(size=(3, 3))
    C = A @ A.T
    np.testing.assert_allclose(rotate_cov_xy(C, phi), _J(phi) @ C @ _J(phi).T, atol=1e-12)
    iso = np.diag([0.01, 0.01, 0.04])
    assert np.array_equal(rotate_cov_xy(iso, phi), iso)  # isotropic stays exactly isotropic


def test_odometry_covariance_is_rotated_into_the_body_frame(tmp_path):
    # the robot heads +y (theta = 90 deg) and is uncertain mostly along its heading: body-frame sigma_x = 0.1,
    # sigma_y = 0.01; in the odom frame that is sigma_y = 0.1, sigma_x = 0.01
    cov_b = np.diag([0.1**2, 0.01**2, 0.02**2])
    cov_b[0, 2] = cov_b[2, 0] = 0.5 * 0.1 * 0.02
    t0 = 1_700_000_000_000_000_000
    recs = []
    for k in range(3):
        recs.append(Odometry(t0 + k * 50_000_000, Pose2(0.0, 0.1 * k, np.pi / 2), cov_b, 0.2))
        msg = ros2_message(recs[0])
    c6 = np.array(msg["pose"]["covariance"]).reshape(6, 6)
    want_odom = np.array([[0.01**2, 0.0, 0.0], [0.0, 0.1**2, 0.001], [0.0, 0.001, 0.02**2]])
    np.testing.assert_allclose(c6[np.ix_([0, 1, 5], [0, 1, 5])], want_odom, atol=1e-15)
    path = write_ros2_log(tmp_path / "odom.mcap", recs)
    log, _ = read_log(path)
    assert len(log.odometry) == 3
    for o in log.odometry:
        np.testing.assert_allclose(o.cov_odomTb, cov_b, atol=1e-15)
