"""What a solve returns: the optimised anchors and landmarks with their statistics (:class:`Solution`), moved
objects, and, for ``Initialisation.AUTO``, what each start reached and whether they agree (:class:`StartsReport`).
Plain frozen records of numpy arrays; ``holoslam.solve`` re-exports them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam.errors import GraphError
from holoslam.graph.options import Initialisation, Method
from holoslam.graph.problem import MeasurementRef

__all__ = ["MovedObject", "StartOutcome", "StartsReport", "Solution"]


@dataclass(frozen=True, eq=False)
class MovedObject:
    """An object whose sightings split in time: at ``w_position_before`` until anchor ``last_anchor_before``,
    at ``w_position_after`` from anchor ``first_anchor_after``."""

    object_id: str
    w_position_before: np.ndarray
    w_position_after: np.ndarray
    last_anchor_before: int
    first_anchor_after: int

    @property
    def distance(self) -> float:
        return float(np.hypot(*(self.w_position_after - self.w_position_before)))


@dataclass(frozen=True, slots=True)
class StartOutcome:
    """One start of ``Initialisation.AUTO``: its final error (nan: it failed, ``failure`` says why), LM
    iterations, seconds, and how far its poses ended from the kept solution (largest position / heading
    difference). ``reached`` names the earlier start whose solution its LM reached (it stopped there)."""

    initialisation: Initialisation
    final_error: float
    iterations: int = 0
    seconds: float = 0.0
    max_dxy: float = math.nan  # m
    max_dtheta: float = math.nan  # rad
    reached: Initialisation | None = None
    failure: str = ""

    @property
    def ok(self) -> bool:
        return math.isfinite(self.final_error)


@dataclass(frozen=True, slots=True)
class StartsReport:
    """Which starts ``Initialisation.AUTO`` tried and whether they agree. ``agree``: every start that ran ended at
    the kept solution's final error (within ``SolveOptions.auto_agree_error``); None when only one start ran.
    ``beyond`` of ``measurements`` lie beyond the chi-square bound at the kept solution; more than
    ``beyond_limit`` runs ``fallback`` (``fallback_ran``). ``skipped``: starts not solved (same as an earlier one,
    or a loop-free graph where LAGO returns the chain)."""

    outcomes: tuple[StartOutcome, ...]
    kept: Initialisation
    agree: bool | None
    beyond: int
    measurements: int
    beyond_limit: int
    fallback: Initialisation | None
    fallback_ran: bool
    skipped: tuple[tuple[Initialisation, str], ...] = ()

    @property
    def fits(self) -> bool:
        """The kept solution explains the measurements (no more beyond the chi-square bound than allowed)."""
        return self.beyond <= self.beyond_limit


@dataclass(frozen=True, eq=False)
class Solution:
    """The optimised anchors ``wTa`` (N, 3) and landmarks ``w_landmarks`` (L, 2) named by ``landmark_ids``
    (a moved object's earlier position is ``"<id>@before"``), their marginal covariances when asked for (NaN rows
    for anchors not asked for), solver statistics, the rejected measurements, moved objects, and the compass
    bias (yaw_compass - theta_true, radians; None without headings)."""

    wTa: np.ndarray
    cov_wTa: np.ndarray | None
    landmark_ids: tuple[str, ...]
    w_landmarks: np.ndarray
    cov_w_landmarks: np.ndarray | None
    iterations: int
    initial_error: float
    final_error: float
    rejected: tuple[MeasurementRef, ...] = ()
    moved_objects: tuple[MovedObject, ...] = ()
    compass_bias: float | None = None
    method: Method = Method.BATCH
    rounds: int = 1
    seconds: float = 0.0
    pose_ids: np.ndarray | None = None
    initialisation: Initialisation | None = None  # the start used (AUTO: the kept candidate)
    candidates: tuple[tuple[Initialisation, float], ...] = ()  # AUTO: (start, final error; nan = failed)
    starts: StartsReport | None = None  # AUTO: every start's outcome, their agreement, the fallback decision

    def landmark(self, object_id: str) -> np.ndarray:
        try:
            return self.w_landmarks[self.landmark_ids.index(object_id)]
        except ValueError:
            raise GraphError(
                f"no landmark {object_id!r} in the solution; known: {self.landmark_ids}"
            ) from None
