"""SE(2) group axioms, Jacobians and covariance propagation of holoslam.geometry (against gtsam too)."""

from __future__ import annotations

import gtsam
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam import geometry as geo

coord = st.floats(-20.0, 20.0, allow_nan=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False, exclude_max=True)
pose = st.tuples(coord, coord, angle).map(np.array)


def close(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> bool:
    d = np.asarray(a) - np.asarray(b)
    d[..., 2] = geo.wrap(d[..., 2])
    return bool(np.all(np.abs(d) < tol))


@given(pose)
def test_identity_and_inverse(T):
    e = np.zeros(3)
    assert close(geo.compose(T, e), T) and close(geo.compose(e, T), T)
    assert close(geo.compose(T, geo.inverse(T)), e) and close(geo.compose(geo.inverse(T), T), e)
    assert close(geo.inverse(geo.inverse(T)), T)


@given(pose, pose, pose)
def test_associativity_and_between(A, B, C):
    assert close(geo.compose(geo.compose(A, B), C), geo.compose(A, geo.compose(B, C)), 1e-8)
    assert close(geo.compose(A, geo.between(A, B)), B, 1e-8)


@given(pose, pose)
def test_compose_matches_gtsam(A, B):
    g = gtsam.Pose2(*A).compose(gtsam.Pose2(*B))
    assert close(geo.compose(A, B), np.array([g.x(), g.y(), g.theta()]))
    h = gtsam.Pose2(*A).between(gtsam.Pose2(*B))
    assert close(geo.between(A, B), np.array([h.x(), h.y(), h.theta()]), 1e-8)


def _numerical_jacobian(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """d f(x ∘ Exp(d)) / d d, with the result compared through a right perturbation too (first order)."""
    y0 = f(x)
    J = np.zeros((3, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        yp = f(geo.compose(x, d))
        ym = f(geo.compose(x, -d))
        J[:, k] = (geo.between(y0, yp) - geo.between(y0, ym)) / (2 * eps)
    return J


@settings(max_examples=50)
@given(pose, pose)
def test_compose_jacobians_numerical_and_gtsam(A, B):
    J1, J2 = geo.compose_jacobians(A, B)
    assert np.allclose(J1, _numerical_jacobian(lambda a: geo.compose(a, B), A), atol=1e-5)
    assert np.allclose(J2, _numerical_jacobian(lambda b: geo.compose(A, b), B), atol=1e-5)
    H1, H2 = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
    gtsam.Pose2(*A).compose(gtsam.Pose2(*B), H1, H2)
    assert np.allclose(J1, H1, atol=1e-9) and np.allclose(J2, H2, atol=1e-9)


@settings(max_examples=50)
@given(pose)
def test_inverse_jacobian_numerical_and_gtsam(A):
    J = geo.inverse_jacobian(A)
    assert np.allclose(J, _numerical_jacobian(geo.inverse, A), atol=1e-5)
    H1, H2 = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
    gtsam.Pose2(*A).between(gtsam.Pose2(), H1, H2)  # between(A, I) = A^-1
    assert np.allclose(J, H1, atol=1e-9)


def test_covariance_propagation_monte_carlo():
    rng = np.random.default_rng(42)
    A, B = np.array([1.0, -2.0, 0.7]), np.array([2.5, 0.4, -1.1])
    cA = np.diag([0.02, 0.01, 0.004]) ** 2 * 4
    cB = np.array([[4e-4, 1e-4, 0], [1e-4, 9e-4, 2e-5], [0, 2e-5, 1e-4]])
    mean, cov = geo.propagate_compose(A, cA, B, cB)
    n = 100_000
    sa = geo.compose(A, rng.multivariate_normal(np.zeros(3), cA, n))
    sb = geo.compose(B, rng.multivariate_normal(np.zeros(3), cB, n))
    d = geo.between(np.broadcast_to(mean, (n, 3)), geo.compose(sa, sb))  # right-perturbation samples
    mc = np.cov(d.T)
    assert np.allclose(mc, cov, rtol=0.05, atol=2e-6)
    # between propagation too
    m2, c2 = geo.propagate_between(A, cA, mean, cov)
    assert close(m2, B, 1e-9)
    assert np.all(np.linalg.eigvalsh(c2) > 0)
