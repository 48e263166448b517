"""A 2D SLAM problem as numpy batches and frozen records, so that the front end never touches gtsam.

Frames (GTSAM notation): ``wTa`` is the pose of anchor a in the world; a relative measurement ``iTj`` is the pose
of anchor j in anchor i with its covariance ``cov_iTj`` in the frame of ``iTj`` (right perturbation, what a
``BetweenFactorPose2`` expects). A heading is the raw compass yaw of anchor i (it includes the compass's unknown
constant bias). A landmark sighting is the position of an object in the frame of the anchor that saw it,
``a_position``, with its 2x2 covariance in that same frame.

This module depends on numpy alone; ``holoslam.graph.build`` turns a :class:`SlamProblem` into gtsam factors.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from holoslam import geometry as geo
from holoslam.errors import GraphError

if TYPE_CHECKING:  # pragma: no cover
    from holoslam.io.g2o import G2oGraph

__all__ = [
    "MeasurementFamily",
    "MeasurementRef",
    "RelativePoseMeasurements",
    "HeadingMeasurements",
    "LandmarkMeasurements",
    "PosePrior",
    "SlamProblem",
    "problem_from_g2o",
    "odometry_chain",
]


class MeasurementFamily(str, Enum):
    """Which batch of a :class:`SlamProblem` a measurement belongs to."""

    RELATIVE = "relative"
    HEADING = "heading"
    LANDMARK = "landmark"
    PRIOR = "prior"


@dataclass(frozen=True, slots=True)
class MeasurementRef:
    """One measurement of a problem: its family and its row in that family's batch."""

    family: MeasurementFamily
    index: int


def _readonly(a: np.ndarray, dtype: type | np.dtype = np.float64) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


