"""Camera geometry: Eq. 7 hand-eye chain, Eq. 8-9 PTZ chain against hand-computed transforms, the optical
frame convention, orthonormality checks, projection round trips with distortion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam.errors import VisionError
from holoslam.types import CameraInfo
from holoslam.vision.camera import (
    OPTICAL_IN_BODY,
    PinholeCamera,
    check_rotation,
    eq8_rotation,
    hand_eye_chain,
    invert_transform,
    make_transform,
    projection_matrix,
    ptz_chain,
    rot_y,
    rot_z,
)


def test_hand_eye_chain_eq7_hand_computed():
    # end effector 0.5 m forward, 0.8 m up, turned 90 deg left; camera 0.1 m along the effector's x
    bTe = make_transform(rot_z(math.pi / 2), (0.5, 0.0, 0.8))
    eTc = make_transform(np.eye(3), (0.1, 0.0, 0.0))
    bTc = hand_eye_chain(bTe, eTc)
    assert np.allclose(bTc[:3, 3], (0.5, 0.1, 0.8))  # effector x axis points along base y
    assert np.allclose(bTc[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    # a point 1 m in front of the camera, in the base frame
    assert np.allclose(bTc @ [1, 0, 0, 1], [0.5, 1.1, 0.8, 1])


def test_ptz_chain_eq8_9_hand_computed():
    bTm = make_transform(np.eye(3), (0.2, 0.0, 1.0))  # mount 0.2 m forward, 1 m up
    # pan 90 deg left, no tilt: the optical axis (z) points along base +y, image x (right) along base +x
    T = ptz_chain(bTm, math.pi / 2, 0.0)
    assert np.allclose(T[:3, 3], (0.2, 0.0, 1.0))  # t_b = 0: rotation about the optical centre
    assert (
        np.allclose(T[:3, 2], (0, 1, 0))
        and np.allclose(T[:3, 0], (1, 0, 0))
        and np.allclose(T[:3, 1], (0, 0, -1))
    )
    # tilt 30 deg down, no pan: optical axis = (cos 30, 0, -sin 30)
    T = ptz_chain(bTm, 0.0, math.radians(30))
    assert np.allclose(T[:3, 2], (math.cos(math.radians(30)), 0, -0.5))
    assert np.allclose(T[:3, 0], (0, -1, 0))  # tilting keeps image-right horizontal
    # pan then tilt: the tilt axis is the *rotated* horizontal axis: the optical axis stays in the pan plane
    p, t = math.radians(40), math.radians(25)
    T = ptz_chain(bTm, p, t)
    assert np.allclose(T[:3, 2], (math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), -math.sin(t)))
    assert np.allclose(T[:3, :3], rot_z(p) @ rot_y(t) @ OPTICAL_IN_BODY)


def test_optical_frame_convention():
    R = OPTICAL_IN_BODY  # columns: optical x, y, z written in the body frame (x fwd, y left, z up)
    assert (
        np.allclose(R[:, 0], (0, -1, 0))
        and np.allclose(R[:, 1], (0, 0, -1))
        and np.allclose(R[:, 2], (1, 0, 0))
    )
    check_rotation(R)


def test_eq8_printed_matrix_rejected_corrected_one_is_axis_product():
    p, t = 0.7, -0.4
    cp, sp, ct, st_ = math.cos(p), math.sin(p), math.cos(t), math.sin(t)
    printed = np.array(
        [[cp, 0, sp], [-sp * st_, ct, cp * st_], [-sp * cp, -st_, cp * ct]]
    )  # scan error at (3,1)
    with pytest.raises(VisionError, match="not orthonormal"):
        check_rotation(printed, "printed Eq. 8a")
    R = eq8_rotation(p, t)
    expected = printed.copy()
    expected[2, 0] = -sp * ct
    assert np.allclose(R, expected)
    check_rotation(R)


def test_chains_reject_non_rigid_inputs():
    bad = np.eye(4)
    bad[:3, :3] *= 1.01
    with pytest.raises(VisionError, match="not orthonormal"):
        hand_eye_chain(bad, np.eye(4))
    with pytest.raises(VisionError, match="not orthonormal"):
        ptz_chain(bad, 0.1, 0.2)
    with pytest.raises(VisionError):
        make_transform(np.diag([1, 1, -1.0]))  # a reflection, det -1


def test_projection_matrix_eq6_matches_camera_project():
    K = np.array([[500, 0, 320], [0, 510, 240], [0, 0, 1.0]])
    bTc = ptz_chain(make_transform(np.eye(3), (0.1, 0, 1.2)), 0.3, 0.2)
    Xb = np.array([2.0, 0.8, 0.7, 1.0])
    m = projection_matrix(K, invert_transform(bTc)) @ Xb
    cam = PinholeCamera(K, np.zeros(5))
    assert np.allclose(m[:2] / m[2], cam.project((invert_transform(bTc) @ Xb)[:3][None])[0])


@settings(max_examples=40, deadline=None)
@given(st.floats(-250, 250), st.floats(-200, 200))
def test_project_unproject_round_trip_with_distortion(u_off, v_off):
    info = CameraInfo(
        0, "camera_optical", 640, 480, [520, 0, 321, 0, 518, 242, 0, 0, 1], [-0.12, 0.05, 0.001, -0.0005, 0.0]
    )
    cam = PinholeCamera.from_camera_info(info)
    px = np.array([[321 + u_off, 242 + v_off]])
    ray = cam.unproject(px)
    assert np.isclose(np.linalg.norm(ray), 1.0)
    assert np.allclose(cam.project(ray * 3.0), px, atol=1e-3)


def test_camera_errors():
    cam = PinholeCamera(np.diag([500.0, 500.0, 1.0]), np.zeros(5))
    with pytest.raises(VisionError, match="behind"):
        cam.project(np.array([[0, 0, -1.0]]))
    with pytest.raises(VisionError, match="fx"):
        PinholeCamera(np.zeros((3, 3)), np.zeros(5))
    with pytest.raises(VisionError, match="distortion model"):
        PinholeCamera.from_camera_info(CameraInfo(0, "c", 640, 480, np.eye(3), np.zeros(4), "equidistant"))
