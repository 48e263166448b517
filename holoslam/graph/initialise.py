"""Global starts for the solver: initial anchor poses (and landmark positions) computed from the measurements
alone, without the problem's own guess.

- :func:`chordal`: the chordal relaxation of the rotations (Carlone et al., "Initialization techniques for 3D
  SLAM", ICRA 2015, in 2D: each rotation a free 2-vector ``z_a = (cos, sin)``, every relative measurement the
  linear equation ``z_j = R(theta_ij) z_i`` weighted by its rotation information, one sparse least-squares solve,
  each ``z_a`` normalised back to an angle), then the positions of the anchors and landmarks by a second linear
  least-squares solve with those rotations held (each relative translation and each sighting weighted by its
  full 2x2 information). No angle is unwrapped and no spanning tree chosen, so a drifting odometry chain or a
  strongly anisotropic scan match does not decide the answer: LM from this start reaches the known optimum of
  every standard 2D benchmark (MITb 20.6035, where LM from the file's guess or from LAGO stops at 385.12).
- :func:`lago`: gtsam's LAGO (orientation by phase unwrapping along a spanning tree, diagonal noise only).

Both linear solves are gtsam ``GaussianFactorGraph`` eliminations (multifrontal, COLAMD), built without a Python
loop body. Parts of the graph not connected to the anchored pose are each pinned at their own first pose's guess.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import SolverError
from holoslam.graph.keys import anchor_key
from holoslam.graph.linalg import chol_upper, inv_sym
from holoslam.graph.problem import SlamProblem

__all__ = ["chordal", "lago"]

_PIN = 1e6  # weight (in units of the strongest measurement's) of the equations that pin a gauge


def _components(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Connected-component label of each of ``n`` nodes under the edges (i, j): the smallest node of its
    component (union-find with path halving)."""
    parent = list(range(n))
    for a, b in zip(i.tolist(), j.tolist(), strict=True):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
    root = np.array(parent, dtype=np.int64)
    while True:  # flatten: every node points at its root
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


def _least_squares(
    i: np.ndarray, A_i: np.ndarray, j: np.ndarray, A_j: np.ndarray, b: np.ndarray, pin: int, guess: np.ndarray
) -> np.ndarray:
    """Solve min sum_k |A_i[k] x_i[k] + A_j[k] x_j[k] - b[k]|^2 over the 2-vectors x (as many as ``guess`` has
    rows) with x_pin held (strongly) at ``guess[pin]``. A part of the graph not connected to ``pin`` is pinned at
    its smallest variable's guess (looked for only when the first elimination finds the system singular)."""
    import gtsam

    unit = gtsam.noiseModel.Unit.Create(2)
    n, m = guess.shape[0], len(i)
    w = _PIN * max(float(np.abs(A_j).max()) if m else 1.0, 1.0)

    def pinned(pins: list[int]) -> Any:
        g = gtsam.GaussianFactorGraph()
        try:
            factors = map(gtsam.JacobianFactor, i.tolist(), A_i, j.tolist(), A_j, b, [unit] * m)
            deque(map(g.add, factors), maxlen=0)
            for k in pins:
                g.add(gtsam.JacobianFactor(int(k), w * np.eye(2), w * guess[k], unit))
            return g.optimize()
        except (RuntimeError, ValueError, TypeError, IndexError) as e:
            return e

    present = np.zeros(n, bool)
    present[i], present[j] = True, True
    vv = pinned([pin]) if present.all() else None
    if vv is None or isinstance(vv, Exception):  # parts not connected to the pin: one more pin in each
        labels = _components(n, i, j)
        vv = pinned([pin] + [r for r in np.unique(labels).tolist() if r != labels[pin]])
        if isinstance(vv, Exception):
            raise SolverError(f"chordal initialisation failed: {vv}") from None
    return np.array([vv.at(k) for k in range(n)], dtype=float).reshape(n, 2)


def _rotations(problem: SlamProblem, a0: int, theta0: float) -> np.ndarray:
    rel = problem.relative
    sq = np.sqrt(1.0 / rel.cov_iTj[:, 2, 2])[:, None, None]  # rotation information of each measurement
    R = geo.rot2(rel.iTj[:, 2])
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    guess = np.column_stack([np.cos(problem.initial_wTa[:, 2]), np.sin(problem.initial_wTa[:, 2])])
    guess[a0] = np.cos(theta0), np.sin(theta0)
    m = len(rel)
    eye = np.ascontiguousarray(np.broadcast_to(sq * np.eye(2), (m, 2, 2)))
    z = _least_squares(rel.i, -sq * R, rel.j, eye, np.zeros((m, 2)), a0, guess)
    return np.arctan2(z[:, 1], z[:, 0])


