"""Self-localisation (Eq. 12): closed-form pairs, RANSAC with wrong matches, and point-to-line ICP."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam import geometry as g
from holoslam.sim.world import raycast
from holoslam.submaps.localize import NearestIndex, align_pairs, ransac_align, register_points, scan_normals

# an L-shaped room with a pillar: walls as segments (x0, y0, x1, y1)
ROOM = np.array([
    [0, 0, 6, 0], [6, 0, 6, 3], [6, 3, 3, 3], [3, 3, 3, 5], [3, 5, 0, 5], [0, 5, 0, 0],
    [1.5, 1.5, 1.8, 1.5], [1.8, 1.5, 1.8, 1.8], [1.8, 1.8, 1.5, 1.8], [1.5, 1.8, 1.5, 1.5],
], dtype=float)


def scan_points(wTs, sigma=0.0, rng=None, beams=361):
    ang = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    r = raycast(ROOM, np.asarray(wTs)[None, :2], (ang + wTs[2])[None], 8.0)[0]
    if sigma:
        r = r + rng.normal(0, sigma, r.shape)
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])


def test_eq12_two_pairs_by_hand():
    # robot at (1, 2, 90 deg): a point 1 m ahead is at (1, 3), a point 1 m to the left at (0, 2)
    a = align_pairs(np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[1.0, 3.0], [0.0, 2.0]]))
    np.testing.assert_allclose(a.aTb, [1.0, 2.0, math.pi / 2], atol=1e-12)
    assert a.rms < 1e-12


@given(x=st.floats(-5, 5), y=st.floats(-5, 5), t=st.floats(-3.1, 3.1), seed=st.integers(0, 10_000))
@settings(max_examples=50, deadline=None)
def test_align_recovers_any_pose(x, y, t, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-4, 4, (6, 2))
    T = np.array([x, y, t])
    q = g.transform_points(T, p)
    a = align_pairs(p, q)
    np.testing.assert_allclose(a.aTb[:2], T[:2], atol=1e-9)
    assert abs(g.wrap(a.aTb[2] - T[2])) < 1e-9


def test_align_covariance_matches_monte_carlo():
    rng = np.random.default_rng(3)
    p = rng.uniform(-3, 3, (8, 2))
    T = np.array([0.5, -1.0, 0.7])
    q0 = g.transform_points(T, p)
    sig = 0.02
    xs = np.array([g.between(T, align_pairs(p, q0 + rng.normal(0, sig, q0.shape), sigma=sig).aTb)
                   for _ in range(3000)])
    cov_an = align_pairs(p, q0, sigma=sig).cov_aTb
    np.testing.assert_allclose(np.sqrt(np.diag(cov_an)), xs.std(axis=0), rtol=0.08)


def test_ransac_rejects_wrong_matches():
    rng = np.random.default_rng(5)
    p = rng.uniform(-4, 4, (20, 2))
    T = np.array([2.0, -0.5, -2.2])
    q = g.transform_points(T, p) + rng.normal(0, 0.01, (20, 2))
    wrong = rng.choice(20, 7, replace=False)
    q[wrong] = rng.uniform(-6, 6, (7, 2))  # 35 % wrong matches
    plain = align_pairs(p, q)
    assert np.hypot(*(plain.aTb[:2] - T[:2])) > 0.1
    a = ransac_align(p, q, threshold=0.05)
    assert a is not None
    np.testing.assert_allclose(a.aTb[:2], T[:2], atol=0.02)
    assert abs(g.wrap(a.aTb[2] - T[2])) < 0.01
    assert not a.inliers[wrong].any() and a.inliers.sum() == 13
    assert np.all(np.sqrt(np.diag(a.cov_aTb)) < 0.05)


def test_icp_recovers_known_offset():
    rng = np.random.default_rng(7)
    aTs_map = np.array([2.0, 1.0, 0.3])
    m_s = scan_points(aTs_map)
    a_pts = g.transform_points(aTs_map, m_s)
    nrm, ok = scan_normals(a_pts)
    a_pts, nrm = a_pts[ok], nrm[ok]
    aTs = np.array([2.4, 1.3, 0.45])  # the robot moved 0.5 m and turned
    b_pts = scan_points(aTs, sigma=0.01, rng=rng, beams=181)
    seed = g.compose(aTs, np.array([0.15, -0.1, 0.08]))  # dead reckoning off by 18 cm and 4.6 deg
    reg = register_points(b_pts, a_pts, nrm, seed)
    assert reg.ok, reg
    np.testing.assert_allclose(reg.aTb[:2], aTs[:2], atol=0.02)
    assert abs(g.wrap(reg.aTb[2] - aTs[2])) < 0.005
    err = g.between(reg.aTb, aTs)
    # the truth lies inside the 99.9 % region of the reported covariance
    assert err @ np.linalg.solve(reg.cov_aTb, err) < 16.3


def test_icp_flags_a_bad_match():
    aTs_map = np.array([2.0, 1.0, 0.3])
    a_pts = g.transform_points(aTs_map, scan_points(aTs_map))
    nrm, ok = scan_normals(a_pts)
    other = scan_points(np.array([1.0, 4.0, 2.0]))  # a scan from a different place
    reg = register_points(other, a_pts[ok], nrm[ok], np.array([2.0, 1.0, 0.3]))
    assert not reg.ok


def test_icp_with_a_reused_index_is_the_same_registration():
    # the front end builds one k-d tree per old submap and reuses it for every revisit registration
    rng = np.random.default_rng(11)
    aTs_map = np.array([2.0, 1.0, 0.3])
    a_pts = g.transform_points(aTs_map, scan_points(aTs_map))
    nrm, ok = scan_normals(a_pts)
    a_pts, nrm = a_pts[ok], nrm[ok]
    index = NearestIndex(a_pts)
    for aTs in (np.array([2.4, 1.3, 0.45]), np.array([1.8, 0.7, 0.1]), np.array([4.5, 1.5, 2.0])):
        b_pts = scan_points(aTs, sigma=0.01, rng=rng, beams=181)
        seed = g.compose(aTs, np.array([0.1, -0.05, 0.03]))
        fresh, reused = register_points(b_pts, a_pts, nrm, seed), register_points(b_pts, a_pts, nrm, seed, index=index)
        assert fresh.ok and reused.ok and fresh.iterations == reused.iterations
        np.testing.assert_array_equal(fresh.aTb, reused.aTb)
        np.testing.assert_array_equal(fresh.cov_aTb, reused.cov_aTb)
    with pytest.raises(ValueError, match="NearestIndex"):
        register_points(b_pts, a_pts[:-5], nrm[:-5], seed, index=index)


def test_nearest_index_answers_what_the_kd_tree_answers():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(2)
    for k in range(20):
        walls = g.transform_points(rng.normal(size=3), scan_points(np.array([2.0, 1.5, 0.0]), beams=720))
        pts = np.vstack([walls, rng.normal(0, 0.3, (40, 2)) + walls[0]])
        if k == 19:
            pts = np.vstack([pts, [[5e3, -2e3]]])  # a far outlier: coarser buckets
        index, tree = NearestIndex(pts), cKDTree(pts)
        q = np.vstack([pts[rng.integers(0, len(pts), 200)] + rng.normal(0, 0.2, (200, 2)),
                       rng.uniform(-12, 12, (50, 2))])  # near the map and far outside it
        for gate in (0.05, 0.1, 0.35, 0.5, 3.0, np.inf):
            j, d = index.nearest(q[:, 0], q[:, 1], gate)
            dt, jt = tree.query(q, k=1, distance_upper_bound=gate)
            np.testing.assert_array_equal(d, dt)
            np.testing.assert_array_equal(j, jt)


def test_icp_without_the_compiled_kernels_is_the_same_registration():
    rng = np.random.default_rng(12)
    aTs_map = np.array([2.0, 1.0, 0.3])
    a_pts = g.transform_points(aTs_map, scan_points(aTs_map))
    nrm, ok = scan_normals(a_pts)
    a_pts, nrm = a_pts[ok], nrm[ok]
    aTs = np.array([2.4, 1.3, 0.45])
    b_pts = scan_points(aTs, sigma=0.01, rng=rng, beams=181)
    seed = g.compose(aTs, np.array([0.15, -0.1, 0.08]))
    plain = NearestIndex(a_pts)
    plain._kernel = None  # the numpy path: cKDTree look-ups and numpy terms
    fast, slow = register_points(b_pts, a_pts, nrm, seed), register_points(b_pts, a_pts, nrm, seed, index=plain)
    assert fast.ok and fast.iterations == slow.iterations
    np.testing.assert_array_equal(fast.aTb, slow.aTb)
    np.testing.assert_array_equal(fast.cov_aTb, slow.cov_aTb)
