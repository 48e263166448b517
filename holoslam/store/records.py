"""The map store's records: what a store holds (``StoredSession``, ``StoredSubmap``, ``StoredFactors``,
``StoredSightings``, ``ObjectState``, ``StoredTrajectory``) and what one session adds in one transaction
(``SessionUpdate`` with its ``NewSubmap`` rows). Plain numpy arrays and frozen dataclasses; no SQL here.

Submap references in a ``SessionUpdate``: a stored submap by its row id (>= 1), a submap of the new session by
``new_ref(k)`` = -(k + 1), k its index in the session."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["StoredSession", "StoredSubmap", "StoredFactors", "StoredSightings", "ObjectState", "StoredTrajectory",
           "NewSubmap", "SessionUpdate", "new_ref", "ObjectStatus", "JOINED_BY"]

JOINED_BY = ("laser", "objects", "both", "none")


class ObjectStatus:
    """An object's status in one session (``object_history.status``)."""

    SEEN = "seen"  # seen where the store expected it
    MOVED = "moved"  # seen elsewhere: displaced significantly (distance and chi-square test)
    GONE = "gone"  # not seen although its place was in the robot's view
    NEW = "new"  # seen for the first time in this home
    UNPLACED = "unplaced"  # seen in a session that could not be joined: position in the session's own frame
    ALL = (SEEN, MOVED, GONE, NEW, UNPLACED)


def new_ref(k: int) -> int:
    """The reference of the new session's submap of index k in a ``SessionUpdate``."""
    return -(int(k) + 1)


@dataclass(frozen=True, eq=False)
class StoredSession:
    id: int
    log_name: str
    log_sha256: str
    start_ns: int
    end_ns: int
    added_utc: str
    joined: bool
    joined_by: str
    wTs: np.ndarray  # (3,) the session frame in the world (identity when not joined)
    cov_wTs: np.ndarray | None
    relocalisation_s: float
    summary: dict[str, Any]


@dataclass(frozen=True, eq=False)
class StoredSubmap:
    """A stored submap; ``prob`` is None when read without grids."""

    id: int
    session_id: int
    idx: int
    anchor_stamp_ns: int
    wTa: np.ndarray
    cov_wTa: np.ndarray | None
    sTa: np.ndarray
    origin: tuple[float, float]
    resolution: float
    retired_by: int | None
    prob: np.ndarray | None = None
    points: np.ndarray | None = None
    known: np.ndarray | None = None  # cells a scan updated (the grid's unknown cells read p_min = 0.1)


@dataclass(frozen=True, eq=False)
class StoredFactors:
    """Relative poses between stored submaps (row ids ``i``, ``j``), as batches."""

    id: np.ndarray
    session_id: np.ndarray
    i: np.ndarray
    j: np.ndarray
    iTj: np.ndarray
    cov_iTj: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])


@dataclass(frozen=True, eq=False)
class StoredSightings:
    submap_id: np.ndarray
    object_id: tuple[str, ...]
    placement: tuple[str, ...]
    a_position: np.ndarray  # (L, 2)
    cov_a_position: np.ndarray  # (L, 2, 2)
    z: np.ndarray

    def __len__(self) -> int:
        return int(self.submap_id.shape[0])


@dataclass(frozen=True, eq=False)
class ObjectState:
    """One object in one session: its world position (x, y) and height z with the 2x2 covariance, its status
    (``ObjectStatus``), the displacement from its previous place and its covariance when it moved, how often it
    was seen, the mean direction from the object to the robot when it was seen (unit vector; None when not
    seen), its placement (the landmark variable of the joint graph), and its label's outward normal: the
    horizontal unit direction in the world out of its printed face, from the pose of its readings (None when
    not known), with the standard deviation of that direction in rad."""

    object_id: str
    kind: str
    payload: str
    status: str
    w_xy: np.ndarray | None
    z: float
    cov_w_xy: np.ndarray | None
    sightings: int
    placement: str = ""
    displacement: np.ndarray | None = None
    cov_displacement: np.ndarray | None = None
    view: np.ndarray | None = None
    session_id: int = 0
    normal: np.ndarray | None = None
    normal_sigma_rad: float = float("nan")


@dataclass(frozen=True, eq=False)
class StoredTrajectory:
    """A session's base poses: at ``stamps_ns``, the pose ``aTb`` in the anchor frame of its submap ``anchor_idx``
    (index in the session) and ``sTb`` in the session's own frame."""

    stamps_ns: np.ndarray
    anchor_idx: np.ndarray
    aTb: np.ndarray
    sTb: np.ndarray


@dataclass(frozen=True, eq=False)
class NewSubmap:
    idx: int
    anchor_stamp_ns: int
    wTa: np.ndarray
    cov_wTa: np.ndarray | None
    sTa: np.ndarray
    prob: np.ndarray
    origin: tuple[float, float]
    resolution: float
    points: np.ndarray
    known: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class SessionUpdate:
    """Everything one session adds or changes, committed in one transaction (``MapStore.add_session``).

    ``factors_*``: relative poses (i, j as submap references, see the module docstring); ``sightings_*``: objects
    seen from submaps; ``objects``: the session's object states; ``trajectory``; ``wTa_updates``: stored
    submaps re-estimated by the joint solve (row id -> (wTa, cov_wTa or None)); ``retire``: stored submap row
    ids the new session's submaps replace in the working graph."""

    log_name: str
    log_sha256: str
    start_ns: int
    end_ns: int
    joined: bool
    joined_by: str
    wTs: np.ndarray
    cov_wTs: np.ndarray | None
    relocalisation_s: float
    summary: dict[str, Any]
    submaps: tuple[NewSubmap, ...]
    factors_i: np.ndarray
    factors_j: np.ndarray
    factors_iTj: np.ndarray
    factors_cov: np.ndarray
    factors_kind: tuple[str, ...]
    sightings_ref: np.ndarray
    sightings_object: tuple[str, ...]
    sightings_placement: tuple[str, ...]
    sightings_a_position: np.ndarray
    sightings_cov: np.ndarray
    sightings_z: np.ndarray
    objects: tuple[ObjectState, ...]
    trajectory: StoredTrajectory
    wTa_updates: dict[int, tuple[np.ndarray, np.ndarray | None]] = field(default_factory=dict)
    retire: tuple[int, ...] = ()
    expected_id: int = 0  # the session id the update was computed for (0: any); another writer in between fails it