@functools.cache
def _off_diagonal(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices of the (i, j), i < j, entries of a dim x dim matrix and of their (j, i) mirrors."""
    i, j = np.triu_indices(dim, 1)
    return i * dim + j, j * dim + i


def _check_cov(cov: np.ndarray, dim: int, what: str) -> None:
    """Covariances must be finite, symmetric and positive definite (vectorised over the batch)."""
    if cov.ndim != 3 or cov.shape[1:] != (dim, dim):
        raise GraphError(f"{what}: expected shape (M, {dim}, {dim}), got {cov.shape}")
    m = cov.shape[0]
    if m == 0:
        return
    flat = cov.reshape(m, dim * dim)
    finite = np.isfinite(flat).all(axis=1)
    if not finite.all():
        bad = int(np.argmin(finite))
        raise GraphError(f"{what}[{bad}] has non-finite entries: {cov[bad].tolist()}; fix the measurement")
    upper, lower = _off_diagonal(dim)
    asym = np.abs(flat[:, upper] - flat[:, lower]).max(axis=1, initial=0.0)
    scale = np.abs(flat).max(axis=1)
    unsym = asym > 1e-9 * np.maximum(scale, 1e-300)
    if unsym.any():
        bad = int(np.argmax(unsym))
        raise GraphError(f"{what}[{bad}] is not symmetric: {cov[bad].tolist()}")
    from holoslam.io.g2o import positive_definite

    pd = positive_definite(cov if not asym.any() else 0.5 * (cov + np.swapaxes(cov, 1, 2)))
    if not pd.all():
        bad = int(np.argmax(~pd))
        eig = np.linalg.eigvalsh(cov[bad : bad + 1])
        raise GraphError(
            f"{what}[{bad}] is not positive definite (eigenvalues {eig[0].tolist()}); "
            "give every measurement a non-zero uncertainty"
        )


def _check_index(idx: np.ndarray, n: int, what: str) -> None:
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        bad = int(np.argmax((idx < 0) | (idx >= n)))
        raise GraphError(f"{what}[{bad}] = {int(idx[bad])} is not an anchor index in [0, {n})")


@dataclass(frozen=True, eq=False)
class RelativePoseMeasurements:
    """M relative poses ``iTj`` between anchors i and j (between-factors), with covariances and a kind
    ("dead_reckoning", "scan_match", "loop", "odometry", ...). Loops get the outlier treatment."""

    i: np.ndarray
    j: np.ndarray
    iTj: np.ndarray
    cov_iTj: np.ndarray
    kind: np.ndarray

    def __post_init__(self) -> None:
        m = len(np.atleast_1d(self.i))
        object.__setattr__(self, "i", _readonly(np.reshape(self.i, (m,)), np.int64))
        object.__setattr__(self, "j", _readonly(np.reshape(self.j, (m,)), np.int64))
        object.__setattr__(self, "iTj", _readonly(np.reshape(self.iTj, (m, 3))))
        object.__setattr__(self, "cov_iTj", _readonly(np.reshape(self.cov_iTj, (m, 3, 3))))
        kind = np.asarray(self.kind, dtype=object)
        if kind.ndim == 0:
            kind = np.full(m, kind.item(), dtype=object)
        object.__setattr__(self, "kind", _readonly(np.reshape(kind, (m,)), object))
        _check_cov(self.cov_iTj, 3, "RelativePoseMeasurements.cov_iTj")
        if m and np.any(self.i == self.j):
            bad = int(np.argmax(self.i == self.j))
            raise GraphError(f"relative measurement {bad} links anchor {int(self.i[bad])} to itself")

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def empty(cls) -> RelativePoseMeasurements:
        return cls(
            np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, object)
        )

    def select(self, mask: np.ndarray) -> RelativePoseMeasurements:
        return RelativePoseMeasurements(
            self.i[mask], self.j[mask], self.iTj[mask], self.cov_iTj[mask], self.kind[mask]
        )


@dataclass(frozen=True, eq=False)
class HeadingMeasurements:
    """K raw compass yaws of anchors i (radians, with the compass's constant bias) and their sigmas."""

    i: np.ndarray
    yaw: np.ndarray
    sigma: np.ndarray

    def __post_init__(self) -> None:
        k = len(np.atleast_1d(self.i))
        object.__setattr__(self, "i", _readonly(np.reshape(self.i, (k,)), np.int64))
        object.__setattr__(self, "yaw", _readonly(geo.wrap(np.reshape(self.yaw, (k,)).astype(float))))
        object.__setattr__(self, "sigma", _readonly(np.reshape(self.sigma, (k,))))
        if k and not np.all(np.isfinite(self.sigma) & (self.sigma > 0)):
            bad = int(np.argmax(~(np.isfinite(self.sigma) & (self.sigma > 0))))
            raise GraphError(f"heading {bad} has sigma {self.sigma[bad]}; sigmas must be finite and > 0")

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def empty(cls) -> HeadingMeasurements:
        return cls(np.zeros(0, int), np.zeros(0), np.zeros(0))


@dataclass(frozen=True, eq=False)
class LandmarkMeasurements:
    """L sightings: anchor ``i`` saw object ``landmark[k]`` at ``a_position[k]`` (anchor frame) with 2x2
    covariance ``cov_a_position[k]``; ``z`` is the label's height (m, NaN when unknown; not optimised)."""

    i: np.ndarray
    landmark: tuple[str, ...]
    a_position: np.ndarray
    cov_a_position: np.ndarray
    z: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(np.atleast_1d(self.i))
        object.__setattr__(self, "i", _readonly(np.reshape(self.i, (n,)), np.int64))
        object.__setattr__(self, "landmark", tuple(str(s) for s in self.landmark))
        object.__setattr__(self, "a_position", _readonly(np.reshape(self.a_position, (n, 2))))
        object.__setattr__(self, "cov_a_position", _readonly(np.reshape(self.cov_a_position, (n, 2, 2))))
        z = np.full(n, np.nan) if self.z is None else np.reshape(self.z, (n,))
        object.__setattr__(self, "z", _readonly(z))
        if len(self.landmark) != n:
            raise GraphError(f"LandmarkMeasurements: {n} anchors but {len(self.landmark)} landmark ids")
        _check_cov(self.cov_a_position, 2, "LandmarkMeasurements.cov_a_position")
        r = np.hypot(self.a_position[:, 0], self.a_position[:, 1]) if n else np.zeros(0)
        if n and np.any(r < 1e-6):
            bad = int(np.argmax(r < 1e-6))
            raise GraphError(
                f"landmark sighting {bad} ({self.landmark[bad]}) is at the anchor origin; a sighting needs a "
                "non-zero range to be a bearing/range factor"
            )

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def empty(cls) -> LandmarkMeasurements:
        return cls(np.zeros(0, int), (), np.zeros((0, 2)), np.zeros((0, 2, 2)))

    def select(self, mask: np.ndarray) -> LandmarkMeasurements:
        idx = np.flatnonzero(np.asarray(mask)) if np.asarray(mask).dtype == bool else np.asarray(mask)
        assert self.z is not None  # set by __post_init__
        return LandmarkMeasurements(
            self.i[idx],
            tuple(self.landmark[k] for k in idx),
            self.a_position[idx],
            self.cov_a_position[idx],
            self.z[idx],
        )

    def relabel(self, landmark: tuple[str, ...]) -> LandmarkMeasurements:
        return LandmarkMeasurements(self.i, landmark, self.a_position, self.cov_a_position, self.z)


@dataclass(frozen=True, eq=False)
class PosePrior:
    """A Gaussian prior on anchor i: ``wTa`` with covariance ``cov_wTa`` (fixes the gauge)."""

    i: int
    wTa: np.ndarray
    cov_wTa: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "i", int(self.i))
        object.__setattr__(self, "wTa", _readonly(np.reshape(self.wTa, (3,))))
        object.__setattr__(self, "cov_wTa", _readonly(np.reshape(self.cov_wTa, (3, 3))))
        _check_cov(self.cov_wTa[None], 3, f"PosePrior({self.i}).cov_wTa")


def default_prior(
    i: int, wTa: np.ndarray, sigmas: tuple[float, float, float] = (1e-4, 1e-4, 1e-5)
) -> PosePrior:
    """A tight prior that pins anchor i at ``wTa`` (what "first pose fixed" means)."""
    return PosePrior(i, wTa, np.diag(np.square(sigmas)))


@dataclass(frozen=True, eq=False)
class SlamProblem:
    """Everything the solver needs. ``initial_wTa`` (N, 3) is the initial guess of the anchor poses,
    ``initial_landmarks`` maps object ids to an initial world position (missing ids are initialised from their
    first sighting). ``pose_ids`` are external ids of the anchors (g2o vertex ids), default 0..N-1;
    ``landmark_ids`` likewise for landmarks read from a file. ``stamps_ns`` are the anchors' times (or None)."""

    num_poses: int
    relative: RelativePoseMeasurements = field(default_factory=RelativePoseMeasurements.empty)
    headings: HeadingMeasurements = field(default_factory=HeadingMeasurements.empty)
    landmarks: LandmarkMeasurements = field(default_factory=LandmarkMeasurements.empty)
    initial_wTa: np.ndarray | None = None
    initial_landmarks: dict[str, np.ndarray] = field(default_factory=dict)
    priors: tuple[PosePrior, ...] = ()
    pose_ids: np.ndarray | None = None
    stamps_ns: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = int(self.num_poses)
        object.__setattr__(self, "num_poses", n)
        if n <= 0:
            raise GraphError("SlamProblem needs at least one anchor pose")
        _check_index(self.relative.i, n, "relative.i")
        _check_index(self.relative.j, n, "relative.j")
        if self.initial_wTa is None:
            init = odometry_chain(n, self.relative)
        else:
            init = np.asarray(self.initial_wTa, dtype=np.float64)
        if init.shape != (n, 3) or not np.all(np.isfinite(init)):
            raise GraphError(f"initial_wTa must be a finite ({n}, 3) array, got shape {init.shape}")
        init = init.copy()
        init[:, 2] = geo.wrap(init[:, 2])
        object.__setattr__(self, "initial_wTa", _readonly(init))
        ids = np.arange(n) if self.pose_ids is None else np.asarray(self.pose_ids)
        if ids.shape != (n,):
            raise GraphError(f"pose_ids must have shape ({n},), got {ids.shape}")
        object.__setattr__(self, "pose_ids", _readonly(ids, np.int64))
        if self.stamps_ns is not None:
            object.__setattr__(self, "stamps_ns", _readonly(np.reshape(self.stamps_ns, (n,)), np.int64))
        _check_index(self.relative.i, n, "relative.i")
        _check_index(self.relative.j, n, "relative.j")
        _check_index(self.headings.i, n, "headings.i")
        _check_index(self.landmarks.i, n, "landmarks.i")
        for p in self.priors:
            _check_index(np.array([p.i]), n, "priors.i")
        lm = {str(k): _readonly(np.reshape(v, (2,))) for k, v in self.initial_landmarks.items()}
        object.__setattr__(self, "initial_landmarks", lm)

    @property
    def landmark_ids(self) -> tuple[str, ...]:
        """Object ids of the landmark variables, in order of first sighting."""
        return tuple(dict.fromkeys(self.landmarks.landmark))


def odometry_chain(num_poses: int, relative: RelativePoseMeasurements) -> np.ndarray:
    """Initial poses by composing relative measurements in their order (gtsam ``load2D``'s rule): an anchor not
    yet placed is put at the identity when it is the first end of a measurement, or at ``wTi ∘ iTj`` when it is
    the second end. Anchors no measurement reaches stay at the identity."""
    wTa = np.zeros((num_poses, 3))
    placed = np.zeros(num_poses, dtype=bool)
    ii, jj, iTj = relative.i, relative.j, relative.iTj
    for k in range(len(relative)):
        i, j = int(ii[k]), int(jj[k])
        placed[i] = True
        if not placed[j]:
            x, y, t = wTa[i]
            c, s = math.cos(t), math.sin(t)
            mx, my, mt = iTj[k]
            wTa[j] = (x + c * mx - s * my, y + s * mx + c * my, t + mt)
            placed[j] = True
    wTa[:, 2] = geo.wrap(wTa[:, 2])
    return wTa


def _chain_initialisation(
    n: int,
    ei: np.ndarray,
    ej: np.ndarray,
    meas: np.ndarray,
    eline: np.ndarray,
    li: np.ndarray,
    lline: np.ndarray,
) -> np.ndarray | None:
    """gtsam ``load2D``'s file-order initialisation, vectorised for the common case of a graph without vertices
    whose poses are first mentioned by the odometry chain: pose 0 first appears as the first end of an edge and
    every pose k > 0 first appears (over edge and landmark lines) as the second end of an edge (k-1, k). Then the
    rule reduces to composing that chain (a cumulative sum of headings and of rotated steps). Returns None when
    the case does not apply (the caller runs the line-by-line rule)."""
    if ei.size < n - 1:
        return None
    lines = np.concatenate([eline, eline, lline])
    poses = np.concatenate([ei, ej, li])
    first_line = np.full(n, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(first_line, poses, lines)
    odo = np.flatnonzero(ej == ei + 1)
    # the first odometry edge (in file order) reaching each pose k > 0
    odo = odo[np.argsort(eline[odo], kind="stable")]
    _, first = np.unique(ej[odo], return_index=True)
    step = odo[first]
    if step.size != n - 1 or not np.array_equal(ej[step], np.arange(1, n)):
        return None
    if not np.array_equal(eline[step], first_line[1:]):
        return None
    first0 = np.flatnonzero((ei == 0) & (eline == first_line[0]))
    if first0.size == 0:
        return None
    m = meas[step]
    theta = np.concatenate([[0.0], np.cumsum(m[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    wTa = np.zeros((n, 3))
    wTa[1:, 0] = np.cumsum(c * m[:, 0] - s * m[:, 1])
    wTa[1:, 1] = np.cumsum(s * m[:, 0] + c * m[:, 1])
    wTa[:, 2] = geo.wrap(theta)
    return wTa


def _pose_index(*id_arrays: np.ndarray) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The sorted distinct pose ids of a file (vertex ids and the poses its edges name) and a function mapping ids
    to their anchor index. Dense non-negative ids (the usual 0..N-1) are found with a presence mask and mapped by
    a lookup table, O(N) with no sort; others (huge or negative ids of a graph built in memory) by sorting."""
    ids = [np.asarray(a, dtype=np.int64).reshape(-1) for a in id_arrays]
    total = sum(a.size for a in ids)
    top = max((int(a.max()) for a in ids if a.size), default=-1)
    low = min((int(a.min()) for a in ids if a.size), default=0)
    if total == 0:
        return np.zeros(0, np.int64), lambda x: np.zeros(0, np.int64)
    if low >= 0 and top < 4 * total + 1024:
        present = np.zeros(top + 1, dtype=bool)
        for a in ids:
            present[a] = True
        pose_ids = np.flatnonzero(present).astype(np.int64)
        if pose_ids.size == top + 1:  # ids 0..N-1: the id is the index
            return pose_ids, lambda x: np.asarray(x, dtype=np.int64).reshape(-1).copy()
        lut = np.cumsum(present, dtype=np.int64) - 1
        return pose_ids, lambda x: lut[np.asarray(x, dtype=np.int64).reshape(-1)]
    pose_ids = np.unique(np.concatenate(ids))
    return pose_ids, lambda x: np.searchsorted(pose_ids, np.asarray(x, dtype=np.int64).reshape(-1)).astype(
        np.int64
    )


def problem_from_g2o(graph: G2oGraph, fix_first: bool = True) -> SlamProblem:
    """Turn a parsed g2o / TORO / iSAM text graph into a :class:`SlamProblem`.

    Pose vertex ids are mapped to anchor indices in increasing id order (``pose_ids`` keeps them). Poses without a
    VERTEX line and landmarks without a VERTEX_XY line are initialised like gtsam's ``load2D`` (in file order,
    composing each edge onto its first pose). With ``fix_first`` the lowest-id pose (or the one marked FIX) gets a
    tight prior at its initial value.
    """
    pose_ids, to_index = _pose_index(graph.vertex_ids, graph.edge_i, graph.edge_j, graph.landmark_pose)
    n = pose_ids.size
    if n == 0:
        raise GraphError(f"{graph.source}: the graph has no poses")

    ei = to_index(graph.edge_i) if graph.edge_i.size else np.zeros(0, np.int64)
    ej = to_index(graph.edge_j) if graph.edge_j.size else np.zeros(0, np.int64)
    relative = RelativePoseMeasurements(
        ei, ej, graph.edge_measured, graph.edge_cov, np.full(ei.size, "g2o", object)
    )
    li = to_index(graph.landmark_pose) if graph.landmark_pose.size else np.zeros(0, np.int64)
    landmarks = LandmarkMeasurements(
        li, tuple(str(int(v)) for v in graph.landmark_id), graph.landmark_measured, graph.landmark_cov
    )

    # Initial values: vertices first, then gtsam load2D's file-order rule for everything else.
    wTa = np.zeros((n, 3))
    placed = np.zeros(n, dtype=bool)
    if graph.vertex_ids.size:
        vi = to_index(graph.vertex_ids)
        wTa[vi] = graph.vertex_poses
        placed[vi] = True
    init_lm: dict[str, np.ndarray] = {
        str(int(k)): np.asarray(p, dtype=float)
        for k, p in zip(graph.point_ids, graph.point_positions, strict=True)
    }
    assert graph.edge_line is not None and graph.landmark_line is not None  # set by G2oGraph.__post_init__
    chain = None
    if not placed.any() and n > 1:
        chain = _chain_initialisation(
            n, ei, ej, graph.edge_measured, graph.edge_line, li, graph.landmark_line
        )
    if chain is not None:
        wTa[:] = chain
        placed[:] = True
        if li.size:
            order = np.argsort(graph.landmark_line, kind="stable")
            names = np.array(landmarks.landmark, dtype=object)[order]
            _, first = np.unique(names.astype(str), return_index=True)
            rows = order[np.sort(first)]
            pts = geo.transform_points(wTa[li[rows]], graph.landmark_measured[rows])
            for r, p in zip(rows.tolist(), pts, strict=True):
                init_lm.setdefault(landmarks.landmark[r], p)
    if not placed.all() or len(init_lm) < len(set(landmarks.landmark)):
        el, ll = graph.edge_line.tolist(), graph.landmark_line.tolist()
        events = sorted([(el[k], 0, k) for k in range(ei.size)] + [(ll[k], 1, k) for k in range(li.size)])
        eil, ejl, meas = ei.tolist(), ej.tolist(), graph.edge_measured.tolist()
        for _, typ, k in events:
            if typ == 0:
                i, j = eil[k], ejl[k]
                placed[i] = True
                if not placed[j]:
                    x, y, t = wTa[i]
                    c, s = math.cos(t), math.sin(t)
                    mx, my, mt = meas[k]
                    wTa[j] = (x + c * mx - s * my, y + s * mx + c * my, math.remainder(t + mt, 2 * math.pi))
                    placed[j] = True
            else:
                i, name = int(li[k]), landmarks.landmark[k]
                placed[i] = True
                if name not in init_lm:
                    init_lm[name] = geo.transform_points(wTa[i], graph.landmark_measured[k][None])[0]
    priors: tuple[PosePrior, ...] = ()
    if graph.fixed_ids.size:
        index_of = {int(v): k for k, v in enumerate(pose_ids.tolist())}
        priors = tuple(
            default_prior(index_of[int(f)], wTa[index_of[int(f)]])
            for f in graph.fixed_ids
            if int(f) in index_of
        )
    elif fix_first:
        priors = (default_prior(0, wTa[0]),)
    return SlamProblem(
        num_poses=n,
        relative=relative,
        landmarks=landmarks,
        initial_wTa=wTa,
        initial_landmarks=init_lm,
        priors=priors,
        pose_ids=pose_ids,
    )
