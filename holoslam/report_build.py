"""The run report from the stages' outputs (``build_report``, :class:`holoslam.report.RunReport`) and its
accuracy against the log's ground truth (``accuracy``)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from holoslam.report import RunReport
from holoslam.report_records import (
    Accuracy,
    GraphSize,
    HolographicSummary,
    MapSummary,
    MovedObject,
    ObjectErrors,
    ObjectSummary,
    PlanningSummary,
    PoseErrors,
    SolverSummary,
    SubmapSummary,
)

__all__ = ["absent_inputs", "build_report", "accuracy", "static_frames"]


def absent_inputs(log: Any) -> list[str]:
    """The optional inputs a log lacks (a run goes on without each)."""
    present = (
        ("compass", bool(log.headings)),
        ("camera images", bool(log.images)),
        ("tag sightings", bool(log.tags)),
        ("ground truth", bool(log.ground_truth)),
    )
    return [name for name, there in present if not there]


def _count(items: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for i in items:
        out[i] = out.get(i, 0) + 1
    return out


def submap_summary(fe: Any, revisits: Any = None, mounting: Any = None, odometer: Any = None) -> SubmapSummary:
    """The front end's summary; ``revisits`` the keyframe stage's ``holoslam.graph.nodes.KeyframeSolve``,
    ``mounting`` the laser mounting check (``laser_mounting``) or None, ``odometer`` the odometer check
    (``odometer_check``) or None."""
    return SubmapSummary(
        count=len(fe.submaps),
        split_reasons=_count(str(sm.reason) for sm in fe.submaps),
        loops_tried=int(fe.loops_tried),
        observations_before_first_anchor=int(fe.skipped_observations),
        nodes=int(np.unique(np.concatenate([sm.scan_stamps_ns for sm in fe.submaps])).size),
        scans_localised_between_nodes=int(sum(len(sm.track_stamps_ns) for sm in fe.submaps)),
        dead_reckoning_inflation=round(float(fe.dead_reckoning_inflation), 3),
        odometry_noise=fe.odometry_noise.to_dict() if fe.odometry_noise is not None else None,
        loop_pairs=int(fe.loop_groups),
        dead_reckoning_slips=int(fe.dead_reckoning_slips),
        keyframes_solved=revisits is not None,
        keyframe_matches=0 if revisits is None else len(revisits.matches),
        keyframe_matches_tried=0 if revisits is None else int(revisits.matches.tried),
        keyframes_disputed=0 if revisits is None else int(revisits.solution.disputed),
        laser_mounting=mounting,
        odometer=odometer,
        loop_search=dict(fe.loop_counts) or None,
        breaks=int(fe.breaks),
        return_gap_m=round(float(fe.return_gap_m), 4) if math.isfinite(fe.return_gap_m) else None,
        bridged_returns=bool(fe.bridged_returns),
        grid_cell_m=float(fe.grid_cell_m),
    )


def odometer_check(log: Any, trajectory: Any, fe: Any = None) -> dict[str, Any] | None:
    """The odometer check of a run: its raw odometry (``log``'s) against the scan-matched keyframes
    (``holoslam.submaps.odometer``), with the correction the front end ``fe`` mapped with under ``corrected``
    (when it made one); None when the run drove too few straight stretches and made no correction."""
    from holoslam.submaps.odometer import odometer_bias

    corr = getattr(fe, "odometer_correction", None)
    extra = {} if corr is None else {"corrected": corr.to_dict()}
    if not log.odometry:
        return None
    odom_stamps, odomTb = log.odometry_arrays()
    blind_at = getattr(fe, "blind_at", None)  # (a front end of a stored session may predate the record)
    blind = None if blind_at is None else blind_at(trajectory.key_stamps_ns)
    m = odometer_bias(trajectory.key_stamps_ns, trajectory.wTk, odom_stamps, odomTb, blind=blind)
    return (extra or None) if m is None else {**m.to_dict(), **extra}


def laser_mounting(log: Any, fe: Any, trajectory: Any) -> dict[str, Any] | None:
    """The laser mounting check of a run on the optimised poses at the scans (``holoslam.submaps.mounting``)."""
    from holoslam.submaps.mounting import mounting_check

    if not log.scans or fe.bTs is None:
        return None
    stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    return mounting_check(stamps, trajectory.at_scans(log), np.asarray(fe.bTs), str(log.base_frame),
                          str(log.scans[0].frame_id))


def factor_counts(p: Any) -> dict[str, int]:
    """Measurements per family in the SLAM problem ``p`` (relative poses by kind)."""
    kinds = _count(str(k) for k in p.relative.kind)
    factors = {f"relative_pose/{k}": v for k, v in sorted(kinds.items())}
    factors["compass_heading"] = 0 if p.headings is None else int(len(p.headings.i))
    factors["object_landmark"] = 0 if p.landmarks is None else int(len(p.landmarks.i))
    return factors


def solver_summary(sol: Any) -> SolverSummary:
    return SolverSummary(
        method=str(getattr(sol.method, "value", sol.method)),
        iterations=int(sol.iterations),
        rounds=int(sol.rounds),
        initial_error=float(sol.initial_error),
        final_error=float(sol.final_error),
        rejected_measurements=len(sol.rejected),
        compass_bias_deg=None if sol.compass_bias is None else round(float(np.degrees(sol.compass_bias)), 3),
        seconds=round(float(sol.seconds), 4),
    )


def _object_nodes(holo: Any) -> tuple[list[Any], list[Any], set[Any]]:
    """The holographic graph's environment nodes, object nodes and the objects with an edge to the environment."""
    env = [n for n, d in holo.nodes(data=True) if d.get("kind") == "environment"]
    obj = [n for n, d in holo.nodes(data=True) if d.get("kind") == "object"]
    reachable = {n for u, v in holo.edges() for n in (u, v) if n in obj and ((u in obj) != (v in obj))}
    return env, obj, reachable


def object_summary(objects: Sequence[Any], sol: Any, holo: Any, located_by: dict | None) -> ObjectSummary:
    from holoslam.maps.holographic import CONFIRMING_SIGHTINGS

    _, obj, reachable = _object_nodes(holo)
    moved = [
        MovedObject(
            id=m.object_id,
            before=[round(float(v), 4) for v in m.w_position_before],
            after=[round(float(v), 4) for v in m.w_position_after],
            distance_m=round(m.distance, 3),
        )
        for m in sol.moved_objects
    ]
    return ObjectSummary(
        count=len(objects),
        ids=[o.object_id for o in objects],
        moved=moved,
        without_reach_edge=sorted(set(obj) - reachable),
        unconfirmed=sorted(o.object_id for o in objects if o.sightings < CONFIRMING_SIGHTINGS),
        located_by=located_by or {},
    )


def holographic_summary(holo: Any) -> HolographicSummary:
    import networkx as nx

    env, obj, reachable = _object_nodes(holo)
    rest = holo.subgraph([n for n in holo if n in reachable or n in env])
    return HolographicSummary(
        environment_nodes=len(env),
        places=_count(str(holo.nodes[n].get("place", "?")) for n in env),
        object_nodes=len(obj),
        object_edges=sum(1 for u, v in holo.edges() if (u in obj) != (v in obj)),
        objects_with_edge=len(reachable),
        edges=holo.number_of_edges(),
        connected=bool(rest.number_of_nodes() > 0 and nx.is_connected(nx.Graph(rest))),
    )


def map_summary(grid: Any) -> MapSummary:
    return MapSummary(
        shape=list(grid.shape),
        resolution_m=grid.resolution,
        origin=[grid.origin_x, grid.origin_y],
        free_cells=int(grid.free.sum()),
        occupied_cells=int(grid.occupied.sum()),
    )


def build_report(*, log: Any, ingest_report: Any, sightings: Any, fe: Any, sol: Any, objects: Sequence[Any],
                 maps: Any, trajectory: Any, timings: dict[str, float], located_by: dict | None = None,
                 codes_truth: bool = False, revisits: Any = None) -> RunReport:
    """The run report from every stage's output (``maps``: ``holoslam.mapping.RunMaps``; ``trajectory``:
    ``holoslam.trajectory.RunTrajectory``)."""
    from holoslam.io.mcap import report_to_dict

    return RunReport(
        source=log.source,
        inputs_absent=absent_inputs(log),
        ingest=report_to_dict(ingest_report),
        vision=sightings.report,
        submaps=submap_summary(fe, revisits, laser_mounting(log, fe, trajectory), odometer_check(log, trajectory, fe)),
        factors=factor_counts(fe.problem),
        solver=solver_summary(sol),
        objects=object_summary(objects, sol, maps.holographic, located_by),
        map=map_summary(maps.grid),
        topology=GraphSize(maps.topology.number_of_nodes(), maps.topology.number_of_edges(),
                           int(maps.topology.graph.get("spurs_pruned", 0)),
                           round(float(maps.topology.graph.get("spur_beyond_clearance_m", 0.0)), 3)),
        holographic=holographic_summary(maps.holographic),
        planning=PlanningSummary(int(maps.planning.n_blocks), int(maps.planning.n_regions)),
        timings_s=timings,
        accuracy=accuracy(log, fe, sol, objects, trajectory, codes_truth),
        frames=static_frames(log),
    )


def static_frames(log: Any) -> dict[str, Any]:
    """{"base": name, "poses": {frame: [x, y, yaw]}}: every frame the log's static transforms tie to the base,
    in the base frame (``RunReport.frames``)."""
    from holoslam.frames import TransformLookupError, TransformTree

    tree = TransformTree(tuple(t for t in log.transforms if t.static))
    base = str(log.base_frame)
    stamp = int(log.scans[0].stamp_ns) if log.scans else 0
    poses: dict[str, list[float]] = {}
    for child in sorted({t.child for t in log.transforms if t.static} - {base}):
        try:
            poses[child] = [round(float(v), 9) for v in tree.planar(base, child, stamp)]
        except TransformLookupError:
            continue  # a static frame not below the base (a map frame, another robot's): not the robot's
    return {"base": base, "poses": poses}


# ------------------------------------------------------------------------------------------------- accuracy


def _num_or_none(v: float | None, digits: int = 3) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), digits)


