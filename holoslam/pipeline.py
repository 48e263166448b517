"""One function per user job. Each returns results and writes nothing itself except where the job *is* to
write files (``run_log_to_folder``, ``simulate``, ``solve_graph_file``, ...), and then only through ``holoslam.io``
and only under the folder the caller named.

The main job, ``run``::

    log --ingest--> records --vision--> object observations
        --front end--> submaps + SLAM problem (Eq. 12, 14-16) --solve--> anchors, objects, covariances
        --> trajectory --> occupancy grid --> thinning topology --> holographic graph --> two-layer planning graph

Every stage is timed; the result carries what a report needs (``RunResult.report``).
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.errors import ConfigError, HoloslamError, IngestError
from holoslam.jobs import (  # the light commands' jobs live in holoslam.jobs; kept here by their old names
    decode_tags,
    list_datasets,
    solve_graph_file,
    topology_from_map_file,
)
from holoslam.jobs import inspect_log_file as inspect
from holoslam.sightings import see_objects, triangulate_objects
from holoslam.timing import StageClock

__all__ = [
    "RunConfig",
    "SolverConfig",
    "GridConfig",
    "TopologyConfig",
    "HolographicConfig",
    "PlanningConfig",
    "RobotConfig",
    "VisionConfig",
    "RunResult",
    "run",
    "run_log_to_folder",
    "run_logs",
    "load_run_config",
    "optimised_trajectory",
    "simulate",
    "inspect",
    "solve_graph_file",
    "plan_to_object",
    "export_run",
    "list_datasets",
    "decode_tags",
    "topology_from_map_file",
]

Progress = Callable[..., None]


def _noop(*_a: Any, **_k: Any) -> None:
    return None


# ------------------------------------------------------------------------------------------------- config


# The configuration tree lives in holoslam.config; re-exported here for existing callers.
from holoslam.config import (  # noqa: E402
    GridConfig,
    HolographicConfig,
    PlanningConfig,
    RobotConfig,
    RunConfig,
    SolverConfig,
    SolverMethod,
    TopologyConfig,
    VisionConfig,
    load_run_config,
)

# ------------------------------------------------------------------------------------------------- result


@dataclass(frozen=True, eq=False)
class RunResult:
    """Everything a run produced, as numpy arrays, records and networkx graphs (nothing written yet)."""

    source: str
    config: RunConfig
    stamps_ns: np.ndarray  # (N,) odometry and scan stamps, sorted, unique
    wTb: np.ndarray  # (N, 3) optimised base trajectory at stamps_ns
    dead_reckoning_wTb: np.ndarray  # (N, 3)
    anchor_stamps_ns: np.ndarray  # (K,)
    wTa: np.ndarray  # (K, 3)
    cov_wTa: np.ndarray | None  # (K, 3, 3) body frame
    objects: tuple  # holoslam.maps.holographic.ObjectInfo
    moved_objects: tuple
    problem: Any  # holoslam.graph.problem.SlamProblem
    solution: Any  # holoslam.solve.Solution
    frontend: Any  # holoslam.submaps.frontend.FrontEnd
    grid: Any  # OccupancyGrid
    topology: Any  # nx.MultiGraph
    holographic: Any  # nx.Graph
    planning: Any  # TwoLayerGraph
    report: dict[str, Any]
    rooms: Any = None  # holoslam.maps.rooms.RoomSegmentation: ids = the holographic graph's room nodes


def reestimate_anchors(problem: Any) -> np.ndarray:
    """The front end's re-estimate after loop closures: the anchors' poses from the relative poses found so
    far, loops under the robust kernel, one plain solve (no outlier rounds: the final solve does those)."""
    from holoslam.solve import SolveOptions, solve

    opts = SolveOptions(reject_outliers=True, max_rounds=0, final_gaussian=False, detect_moved=False,
                        max_iterations=50, build=run_build_options())
    return solve(problem, opts).wTa


def run_build_options() -> Any:
    """Robust kernels of a run: loops under Huber (3 sigma), not DCS. On real logs the chain of scan matches is
    less certain than its covariances say, and DCS (redescending) drops the very closures that correct it;
    Huber keeps their pull linear beyond 3 sigma (Cartographer uses Huber on loops for the same reason). The
    chi-square rounds of the final solve remove what is still inconsistent."""
    from holoslam.graph import factors as fac
    from holoslam.graph.build import BuildOptions

    return BuildOptions(loop_kernel=fac.Kernel(fac.RobustKernel.HUBER, 3.0))


def optimised_trajectory(
    stamps_ns: np.ndarray,
    dr_stamps_ns: np.ndarray,
    dr_wTb: np.ndarray,
    anchor_stamps_ns: np.ndarray,
    wTa: np.ndarray,
) -> np.ndarray:
    """The base pose at every stamp from optimised reference poses (anchors or keyframes) ``wTa`` at
    ``anchor_stamps_ns``: after reference k (until the next) the pose is wTa_k composed with the dead-reckoned
    motion since it, wTb(t) = wTa_k ∘ (drTa_k^-1 ∘ drTb(t)). Before the first, reference 0 is used backwards."""
    from holoslam.submaps.deadreckon import interpolate_poses

    stamps = np.asarray(stamps_ns, dtype=np.int64)
    dr_t = interpolate_poses(dr_stamps_ns, dr_wTb, stamps)
    dr_a = interpolate_poses(dr_stamps_ns, dr_wTb, np.asarray(anchor_stamps_ns, dtype=np.int64))
    k = np.clip(np.searchsorted(anchor_stamps_ns, stamps, side="right") - 1, 0, len(anchor_stamps_ns) - 1)
    return g.compose(np.asarray(wTa)[k], g.between(dr_a[k], dr_t))


def _feature_attrs(f: Any) -> dict[str, Any]:
    """The object feature set (Eq. 13) as node attributes: scalars and small arrays."""
    s = f.to_summary()
    return {
        "size_m": s["size_m"] if s["size_m"] is not None else float("nan"),
        "range_m": s["range_m"] if s["range_m"] is not None else float("nan"),
        "n_crops": s["n_crops"],
        "n_sift": s["n_sift"],
        "texture_lbp": np.asarray(s["texture_lbp"], dtype=np.float64),
        "colours_lab": np.asarray(s["colours_lab"], dtype=np.float64),
        "colour_weights": np.asarray(s["colour_weights"], dtype=np.float64),
    }


def keyframe_poses(submaps: Sequence[Any], wTa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every submap keyframe's base pose in the world, sorted by stamp: wTb = wTa_k ∘ aTb (the keyframes are
    registered in their submap by scan matching, so they are more accurate than dead reckoning between anchors),
    with the scans localised in a submap without being inserted (``Submap.track_*``)."""
    stamps = [np.concatenate([np.asarray(sm.scan_stamps_ns, np.int64), np.asarray(sm.track_stamps_ns, np.int64)])
              for sm in submaps]
    rel = [np.vstack([np.reshape(sm.aTb, (-1, 3)), np.reshape(sm.track_aTb, (-1, 3))]) for sm in submaps]
    poses = [g.compose(np.broadcast_to(wTa[sm.index], r.shape), r) for sm, r in zip(submaps, rel, strict=True)]
    if not stamps:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    s, p = np.concatenate(stamps), np.concatenate(poses).reshape(-1, 3)
    order = np.argsort(s, kind="stable")
    s, p = s[order], p[order]
    keep = np.concatenate([[True], np.diff(s) > 0])
    return s[keep], p[keep]


