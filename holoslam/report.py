"""The run report: a typed ``RunReport`` with one record per stage, its JSON form (``to_dict``, what report.json
holds; ``from_dict`` reads it back) and its text form (``text``, what report.txt and ``holoslam run`` print).

``build_report`` makes it from the stages' outputs; ``accuracy`` scores the run against the log's ground truth.
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

__all__ = [
    "RunReport",
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
    "absent_inputs",
    "build_report",
    "accuracy",
    "format_run_report",
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
    # the laser's position from the point the robot turns about, measured from its motion, against the log's
    # transform (holoslam.submaps.mounting.mounting_check); None when the robot turned too little to tell
    laser_mounting: dict[str, Any] | None = None
    # the loop search's searches and their outcomes by reason (windowed / global; accepted, no match, ambiguous,
    # waiting for a consistent second closure...), and the breaks of local SLAM (a gap in the laser: lost)
    loop_search: dict[str, int] | None = None
    breaks: int = 0


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


@dataclass(frozen=True)
class RunReport:
    """What a run did, stage by stage. ``ingest`` and ``vision`` are those stages' own JSON forms
    (``holoslam.io.mcap.report_to_dict``, ``holoslam.vision.observe.VisionReport``); ``factors`` counts the
    graph's measurements per family; ``timings_s`` the wall seconds per stage and in total."""

    source: str
    inputs_absent: list[str]
    ingest: dict[str, Any]
    vision: dict[str, Any]
    submaps: SubmapSummary
    factors: dict[str, int]
    solver: SolverSummary
    objects: ObjectSummary
    map: MapSummary
    topology: GraphSize
    holographic: HolographicSummary
    planning: PlanningSummary
    timings_s: dict[str, float]
    accuracy: Accuracy | None = None
    # the base frame's name and the planar pose (x m, y m, yaw rad) in it of every frame the log's static
    # transforms fix to it (the laser, cameras): ``holoslam evaluate --frame`` moves the trajectory there
    frames: dict[str, Any] = dataclasses.field(default_factory=dict)
    session: Any = None  # holoslam.lifelong.summary.SessionSummary: the run as a session of a map store

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (report.json); ``session`` only for a run into a map store."""
        out: dict[str, Any] = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for k in ("submaps", "solver", "objects", "map", "topology", "holographic", "planning"):
            out[k] = dataclasses.asdict(out[k])
        out["accuracy"] = self.accuracy.to_dict() if self.accuracy is not None else None
        if self.session is None:
            del out["session"]
        else:
            out["session"] = self.session.to_dict()
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RunReport:
        """A report read back from its JSON form."""
        acc = d.get("accuracy")
        return cls(
            source=d["source"],
            inputs_absent=list(d.get("inputs_absent", [])),
            ingest=dict(d["ingest"]),
            vision=dict(d["vision"]),
            submaps=_make(SubmapSummary, d["submaps"]),
            factors=dict(d["factors"]),
            solver=_make(SolverSummary, d["solver"]),
            objects=ObjectSummary.from_dict(d["objects"]),
            map=_make(MapSummary, d["map"]),
            topology=_make(GraphSize, d["topology"]),
            holographic=_make(HolographicSummary, d["holographic"]),
            planning=_make(PlanningSummary, d["planning"]),
            timings_s=dict(d["timings_s"]),
            accuracy=Accuracy.from_dict(acc) if acc else None,
            frames=dict(d.get("frames") or {}),
            session=_session_from_dict(d.get("session")),
        )

    def text(self) -> str:
        """The readable summary (report.txt)."""
        lines = [f"holoslam run of {self.source}"]
        if self.inputs_absent:
            lines.append(f"  inputs absent: {', '.join(self.inputs_absent)}")
        lines += _ingest_text(self.ingest) + _vision_text(self.vision) + _submaps_text(self.submaps)
        lines.append("  factors: " + ", ".join(f"{k} {n}" for k, n in self.factors.items()))
        s = self.solver
        lines.append(
            f"  solver: {s.method}, {s.iterations} iterations in {s.rounds} rounds, error "
            f"{s.initial_error:.4g} -> {s.final_error:.4g}, {s.rejected_measurements} measurements "
            f"rejected, compass bias {s.compass_bias_deg} deg"
        )
        lines += _objects_text(self.objects)
        h = self.holographic
        lines.append(
            f"  holographic graph: {h.environment_nodes} environment nodes "
            f"({', '.join(f'{k} {n}' for k, n in h.places.items())}), {h.object_nodes} object nodes, "
            f"{h.object_edges} object edges ({h.objects_with_edge} objects reachable), connected: {h.connected}"
        )
        m = self.map
        lines.append(
            f"  map: {m.shape[1]} x {m.shape[0]} cells at {m.resolution_m} m; topology "
            f"{self.topology.nodes} nodes / {self.topology.edges} edges ({self.topology.spurs_pruned} dead-end "
            f"branches pruned: less than {self.topology.spur_depth_m:.2f} m beyond their junction's clearance); "
            "planning "
            f"{self.planning.layer1_blocks} blocks / {self.planning.layer2_regions} regions"
        )
        if self.accuracy is not None:
            lines += _accuracy_text(self.accuracy)
        if self.session is not None:
            lines += self.session.text_lines()
        lines.append("  timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in self.timings_s.items()))
        return "\n".join(lines)


def _session_from_dict(d: Mapping[str, Any] | None) -> Any:
    if not d:
        return None
    from holoslam.lifelong.summary import SessionSummary

    return SessionSummary.from_dict(d)


def format_run_report(report: RunReport | Mapping[str, Any]) -> str:
    """The readable summary of a run's report (a ``RunReport`` or its JSON form, as report.json holds it)."""
    return (report if isinstance(report, RunReport) else RunReport.from_dict(report)).text()


