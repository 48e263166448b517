"""The records of the run report, one per stage (:class:`holoslam.report.RunReport` holds them): frozen
dataclasses in their JSON form's field names, each read back from it by ``_make`` or its ``from_dict``."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

__all__ = [
    "SubmapSummary",
    "SolverSummary",
    "MovedObject",
    "ObjectSummary",
    "MapSummary",
    "GraphSize",
    "HolographicSummary",
    "PlanningSummary",
    "PoseErrors",
    "ObjectErrors",
    "Accuracy",
]

_T = TypeVar("_T")


def _make(cls: type[_T], d: Mapping[str, Any]) -> _T:
    """``cls`` from the keys of ``d`` it has fields for (a report written by another version may have more)."""
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    return cls(**{k: v for k, v in d.items() if k in names})


@dataclass(frozen=True)
class SubmapSummary:
    """The front end: submaps, revisits tried, local SLAM nodes, and the dead-reckoning noise model."""

    count: int
    split_reasons: dict[str, int]
    loops_tried: int
    observations_before_first_anchor: int = 0
    nodes: int | None = None
    scans_localised_between_nodes: int = 0
    # the dead-reckoning noise model's covariances were multiplied by this to agree with the log's own scan
    # matches (1: the model already did)
    dead_reckoning_inflation: float = 1.0
    # the odometer noise model: the log's own propagated covariance, or the defaults, and why
    odometry_noise: dict[str, Any] | None = None
    # anchor pairs joined by loop closures; each pair's closures together count as one measurement
    loop_pairs: int = 0
    # dead-reckoning segments beyond the chi-square 95 % gate against their scan match (slips), down-weighted
    dead_reckoning_slips: int = 0
    # keyframes solved as poses against the old submaps they revisit (holoslam.graph.nodes): matches kept / tried
    keyframes_solved: bool = False
    keyframe_matches: int = 0
    keyframe_matches_tried: int = 0
    # keyframes the solved anchors placed more than RevisitConfig.max_shift_m apart by their two submaps (a slip of
    # local SLAM inside one): matched from both placements, their ties robust (holoslam.submaps.revisits)
    keyframes_disputed: int = 0
    # the laser's position from the point the robot turns about, measured from its motion, against the log's
    # transform (holoslam.submaps.mounting.mounting_check); None when the robot turned too little to tell
    laser_mounting: dict[str, Any] | None = None
    # the odometer's distance scale and heading drift against the scan-matched keyframes on straight stretches
    # (holoslam.submaps.odometer); None when the run drove too few straight stretches to tell
    odometer: dict[str, Any] | None = None
    # the loop search's searches and their outcomes by reason (windowed / global; accepted, no match, ambiguous,
    # waiting for a consistent second closure...), and the breaks of local SLAM (a gap in the laser or
    # scans that stopped fitting the map: lost)
    loop_search: dict[str, int] | None = None
    breaks: int = 0
    # m: the gap between neighbouring returns at the laser's median range; True when wider than a submap cell,
    # so that each scan's returns on one surface were joined in the submaps (GridConfig.bridge_over_cells)
    return_gap_m: float | None = None
    bridged_returns: bool = False
    grid_cell_m: float | None = None  # m: the submaps' cell


@dataclass(frozen=True)
class SolverSummary:
    method: str
    iterations: int
    rounds: int
    initial_error: float
    final_error: float
    rejected_measurements: int
    compass_bias_deg: float | None
    seconds: float


@dataclass(frozen=True)
class MovedObject:
    id: str
    before: list[float]
    after: list[float]
    distance_m: float


@dataclass(frozen=True)
class ObjectSummary:
    count: int
    ids: list[str]
    moved: list[MovedObject]
    without_reach_edge: list[str]
    # seen fewer than CONFIRMING_SIGHTINGS times: a single misread id cannot be told from a real label
    unconfirmed: list[str] = field(default_factory=list)
    # per object: where its sightings came from (images / tags) and how it was located (pnp / triangulation)
    located_by: dict[str, dict[str, str]] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ObjectSummary:
        return _make(cls, {**d, "moved": [_make(MovedObject, m) for m in d.get("moved", [])]})


@dataclass(frozen=True)
class MapSummary:
    shape: list[int]
    resolution_m: float
    origin: list[float]
    free_cells: int
    occupied_cells: int


@dataclass(frozen=True)
class GraphSize:
    nodes: int
    edges: int
    # dead-end branches (spurs) pruned from the topology: those that do not leave their junction's free disc
    # by this depth (m, the robot's diameter: TopologyConfig.spur_robot_diameters) or are otherwise too short
    spurs_pruned: int = 0
    spur_depth_m: float = 0.0


@dataclass(frozen=True)
class HolographicSummary:
    environment_nodes: int
    places: dict[str, int]
    object_nodes: int
    object_edges: int
    objects_with_edge: int
    edges: int
    # the unreachable objects have no edge by definition: connectivity is of the rest
    connected: bool


@dataclass(frozen=True)
class PlanningSummary:
    layer1_blocks: int
    layer2_regions: int


@dataclass(frozen=True)
class PoseErrors:
    """Errors of poses against ground truth after the best SE(2) alignment (``holoslam.evaluate``)."""

    rmse_m: float
    max_m: float
    heading_rmse_deg: float
    n: int
    coverage95: float | None


@dataclass(frozen=True)
class ObjectErrors:
    rmse_m: float
    max_m: float
    matched: int
    missing: list[str]
    unexpected: list[str]
    coverage95: float | None
    per_object_m: dict[str, float]


@dataclass(frozen=True)
class Accuracy:
    """The run against the log's ground truth (the run's world frame is its own: errors after alignment)."""

    anchors: PoseErrors
    anchors_dead_reckoning: PoseErrors
    trajectory: PoseErrors
    trajectory_dead_reckoning: PoseErrors
    anchor_improvement_over_dead_reckoning: float | None = None  # absent when the anchors are exact
    objects: ObjectErrors | None = None  # absent when the log has no world description

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        return {k: v for k, v in d.items() if v is not None or k not in ("anchor_improvement_over_dead_reckoning",
                                                                          "objects")}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Accuracy:
        poses = {k: _make(PoseErrors, d[k]) for k in
                 ("anchors", "anchors_dead_reckoning", "trajectory", "trajectory_dead_reckoning")}
        objects = _make(ObjectErrors, d["objects"]) if d.get("objects") else None
        return cls(**poses, anchor_improvement_over_dead_reckoning=d.get("anchor_improvement_over_dead_reckoning"),
                   objects=objects)
