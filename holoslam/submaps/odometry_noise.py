"""The odometer's random-walk noise from the log's own odometry covariance, when it is a plausible one.

A wheel-odometry driver that propagates its own uncertainty publishes, with every pose, the covariance of that
pose since the odometry started: per step k (body motion u_k: distance s_k, turn dtheta_k) the body-frame
covariance grows as ``C_{k+1} = Ad(u_k^-1) C_k Ad(u_k^-1)^T + Q_k`` with ``Q_k = diag(a |s_k|, b |s_k|, c
|dtheta_k| + d |s_k|)``: the distance, lateral and heading random walks of ``DeadReckoningConfig``. The published
covariance is linear in (a, b, c, d), so the four rates are found by non-negative least squares against the
covariances the log carries (``propagated_rates``), each basis propagated along the log's own odometry.

ROS drivers often publish something else: all zeros ("unknown"; the reader gives None), a constant diagonal
(``diff_drive_controller``'s ``pose_covariance_diagonal``, Gazebo plugins; often 1e-9 or 1e-3 on x, y, yaw),
or 1e3 / 1e6 / 99999 on the axes they do not estimate. The rule (``odometry_noise``), in order:

1. absent: fewer than ``PRESENT_FRACTION`` of the odometry messages carry a covariance -> the defaults;
2. placeholder: an x, y or yaw variance of at least ``PLACEHOLDER_VAR`` in the first tenth of the messages (a
   propagated covariance starts small) -> the defaults;
3. constant: the yaw and position variances do not grow while the robot drives (a covariance that does not
   grow with the distance driven is a statement about a single pose, not about the motion between two) ->
   the defaults;
4. not propagated: the fitted model leaves more than ``MAX_RELATIVE_RESIDUAL`` of the covariance's growth
   unexplained -> the defaults;
5. implausible: a fitted rate beyond ``MAX_RATES`` (e.g. more than 0.3 m per sqrt(m)) -> the defaults;
6. otherwise the fitted rates replace the defaults' random-walk rates. The systematic terms (odometer scale,
   turn scale, drift) stay the defaults': no driver publishes its calibration error.

``OdometryNoise`` says which was used and why (the run report shows it).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.deadreckon import DeadReckoningConfig

__all__ = ["OdometryNoise", "odometry_noise", "propagated_rates", "PRESENT_FRACTION", "PLACEHOLDER_VAR",
           "MAX_RELATIVE_RESIDUAL", "MAX_RATES"]

PRESENT_FRACTION = 0.9  # of the odometry messages must carry a (non-zero) covariance
PLACEHOLDER_VAR = 1e3  # m^2 or rad^2: the ROS convention for "not estimated" (1e3, 1e6, 99999)
MAX_RELATIVE_RESIDUAL = 0.2  # of the covariance growth the propagated model may leave unexplained
# sigmas per sqrt(unit): distance m/sqrt(m), lateral m/sqrt(m), turn rad/sqrt(rad), heading rad/sqrt(m)
MAX_RATES = (0.3, 0.3, 0.5, 0.2)
_FIT_SAMPLES = 400  # covariances compared with the model (evenly spaced over the log)
_MAX_STEPS = 20_000  # longer odometry streams are propagated over merged steps


@dataclass(frozen=True, slots=True)
class OdometryNoise:
    """The dead-reckoning noise model used for a log: ``config`` (the defaults, or the defaults with the log's
    rates), ``source`` ("log" or "defaults"), ``reason`` (why), and the rates fitted to the log's covariance
    (sigmas per sqrt(unit): distance, lateral, turn, heading; None when no fit was made)."""

    config: DeadReckoningConfig
    source: str
    reason: str
    fitted_sigmas: tuple[float, float, float, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        c = self.config
        return {
            "source": self.source,
            "reason": self.reason,
            "sigma_s_per_sqrt_m": round(c.sigma_s_per_sqrt_m, 6),
            "sigma_lateral_per_sqrt_m": round(c.sigma_lateral_per_sqrt_m, 6),
            "odo_sigma_turn_per_sqrt_rad": round(c.odo_sigma_turn_per_sqrt_rad, 6),
            "odo_sigma_heading_per_sqrt_m": round(c.odo_sigma_heading_per_sqrt_m, 6),
        }


def _merged_steps(P: np.ndarray, covs: np.ndarray, max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th pose and covariance so that at most ``max_steps`` steps remain (the first and last kept)."""
    n = len(P)
    if n - 1 <= max_steps:
        return P, covs
    idx = np.unique(np.round(np.linspace(0, n - 1, max_steps + 1)).astype(np.int64))
    return P[idx], covs[idx]


