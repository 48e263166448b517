"""SE(2) on (N, 3) arrays of (x, y, theta), point transforms, and first-order covariance propagation.

Conventions (GTSAM's): ``aTb`` is the pose of frame b in frame a, ``compose(aTb, bTc) = aTc``,
``between(aTb, aTc) = bTc``. A covariance of a pose is expressed in the pose's own (body) frame, i.e. the
perturbation is applied on the right: ``aTb_true = aTb ∘ Exp(xi)``, ``xi ~ N(0, cov_aTb)`` with
xi = (x, y, theta) in the tangent space. For small xi, Exp is the identity to first order, which is what the
Jacobians below use (exactly GTSAM's Pose2 convention for the chart used by its Jacobians).

Every function accepts a single pose of shape (3,) or a batch (N, 3) and broadcasts; angles come back
wrapped to [-pi, pi). This module depends on numpy alone.
"""

from __future__ import annotations

import math
from typing import overload

import numpy as np

__all__ = [
    "wrap",
    "compose",
    "inverse",
    "between",
    "transform_points",
    "rot2",
    "compose_jacobians",
    "inverse_jacobian",
    "propagate_compose",
    "propagate_between",
    "adjoint",
    "interpolate_poses",
]


@overload
def wrap(theta: float) -> float: ...
@overload
def wrap(theta: np.ndarray) -> np.ndarray: ...
def wrap(theta: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to [-pi, pi)."""
    if type(theta) is float:  # one Python float: the same arithmetic without an array round trip (~10x faster)
        return _wrap1(theta)
    w = (np.asarray(theta, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi
    w = np.where(w >= np.pi, -np.pi, w)  # float rounding can land exactly on +pi
    return float(w) if np.ndim(theta) == 0 else w


def _split(T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    T = np.asarray(T, dtype=np.float64)
    return T[..., 0], T[..., 1], T[..., 2]


def rot2(theta: np.ndarray | float) -> np.ndarray:
    """Rotation matrices R(theta), shape (..., 2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _one(T: object) -> bool:
    """Whether T is a single float64 pose array (3,): the pose-by-pose path below, without numpy's per-call
    overhead (a front end composes poses one at a time tens of thousands of times a run)."""
    return type(T) is np.ndarray and T.shape == (3,) and T.dtype == np.float64


def _wrap1(theta: float) -> float:
    s = (theta + math.pi) % (2.0 * math.pi) - math.pi
    return -math.pi if s >= math.pi else s


def compose(aTb: np.ndarray, bTc: np.ndarray) -> np.ndarray:
    """aTc = aTb ∘ bTc."""
    if _one(aTb) and _one(bTc):  # the same arithmetic on Python floats (equal to the last bit)
        x1, y1, t1 = aTb.tolist()
        x2, y2, t2 = bTc.tolist()
        c, s = math.cos(t1), math.sin(t1)
        return np.array([x1 + c * x2 - s * y2, y1 + s * x2 + c * y2, _wrap1(t1 + t2)])
    x1, y1, t1 = _split(aTb)
    x2, y2, t2 = _split(bTc)
    c, s = np.cos(t1), np.sin(t1)
    return np.stack([x1 + c * x2 - s * y2, y1 + s * x2 + c * y2, wrap(t1 + t2)], axis=-1)


def inverse(aTb: np.ndarray) -> np.ndarray:
    """bTa = (aTb)^-1."""
    if _one(aTb):
        x, y, t = aTb.tolist()
        c, s = math.cos(t), math.sin(t)
        return np.array([-c * x - s * y, s * x - c * y, _wrap1(-t)])
    x, y, t = _split(aTb)
    c, s = np.cos(t), np.sin(t)
    return np.stack([-c * x - s * y, s * x - c * y, wrap(-t)], axis=-1)


def between(aTb: np.ndarray, aTc: np.ndarray) -> np.ndarray:
    """bTc = (aTb)^-1 ∘ aTc."""
    return compose(inverse(aTb), aTc)


def transform_points(aTb: np.ndarray, b_points: np.ndarray) -> np.ndarray:
    """Points given in frame b, expressed in frame a: p_a = R(theta) p_b + t (Eq. 12 of seed 002).

    ``aTb`` is one pose (3,) and ``b_points`` is (M, 2), or ``aTb`` is (N, 3) and ``b_points`` (N, 2).
    """
    aTb = np.asarray(aTb, dtype=np.float64)
    p = np.asarray(b_points, dtype=np.float64)
    c, s = np.cos(aTb[..., 2]), np.sin(aTb[..., 2])
    if aTb.ndim == 1:
        return np.column_stack([aTb[0] + c * p[:, 0] - s * p[:, 1], aTb[1] + s * p[:, 0] + c * p[:, 1]])
    return np.stack([aTb[:, 0] + c * p[:, 0] - s * p[:, 1], aTb[:, 1] + s * p[:, 0] + c * p[:, 1]], axis=-1)


def adjoint(aTb: np.ndarray) -> np.ndarray:
    """The 3x3 adjoint of a single pose: Exp(Ad xi) ∘ T = T ∘ Exp(xi) to first order."""
    x, y, t = (float(v) for v in aTb)
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, y], [s, c, -x], [0.0, 0.0, 1.0]])


