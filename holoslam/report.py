"""The run report: a typed ``RunReport`` with one record per stage, its JSON form (``to_dict``, what report.json
holds; ``from_dict`` reads it back) and its text form (``text``, what report.txt and ``holoslam run`` print).

``build_report`` makes it from the stages' outputs; ``accuracy`` scores the run against the log's ground truth
(both :mod:`holoslam.report_build`'s); the records are :mod:`holoslam.report_records`', their text
:mod:`holoslam.report_text`'s.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

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
    _make,
)
from holoslam.report_text import _accuracy_text, _ingest_text, _objects_text, _submaps_text, _vision_text

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
    "format_run_report",
]


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
