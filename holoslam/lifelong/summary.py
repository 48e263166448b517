"""The ``session`` object of a run's report (report.json) when the run was a session of a map store."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SessionSummary", "ObjectChange"]


@dataclass(frozen=True)
class ObjectChange:
    """One object's change in this session: status moved / gone / new (seen objects are counted, not listed),
    its place now (or where it was expected, for gone), the displacement and its 2x2 covariance when moved."""

    id: str
    status: str
    x: float | None = None
    y: float | None = None
    displacement_m: float | None = None
    displacement: list[float] | None = None
    cov_displacement: list[list[float]] | None = None


@dataclass(frozen=True)
class SessionSummary:
    """The run as a session of a store: its id, whether it was joined to the world and by what (laser /
    objects / both / none; ``founded``: the first session, whose frame is the world), the relocalisation's
    wall time and why it placed the session or not, the session frame in the world, the joint solve, and the
    object changes."""

    store: str
    session_id: int
    joined: bool
    joined_by: str
    founded: bool
    relocalisation_s: float
    why: str
    wTs: list[float] | None
    laser_matches: int
    laser_searches: int
    objects_seen: int
    changes: list[ObjectChange] = field(default_factory=list)
    joint: dict[str, Any] = field(default_factory=dict)
    working_submaps: int = 0
    retired_submaps: int = 0
    relocalisation_cpu_s: float = 0.0  # the process's CPU time of the relocalisation
    # the stored objects not located in this session, each with its share of the camera's time with its place in
    # view (s): gone from ChangeConfig.view_min_s, else kept as it was (not seen, not in view long enough)
    unseen_in_view_s: dict[str, float] = field(default_factory=dict)
    # the same objects, each with the number of the session's images that held its place readable (gone from
    # ChangeConfig.min_images; empty for a log without images)
    unseen_in_images: dict[str, int] = field(default_factory=dict)
    # the same objects whose support (the thing the label was on) the session's laser saw gone from their place
    # (``holoslam.lifelong.support``): gone
    unseen_support_left: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SessionSummary:
        kw = dict(d)
        kw["changes"] = [ObjectChange(**c) for c in d.get("changes", [])]
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in kw.items() if k in names})

    def counts(self) -> dict[str, int]:
        out = {"seen": self.objects_seen, "moved": 0, "gone": 0, "new": 0}
        for c in self.changes:
            out[c.status] = out.get(c.status, 0) + 1
        return out

    def text_lines(self) -> list[str]:
        if self.founded:
            state = "founded the store's world frame (first session)"
        elif self.joined:
            state = f"joined by {self.joined_by} in {self.relocalisation_s:.1f} s"
        else:
            state = f"NOT joined (kept as a separate session): {self.why}"
        lines = [f"  session {self.session_id} of {self.store}: {state}"]
        if self.joined and not self.founded:
            lines.append(f"    {self.why}")
        c = self.counts()
        lines.append(f"    objects: {c['seen']} seen where expected, {c['moved']} moved, {c['gone']} gone, "
                     f"{c['new']} new; working graph {self.working_submaps} submaps ({self.retired_submaps} retired)")
        for ch in self.changes:
            if ch.status == "moved":
                lines.append(f"    {ch.id} moved {ch.displacement_m:.2f} m to ({ch.x:.2f}, {ch.y:.2f})")
            elif ch.status == "gone":
                lines.append(f"    {ch.id} gone from ({ch.x:.2f}, {ch.y:.2f})")
            elif ch.status == "new":
                lines.append(f"    {ch.id} new at ({ch.x:.2f}, {ch.y:.2f})")
        return lines