def _objects(problem: Any, solution: Any, observations: Sequence[Any], features: dict | None = None,
             extra_sightings: dict[str, int] | None = None) -> tuple:
    """The located objects as graph records. ``extra_sightings``: views beyond one per landmark measurement (a
    triangulated code is one measurement from several agreeing views; they all count as sightings)."""
    from holoslam.graph.problem import MeasurementFamily
    from holoslam.maps.holographic import ObjectInfo
    from holoslam.vision.label import FOREIGN_PREFIX, parse_label

    payload = {o.object_id: o.payload for o in observations}
    lm = problem.landmarks
    rejected = {r.index for r in solution.rejected if r.family is MeasurementFamily.LANDMARK}
    kept = Counter(
        name.split("@")[0] for k, name in enumerate(lm.landmark if lm is not None else ()) if k not in rejected
    )
    objs = []
    for k, oid in enumerate(solution.landmark_ids):
        base = oid.split("@")[0]
        z = np.nan
        if lm is not None and len(lm.landmark):
            sel = np.array([name == oid or name.split("@")[0] == base for name in lm.landmark])
            zs = lm.z[sel]
            zs = zs[np.isfinite(zs)]
            z = float(np.median(zs)) if zs.size else np.nan
        cov = np.full((3, 3), np.nan)
        if solution.cov_w_landmarks is not None:
            cov = np.zeros((3, 3))
            cov[:2, :2] = solution.cov_w_landmarks[k]
            cov[2, 2] = 0.02**2
        try:
            label = parse_label(payload.get(base, ""))
            kind, attrs, text = label.kind, label.attributes, payload[base]
        except HoloslamError:  # an anonymous landmark (a foreign code keyed by its payload), or unknown
            kind = "qr_code" if base.startswith(FOREIGN_PREFIX) else "unknown"
            attrs, text = (), payload.get(base, "")
        if "@" in oid:  # a moved object's earlier place: kept in the result, not as a separate graph object
            continue
        xy = solution.w_landmarks[k]
        feats = _feature_attrs(features[oid]) if features and oid in features else {}
        objs.append(
            ObjectInfo(
                oid,
                kind,
                np.array([xy[0], xy[1], 0.0 if not np.isfinite(z) else z]),
                cov,
                attrs,
                text,
                feats,
                sightings=kept[oid] + (extra_sightings or {}).get(oid, 0),
            )
        )
    return tuple(objs)