def _nnls(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """argmin ||A x - y|| subject to x >= 0 for a few columns (here 4), exactly: the optimum is the unconstrained
    least-squares solution on its own support, so the best non-negative one over every support (2^4 = 16 small
    solves) is it. The same answer as ``scipy.optimize.nnls``, without importing scipy.optimize (~0.6 s of a
    run's start, for this one call)."""
    n = A.shape[1]
    best, best_r = np.zeros(n), float(np.linalg.norm(y))
    for mask in range(1, 1 << n):
        cols = [k for k in range(n) if mask >> k & 1]
        x, *_ = np.linalg.lstsq(A[:, cols], y, rcond=None)
        if np.all(x >= 0.0):
            r = float(np.linalg.norm(A[:, cols] @ x - y))
            if r < best_r:
                best, best_r = np.zeros(n), r
                best[cols] = x
    return best


def propagated_rates(odomTb: np.ndarray, cov_odomTb: np.ndarray) -> tuple[np.ndarray, float]:
    """Fit (a, b, c, d) (module docstring; variances per unit) to body-frame covariances (N, 3, 3) published with
    the poses (N, 3). Returns the rates and the fraction of the covariance growth the fit leaves unexplained."""
    P, C = _merged_steps(np.asarray(odomTb, float), np.asarray(cov_odomTb, float), _MAX_STEPS)
    u = g.between(P[:-1], P[1:])
    s = np.hypot(u[:, 0], u[:, 1])
    dth = np.abs(g.wrap(u[:, 2]))
    A = np.array([g.adjoint(g.inverse(x)) for x in u])  # Ad(u^-1): body frame at k -> body frame at k+1
    n = len(P)
    # the bases: the start covariance transported, and one unit rate of each random walk
    M = np.zeros((5, 3, 3))
    M[0] = C[0]
    sample = np.unique(np.round(np.linspace(1, n - 1, min(_FIT_SAMPLES, n - 1))).astype(np.int64))
    want = set(sample.tolist())
    rows: list[np.ndarray] = []
    got: list[np.ndarray] = []
    unit = np.zeros((4, 3, 3))
    for k in range(n - 1):
        M = A[k] @ M @ A[k].T
        unit[:] = 0.0
        unit[0, 0, 0] = unit[1, 1, 1] = s[k]
        unit[2, 2, 2] = dth[k]
        unit[3, 2, 2] = s[k]
        M[1:] += unit
        if k + 1 in want:
            rows.append(M.copy())
            got.append(C[k + 1])
    B = np.array(rows)  # (S, 5, 3, 3)
    Y = np.array(got)  # (S, 3, 3)
    iu = np.triu_indices(3)
    # each sample weighted by its own size, so the early (small) covariances count as much as the late ones
    w = 1.0 / (np.abs(np.trace(Y, axis1=1, axis2=2)) + np.abs(np.trace(B[:, 0], axis1=1, axis2=2)) + 1e-12)
    X = (B[:, 1:, iu[0], iu[1]] * w[:, None, None]).transpose(0, 2, 1).reshape(-1, 4)
    y = ((Y - B[:, 0])[:, iu[0], iu[1]] * w[:, None]).reshape(-1)
    scale = np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    theta = _nnls(X / scale, y) / scale
    growth = float(np.linalg.norm(y))
    unexplained = float(np.linalg.norm(y - X @ theta)) / growth if growth > 0 else 1.0
    return theta, unexplained


def odometry_noise(odometry: Any, config: DeadReckoningConfig | None = None) -> OdometryNoise:
    """The noise model for a log's odometry records (``holoslam.types.Odometry``): the log's propagated
    covariance when plausible, else the defaults (module docstring for the rule)."""
    cfg = config or DeadReckoningConfig()
    if not cfg.use_log_covariance:
        return OdometryNoise(cfg, "defaults", "the log's odometry covariance is not used (use_log_covariance off)")
    n = len(odometry)
    covs = [o.cov_odomTb for o in odometry]
    have = sum(c is not None for c in covs)
    if n < 10 or have < PRESENT_FRACTION * n:
        return OdometryNoise(cfg, "defaults", f"absent: {have} of {n} odometry messages carry a covariance")
    idx = [k for k, c in enumerate(covs) if c is not None]
    C = np.array([covs[k] for k in idx], dtype=np.float64)
    P = np.array([(odometry[k].odomTb.x, odometry[k].odomTb.y, odometry[k].odomTb.theta) for k in idx])
    diag = np.diagonal(C, axis1=1, axis2=2)
    head = diag[: max(1, len(diag) // 10)]
    if np.any(head >= PLACEHOLDER_VAR) or not np.all(np.isfinite(C)):
        return OdometryNoise(cfg, "defaults", f"placeholder: x, y or yaw variance >= {PLACEHOLDER_VAR:g} (the 'not "
                             "estimated' convention)")
    u = g.between(P[:-1], P[1:])
    driven = float(np.sum(np.hypot(u[:, 0], u[:, 1])))
    turned = float(np.sum(np.abs(g.wrap(u[:, 2]))))
    grew = diag[-1] - diag[0]
    if driven < 1.0 or not (grew[2] > 1e-3 * max(diag[0, 2], 1e-12) and (grew[0] + grew[1]) > 0):
        return OdometryNoise(cfg, "defaults", f"constant: the covariance does not grow over {driven:.1f} m and "
                             f"{math.degrees(turned):.0f} deg driven (a per-pose statement, not a propagated one)")
    theta, unexplained = propagated_rates(P, C)
    sig = tuple(float(math.sqrt(max(v, 0.0))) for v in theta)
    if unexplained > MAX_RELATIVE_RESIDUAL:
        return OdometryNoise(cfg, "defaults", f"not propagated: a random walk in distance and turn explains only "
                             f"{100 * (1 - unexplained):.0f} % of its growth", sig)  # type: ignore[arg-type]
    if any(v > m for v, m in zip(sig, MAX_RATES, strict=True)):
        return OdometryNoise(cfg, "defaults", "implausible: fitted sigmas (distance, lateral, turn, heading) "
                             f"{', '.join(f'{v:.3g}' for v in sig)} exceed {MAX_RATES}", sig)  # type: ignore[arg-type]
    used = dataclasses.replace(cfg, sigma_s_per_sqrt_m=sig[0], sigma_lateral_per_sqrt_m=sig[1],
                               odo_sigma_turn_per_sqrt_rad=sig[2], odo_sigma_heading_per_sqrt_m=sig[3])
    return OdometryNoise(used, "log", f"propagated covariance of {n} messages (fit leaves {100 * unexplained:.1f} % "
                         "of its growth unexplained)", sig)  # type: ignore[arg-type]
