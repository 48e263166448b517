"""One small builder per factor family; each returns its own ``gtsam.NonlinearFactorGraph``.

This module (with ``build.py``) is the only place that creates gtsam factors. gtsam is imported inside the
functions, so importing holoslam stays cheap.

Noise: every factor's Gaussian noise comes from the measurement's covariance (``noiseModel.Gaussian.Covariance``
with gtsam's "smart" detection of diagonal matrices, shared between equal covariances). A robust kernel, when
asked for, wraps it (``noiseModel.Robust``): Huber, Cauchy, DCS (dynamic covariance scaling) or Geman-McClure,
with its parameter in whitened (sigma) units.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import numpy as np

from holoslam.choices import RobustKernel
from holoslam.errors import GraphError

__all__ = [
    "RobustKernel",
    "Kernel",
    "NoiseCache",
    "noise_models",
    "between_factors",
    "prior_factors",
    "heading_factors",
    "magnetic_frame_prior",
    "landmark_factors",
    "bearing_range_from_xy",
]


@dataclass(frozen=True, slots=True)
class Kernel:
    """A robust kernel and its parameter (whitened units: residual / sigma)."""

    kind: RobustKernel = RobustKernel.NONE
    parameter: float = 1.0

    def make(self) -> Any:
        import gtsam

        m = gtsam.noiseModel.mEstimator
        k = RobustKernel(self.kind)
        if k is RobustKernel.NONE:
            return None
        if not self.parameter > 0:
            raise GraphError(f"robust kernel {k.value} needs a parameter > 0, got {self.parameter}")
        return {
            RobustKernel.HUBER: m.Huber.Create,
            RobustKernel.CAUCHY: m.Cauchy.Create,
            RobustKernel.DCS: m.DCS.Create,
            RobustKernel.GEMAN_MCCLURE: m.GemanMcClure.Create,
        }[k](float(self.parameter))


NO_KERNEL = Kernel()


class NoiseCache:
    """Shares one gtsam noise model between equal covariances (pose graphs often have only a few)."""

    def __init__(self, kernel: Kernel = NO_KERNEL) -> None:
        self._cache: dict[bytes, Any] = {}
        self._estimator = kernel.make()

    def covariance(self, cov: np.ndarray) -> Any:
        import gtsam

        key = np.ascontiguousarray(cov, dtype=np.float64).tobytes()
        model = self._cache.get(key)
        if model is None:
            try:
                model = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=np.float64), True)
            except RuntimeError as e:
                raise GraphError(
                    f"covariance {np.asarray(cov).tolist()} is not usable as noise: {e}"
                ) from None
            if self._estimator is not None:
                model = gtsam.noiseModel.Robust.Create(self._estimator, model)
            self._cache[key] = model
        return model


# nine generic weights (numpy.random.default_rng(20240601).uniform(0.5, 1.5, 9), written out: importing
# numpy.random costs ~30 ms of start-up)
_FINGERPRINT = np.array(
    [
        1.2918213070746603,
        1.0808676150981338,
        0.9148612535344952,
        1.447036623042723,
        0.642744424057014,
        0.9641058223621174,
        1.0987404988102845,
        1.0406810756493656,
        1.2909342319596049,
    ]
)


@dataclass(frozen=True, eq=False)
class _NoisePlan:
    """The distinct covariances of a batch (in order of first appearance) and what each becomes: ``is_diag``
    ones ``noiseModel.Diagonal.Sigmas(sigmas[k])``, the others ``noiseModel.Gaussian.SqrtInformation(R[k])``;
    ``which[r]`` is row r's distinct covariance."""

    is_diag: np.ndarray  # (K,) bool
    sigmas: np.ndarray  # (K, d)
    R: np.ndarray  # (K, d, d) upper Cholesky factor of the information (zero for diagonal ones)
    which: np.ndarray  # (M,) int64