def run(log_path: str | Path, config: RunConfig | None = None, progress: Progress | None = None) -> RunResult:
    """The main job on one log: ingest, locate objects, build and optimise the graph, build the maps and
    graphs. Raises ``IngestError`` when the log lacks what a run needs (odometry and laser scans)."""
    from holoslam.io.mcap import read_log
    from holoslam.maps.holographic import build_holographic
    from holoslam.maps.occupancy import build_grid
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.rooms import rooms_of_grid
    from holoslam.maps.topology import topology_from_settings
    from holoslam.planning.twolayer import build_two_layer
    from holoslam.solve import CovarianceScope, Method, SolveOptions, solve
    from holoslam.submaps.frontend import build_problem

    cfg = config or RunConfig()
    clock = StageClock(progress)

    with clock.stage("ingest"):
        log, ingest_report = read_log(log_path, mapping=cfg.mapping, require=["odometry", "scan"])
    absent = [
        name
        for name, present in (
            ("compass", bool(log.headings)),
            ("camera images", bool(log.images)),
            ("tag sightings", bool(log.tags)),
            ("ground truth", bool(log.ground_truth)),
        )
        if not present
    ]

    seen = see_objects(log, cfg.vision, clock)

    fe_stage = "front end (submaps, Eq. 12/14/15/16)"
    with clock.stage(fe_stage):
        fe = build_problem(log, seen.observations, cfg.frontend, clock.progress_of(fe_stage),
                           optimize=reestimate_anchors)

    with clock.stage("optimise"):
        options = SolveOptions(
            method=Method.ISAM2 if cfg.solver.method is SolverMethod.ISAM2 else Method.BATCH,
            reject_outliers=cfg.solver.reject_outliers,
            chi2_probability=cfg.solver.chi2_probability,
            covariances=CovarianceScope.ALL if cfg.solver.covariances else CovarianceScope.NONE,
            max_iterations=cfg.solver.max_iterations,
            isam2_relinearize_threshold=cfg.solver.isam2_relinearize_threshold,
            build=run_build_options(),
        )
        sol = solve(fe.problem, options)

    fe, sol, seen = triangulate_objects(seen, fe, sol, log, cfg, options, clock)

    with clock.stage("trajectory"):
        odom_stamps, odomTb = log.odometry_arrays()
        scan_stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
        # a pose at every odometry and every scan stamp, so ground truth stamped by scan (relations) scores it
        stamps = np.union1d(odom_stamps, scan_stamps)
        dr = _interp(fe.dr_stamps_ns, fe.dr_wTb, stamps)
        key_stamps, wTk = keyframe_poses(fe.submaps, sol.wTa)
        # between keyframes (a few tenths of a second) the wheel odometry's own motion is the most faithful
        wTb = optimised_trajectory(stamps, odom_stamps, odomTb, key_stamps, wTk)
        objects = _objects(fe.problem, sol, seen.observations, seen.features, seen.extra_sightings)

    with clock.stage("occupancy grid"):
        wTb_scan = optimised_trajectory(scan_stamps, odom_stamps, odomTb, key_stamps, wTk)
        wTs = g.compose(wTb_scan, np.broadcast_to(fe.bTs, wTb_scan.shape))
        grid = build_grid(
            wTs,
            log.scans,
            cfg.grid.resolution,
            margin_m=cfg.grid.margin_m,
            no_return_clear_m=cfg.grid.no_return_clear_m,
        )

    with clock.stage("topology (thinning)"):
        topology = topology_from_settings(grid, cfg.topology, anchors_wTa=sol.wTa)

    with clock.stage("holographic graph"):
        submap_features = {
            sm.index: {
                "n_scans": int(len(sm.scan_stamps_ns)),
                "n_points": int(len(sm.points)),
                "n_lines": int(len(sm.features.lines)),
                "n_corners": int(len(sm.features.corners)),
                "n_crossings": int(len(sm.features.crossings)),
            }
            for sm in fe.submaps
        }
        edge_paths = EdgePaths(topology)
        rooms = rooms_of_grid(grid, topology, cfg.holographic.rooms, edge_paths)
        holo = build_holographic(
            grid,
            topology,
            anchors_wTa=sol.wTa,
            submap_ids=[sm.index for sm in fe.submaps],
            objects=objects,
            reach_model=reach_model(cfg.robot),
            params=cfg.holographic.places,
            submap_features=submap_features,
            rooms=rooms,
            edge_paths=edge_paths,
        )

    with clock.stage("planning graph"):
        planning = build_two_layer(
            _configuration_space(grid, cfg.robot.radius_m), cfg.planning.min_block_cells
        )

    report = _report(
        log=log,
        ingest_report=ingest_report,
        vision_report=seen.report,
        fe=fe,
        sol=sol,
        objects=objects,
        grid=grid,
        topology=topology,
        holo=holo,
        planning=planning,
        timings=clock.total(),
        absent=absent,
        stamps=stamps,
        wTb=wTb,
        dr=dr,
        located_by=_located_by(seen.observations, objects),
        codes_truth=cfg.vision.foreign_landmarks,
    )
    return RunResult(
        source=str(log_path),
        config=cfg,
        stamps_ns=stamps,
        wTb=wTb,
        dead_reckoning_wTb=dr,
        anchor_stamps_ns=np.asarray(fe.anchor_stamps_ns, dtype=np.int64),
        wTa=sol.wTa,
        cov_wTa=sol.cov_wTa,
        objects=objects,
        moved_objects=tuple(sol.moved_objects),
        problem=fe.problem,
        solution=sol,
        frontend=fe,
        grid=grid,
        topology=topology,
        holographic=holo,
        planning=planning,
        report=report,
        rooms=rooms,
    )


