"""The run's vision stages: object sightings from a log's images and tag messages, located by PnP (and their
feature sets, Eq. 13), then the codes without a printed size (and foreign codes) triangulated over the solved
poses. Each returns a ``Sightings`` record; the run report's ``vision`` section is ``Sightings.report``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from holoslam.config import RunConfig, VisionConfig
    from holoslam.timing import StageClock
    from holoslam.types import LogData
    from holoslam.vision.observe import VisionResult

__all__ = ["Sightings", "see_objects", "object_features", "triangulate_objects"]

_PROBLEMS_KEPT = 50  # problems listed in the report (the counts cover all of them)


@dataclass(frozen=True)
class Sightings:
    """What the vision stages found: landmark observations for the graph, each object's feature set, the vision
    result (``None`` when the log has no images and no tag sightings), the report's ``vision`` section, and per
    object the views beyond one per landmark measurement (a triangulated code is one measurement from several
    agreeing views; they all count as sightings)."""

    observations: tuple = ()
    features: dict[str, Any] = field(default_factory=dict)
    vision: VisionResult | None = None
    report: dict[str, Any] = field(default_factory=lambda: {"skipped": "the log has no images and no tag sightings"})
    extra_sightings: dict[str, int] = field(default_factory=dict)


def see_objects(log: LogData, cfg: VisionConfig, clock: StageClock) -> Sightings:
    """The stages ``vision`` (sightings located by PnP, ``holoslam.vision.observe.locate_from_log``) and
    ``object features (Eq. 13)`` (``object_features``); nothing when the log has neither images nor tag
    sightings. Reads the log only: the run calls it in a thread beside the front end."""
    from holoslam.vision.observe import locate_from_log
    from holoslam.vision.stream import frames_per_second

    if not (log.images or log.tags):
        return Sightings()
    with clock.stage("vision"):
        vision = locate_from_log(
            log,
            base_frame=cfg.base_frame or log.base_frame,
            sigma_px=cfg.sigma_px,
            source=cfg.source,
            progress=frames_per_second(clock.progress, "vision"),
            triangulate=cfg.triangulate,
            foreign=cfg.foreign_landmarks,
            stream=cfg.stream_settings(),
        )
        report = dataclasses.asdict(vision.report)
        report["problems"] = list(report.get("problems", ()))[:_PROBLEMS_KEPT]
    seen = Sightings(vision.observations, {}, vision, report)
    return dataclasses.replace(seen, features=object_features(log, seen, cfg, clock))


def object_features(log: LogData, seen: Sightings, cfg: VisionConfig, clock: StageClock) -> dict[str, Any]:
    """The stage ``object features (Eq. 13)``: each sighted object's feature set from the log's images ({} when
    ``cfg.features`` is off or nothing was sighted in an image)."""
    if not (cfg.features and log.images and seen.vision is not None and seen.vision.sightings):
        return {}
    from holoslam.vision.features import object_features_from_log

    with clock.stage("object features (Eq. 13)"):
        return object_features_from_log(log, seen.vision.sightings)


def triangulate_objects(
    seen: Sightings, fe: Any, sol: Any, log: LogData, cfg: RunConfig, options: Any, clock: StageClock
) -> tuple[Any, Any, Sightings]:
    """The stage ``objects by triangulation`` (when the vision stage kept views to triangulate): the codes
    without a printed size (and foreign codes) triangulated over the solved poses, added to the problem as
    landmark measurements, and the problem solved again (``holoslam.vision.landmarks``). Returns the front end
    (with the grown problem), the solution and the sightings with the triangulated observations."""
    if seen.vision is None or not seen.vision.views:
        return fe, sol, seen
    with clock.stage("objects by triangulation"):
        fe, sol, tri = _triangulated(seen.vision.views, fe, sol, log, cfg, options)
        report = dict(seen.report)
        report["triangulation"] = {**dataclasses.asdict(tri.report), "laser_ranged": tri.laser_ranged,
                                   "problems": list(tri.report.problems)[:_PROBLEMS_KEPT]}
        extra = dict(seen.extra_sightings)
        for p in tri.points:
            extra[p.object_id] = extra.get(p.object_id, 0) + len(p.views) - 1
    seen = dataclasses.replace(seen, observations=tuple(seen.observations) + tri.observations, report=report,
                               extra_sightings=extra)
    return fe, sol, seen


def _triangulated(views: Sequence[Any], fe: Any, sol: Any, log: LogData, cfg: RunConfig, options: Any):
    from holoslam.solve import solve
    from holoslam.vision.landmarks import triangulated_landmarks, with_landmarks

    odom_stamps, odomTb = log.odometry_arrays()
    tl = triangulated_landmarks(views, fe.submaps, sol.wTa, sol.cov_wTa, odom_stamps, odomTb, cfg.vision.sigma_px,
                                cfg.vision.min_parallax_deg, cfg.vision.inlier_m, cfg.vision.laser_range)
    if len(tl.ids):
        problem = with_landmarks(fe.problem, tl, sol.wTa)
        sol = solve(problem, options)
        fe = dataclasses.replace(fe, problem=problem)
    return fe, sol, tl