# ------------------------------------------------------------------------------------------------- text


def _ingest_text(ing: Mapping[str, Any]) -> list[str]:
    chans = ing.get("channels", [])
    lines = [
        f"  ingest: {len(chans)} channels, {sum(c.get('decoded', 0) for c in chans)} messages decoded, "
        f"{sum(c.get('failed', 0) for c in chans)} failed, {sum(c.get('skipped', 0) for c in chans)} "
        f"skipped, {len(ing.get('warnings', []))} warnings; base frame {ing.get('base_frame', '?')}"
    ]
    for c in ing.get("choices", []):
        lines.append(f"    {c['role']}: {c['topic']} used, not {', '.join(c['others'])} ({c['rule']})")
    lines.extend(f"    levelled: {m}" for m in ing.get("levelled", []))
    return lines


def _vision_text(v: Mapping[str, Any]) -> list[str]:
    if "skipped" in v:
        return [f"  vision: skipped ({v['skipped']})"]
    lines = [
        f"  vision: sightings from {v.get('source') or '?'}: {v['images']} images, {v['decodes']} codes "
        f"decoded, {v['tag_sightings']} robot sightings, {v['observations']} object observations (PnP), "
        f"{v['foreign']} foreign codes"
    ]
    if v.get("images") and "full_decodes" in v:  # the stream steps (holoslam.vision.stream): what was skipped
        lines.append(
            f"  frames: {v['images']} ({v.get('images_decoded', 0)} with codes): {v['full_decodes']} decoded in full, "
            f"skipped {v.get('skipped_no_code', 0)} without a code (quick look) and {v.get('skipped_same_view', 0)} "
            f"showing the view just decoded; {v.get('frames_per_s') or float('nan'):.0f} frames/s"
        )
    t = v.get("triangulation")
    if t:
        lines.append(
            f"  triangulation: {t['views']} views of {t['codes']} codes without a printed size or foreign "
            f"-> {t['points']} points ({t['views_unused']} views unused); {t.get('laser_ranged', 0)} views "
            "ranged by the laser instead"
        )
    return lines


def _submaps_text(sm: SubmapSummary) -> list[str]:
    lines = [
        f"  submaps: {sm.count} ({', '.join(f'{k} {n}' for k, n in sm.split_reasons.items())}); "
        f"{sm.loops_tried} revisit registrations tried"
    ]
    if sm.nodes is not None:
        lines.append(
            f"  local SLAM: {sm.nodes} nodes matched into submaps, {sm.scans_localised_between_nodes} scans "
            f"localised between them; dead-reckoning covariance x{sm.dead_reckoning_inflation} (calibrated "
            f"against the scan matches; {sm.dead_reckoning_slips} slipped segments down-weighted), loop "
            f"closures between {sm.loop_pairs} anchor pairs (each pair's count as one)"
        )
    if sm.loop_search:
        lines.append("  loop search: " + ", ".join(f"{k} {v}" for k, v in sm.loop_search.items())
                     + (f"; {sm.breaks} gaps in the laser began afresh (lost)" if sm.breaks else ""))
    if sm.keyframes_solved:
        lines.append(
            f"  keyframes: solved as poses against the old submaps they revisit, {sm.keyframe_matches} of "
            f"{sm.keyframe_matches_tried} matches into old submaps kept"
        )
    if sm.odometry_noise:
        lines.append(f"  odometry noise: {sm.odometry_noise['source']} ({sm.odometry_noise['reason']})")
    if sm.laser_mounting:
        from holoslam.submaps.mounting import mounting_text

        lines.extend(mounting_text(sm.laser_mounting))
    return lines


def _objects_text(o: ObjectSummary) -> list[str]:
    lines = [
        f"  objects: {o.count}; moved: {[m.id for m in o.moved] or 'none'}; "
        f"without a reach edge: {o.without_reach_edge or 'none'}; "
        f"unconfirmed (seen once): {o.unconfirmed or 'none'}"
    ]
    if o.located_by:
        ways = Counter(f"{d['source']} by {d['method']}" for d in o.located_by.values())
        lines.append("  objects located from: " + ", ".join(f"{k} {n}" for k, n in sorted(ways.items())))
    return lines


def _accuracy_text(acc: Accuracy) -> list[str]:
    a, d = acc.anchors, acc.anchors_dead_reckoning
    lines = [
        f"  accuracy vs ground truth: anchors {a.rmse_m:.3f} m RMSE (dead reckoning {d.rmse_m:.3f} m),"
        f" heading {a.heading_rmse_deg:.2f} deg, 95% ellipse coverage {a.coverage95}"
    ]
    if acc.objects is not None:
        ob = acc.objects
        lines.append(
            f"                            objects {ob.rmse_m:.3f} m RMSE (max {ob.max_m:.3f} m), "
            f"{ob.matched} matched, missing {ob.missing or 'none'}"
        )
    return lines


# ------------------------------------------------------------------------------------------------- building


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


def submap_summary(fe: Any, revisits: Any = None, mounting: Any = None) -> SubmapSummary:
    """The front end's summary; ``revisits`` the keyframe stage's ``holoslam.graph.nodes.KeyframeSolve``,
    ``mounting`` the laser mounting check (``laser_mounting``) or None."""
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
        laser_mounting=mounting,
        loop_search=dict(fe.loop_counts) or None,
        breaks=int(fe.breaks),
    )


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
        submaps=submap_summary(fe, revisits, laser_mounting(log, fe, trajectory)),
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