def _located_by(observations: Sequence[Any], objects: Sequence[Any]) -> dict[str, dict[str, str]]:
    """Per located object: where its sightings came from ("images", "tags", "images+tags") and how it was
    located ("pnp", "triangulation", "pnp+triangulation")."""
    src: dict[str, set[str]] = {}
    how: dict[str, set[str]] = {}
    for o in observations:
        src.setdefault(o.object_id, set()).add(o.source or "?")
        how.setdefault(o.object_id, set()).add(o.method)
    return {
        o.object_id: {"source": "+".join(sorted(src.get(o.object_id, {"?"}))),
                      "method": "+".join(sorted(how.get(o.object_id, {"?"}), key=lambda m: m != "pnp"))}
        for o in objects
    }


def _interp(stamps: np.ndarray, poses: np.ndarray, query: np.ndarray) -> np.ndarray:
    from holoslam.submaps.deadreckon import interpolate_poses

    return interpolate_poses(stamps, poses, query)


def reach_model(robot: RobotConfig) -> Any:
    """The holographic graph's reach model (``holoslam.maps.holographic.ReachModel``) of a robot description."""
    from holoslam.maps.holographic import ReachModel

    return ReachModel(robot_radius_m=robot.radius_m, arm_reach_m=robot.arm_reach_m, z_min_m=robot.reach_z_min_m,
                      z_max_m=robot.reach_z_max_m, reach_through_m=robot.reach_through_m)


def _configuration_space(grid: Any, robot_radius_m: float) -> Any:
    """The grid with free space eroded by the robot radius: a free cell of the result is a place the robot's
    centre can be. Unknown and occupied cells both block."""
    import cv2

    from holoslam.maps.grid import OccupancyGrid

    r = int(np.ceil(robot_radius_m / grid.resolution))
    free = grid.free.astype(np.uint8)
    if r > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        free = cv2.erode(free, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return OccupancyGrid.from_free_mask(free.astype(bool), grid.resolution, grid.origin_x, grid.origin_y)


def _accuracy(
    log: Any, fe: Any, sol: Any, objects: Sequence[Any], stamps: np.ndarray, wTb: np.ndarray, dr: np.ndarray,
    codes: bool = False,
) -> dict[str, Any] | None:
    """Errors against the log's ground truth after the best SE(2) alignment (the run's world frame is its own);
    with ``codes`` the simulator's foreign codes (world ``codes``, keyed like the anonymous landmarks) count
    as objects too."""
    if not log.ground_truth:
        return None
    from holoslam.evaluate import align_se2, object_errors, trajectory_errors, truth_at

    gs, gp = log.ground_truth_arrays()
    true_a = truth_at(fe.anchor_stamps_ns, gs, gp)
    anchors = trajectory_errors(sol.wTa, true_a, sol.cov_wTa)
    dr_a = _interp(fe.dr_stamps_ns, fe.dr_wTb, fe.anchor_stamps_ns)
    anchors_dr = trajectory_errors(dr_a, true_a, None)
    true_b = truth_at(stamps, gs, gp)
    traj = trajectory_errors(wTb, true_b, None)
    traj_dr = trajectory_errors(dr, true_b, None)
    out: dict[str, Any] = {
        "anchors": _errors_dict(anchors),
        "anchors_dead_reckoning": _errors_dict(anchors_dr),
        "trajectory": _errors_dict(traj),
        "trajectory_dead_reckoning": _errors_dict(traj_dr),
    }
    if anchors.rmse_m > 0:
        out["anchor_improvement_over_dead_reckoning"] = round(anchors_dr.rmse_m / anchors.rmse_m, 2)
    if log.world_json:
        world = json.loads(log.world_json)
        truth = {o["id"]: np.asarray(o["position"], dtype=np.float64) for o in world.get("objects", [])}
        if codes:
            truth.update({c["id"]: np.asarray(c["position"], dtype=np.float64) for c in world.get("codes", [])})
        T = align_se2(sol.wTa[:, :2], true_a[:, :2])
        ids = [o.object_id for o in objects]
        est = np.array([o.w_position for o in objects]).reshape(-1, 3)
        covs = np.array([o.cov_w_position[:2, :2] for o in objects]).reshape(-1, 2, 2)
        oe = object_errors(ids, est[:, :2], truth, T, covs if np.all(np.isfinite(covs)) else None)
        out["objects"] = {
            "rmse_m": round(oe.rmse_m, 4),
            "max_m": round(oe.max_m, 4),
            "matched": oe.n_matched,
            "missing": list(oe.missing),
            "unexpected": list(oe.unexpected),
            "coverage95": _num_or_none(oe.coverage95),
            "per_object_m": {k: round(float(v), 4) for k, v in sorted(oe.errors_m.items())},
        }
    return out


def _errors_dict(e: Any) -> dict[str, Any]:
    return {
        "rmse_m": round(float(e.rmse_m), 4),
        "max_m": round(float(e.max_m), 4),
        "heading_rmse_deg": round(float(e.heading_rmse_deg), 3),
        "n": int(e.n),
        "coverage95": _num_or_none(e.coverage95),
    }


def _num_or_none(v: float | None, digits: int = 3) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), digits)


