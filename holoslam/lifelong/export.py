"""What a map store answers: the merged map of its working submaps (``holoslam.lifelong.merge``), every
session's trajectory in one frame (the world; an unjoined session's in its own frame, marked so), the objects now
and their history (``object_history``: "where is X now, and where was it on Monday?")."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.store.records import ObjectState, ObjectStatus

__all__ = ["StoreExport", "ObjectHistory", "store_export", "object_history", "session_trajectories"]


@dataclass(frozen=True, eq=False)
class StoreExport:
    """The store's merged occupancy grid (``OccupancyGrid``), its topology (``nx.MultiGraph``), per session the
    trajectory (id -> (stamps_ns, wTb, joined)), the objects now (their latest state) and every object state."""

    store: str
    grid: Any
    topology: Any
    trajectories: dict[int, tuple[np.ndarray, np.ndarray, bool]]
    objects_now: tuple[ObjectState, ...]
    history: tuple[ObjectState, ...]
    counts: dict[str, int] = field(default_factory=dict)


def session_trajectories(store: Any) -> dict[int, tuple[np.ndarray, np.ndarray, bool]]:
    """Every session's base poses: a joined session's hung from its submaps' current world anchors (so the last
    joint solve moves them), an unjoined one's in its own frame."""
    out: dict[int, tuple[np.ndarray, np.ndarray, bool]] = {}
    for s in store.sessions():
        t = store.trajectory(s.id)
        if not s.joined:
            out[s.id] = (t.stamps_ns, np.asarray(t.sTb, np.float64), False)
            continue
        subs = sorted(store.submaps(working=False, session_id=s.id), key=lambda m: m.idx)
        wTa = np.array([m.wTa for m in subs]).reshape(-1, 3)
        k = np.clip(np.asarray(t.anchor_idx, np.int64), 0, len(wTa) - 1)
        out[s.id] = (t.stamps_ns, g.compose(wTa[k], np.asarray(t.aTb, np.float64)), True)
    return out


def store_export(store_path: str | Path) -> StoreExport:
    """Everything ``holoslam export STORE`` writes, computed (nothing written here)."""
    from holoslam.lifelong.merge import merge_submaps, to_occupancy_grid
    from holoslam.maps.settings import TopologyConfig
    from holoslam.maps.topology import topology_from_settings
    from holoslam.store.db import MapStore

    with MapStore.open(store_path, create=False) as store:
        subs = store.submaps(working=True, grids=True)
        merged = merge_submaps(np.array([s.wTa for s in subs]).reshape(-1, 3),
                               [(s.prob, s.known, s.origin, s.resolution) for s in subs], [s.session_id for s in subs])
        grid = to_occupancy_grid(merged)
        topology = topology_from_settings(grid, TopologyConfig(), anchors_wTa=np.array([s.wTa for s in subs]))
        latest = store.latest_objects()
        return StoreExport(str(store_path), grid, topology, session_trajectories(store),
                           tuple(latest[k] for k in sorted(latest)), store.object_history(), store.counts())


@dataclass(frozen=True, eq=False)
class ObjectHistory:
    """Object states by session (``holoslam objects STORE``), with each session's log name and date."""

    store: str
    states: tuple[ObjectState, ...]
    sessions: dict[int, tuple[str, str, bool]]  # id -> (log name, added UTC, joined)

    def to_dict(self) -> dict[str, Any]:
        def row(o: ObjectState) -> dict[str, Any]:
            return {"session": o.session_id, "id": o.object_id, "type": o.kind, "status": o.status,
                    "x": None if o.w_xy is None else float(o.w_xy[0]), "y": None if o.w_xy is None else float(o.w_xy[1]),
                    "cov_xy": None if o.cov_w_xy is None else np.asarray(o.cov_w_xy).tolist(),
                    "displacement": None if o.displacement is None else [float(v) for v in o.displacement],
                    "sightings": o.sightings, "placement": o.placement}
        return {"store": self.store, "sessions": {str(k): {"log": v[0], "added_utc": v[1], "joined": v[2]}
                                                  for k, v in self.sessions.items()},
                "states": [row(o) for o in self.states]}

    def text(self) -> str:
        if not self.states:
            return f"{self.store}: no object states match"
        lines = []
        for o in self.states:
            log, when, joined = self.sessions.get(o.session_id, ("?", "?", False))
            where = "-" if o.w_xy is None else f"({o.w_xy[0]:.3f}, {o.w_xy[1]:.3f})"
            frame = "" if joined else " [session frame: not joined]"
            extra = ""
            if o.status == ObjectStatus.MOVED and o.displacement is not None:
                extra = f" moved {float(np.hypot(*o.displacement)):.2f} m"
            sig = "" if o.cov_w_xy is None else f" +-{np.sqrt(max(np.trace(o.cov_w_xy), 0.0)) * 1000:.0f} mm"
            lines.append(f"session {o.session_id} ({log}, {when}): {o.object_id} {o.kind} {o.status} at "
                         f"{where}{sig}{extra}{frame}")
        return "\n".join(lines)


def object_history(store_path: str | Path, object_id: str | None = None, at: int | None = None) -> ObjectHistory:
    """The object states of the store, of one object (``object_id``) and/or one session (``at``)."""
    from holoslam.errors import StoreError
    from holoslam.store.db import MapStore

    with MapStore.open(store_path, create=False) as store:
        sessions = {s.id: (s.log_name, s.added_utc, s.joined) for s in store.sessions()}
        if at is not None and at not in sessions:
            raise StoreError(f"{store_path} has no session {at}; sessions: {', '.join(map(str, sessions)) or 'none'}")
        states = store.object_history(object_id, at)
        if object_id is not None and not states:
            known = sorted({o.object_id for o in store.object_history()})
            raise StoreError(f"{store_path} knows no object {object_id!r}; known: {', '.join(known) or 'none'}")
    return ObjectHistory(str(store_path), states, sessions)
