"""Dead reckoning between two stamps (seed 002 Eq. 14) and the relative pose of two submaps (Eq. 15).

Eq. 14 integrates the odometer distances s_k and the compass heading changes dtheta_k from a known pose in a
submap's anchor frame::

    x_{k+1} = x_k + s_k cos(theta_k + h dtheta_k),  y_{k+1} = y_k + s_k sin(theta_k + h dtheta_k),
    theta_{k+1} = theta_k + dtheta_k

The paper prints h = 0 (the heading at the start of the step). With h = 0 a turn of angle Phi over arc length L
sampled in N steps gets a systematic lateral error of about L Phi / (2 N), several centimetres for a 90 degree
turn at 20 Hz; the default here is the midpoint rule h = 1/2 (``midpoint=True``), which is exact for arcs.
Each step is the SE(2) increment u_k = (s_k cos(h dtheta_k), s_k sin(h dtheta_k), dtheta_k), so the
integrated pose is ``aTb_j = aTb_i ∘ u_i ∘ ... ∘ u_{j-1}``.

Inputs:

* s_k is the signed distance between consecutive odometry positions (negative when the base moved against
  its heading).
* dtheta_k comes from the compass: the compass yaw (unwrapped) is interpolated linearly at the sample stamps
  and differenced. Differencing cancels the compass's constant bias and any local magnetic offset that stays
  constant over a step. Where the compass is disturbed (the robot enters or leaves a magnetic disturbance,
  e.g. near a fridge), the compass turn rate disagrees with the odometry turn rate by more than their noise:
  the residual r = (sum of compass dtheta) - (sum of odometry dtheta) over a sliding window of
  ``window_ns`` starting at every sample is tested against ``gate`` times its standard deviation
  sqrt(2 sigma_c^2 + sum sigma_o^2); a step that no passing window covers uses the odometry heading change
  instead (fallback, not a blend). A step-like disturbance thus costs only the steps around its edges; a
  slowly ramping one is caught where its ramp exceeds the gate within a window.

Covariance (analytic, first order, GTSAM's right-perturbation convention, in the final pose's own frame): the
error of the final pose is a linear function of independent noise sources, each mapped through the Jacobian of
its step and the adjoint of the remaining motion, ``Ad(between(P_j, P_{k+1}))``. Every random term is a random
walk in the distance driven or the angle turned (variance proportional to |s_k| or |dtheta_k|), so the
covariance of a segment does not depend on how often the odometry is published:

* distance slip, variance ``sigma_s_per_sqrt_m``^2 |s_k|, and lateral slip ``sigma_lateral_per_sqrt_m``^2 |s_k|;
* for compass steps, the compass readings' white noise (sigma from the log, else ``compass_sigma``). A heading
  change is the difference of two interpolated readings, so consecutive changes are negatively correlated
  and the heading error does not grow with the number of steps; this is modelled exactly through the
  interpolation weights;
* for odometry steps, heading-change noise of variance ``odo_sigma_turn_per_sqrt_rad``^2 |dtheta_k| +
  ``odo_sigma_heading_per_sqrt_m``^2 |s_k|;
* the start pose's covariance, and once per segment a floor (``sigma_floor_m``, ``sigma_floor_rad``);
* systematic errors, each one unknown per integrated segment (so fully correlated over its steps): the odometer
  scale (``sigma_scale``: s_k -> (1 + e) s_k, sensitivity sum_k F_k s_k), and for odometry-heading steps the
  turn scale (``odo_sigma_turn_scale``) and a heading drift per metre (``odo_sigma_drift_per_m``, unequal
  wheels). Without them the per-step noise averages out and a 3 m segment with a 1.5 % scale error is reported
  about ten times too confident.

The defaults (``DeadReckoningConfig``) describe an uncalibrated differential-drive base and a consumer digital
compass, each value with its physical source beside it. Where the log's odometry carries its own propagated
covariance, its random-walk rates replace the defaults' (``holoslam.submaps.odometry_noise``); the front end then
scales the dead-reckoning covariances by what the log's own scan matches say (``FrontEnd.dead_reckoning_inflation``).

Not modelled: the correlation between consecutive dead-reckoning segments (the same scale error, the compass
reading shared at their common anchor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoslam import geometry as g
from holoslam.errors import IngestError

__all__ = [
    "DeadReckoningConfig",
    "DeadReckoning",
    "interpolate_yaw",
    "odometry_increments",
    "integrate",
    "dead_reckon",
    "relative_anchor_pose",
    "batch_adjoint",
]


@dataclass(frozen=True, slots=True)
class DeadReckoningConfig:
    """Noise model and options of dead reckoning (module docstring). The defaults describe an uncalibrated
    differential-drive household base (a Pioneer-class robot: 0.33 m wheelbase, rubber tyres about 5 cm wide) and
    a consumer tilt-compensated compass; the random-walk rates give way to the log's own odometry covariance when
    it is a plausible propagated one (``use_log_covariance``, ``holoslam.submaps.odometry_noise``)."""

    # m/sqrt(m): random wheel slip on floor joints, rugs and thresholds (the non-systematic error of Borenstein &
    # Feng's classification of odometry errors); 1 cm after 1 m, 10 cm after 100 m
    sigma_s_per_sqrt_m: float = 0.01
    # m/sqrt(m): sideways slip; 0: a differential drive cannot move sideways (its lateral error comes from its
    # heading error, which is modelled)
    sigma_lateral_per_sqrt_m: float = 0.0
    # fraction: odometer scale error, one unknown per segment: the effective wheel radius of rubber tyres changes
    # by 1-3 % with load, wear, pressure and carpet versus hard floor
    sigma_scale: float = 0.02
    # rad/sqrt(rad): random heading error of the wheel odometry while turning (tyre scrub; 3 deg per turn round)
    odo_sigma_turn_per_sqrt_rad: float = 0.02
    # rad/sqrt(m): random heading error while driving (uneven floor, thresholds); 0.2 deg after 1 m
    odo_sigma_heading_per_sqrt_m: float = 0.0035
    # fraction: turn scale error, one unknown per segment: the effective wheelbase lies somewhere within the tyres'
    # contact width, +-2.5 cm on 0.33 m (uniform: 4.4 % sigma)
    odo_sigma_turn_scale: float = 0.044
    # rad/m: heading drift from unequal wheel diameters, one unknown per segment: 0.3 % difference over a 0.33 m
    # wheelbase
    odo_sigma_drift_per_m: float = 0.01
    # rad: compass white noise when the log gives none: 2 deg, a consumer tilt-compensated compass module's
    # specified heading accuracy (e.g. Honeywell HMC6343: 2 deg RMS)
    compass_sigma: float = 0.035
    # m and rad, once per segment: odometry and scans are stamped by different clocks; a few milliseconds of
    # jitter at 0.4 m/s and 0.5 rad/s
    sigma_floor_m: float = 0.002
    sigma_floor_rad: float = 0.002  # rad, likewise
    use_compass: bool = True  # heading changes from the compass where it agrees with the odometry (Eq. 14)
    # the log's own odometry covariance, when it is a plausible propagated one, gives the random-walk rates above
    use_log_covariance: bool = True
    gate: float = 4.0  # compass/odometry consistency gate in sigmas
    window_ns: int = 1_000_000_000  # ns: the sliding window of the compass/odometry consistency test
    midpoint: bool = True  # Eq. 14 with the heading at the middle of each step (exact on arcs)


@dataclass(frozen=True, slots=True)
class DeadReckoning:
    """The result of integrating from ``stamps_ns[0]`` to ``stamps_ns[-1]``.

    ``aTb`` (N, 3) are the poses at every sample stamp (the start pose first), ``cov_aTb_end`` the 3x3
    covariance of the last pose in its own frame, ``compass_used`` (N-1,) which steps used the compass.
    """

    stamps_ns: np.ndarray
    aTb: np.ndarray
    cov_aTb_end: np.ndarray
    compass_used: np.ndarray

    @property
    def end(self) -> np.ndarray:
        return self.aTb[-1]


def batch_adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint matrices (N, 3, 3) of a batch of poses (N, 3) (see ``holoslam.geometry.adjoint``)."""
    T = np.asarray(T, dtype=np.float64).reshape(-1, 3)
    c, s = np.cos(T[:, 2]), np.sin(T[:, 2])
    A = np.zeros((T.shape[0], 3, 3))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = c, -s, T[:, 1]
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = s, c, -T[:, 0]
    A[:, 2, 2] = 1.0
    return A