def _noise_plan(cov: np.ndarray) -> _NoisePlan:
    """Vectorised part of :func:`noise_models`: distinct matrices, diagonal test, batched Cholesky, checks."""
    cov = np.ascontiguousarray(cov, dtype=np.float64)
    m, d = cov.shape[0], cov.shape[1]
    flat = cov.reshape(m, d * d)
    # a random projection of each matrix: distinct fingerprints prove distinct matrices (the usual case of
    # scan-matched edges) and equal ones everywhere flag a single shared covariance, both without sorting rows
    fp = np.sort(flat @ _FINGERPRINT[: d * d]) if m > 1 else np.zeros(m)
    if m <= 1 or np.all(fp[1:] != fp[:-1]):
        uniq, inverse = flat, np.arange(m)
    elif fp[0] == fp[-1] and np.array_equal(flat, np.broadcast_to(flat[0], flat.shape)):
        uniq, inverse = flat[:1], np.zeros(m, np.int64)
    else:
        void = flat.view(np.dtype((np.void, flat.dtype.itemsize * d * d))).ravel()
        _, first, inverse = np.unique(void, return_index=True, return_inverse=True)
        # number the distinct matrices in order of first appearance, so that the models are allocated in the
        # order of the factors that use them (np.unique's byte order scatters them in memory, and the solver's
        # linearisation, which walks the factors in order, pays ~3% for the cache misses)
        by_first = np.argsort(first, kind="stable")
        rank = np.empty_like(by_first)
        rank[by_first] = np.arange(by_first.size)
        uniq, inverse = flat[first[by_first]], rank[inverse.reshape(-1)]
    uc = uniq.reshape(-1, d, d)
    k_ = np.arange(d)
    diag = uniq[:, k_ * (d + 1)]
    # diagonal up to rounding: every off-diagonal entry c_ij is 0 or |c_ij| < 1e-12 sqrt(c_ii c_jj) (e.g. a
    # bearing/range covariance propagated to x/y and back)
    oi, oj = np.nonzero(~np.eye(d, dtype=bool))
    off = uniq[:, oi * d + oj]
    with np.errstate(invalid="ignore", over="ignore"):
        is_diag = np.all((off == 0) | (off * off < 1e-24 * np.abs(diag[:, oi] * diag[:, oj])), axis=1)
    ok = np.all(np.isfinite(uniq), axis=1) & np.all(diag > 0, axis=1)
    R = np.zeros_like(uc)
    full = ~is_diag & ok
    if full.any():
        from holoslam.graph.linalg import chol_upper, inv_sym

        R[full] = chol_upper(inv_sym(uc[full]))
    sigmas = np.sqrt(np.where(diag > 0, diag, 1.0))
    ok &= is_diag | np.all(np.isfinite(R), axis=(1, 2))
    if not ok.all():
        k = int(np.argmin(ok))
        raise GraphError(
            f"covariance {uc[k].tolist()} is not usable as noise (not positive definite); "
            "give every measurement a finite, non-zero uncertainty"
        )
    return _NoisePlan(is_diag, sigmas, R, inverse.astype(np.int64))


def _plan_models(plan: _NoisePlan, est: Any) -> list[Any]:
    """One gtsam noise model per distinct covariance of ``plan``, wrapped in ``est`` (an m-estimator) if any."""
    import gtsam

    diag_model, full_model = gtsam.noiseModel.Diagonal.Sigmas, gtsam.noiseModel.Gaussian.SqrtInformation
    models: list[Any] = [
        diag_model(s_k) if d_k else full_model(r_k, False)
        for d_k, s_k, r_k in zip(plan.is_diag.tolist(), plan.sigmas, plan.R, strict=True)
    ]
    if est is not None:
        robust = gtsam.noiseModel.Robust.Create
        models = [robust(est, model) for model in models]
    return models


def _row_models(plan: _NoisePlan, kernel: Kernel) -> Iterator[Any]:
    """Each row's noise model, in row order. When every row has its own Gaussian model (no kernel, all diagonal
    or all full), the models are made lazily, each just before the factor that takes it, so factor and model
    sit side by side in memory (as in gtsam's own readers); otherwise the distinct models are shared."""
    import gtsam

    est = kernel.make()
    if plan.which.size == plan.is_diag.size and est is None:
        if plan.is_diag.all():
            return map(gtsam.noiseModel.Diagonal.Sigmas, plan.sigmas)
        if not plan.is_diag.any():
            return map(gtsam.noiseModel.Gaussian.SqrtInformation, plan.R, repeat(False))
    return map(_plan_models(plan, est).__getitem__, plan.which.tolist())


def noise_models(cov: np.ndarray, kernel: Kernel = NO_KERNEL) -> tuple[list[Any], np.ndarray]:
    """Gaussian noise models for a batch of covariances (M, d, d), one per distinct covariance (in order of first
    appearance), and each row's model index. Vectorised: distinct matrices found with one ``np.unique``;
    diagonal ones (to 1e-12 in correlation) become ``noiseModel.Diagonal.Sigmas`` (what gtsam's "smart"
    constructors pick), the others ``noiseModel.Gaussian.SqrtInformation`` with the upper Cholesky factor R of
    the information (R^T R = cov^-1) computed in one batched numpy call. A robust kernel, when given, wraps
    every model."""
    plan = _noise_plan(cov)
    if plan.which.size == 0:
        return [], plan.which
    return _plan_models(plan, kernel.make()), plan.which