def _pose_errors(e: Any) -> PoseErrors:
    return PoseErrors(
        rmse_m=round(float(e.rmse_m), 4),
        max_m=round(float(e.max_m), 4),
        heading_rmse_deg=round(float(e.heading_rmse_deg), 3),
        n=int(e.n),
        coverage95=_num_or_none(e.coverage95),
    )


def accuracy(log: Any, fe: Any, sol: Any, objects: Sequence[Any], trajectory: Any,
             codes: bool = False) -> Accuracy | None:
    """Errors against the log's ground truth after the best SE(2) alignment (the run's world frame is its own);
    with ``codes`` the simulator's foreign codes (world ``codes``, keyed like the anonymous landmarks) count as
    objects too. ``None`` when the log has no ground truth."""
    if not log.ground_truth:
        return None
    from holoslam.evaluate import trajectory_errors, truth_at
    from holoslam.geometry import interpolate_poses

    gs, gp = log.ground_truth_arrays()
    true_a = truth_at(fe.anchor_stamps_ns, gs, gp)
    anchors = trajectory_errors(sol.wTa, true_a, sol.cov_wTa)
    dr_a = interpolate_poses(fe.dr_stamps_ns, fe.dr_wTb, fe.anchor_stamps_ns)
    anchors_dr = trajectory_errors(dr_a, true_a, None)
    true_b = truth_at(trajectory.stamps_ns, gs, gp)
    return Accuracy(
        anchors=_pose_errors(anchors),
        anchors_dead_reckoning=_pose_errors(anchors_dr),
        trajectory=_pose_errors(trajectory_errors(trajectory.wTb, true_b, None)),
        trajectory_dead_reckoning=_pose_errors(trajectory_errors(trajectory.dead_reckoning_wTb, true_b, None)),
        anchor_improvement_over_dead_reckoning=round(anchors_dr.rmse_m / anchors.rmse_m, 2)
        if anchors.rmse_m > 0 else None,
        objects=_object_errors(log, sol, objects, true_a, codes) if log.world_json else None,
    )