def interpolate_yaw(
    stamps_ns: np.ndarray, yaw: np.ndarray, query_ns: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unwrapped yaw at ``query_ns`` and the interpolation (index (Q, 2), weight (Q, 2)) into the inputs."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    yaw = np.unwrap(np.asarray(yaw, dtype=np.float64))
    q = np.asarray(query_ns, dtype=np.int64)
    n = stamps.size
    if n == 0:
        raise IngestError("cannot interpolate compass yaw: the heading stream is empty")
    hi = np.clip(np.searchsorted(stamps, q, side="left"), 1, max(n - 1, 1)) if n > 1 else np.zeros_like(q)
    lo = np.maximum(hi - 1, 0)
    span = (stamps[hi] - stamps[lo]).astype(np.float64)
    w_hi = np.where(span > 0, (q - stamps[lo]) / np.where(span > 0, span, 1.0), 0.0)
    w_hi = np.clip(w_hi, 0.0, 1.0)
    idx = np.column_stack([lo, hi])
    w = np.column_stack([1.0 - w_hi, w_hi])
    return (w * yaw[idx]).sum(axis=1), idx, w


def odometry_increments(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances s_k (N-1,) and heading changes dtheta_k (N-1,) between consecutive odometry poses."""
    samples = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
    d = np.diff(samples[:, :2], axis=0)
    dist = np.hypot(d[:, 0], d[:, 1])
    fwd = d[:, 0] * np.cos(samples[:-1, 2]) + d[:, 1] * np.sin(samples[:-1, 2])
    s = np.where(fwd < 0.0, -dist, dist)
    dth = g.wrap(np.diff(samples[:, 2]))
    return s, np.asarray(dth, dtype=np.float64).reshape(-1)


def _step_increments(s: np.ndarray, dth: np.ndarray, midpoint: bool) -> tuple[np.ndarray, np.ndarray]:
    """SE(2) increments u_k (N, 3) and the Jacobians (N, 3, 3) of their right perturbation w.r.t. (s, dtheta,
    lateral slip)."""
    h = 0.5 if midpoint else 0.0
    a = h * dth
    u = np.column_stack([s * np.cos(a), s * np.sin(a), dth])
    # d(translation)/d(s, dth, lateral) in the start frame, then rotated into the increment's own frame.
    Jt = np.zeros((s.size, 2, 3))
    Jt[:, 0, 0], Jt[:, 1, 0] = np.cos(a), np.sin(a)
    Jt[:, 0, 1], Jt[:, 1, 1] = -h * s * np.sin(a), h * s * np.cos(a)
    Jt[:, 0, 2], Jt[:, 1, 2] = -np.sin(a), np.cos(a)
    RT = np.transpose(g.rot2(dth), (0, 2, 1))
    J = np.zeros((s.size, 3, 3))
    J[:, :2, :] = RT @ Jt
    J[:, 2, 1] = 1.0
    return u, J


def integrate(start: np.ndarray, s: np.ndarray, dth: np.ndarray, midpoint: bool = True) -> np.ndarray:
    """Eq. 14, vectorised: the poses (N+1, 3) from ``start`` after each step (s_k, dtheta_k)."""
    s = np.asarray(s, dtype=np.float64).reshape(-1)
    dth = np.asarray(dth, dtype=np.float64).reshape(-1)
    start = np.asarray(start, dtype=np.float64).reshape(3)
    h = 0.5 if midpoint else 0.0
    theta = start[2] + np.concatenate([[0.0], np.cumsum(dth)])
    head = theta[:-1] + h * dth
    x = start[0] + np.concatenate([[0.0], np.cumsum(s * np.cos(head))])
    y = start[1] + np.concatenate([[0.0], np.cumsum(s * np.sin(head))])
    return np.column_stack([x, y, g.wrap(theta)])


def _consistency_mask(
    stamps: np.ndarray, dth_c: np.ndarray, dth_o: np.ndarray, var_c_pair: float, var_o: np.ndarray, cfg
) -> np.ndarray:
    """True where the compass step agrees with odometry over every window containing it."""
    n = dth_c.size
    if n == 0:
        return np.zeros(0, dtype=bool)
    r = np.concatenate([[0.0], np.cumsum(dth_c - dth_o)])
    vo = np.concatenate([[0.0], np.cumsum(var_o)])
    t = stamps.astype(np.int64)
    # window k covers steps [k, end_k) with end_k the first sample at least window_ns after sample k
    end = np.searchsorted(t, t[:-1] + cfg.window_ns, side="left")
    end = np.clip(end, np.arange(1, n + 1), n)
    res = r[end] - r[:-1]
    sd = np.sqrt(var_c_pair + vo[end] - vo[:-1])
    good_window = np.abs(res) <= cfg.gate * sd
    # a step is trusted when at least one window containing it passes (difference array over [k, end_k)),
    # so a disturbance's onset flags only the steps no passing window can vouch for
    mark = np.zeros(n + 1, dtype=np.int64)
    np.add.at(mark, np.nonzero(good_window)[0], 1)
    np.add.at(mark, end[good_window], -1)
    return np.cumsum(mark)[:n] > 0


def dead_reckon(
    odom_stamps_ns: np.ndarray,
    odomTb: np.ndarray,
    t0_ns: int,
    t1_ns: int,
    start: np.ndarray | None = None,
    cov_start: np.ndarray | None = None,
    heading_stamps_ns: np.ndarray | None = None,
    heading_yaw: np.ndarray | None = None,
    heading_sigma: np.ndarray | None = None,
    config: DeadReckoningConfig | None = None,
) -> DeadReckoning:
    """Integrate Eq. 14 from ``t0_ns`` (pose ``start`` in the anchor frame, identity by default) to ``t1_ns``.

    The samples are t0, every odometry stamp strictly between, and t1; odometry poses and compass yaws are
    interpolated there. Without headings (or ``use_compass=False``) the odometry heading changes are used.
    """
    cfg = config or DeadReckoningConfig()
    ost = np.asarray(odom_stamps_ns, dtype=np.int64)
    if t1_ns < t0_ns:
        raise ValueError(f"dead_reckon: end stamp {t1_ns} is before start stamp {t0_ns}; pass them in time order")
    inner = ost[(ost > t0_ns) & (ost < t1_ns)]
    st = np.concatenate([[t0_ns], inner, [t1_ns]]).astype(np.int64) if t1_ns > t0_ns else np.array([t0_ns])
    samples = g.interpolate_poses(ost, odomTb, st)
    s, dth_o = odometry_increments(samples)
    start = np.zeros(3) if start is None else np.asarray(start, dtype=np.float64).reshape(3)
    cov0 = np.zeros((3, 3)) if cov_start is None else np.asarray(cov_start, dtype=np.float64)
    var_o = cfg.odo_sigma_turn_per_sqrt_rad**2 * np.abs(dth_o) + cfg.odo_sigma_heading_per_sqrt_m**2 * np.abs(s)
    use_c = np.zeros(s.size, dtype=bool)
    dth = dth_o.copy()
    if heading_stamps_ns is not None and heading_yaw is None:
        raise ValueError("dead_reckon: heading_stamps_ns given without heading_yaw; pass the yaws at those stamps")
    have_compass = cfg.use_compass and heading_stamps_ns is not None and len(heading_stamps_ns) >= 2
    if have_compass and heading_yaw is not None:  # (not None with the stamps, checked above)
        hst = np.asarray(heading_stamps_ns, dtype=np.int64)
        hsig = np.full(hst.size, cfg.compass_sigma) if heading_sigma is None else np.asarray(heading_sigma, float)
        hsig = np.where(np.isfinite(hsig) & (hsig > 0), hsig, cfg.compass_sigma)
        yaw_i, idx, w = interpolate_yaw(hst, heading_yaw, st)
        dth_c = np.diff(yaw_i)
        covered = (st[:-1] >= hst[0]) & (st[1:] <= hst[-1])
        var_c_pair = 2.0 * float(np.median(hsig)) ** 2
        use_c = _consistency_mask(st, dth_c, dth_o, var_c_pair, var_o, cfg) & covered
        dth = np.where(use_c, dth_c, dth_o)
    poses = integrate(start, s, dth, cfg.midpoint)
    # ---- covariance of the end pose -------------------------------------------------------------------
    _, J = _step_increments(s, dth, cfg.midpoint)
    end = poses[-1]
    Ad = batch_adjoint(g.between(np.broadcast_to(end, poses[1:].shape), poses[1:]))  # Ad(P_end^-1 P_{k+1})
    M = Ad @ J  # (N, 3, 3): end-pose sensitivity to (s_k, dtheta_k, lateral slip)
    F, G, L = M[:, :, 0], M[:, :, 1], M[:, :, 2]
    cov = np.einsum("k,ki,kj->ij", cfg.sigma_s_per_sqrt_m**2 * np.abs(s), F, F)
    if cfg.sigma_lateral_per_sqrt_m > 0.0:
        cov += np.einsum("k,ki,kj->ij", cfg.sigma_lateral_per_sqrt_m**2 * np.abs(s), L, L)
    cov += np.einsum("k,ki,kj->ij", np.where(use_c, 0.0, var_o), G, G)
    # systematic errors: one scale factor for all steps of the segment (s_k -> (1 + e) s_k), one turn scale
    # and one drift rate for its odometry-heading steps; each maps through the summed sensitivities
    v_scale = F.T @ s
    cov += cfg.sigma_scale**2 * np.outer(v_scale, v_scale)
    odo_steps = ~use_c
    v_turn = G[odo_steps].T @ dth_o[odo_steps]
    v_drift = G[odo_steps].T @ np.abs(s[odo_steps])
    cov += cfg.odo_sigma_turn_scale**2 * np.outer(v_turn, v_turn)
    cov += cfg.odo_sigma_drift_per_m**2 * np.outer(v_drift, v_drift)
    if have_compass and use_c.any():
        kk = np.nonzero(use_c)[0]
        S = np.zeros((hst.size, 3))  # sensitivity of the end pose to each compass reading
        for sign, row in ((1.0, kk + 1), (-1.0, kk)):
            for c in range(2):
                np.add.at(S, idx[row, c], sign * w[row, c][:, None] * G[kk])
        cov += np.einsum("m,mi,mj->ij", hsig**2, S, S)
    A0 = g.adjoint(g.between(end, poses[0]))
    cov += A0 @ cov0 @ A0.T
    if t1_ns > t0_ns:
        cov += np.diag([cfg.sigma_floor_m**2, cfg.sigma_floor_m**2, cfg.sigma_floor_rad**2])
    return DeadReckoning(st, poses, 0.5 * (cov + cov.T), use_c)


def relative_anchor_pose(
    mTr: np.ndarray, cov_mTr: np.ndarray, nTr: np.ndarray, cov_nTr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 15: the pose of anchor n in anchor m, ``mTn = mTr ∘ (nTr)^-1``, and its covariance.

    ``mTr`` is the robot pose at arrival in submap m (dead reckoning), ``nTr`` the same robot pose in submap
    n (self-localisation, Eq. 12); the two are independent. (The paper's printed Eq. 15 is garbled; this is the
    composition it describes, with theta_mn = theta_rm - theta_rn.)
    """
    nTr = np.asarray(nTr, dtype=np.float64)
    Ji = g.inverse_jacobian(nTr)
    return g.propagate_compose(np.asarray(mTr, float), np.asarray(cov_mTr, float), g.inverse(nTr),
                               Ji @ np.asarray(cov_nTr, float) @ Ji.T)
