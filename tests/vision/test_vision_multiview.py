"""Codes without a printed size located by triangulation over sightings from different robot poses
(holoslam.vision.multiview): accuracy at 3 m with a 0.3 m baseline, covariance consistency under pixel and
pose noise, the consensus that leaves a misread view out and splits a moved code, and the rendered-pixels
path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.vision.camera import PinholeCamera, invert_transform, make_transform, ptz_chain
from holoslam.vision.multiview import View, locate_from_views, planar_to_matrix

BTM = make_transform(np.eye(3), (0.05, 0.0, 1.10))  # the PTZ mount on the base
CHI2_3_95 = 7.815


def _camera(f: float) -> PinholeCamera:
    return PinholeCamera(np.array([[f, 0, 320.8], [0, f, 238.7], [0, 0, 1]]), np.zeros(0), 640, 480)


def _view(w_X, wTb, cam, oid="O40", px_noise=None, stamp=0, payload="HL1;O40;vase") -> View:
    """The PTZ camera at base pose ``wTb`` aimed at ``w_X``; the code centre's pixel (plus noise)."""
    b_X = invert_transform(planar_to_matrix(wTb)) @ np.r_[w_X, 1.0]
    rel = b_X[:3] - BTM[:3, 3]
    bTc = ptz_chain(BTM, math.atan2(rel[1], rel[0]), -math.atan2(rel[2], math.hypot(rel[0], rel[1])))  # tilt > 0: down
    c_X = (invert_transform(bTc) @ b_X)[:3]
    px = cam.project(c_X[None])[0] + (0 if px_noise is None else px_noise)
    return View(stamp, oid, payload, px, cam, bTc)


def _two_views_3m(rng, cam, sigma_px, sigma_xy, sigma_th):
    """A code 3 m ahead (1.2 m high, 0.4 m to the side), seen from two base poses 0.3 m apart; the poses the
    estimator is given carry the noise (the true ones do not)."""
    w_X = np.array([3.0, 0.4, 1.2])
    true = np.array([[0.0, 0.0, 0.05], [0.0, 0.3, -0.08]])
    views = [_view(w_X, p, cam, px_noise=rng.normal(0, sigma_px, 2), stamp=k) for k, p in enumerate(true)]
    cov = np.diag([sigma_xy, sigma_xy, sigma_th]) ** 2
    noisy = np.array([g.compose(p, rng.multivariate_normal(np.zeros(3), cov)) for p in true]) if sigma_xy else true
    return w_X, views, noisy, np.broadcast_to(cov, (2, 3, 3))


@pytest.mark.parametrize(
    "f,sigma_xy,sigma_th_deg",
    [
        (1000.0, 0.0, 0.0),  # a fixed camera, pixel noise only
        (3000.0, 0.001, 0.02),  # the PTZ zoomed to ~5 px per module, poses known to 1 mm and 0.02 deg
    ],
)
def test_three_metres_two_views_0_3_m_apart_within_5_cm_and_covariance(f, sigma_xy, sigma_th_deg):
    rng = np.random.default_rng(int(f))
    cam = _camera(f)
    errs, d2 = [], []
    for _ in range(150):
        w_X, views, poses, cov = _two_views_3m(rng, cam, 0.5, sigma_xy, math.radians(sigma_th_deg))
        (p,), rep = locate_from_views(views, poses, cov, sigma_px=0.5)
        assert rep.views_used == 2 and p.views == (0, 1)
        r = p.w_position - w_X
        errs.append(np.linalg.norm(r))
        d2.append(r @ np.linalg.solve(p.cov_w_position, r))
    errs = np.asarray(errs)
    # measured (300 trials): f 1000 px, pixels only: RMS 2.0 cm, 95th percentile 3.8 cm; f 3000 px with the pose
    # noise: RMS 2.1 cm, 3.8 cm (at 2 mm / 0.03 deg: 3.5 / 6.5 cm; the relative pose between the views limits it)
    assert math.sqrt(np.mean(errs**2)) <= 0.05 and np.percentile(errs, 95) <= 0.05
    assert 0.88 <= np.mean(np.asarray(d2) < CHI2_3_95) <= 0.99  # the covariance says how good it is