def between_factors(
    keys_i: np.ndarray, keys_j: np.ndarray, iTj: np.ndarray, cov_iTj: np.ndarray, kernel: Kernel = NO_KERNEL
) -> Any:
    """BetweenFactorPose2(key_i, key_j, iTj) for each row, noise from ``cov_iTj`` (see :func:`noise_models`);
    only the unavoidable per-factor constructor calls run per row, chained through ``map`` (no Python loop
    body)."""
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    m = np.reshape(iTj, (-1, 3))
    ki, kj = np.asarray(keys_i).tolist(), np.asarray(keys_j).tolist()
    if not len(ki) == len(kj) == m.shape[0] == np.shape(cov_iTj)[0]:
        raise GraphError(
            f"between_factors: {len(ki)} / {len(kj)} keys, {m.shape[0]} measurements and "
            f"{np.shape(cov_iTj)[0]} covariances; give one of each per factor"
        )
    models = _row_models(_noise_plan(np.reshape(cov_iTj, (-1, 3, 3))), kernel)
    poses = map(gtsam.Pose2, m[:, 0].tolist(), m[:, 1].tolist(), m[:, 2].tolist())
    deque(map(graph.add, map(gtsam.BetweenFactorPose2, ki, kj, poses, models)), maxlen=0)
    return graph


def prior_factors(keys: np.ndarray, wTa: np.ndarray, cov_wTa: np.ndarray) -> Any:
    """PriorFactorPose2 on each key."""
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    noise = NoiseCache()
    for k, m, c in zip(
        np.asarray(keys).tolist(),
        np.reshape(wTa, (-1, 3)).tolist(),
        np.reshape(cov_wTa, (-1, 3, 3)),
        strict=True,
    ):
        graph.add(gtsam.PriorFactorPose2(k, gtsam.Pose2(*m), noise.covariance(c)))
    return graph


def heading_factors(
    anchor_keys: np.ndarray,
    yaw: np.ndarray,
    sigma: np.ndarray,
    magnetic_key: int,
    kernel: Kernel = NO_KERNEL,
    xy_sigma: float = 1e4,
) -> Any:
    """Compass headings as BetweenFactorPose2(M, a_i, Pose2(0, 0, yaw_i)) with sigmas (xy_sigma, xy_sigma, sigma_i).

    M is the compass's magnetic frame: its rotation is the angle from the world x axis to the compass's zero, so
    ``theta_a = theta_M + yaw`` and the compass's constant bias (yaw = theta_a + bias) is ``-theta_M``. The huge
    x/y sigmas make the factor constrain the heading only.
    """
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    est = kernel.make()
    for k, y, s in zip(
        np.asarray(anchor_keys).tolist(), np.asarray(yaw).tolist(), np.asarray(sigma).tolist(), strict=True
    ):
        model: Any = gtsam.noiseModel.Diagonal.Sigmas(np.array([xy_sigma, xy_sigma, s]))
        if est is not None:
            model = gtsam.noiseModel.Robust.Create(est, model)
        graph.add(gtsam.BetweenFactorPose2(magnetic_key, k, gtsam.Pose2(0.0, 0.0, y), model))
    return graph


def magnetic_frame_prior(magnetic_key: int, theta0: float, xy_sigma: float = 1.0) -> Any:
    """Pins the magnetic frame's (meaningless) position at the origin; its rotation stays free."""
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    graph.add(
        gtsam.PriorFactorPose2(
            magnetic_key,
            gtsam.Pose2(0.0, 0.0, theta0),
            gtsam.noiseModel.Diagonal.Sigmas(np.array([xy_sigma, xy_sigma, 1e4])),
        )
    )
    return graph


def bearing_range_from_xy(
    a_position: np.ndarray, cov_a_position: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bearing, range and their 2x2 covariance (first-order propagation) of points in an anchor frame."""
    x, y = a_position[:, 0], a_position[:, 1]
    r2 = x * x + y * y
    r = np.sqrt(r2)
    J = np.stack([np.stack([-y / r2, x / r2], -1), np.stack([x / r, y / r], -1)], -2)
    cov = J @ cov_a_position @ np.swapaxes(J, 1, 2)
    return np.arctan2(y, x), r, 0.5 * (cov + np.swapaxes(cov, 1, 2))


def landmark_factors(
    anchor_keys: np.ndarray,
    landmark_keys: np.ndarray,
    a_position: np.ndarray,
    cov_a_position: np.ndarray,
    kernel: Kernel = NO_KERNEL,
) -> Any:
    """Eq. 16 of seed 002: an object seen at ``a_position`` in an anchor frame, as a native BearingRangeFactor2D
    whose bearing/range covariance is the x/y covariance propagated to first order."""
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    if len(anchor_keys) == 0:
        return graph
    bearing, rng, cov = bearing_range_from_xy(
        np.asarray(a_position, float), np.asarray(cov_a_position, float)
    )
    models, which = noise_models(cov, kernel)
    Factor, Rot2, add = gtsam.BearingRangeFactor2D, gtsam.Rot2, graph.add
    for ka, kl, b, r, w in zip(
        np.asarray(anchor_keys).tolist(),
        np.asarray(landmark_keys).tolist(),
        bearing.tolist(),
        rng.tolist(),
        which.tolist(),
        strict=True,
    ):
        add(Factor(ka, kl, Rot2(b), r, models[w]))
    return graph