def _object_errors(log: Any, sol: Any, objects: Sequence[Any], true_a: np.ndarray, codes: bool) -> ObjectErrors:
    from holoslam.evaluate import align_se2, object_errors

    world = json.loads(log.world_json)
    truth = {o["id"]: np.asarray(o["position"], dtype=np.float64) for o in world.get("objects", [])}
    if codes:
        truth.update({c["id"]: np.asarray(c["position"], dtype=np.float64) for c in world.get("codes", [])})
    T = align_se2(sol.wTa[:, :2], true_a[:, :2])
    ids = [o.object_id for o in objects]
    est = np.array([o.w_position for o in objects]).reshape(-1, 3)
    covs = np.array([o.cov_w_position[:2, :2] for o in objects]).reshape(-1, 2, 2)
    oe = object_errors(ids, est[:, :2], truth, T, covs if np.all(np.isfinite(covs)) else None)
    return ObjectErrors(
        rmse_m=round(oe.rmse_m, 4),
        max_m=round(oe.max_m, 4),
        matched=oe.n_matched,
        missing=list(oe.missing),
        unexpected=list(oe.unexpected),
        coverage95=_num_or_none(oe.coverage95),
        per_object_m={k: round(float(v), 4) for k, v in sorted(oe.errors_m.items())},
    )