def _positions(
    problem: SlamProblem, theta: np.ndarray, a0: int, xy0: np.ndarray
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    rel, lm, n = problem.relative, problem.landmarks, problem.num_poses
    names = problem.landmark_ids
    var = {name: n + k for k, name in enumerate(names)}
    Ri, Rl = geo.rot2(theta[rel.i]), geo.rot2(theta[lm.i])
    i = np.concatenate([rel.i, lm.i]).astype(np.int64)
    j = np.concatenate([rel.j, np.array([var[x] for x in lm.landmark], dtype=np.int64)])
    b = np.concatenate(
        [np.einsum("kab,kb->ka", Ri, rel.iTj[:, :2]), np.einsum("kab,kb->ka", Rl, lm.a_position)]
    ).reshape(-1, 2)
    info_rel = inv_sym(rel.cov_iTj)[:, :2, :2]  # translation information with the rotation held
    info = np.concatenate(
        [
            Ri @ info_rel @ np.swapaxes(Ri, 1, 2),
            Rl @ inv_sym(lm.cov_a_position) @ np.swapaxes(Rl, 1, 2),
        ]
    ).reshape(-1, 2, 2)
    U = chol_upper(info)  # U^T U = information (world frame)
    guess = np.zeros((n + len(names), 2))
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    guess[:n] = problem.initial_wTa[:, :2]
    for name in names:
        guess[var[name]] = problem.initial_landmarks.get(name, np.zeros(2))
    guess[a0] = xy0
    xy = _least_squares(i, -U, j, U, np.einsum("kab,kb->ka", U, b), a0, guess)
    return xy[:n], {name: xy[var[name]] for name in names}


def chordal(problem: SlamProblem) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The chordal start (see the module docstring): anchor poses (N, 3) and landmark positions by object id.
    The anchor of the problem's first prior (else anchor 0) keeps its pose (the prior's, else the guess)."""
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    a0, w0 = (problem.priors[0].i, problem.priors[0].wTa) if problem.priors else (0, problem.initial_wTa[0])
    w0 = np.asarray(w0, dtype=float)
    theta = _rotations(problem, a0, float(w0[2]))
    theta[a0] = w0[2]
    xy, landmarks = _positions(problem, theta, a0, w0[:2])
    wTa = np.column_stack([xy, geo.wrap(theta)])
    if not np.all(np.isfinite(wTa)):
        raise SolverError("chordal initialisation gave non-finite poses; the measurements leave poses free")
    return wTa, landmarks


def lago(problem: SlamProblem, relative_rows: np.ndarray) -> np.ndarray:
    """LAGO on the relative measurements ``relative_rows`` (diagonal part of each covariance), aligned to the
    initial anchor 0."""
    import gtsam

    from holoslam.graph.factors import between_factors, prior_factors
    from holoslam.graph.keys import anchor_keys

    rel = problem.relative
    rows = np.asarray(relative_rows, dtype=np.int64)
    covd = np.zeros((rows.size, 3, 3))
    d = np.einsum("kii->ki", rel.cov_iTj[rows])
    covd[:, [0, 1, 2], [0, 1, 2]] = d
    g = between_factors(anchor_keys(rel.i[rows]), anchor_keys(rel.j[rows]), rel.iTj[rows], covd)
    g.push_back(prior_factors(anchor_keys(np.array([0])), np.zeros(3), np.diag([1e-8, 1e-8, 1e-10])))
    try:
        v = gtsam.lago.initialize(g)
    except (RuntimeError, IndexError) as e:  # IndexError: gtsam's map::at on some graphs (ais2klinik)
        raise SolverError(f"LAGO initialisation failed: {type(e).__name__}: {e}") from None
    wTa = np.array(problem.initial_wTa, dtype=float)
    for a in range(problem.num_poses):
        k = anchor_key(a)
        if v.exists(k):
            p = v.atPose2(k)
            wTa[a] = (p.x(), p.y(), p.theta())
    assert problem.initial_wTa is not None  # set by SlamProblem.__post_init__
    align = geo.compose(problem.initial_wTa[0], geo.inverse(wTa[0]))
    return geo.compose(align, wTa)
