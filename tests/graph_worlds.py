"""Small synthetic worlds with ground truth for the graph / solver tests (numpy only)."""

from __future__ import annotations

import numpy as np

from holoslam import geometry as geo
from holoslam.graph.problem import (
    HeadingMeasurements,
    LandmarkMeasurements,
    RelativePoseMeasurements,
    SlamProblem,
)


def square_loop(n_side: int = 6, step: float = 1.0) -> np.ndarray:
    """True anchor poses driving around a square twice (so the second lap revisits the first)."""
    poses = []
    x = y = t = 0.0
    for _lap in range(2):
        for _side in range(4):
            for _ in range(n_side):
                poses.append((x, y, t))
                x += step * np.cos(t)
                y += step * np.sin(t)
            t = float(geo.wrap(t + np.pi / 2))
    return np.array(poses)


def make_world(
    seed: int = 0,
    sigma_xy: float = 0.03,
    sigma_t: float = 0.01,
    n_side: int = 6,
    compass_bias: float | None = 0.3,
    heading_sigma: float = 0.03,
    landmark_sigma: float = 0.05,
    n_objects: int = 8,
):
    """Dead-reckoning chain + loop closures between laps + landmark sightings (+ compass)."""
    rng = np.random.default_rng(seed)
    wTa = square_loop(n_side)
    n = wTa.shape[0]
    half = n // 2
    cov = np.diag([sigma_xy**2, sigma_xy**2, sigma_t**2])
    i = list(range(n - 1))
    j = list(range(1, n))
    kind = ["dead_reckoning"] * (n - 1)
    # loops: anchor k of lap 2 to anchor k of lap 1
    for k in range(0, half, 3):
        i.append(k)
        j.append(k + half)
        kind.append("loop")
    i, j = np.array(i), np.array(j)
    true_rel = geo.between(wTa[i], wTa[j])
    noise = rng.multivariate_normal(np.zeros(3), cov, size=i.size)
    meas = geo.compose(true_rel, noise)
    rel = RelativePoseMeasurements(i, j, meas, np.repeat(cov[None], i.size, 0), np.array(kind, dtype=object))
    # objects around the square
    objects = {f"obj{k}": rng.uniform([-1.0, -1.0], [n_side + 1.0, n_side + 1.0]) for k in range(n_objects)}
    li, names, apos = [], [], []
    for a in range(n):
        for name, p in objects.items():
            a_p = geo.transform_points(geo.inverse(wTa[a]), p[None])[0]
            if 0.5 < np.hypot(*a_p) < 3.5:
                li.append(a)
                names.append(name)
                apos.append(a_p + rng.normal(0, landmark_sigma, 2))
    lcov = np.repeat((landmark_sigma**2 * np.eye(2))[None], len(li), 0)
    lm = LandmarkMeasurements(np.array(li), tuple(names), np.array(apos), lcov)
    if compass_bias is not None:
        hd = HeadingMeasurements(
            np.arange(n),
            geo.wrap(wTa[:, 2] + compass_bias + rng.normal(0, heading_sigma, n)),
            np.full(n, heading_sigma),
        )
    else:
        hd = HeadingMeasurements.empty()
    dr = SlamProblem(
        n,
        RelativePoseMeasurements(
            i[: n - 1], j[: n - 1], meas[: n - 1], np.repeat(cov[None], n - 1, 0), "dead_reckoning"
        ),
    )
    # the initial guess is dead reckoning, anchored at the true first pose
    init = geo.compose(wTa[0], dr.initial_wTa)
    problem = SlamProblem(n, rel, hd, lm, initial_wTa=init)
    return problem, wTa, objects