def test_a_misread_view_is_left_out_and_a_moved_code_gives_two_points():
    cam = _camera(1500.0)
    a, b = np.array([3.0, 1.0, 1.0]), np.array([2.0, -1.5, 0.8])
    poses = np.array([[0, 0, 0], [0.0, 0.5, 0], [0.4, 0.2, 0.1], [0.0, 0.0, 0.0], [0.5, 0.0, -0.3], [0.0, -0.5, 0]])
    views = [_view(a, p, cam, stamp=k) for k, p in enumerate(poses[:3])]
    views.append(_view(np.array([1.0, 2.5, 1.0]), poses[3], cam, stamp=3))  # a ray pointing elsewhere
    views += [_view(b, p, cam, stamp=4 + k) for k, p in enumerate(poses[4:])]  # the code moved to b
    pts, rep = locate_from_views(views, poses)
    assert len(pts) == 2 and rep.views_used == 5 and rep.views_unused == 1
    assert pts[0].views == (0, 1, 2) and np.allclose(pts[0].w_position, a, atol=1e-6)
    assert pts[1].views == (4, 5) and np.allclose(pts[1].w_position, b, atol=1e-6)


def test_views_without_parallax_locate_nothing_and_say_why():
    cam = _camera(1000.0)
    X = np.array([3.0, 0.0, 1.0])
    views = [_view(X, p, cam, stamp=k) for k, p in enumerate([[0, 0, 0], [0.02, 0, 0]])]  # 2 cm apart
    pts, rep = locate_from_views(views, np.array([[0, 0, 0], [0.02, 0, 0]]))
    assert pts == [] and rep.views_unused == 2 and "not located" in rep.problems[0]


def test_rendered_label_without_size_from_pixels_at_3_m():
    """Decode a sizeless label in two rendered views 0.3 m apart at 3 m (PTZ zoomed to ~5 px per module),
    triangulate the decoded centres: within 5 cm, and the printed size recovered from the images."""
    from holoslam.sim.label_views import RenderConditions, render_label_view
    from holoslam.vision.qr import detect_qr

    payload, side = "HL1;O41;clock;g=top", 0.10
    w_X = np.array([3.0, 0.2, 1.3])
    w_n = np.array([-1.0, 0.0, 0.0])  # the label faces the robot's start
    cam = _camera(3000.0)
    views, poses = [], np.array([[0.0, -0.15, 0.0], [0.0, 0.15, 0.0]])
    for k, wTb in enumerate(poses):
        v = _view(w_X, wTb, cam, stamp=k)
        wTc = planar_to_matrix(wTb) @ v.bTc
        # the label frame: z out of the face (towards -x world), x right for a viewer, y up
        wRo = np.column_stack([np.cross([0.0, 0.0, 1.0], w_n), [0.0, 0.0, 1.0], w_n])
        cTo = invert_transform(wTc) @ make_transform(wRo, w_X)
        img, _ = render_label_view(payload, side, cTo, cam.K, conditions=RenderConditions(noise_sigma=2.0),
                                   seed=k)
        (d,) = detect_qr(img)
        assert d.label.size_m is None
        sides = np.linalg.norm(d.corners - np.roll(d.corners, -1, axis=0), axis=1)
        views.append(View(k, d.label.object_id, d.payload, d.centre, cam, v.bTc, side_px=float(sides.mean())))
    (p,), _ = locate_from_views(views, poses, sigma_px=0.5)
    assert np.linalg.norm(p.w_position - w_X) <= 0.05
    assert p.size_m == pytest.approx(side, rel=0.05)


class _Submap:
    """The parts of a front-end submap the landmark step reads: anchor stamp, keyframes, laser points."""

    def __init__(self, points, stamps, aTb):
        self.anchor_stamp_ns = int(stamps[0])
        self.scan_stamps_ns = np.asarray(stamps, np.int64)
        self.aTb = np.asarray(aTb, np.float64)
        self.cov_aTb = np.broadcast_to(np.diag([0.005, 0.005, math.radians(0.3)]) ** 2, (len(stamps), 3, 3))
        self.track_stamps_ns = np.zeros(0, np.int64)
        self.track_aTb = np.zeros((0, 3))
        self.points = np.asarray(points, np.float64)