def _report(
    *,
    log,
    ingest_report,
    vision_report,
    fe,
    sol,
    objects,
    grid,
    topology,
    holo,
    planning,
    timings,
    absent,
    stamps,
    wTb,
    dr,
    located_by=None,
    codes_truth=False,
) -> dict[str, Any]:
    """The run report (JSON-able) from every stage's output."""
    from holoslam.io.mcap import report_to_dict
    from holoslam.maps.holographic import CONFIRMING_SIGHTINGS

    p = fe.problem
    kinds: dict[str, int] = {}
    for k in p.relative.kind:
        kinds[str(k)] = kinds.get(str(k), 0) + 1
    factors = {f"relative_pose/{k}": v for k, v in sorted(kinds.items())}
    factors["compass_heading"] = 0 if p.headings is None else int(len(p.headings.i))
    factors["object_landmark"] = 0 if p.landmarks is None else int(len(p.landmarks.i))
    env = [n for n, d in holo.nodes(data=True) if d.get("kind") == "environment"]
    places: dict[str, int] = {}
    for n in env:
        pl = str(holo.nodes[n].get("place", "?"))
        places[pl] = places.get(pl, 0) + 1
    obj_nodes = [n for n, d in holo.nodes(data=True) if d.get("kind") == "object"]
    reachable = {
        n
        for u, v in holo.edges()
        for n in (u, v)
        if n in obj_nodes and ((u in obj_nodes) != (v in obj_nodes))
    }
    return {
        "source": log.source,
        "inputs_absent": absent,
        "ingest": report_to_dict(ingest_report),
        "vision": vision_report,
        "submaps": {
            "count": len(fe.submaps),
            "split_reasons": _count(str(sm.reason) for sm in fe.submaps),
            "loops_tried": int(fe.loops_tried),
            "observations_before_first_anchor": int(fe.skipped_observations),
            "nodes": int(np.unique(np.concatenate([sm.scan_stamps_ns for sm in fe.submaps])).size),
            "scans_localised_between_nodes": int(sum(len(sm.track_stamps_ns) for sm in fe.submaps)),
            # the dead-reckoning noise model's covariances were multiplied by this to agree with the log's own
            # scan matches (1: the model already did)
            "dead_reckoning_inflation": round(float(fe.dead_reckoning_inflation), 3),
            # the odometer noise model: the log's own propagated covariance, or the defaults, and why
            "odometry_noise": fe.odometry_noise.to_dict() if fe.odometry_noise is not None else None,
            # anchor pairs joined by loop closures; each pair's closures together count as one measurement
            "loop_pairs": int(fe.loop_groups),
            # dead-reckoning segments beyond the chi-square 95 % gate against their scan match (slips), down-weighted
            "dead_reckoning_slips": int(fe.dead_reckoning_slips),
        },
        "factors": factors,
        "solver": {
            "method": str(getattr(sol.method, "value", sol.method)),
            "iterations": int(sol.iterations),
            "rounds": int(sol.rounds),
            "initial_error": float(sol.initial_error),
            "final_error": float(sol.final_error),
            "rejected_measurements": len(sol.rejected),
            "compass_bias_deg": None
            if sol.compass_bias is None
            else round(float(np.degrees(sol.compass_bias)), 3),
            "seconds": round(float(sol.seconds), 4),
        },
        "objects": {
            "count": len(objects),
            "ids": [o.object_id for o in objects],
            "moved": [
                {
                    "id": m.object_id,
                    "before": [round(float(v), 4) for v in m.w_position_before],
                    "after": [round(float(v), 4) for v in m.w_position_after],
                    "distance_m": round(m.distance, 3),
                }
                for m in sol.moved_objects
            ],
            "without_reach_edge": sorted(set(obj_nodes) - reachable),
            # seen fewer than CONFIRMING_SIGHTINGS times: a single misread id cannot be told from a real label
            "unconfirmed": sorted(o.object_id for o in objects if o.sightings < CONFIRMING_SIGHTINGS),
            # per object: where its sightings came from (images / tags) and how it was located (pnp / triangulation)
            "located_by": located_by or {},
        },
        "map": {
            "shape": list(grid.shape),
            "resolution_m": grid.resolution,
            "origin": [grid.origin_x, grid.origin_y],
            "free_cells": int(grid.free.sum()),
            "occupied_cells": int(grid.occupied.sum()),
        },
        "topology": {"nodes": topology.number_of_nodes(), "edges": topology.number_of_edges()},
        "holographic": {
            "environment_nodes": len(env),
            "places": places,
            "object_nodes": len(obj_nodes),
            "object_edges": sum(1 for u, v in holo.edges() if (u in obj_nodes) != (v in obj_nodes)),
            "objects_with_edge": len(reachable),
            "edges": holo.number_of_edges(),
            # the unreachable objects have no edge by definition: connectivity is of the rest
            "connected": bool(_connected(holo.subgraph([n for n in holo if n in reachable or n in env]))),
        },
        "planning": {"layer1_blocks": int(planning.n_blocks), "layer2_regions": int(planning.n_regions)},
        "timings_s": timings,
        "accuracy": _accuracy(log, fe, sol, objects, stamps, wTb, dr, codes_truth),
    }