def compose_jacobians(aTb: np.ndarray, bTc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of aTc = aTb ∘ bTc with respect to right perturbations of aTb and bTc.

    Returns (J_aTb, J_bTc), each 3x3, so that cov_aTc = J1 cov_aTb J1^T + J2 cov_bTc J2^T for independent
    inputs. J_aTb = Ad(bTc^-1), J_bTc = I (GTSAM's Pose2::compose Jacobians).
    """
    return adjoint(inverse(np.asarray(bTc, dtype=np.float64))), np.eye(3)


def inverse_jacobian(aTb: np.ndarray) -> np.ndarray:
    """Jacobian of bTa = (aTb)^-1 with respect to a right perturbation of aTb: -Ad(aTb)."""
    return -adjoint(np.asarray(aTb, dtype=np.float64))


def propagate_compose(
    aTb: np.ndarray, cov_aTb: np.ndarray, bTc: np.ndarray, cov_bTc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """aTc and its covariance for independent aTb and bTc."""
    J1, J2 = compose_jacobians(aTb, bTc)
    cov = J1 @ cov_aTb @ J1.T + J2 @ cov_bTc @ J2.T
    return compose(aTb, bTc), 0.5 * (cov + cov.T)


def propagate_between(
    aTb: np.ndarray, cov_aTb: np.ndarray, aTc: np.ndarray, cov_aTc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """bTc = aTb^-1 ∘ aTc and its covariance for independent aTb and aTc."""
    bTa = inverse(aTb)
    Ji = inverse_jacobian(aTb)
    cov_bTa = Ji @ cov_aTb @ Ji.T
    return propagate_compose(bTa, cov_bTa, aTc, cov_aTc)


def interpolate_poses(stamps_ns: np.ndarray, poses: np.ndarray, query_ns: np.ndarray) -> np.ndarray:
    """Poses (N, 3) at sorted int-nanosecond ``stamps_ns`` interpolated at ``query_ns`` (Q,): x, y linear and
    theta along the unwrapped angle, clamped at the ends; (Q, 3). Raises ValueError for an empty stream."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if stamps.size == 0:
        raise ValueError("interpolate_poses: no poses to interpolate (empty stream)")
    t0 = stamps[0]
    qn = np.asarray(query_ns, dtype=np.int64).reshape(-1)
    if qn.size:  # only the samples around the queries (unwrapping the whole stream per call is the cost)
        lo = max(int(np.searchsorted(stamps, qn.min(), side="right")) - 1, 0)
        hi = min(int(np.searchsorted(stamps, qn.max(), side="left")) + 1, stamps.size)
        stamps, poses = stamps[lo:hi], poses[lo:hi]
    ts = (stamps - t0).astype(np.float64)
    q = (qn - t0).astype(np.float64)
    th = np.unwrap(poses[:, 2])
    out = np.column_stack([np.interp(q, ts, poses[:, 0]), np.interp(q, ts, poses[:, 1]), np.interp(q, ts, th)])
    out[:, 2] = wrap(out[:, 2])
    return out