def test_laser_range_along_the_rays_replaces_a_triangulation_it_agrees_with():
    """A code on a wall 3 m ahead seen from two poses 0.3 m apart whose headings are off by 0.3 deg: the
    triangulation is decimetres off along the rays (its covariance, from the poses' 0.3 deg, says so), the
    laser's wall gives the range (each view its own measurement), also with a cabinet before the wall whose
    ends the laser saw past (the surface nearest the triangulated point, not the first along the ray); where
    only the cabinet is seen the laser disagrees with the triangulation and the triangulation is kept."""
    from holoslam.vision.landmarks import triangulated_landmarks

    cam = _camera(3000.0)
    w_X = np.array([3.0, 0.4, 1.5])
    true = np.array([[0.0, 0.0, 0.05], [0.0, 0.3, -0.08]])
    views = [_view(w_X, p, cam, stamp=1_000_000_000 * (k + 1)) for k, p in enumerate(true)]
    given = true + np.array([[0, 0, math.radians(0.3)], [0, 0, -math.radians(0.3)]])  # relative heading 0.6 deg
    wall = np.column_stack([np.full(121, 3.0), np.linspace(-1.5, 1.5, 121)])
    stamps = [v.stamp_ns for v in views]
    odo_t = np.array([0, 3_000_000_000], np.int64)
    odo = np.zeros((2, 3))
    wTb = given
    (tri,), _ = locate_from_views(views, wTb, _Submap(wall, stamps, given).cov_aTb)
    assert np.linalg.norm(tri.w_position[:2] - w_X[:2]) > 0.1  # measured 0.29 m: range x 0.6 deg / parallax
    cabinet = wall[40:80] - [1.2, 0.0]
    hidden = np.vstack([wall[:40], wall[80:], cabinet])  # the wall behind the cabinet never seen
    for points, laser_wins in ((wall, True), (np.vstack([wall, cabinet]), True), (hidden, False)):
        tl = triangulated_landmarks(views, [_Submap(points, stamps, given)], np.zeros((1, 3)), None, odo_t, odo, 0.5)
        if laser_wins:
            assert tl.laser_ranged == 2 and len(tl.ids) == 2 and tl.points == ()
            assert all(np.linalg.norm(xy - w_X[:2]) < 0.03 for xy in tl.a_xy)  # measured 1.6 cm (sideways)
            assert {o.method for o in tl.observations} == {"laser_range"}
        else:  # the cabinet 1.2 m before the wall: laser ranges far from the triangulation, not used
            assert tl.laser_ranged == 0 and tl.ids == ("O40",) and tl.observations[0].method == "triangulation"


def test_the_label_normal_follows_a_code_through_triangulation_and_laser_ranging():
    """The same wall code, each view carrying the normal its corners gave (the wall's, facing -x, 2 deg off in
    opposite senses, in the view's base frame): a laser-ranged view keeps its own normal, a triangulated point
    the views' mean, each in its observation's base frame, so in the world every one lies within 2 deg of
    the wall's normal (the mean within the 0.3 deg the given headings are off by)."""
    from dataclasses import replace

    from holoslam.vision.landmarks import triangulated_landmarks

    cam = _camera(3000.0)
    w_X = np.array([3.0, 0.4, 1.5])
    true = np.array([[0.0, 0.0, 0.05], [0.0, 0.3, -0.08]])
    given = true + np.array([[0, 0, math.radians(0.3)], [0, 0, -math.radians(0.3)]])
    wall_normal = 180.0
    views = []
    for k, p in enumerate(true):
        yaw = math.radians(wall_normal + (2.0 if k else -2.0)) - p[2]  # in the base frame at the true pose
        v = _view(w_X, p, cam, stamp=1_000_000_000 * (k + 1))
        views.append(replace(v, b_normal=np.array([math.cos(yaw), math.sin(yaw), 0.0]), normal_sigma_rad=0.01))
    wall = np.column_stack([np.full(121, 3.0), np.linspace(-1.5, 1.5, 121)])
    cabinet = wall[40:80] - [1.2, 0.0]
    hidden = np.vstack([wall[:40], wall[80:], cabinet])
    stamps = [v.stamp_ns for v in views]
    odo_t, odo = np.array([0, 3_000_000_000], np.int64), np.zeros((2, 3))
    for points, method, n_obs, worst in ((wall, "laser_range", 2, 2.4), (hidden, "triangulation", 1, 0.4)):
        tl = triangulated_landmarks(views, [_Submap(points, stamps, given)], np.zeros((1, 3)), None, odo_t, odo, 0.5)
        assert [o.method for o in tl.observations] == [method] * n_obs
        for o in tl.observations:
            k = stamps.index(o.stamp_ns)
            w_yaw = math.degrees(math.atan2(o.b_normal[1], o.b_normal[0]) + given[k, 2])
            assert abs((w_yaw - wall_normal + 180.0) % 360.0 - 180.0) < worst
            assert 0 < o.normal_sigma_rad < math.radians(3.0)