def _count(items) -> dict[str, int]:
    out: dict[str, int] = {}
    for i in items:
        out[i] = out.get(i, 0) + 1
    return out


def _connected(G: Any) -> bool:
    import networkx as nx

    return G.number_of_nodes() > 0 and nx.is_connected(nx.Graph(G))


def format_run_report(report: dict[str, Any]) -> str:
    """The readable summary of a run's report."""
    lines = [f"holoslam run of {report['source']}"]
    if report.get("inputs_absent"):
        lines.append(f"  inputs absent: {', '.join(report['inputs_absent'])}")
    ing = report["ingest"]
    chans = ing.get("channels", [])
    lines.append(
        f"  ingest: {len(chans)} channels, {sum(c.get('decoded', 0) for c in chans)} messages decoded, "
        f"{sum(c.get('failed', 0) for c in chans)} failed, {sum(c.get('skipped', 0) for c in chans)} "
        f"skipped, {len(ing.get('warnings', []))} warnings; base frame {ing.get('base_frame', '?')}"
    )
    for c in ing.get("choices", []):
        lines.append(f"    {c['role']}: {c['topic']} used, not {', '.join(c['others'])} ({c['rule']})")
    lines.extend(f"    levelled: {m}" for m in ing.get("levelled", []))
    v = report["vision"]
    if "skipped" in v:
        lines.append(f"  vision: skipped ({v['skipped']})")
    else:
        lines.append(
            f"  vision: sightings from {v.get('source') or '?'}: {v['images']} images, {v['decodes']} codes "
            f"decoded, {v['tag_sightings']} robot sightings, {v['observations']} object observations (PnP), "
            f"{v['foreign']} foreign codes"
        )
        t = v.get("triangulation")
        if t:
            lines.append(
                f"  triangulation: {t['views']} views of {t['codes']} codes without a printed size or foreign "
                f"-> {t['points']} points ({t['views_unused']} views unused); {t.get('laser_ranged', 0)} views "
                "ranged by the laser instead"
            )
    sm = report["submaps"]
    lines.append(
        f"  submaps: {sm['count']} ({', '.join(f'{k} {n}' for k, n in sm['split_reasons'].items())}); "
        f"{sm['loops_tried']} revisit registrations tried"
    )
    if "nodes" in sm:
        lines.append(
            f"  local SLAM: {sm['nodes']} nodes matched into submaps, {sm['scans_localised_between_nodes']} scans "
            f"localised between them; dead-reckoning covariance x{sm['dead_reckoning_inflation']} (calibrated "
            f"against the scan matches; {sm.get('dead_reckoning_slips', 0)} slipped segments down-weighted), loop "
            f"closures between {sm.get('loop_pairs', 0)} anchor pairs (each pair's count as one)"
        )
    on = sm.get("odometry_noise")
    if on:
        lines.append(f"  odometry noise: {on['source']} ({on['reason']})")
    lines.append("  factors: " + ", ".join(f"{k} {n}" for k, n in report["factors"].items()))
    s = report["solver"]
    lines.append(
        f"  solver: {s['method']}, {s['iterations']} iterations in {s['rounds']} rounds, error "
        f"{s['initial_error']:.4g} -> {s['final_error']:.4g}, {s['rejected_measurements']} measurements "
        f"rejected, compass bias {s['compass_bias_deg']} deg"
    )
    o = report["objects"]
    lines.append(
        f"  objects: {o['count']}; moved: {[m['id'] for m in o['moved']] or 'none'}; "
        f"without a reach edge: {o['without_reach_edge'] or 'none'}; "
        f"unconfirmed (seen once): {o.get('unconfirmed') or 'none'}"
    )
    if o.get("located_by"):
        ways = Counter(f"{d['source']} by {d['method']}" for d in o["located_by"].values())
        lines.append("  objects located from: " + ", ".join(f"{k} {n}" for k, n in sorted(ways.items())))
    h = report["holographic"]
    lines.append(
        f"  holographic graph: {h['environment_nodes']} environment nodes "
        f"({', '.join(f'{k} {n}' for k, n in h['places'].items())}), {h['object_nodes']} object nodes, "
        f"{h['object_edges']} object edges ({h['objects_with_edge']} objects reachable), connected: {h['connected']}"
    )
    m = report["map"]
    lines.append(
        f"  map: {m['shape'][1]} x {m['shape'][0]} cells at {m['resolution_m']} m; topology "
        f"{report['topology']['nodes']} nodes / {report['topology']['edges']} edges; planning "
        f"{report['planning']['layer1_blocks']} blocks / {report['planning']['layer2_regions']} regions"
    )
    acc = report.get("accuracy")
    if acc:
        a, d = acc["anchors"], acc["anchors_dead_reckoning"]
        lines.append(
            f"  accuracy vs ground truth: anchors {a['rmse_m']:.3f} m RMSE (dead reckoning {d['rmse_m']:.3f} m),"
            f" heading {a['heading_rmse_deg']:.2f} deg, 95% ellipse coverage {a['coverage95']}"
        )
        if "objects" in acc:
            ob = acc["objects"]
            lines.append(
                f"                            objects {ob['rmse_m']:.3f} m RMSE (max {ob['max_m']:.3f} m), "
                f"{ob['matched']} matched, missing {ob['missing'] or 'none'}"
            )
    lines.append("  timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in report["timings_s"].items()))
    return "\n".join(lines)


# --------------------------------------------------------------------------------------- jobs with outputs


def run_log_to_folder(
    log: str, out_dir: str, config: RunConfig | None = None, progress: Progress | None = None
) -> dict[str, Any]:
    """Run one log and write its output folder; returns a short summary (for the batch runner)."""
    from holoslam.io.run_folder import prepare_output_folder, write_run

    existed = Path(out_dir).exists()
    prepare_output_folder(out_dir)  # an unwritable folder is a one-line error before the run, not after it
    try:
        result = run(log, config, progress)
    except BaseException:
        if not existed and not any(Path(out_dir).iterdir()):
            Path(out_dir).rmdir()  # a run that failed leaves no empty folder behind
        raise
    written = write_run(
        result,
        out_dir,
        pictures=result.config.pictures,
        results_mcap=result.config.results_mcap,
        progress=progress,
    )
    acc = result.report.get("accuracy") or {}
    return {
        "log": log,
        "out_dir": out_dir,
        "files": len(written),
        "anchors": int(len(result.wTa)),
        "objects": len(result.objects),
        "anchor_rmse_m": acc.get("anchors", {}).get("rmse_m"),
        "object_rmse_m": acc.get("objects", {}).get("rmse_m"),
        "seconds": result.report["timings_s"]["total"],
        "text": format_run_report(result.report),
    }


def run_logs(
    logs: Sequence[Path],
    out_root: str | Path,
    config: RunConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run one or many logs. One log writes straight into ``out_root``; many logs get one sub-folder each,
    processed in parallel (local processes, or a Dask cluster given its scheduler address)."""
    from holoslam.batch import run_many
    from holoslam.io.run_folder import prepare_output_folder

    progress = progress or _noop
    if len(logs) > 1 or scheduler is not None:
        prepare_output_folder(out_root)  # once, before any log is dispatched
    if len(logs) == 1 and scheduler is None:
        try:
            summary = run_log_to_folder(str(logs[0]), str(out_root), config, progress)
        except IngestError as e:  # name the log, once
            msg = str(e)
            raise IngestError(msg if msg.startswith(str(logs[0])) else f"{logs[0]}: {msg}") from None
        return {"ok": True, "logs": [summary], "text": summary["text"] + f"\n  output: {out_root}"}

    def on_done(item, done, total):
        progress(f"{done}/{total} {'ok' if item.ok else 'FAILED'} {item.log} ({item.seconds:.1f} s)")

    items = run_many(
        run_log_to_folder,
        logs,
        out_root,
        workers=workers,
        scheduler=scheduler,
        on_done=on_done,
        config=config,
    )
    lines = [f"{sum(i.ok for i in items)} of {len(items)} logs processed into {out_root}"]
    for i in items:
        lines.append(
            f"  {'ok    ' if i.ok else 'FAILED'} {i.log} -> {i.out_dir} ({i.seconds:.1f} s)"
            + ("" if i.ok else f": {i.error}")
        )
    return {
        "ok": all(i.ok for i in items),
        "logs": [dataclasses.asdict(i) for i in items],
        "text": "\n".join(lines),
    }


def simulate(
    output: str | Path,
    seed: int = 0,
    duration_s: float | None = None,
    image_rate_hz: float | None = None,
    noise_scale: float = 1.0,
    wall_codes: int = 0,
    sizeless_labels: int = 0,
    profile: str = "default",
    camera_rate_hz: float = 0.0,
    exposure_ms: float | None = None,
) -> dict[str, Any]:
    """Write a simulated reference-household log (``holoslam.sim``) to ``output``; ``wall_codes`` foreign QR codes
    on walls and ``sizeless_labels`` labels without a printed size can be added (``holoslam.sim.world``).
    ``profile``: the robot (``holoslam.sim.profiles``: default, noisy, skid-steer), ``noise_scale`` on top.
    ``camera_rate_hz`` > 0: a camera stream, every frame at that rate with motion blur over ``exposure_ms``
    (``holoslam.sim.stream``)."""
    from holoslam.sim import simulate_to_file
    from holoslam.sim.profiles import profile_config

    if noise_scale < 0 or not np.isfinite(noise_scale):
        raise ConfigError(f"--noise-scale must be a non-negative number, got {noise_scale}")
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration must be a positive number of seconds, got {duration_s}")
    if image_rate_hz is not None and not image_rate_hz >= 0:
        raise ConfigError(f"--image-rate must be >= 0 snapshots per second, got {image_rate_hz}")
    kw: dict[str, Any] = {"seed": seed, "wall_codes": wall_codes, "sizeless_labels": sizeless_labels}
    if duration_s is not None:
        kw["duration_s"] = duration_s
    if image_rate_hz is not None:
        kw["image_rate_hz"] = image_rate_hz
    if camera_rate_hz:
        kw["camera_rate_hz"] = camera_rate_hz
    if exposure_ms is not None:
        kw["camera_exposure_ms"] = exposure_ms
    cfg = profile_config(profile, **kw)
    if noise_scale != 1.0:
        cfg = cfg.with_noise_scale(noise_scale)
    out = Path(output)
    if out.parent and not out.parent.exists():
        raise ConfigError(f"folder {out.parent} does not exist; create it first")
    return simulate_to_file(out, cfg)


def plan_to_object(
    run_dir: str | Path, object_id: str, from_xy: tuple[float, float] | None = None
) -> dict[str, Any]:
    """Route from a pose (default: the run's last pose) to an object in a saved run."""
    from holoslam.io.run_folder import load_run
    from holoslam.maps.holographic import CONFIRMING_SIGHTINGS
    from holoslam.planning.routes import plan_to_object as _plan

    saved = load_run(run_dir, parts=("trajectory", "holographic", "planning", "grid"))
    oid = _resolve_object(saved.holographic, object_id)
    start = np.asarray(from_xy if from_xy is not None else saved.wTb[-1, :2], dtype=np.float64)
    route = _plan(saved.planning, saved.holographic, saved.grid, oid, start)
    obj = saved.holographic.nodes[oid]
    wp = np.asarray(route.waypoints)
    text = [
        f"route to {oid} ({obj.get('object_type', obj.get('type', '?'))}) at "
        f"({obj.get('x', float('nan')):.2f}, {obj.get('y', float('nan')):.2f}) from ({start[0]:.2f}, {start[1]:.2f})",
        "  places: " + " -> ".join(str(p) for p in route.places),
        f"  handled from: {route.goal_place}",
        "  waypoints: " + " ".join(f"({x:.2f},{y:.2f})" for x, y in wp),
        f"  length: {route.length:.2f} m",
    ]
    sightings = int(obj.get("sightings", 0))
    if 0 < sightings < CONFIRMING_SIGHTINGS:
        text.append(f"  note: {oid} was seen once (unconfirmed): its label may have been misread")
    return {
        "object": oid,
        "sightings": sightings,
        "from": [float(start[0]), float(start[1])],
        "places": [str(p) for p in route.places],
        "goal_place": route.goal_place,
        "waypoints": wp.round(4).tolist(),
        "length_m": round(float(route.length), 4),
        "text": "\n".join(text),
    }


def _resolve_object(holo: Any, id_or_type: str) -> str:
    from holoslam.errors import PlanningError
    from holoslam.maps.holographic import where_is

    if id_or_type in holo and holo.nodes[id_or_type].get("kind") == "object":
        return id_or_type
    found = where_is(holo, id_or_type) if id_or_type else []
    if not found:
        ids = sorted(n for n, d in holo.nodes(data=True) if d.get("kind") == "object")
        raise PlanningError(f"no object {id_or_type!r} in this run; known objects: {', '.join(ids)}")
    return str(found[0].get("id", found[0].get("object_id")))


def export_run(
    run_dir: str | Path, to: str | Path | None = None, formats: Sequence[str] = ("all",)
) -> list[Path]:
    """Re-export a saved run (pictures, results MCAP, graphs, TUM) into ``to`` (default: the run folder)."""
    from holoslam.io.run_folder import export_saved, load_run

    saved = load_run(run_dir)
    return export_saved(saved, Path(to) if to is not None else Path(run_dir), set(formats))
