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

__all__ = ["StoreExport", "ObjectHistory", "store_export", "object_history", "session_trajectories", "where_now",
           "merged_map"]


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
    holographic: Any = None  # the holographic graph of the merged map with the objects where they are now
    planning: Any = None  # the two-layer planning graph of the merged map (``holoslam plan`` routes on it)


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


def _objects_now(latest: dict[str, ObjectState]) -> tuple:
    """The holographic graph's objects: every object placed in the world and not gone, at its latest position."""
    from holoslam.maps.holographic import ObjectInfo

    out = []
    for k in sorted(latest):
        o = latest[k]
        if o.status in (ObjectStatus.GONE, ObjectStatus.UNPLACED) or o.w_xy is None:
            continue
        cov = np.full((3, 3), np.nan) if o.cov_w_xy is None else np.pad(np.asarray(o.cov_w_xy), ((0, 1), (0, 1)))
        out.append(ObjectInfo(k, o.kind, np.array([o.w_xy[0], o.w_xy[1], o.z if np.isfinite(o.z) else 0.0]), cov,
                              payload=o.payload, sightings=int(o.sightings)))
    return tuple(out)


def _maps(grid: Any, topology: Any, subs: tuple, latest: dict[str, ObjectState], config: Any) -> tuple[Any, Any]:
    """The holographic graph (objects now) and the planning graph of the merged map, as a run builds them."""
    from holoslam.config import RunConfig
    from holoslam.mapping import configuration_space, reach_model
    from holoslam.maps.holographic import build_holographic
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.rooms import rooms_of_grid
    from holoslam.planning.twolayer import build_two_layer

    cfg = config or RunConfig()
    edge_paths = EdgePaths(topology)
    rooms = rooms_of_grid(grid, topology, cfg.holographic.rooms, edge_paths)
    holo = build_holographic(grid, topology, anchors_wTa=np.array([s.wTa for s in subs]).reshape(-1, 3),
                             submap_ids=[int(s.id) for s in subs], objects=_objects_now(latest),
                             reach_model=reach_model(cfg.robot), params=cfg.holographic.places, rooms=rooms,
                             edge_paths=edge_paths)
    planning = build_two_layer(configuration_space(grid, cfg.robot.radius_m), cfg.planning.min_block_cells)
    return holo, planning


def where_now(ex: StoreExport, object_id: str) -> dict[str, Any]:
    """Where an object is now: its latest state in the store (status, position, the session that saw it so) and,
    when it is in the map, its node of the store's holographic graph (the room and places it is handled from)."""
    from holoslam.errors import StoreError
    from holoslam.maps.holographic import where_is

    last = [o for o in ex.history if o.object_id == object_id]
    if not last:
        known = sorted({o.object_id for o in ex.history})
        raise StoreError(f"{ex.store} knows no object {object_id!r}; known: {', '.join(known) or 'none'}")
    now = next(o for o in ex.objects_now if o.object_id == object_id)
    nodes = where_is(ex.holographic, object_id) if ex.holographic is not None else []
    out = {"id": object_id, "status": now.status, "session": now.session_id,
           "x": None if now.w_xy is None else float(now.w_xy[0]), "y": None if now.w_xy is None else float(now.w_xy[1]),
           "places": nodes[0]["places"] if nodes else [], "in_map": bool(nodes)}
    where = "-" if now.w_xy is None else f"({now.w_xy[0]:.3f}, {now.w_xy[1]:.3f})"
    text = f"{object_id} now: {now.status} in session {now.session_id} at {where}"
    if nodes:
        text += "; handled from " + (", ".join(f"{q['place']} ({q['relation']})" for q in out["places"]) or
                                     "no place (out of the robot's reach)")
    elif now.status == ObjectStatus.GONE:
        text += " (its last place; not in the map now)"
    out["text"] = text
    return out


def merged_map(subs: Any) -> Any:
    """The merged grid (``holoslam.lifelong.merge.MergedGrid``) of stored submaps with their grids (a store's
    working ones: ``MapStore.submaps(working=True, grids=True)``), each in the world by its anchor."""
    from holoslam.lifelong.merge import merge_submaps

    return merge_submaps(np.array([s.wTa for s in subs]).reshape(-1, 3),
                         [(s.prob, s.known, s.origin, s.resolution) for s in subs], [s.session_id for s in subs])


def store_export(store_path: str | Path, maps: bool = True, config: Any = None) -> StoreExport:
    """Everything ``holoslam export STORE`` writes, computed (nothing written here); ``maps``: with the
    holographic and planning graphs of the merged map (``config``: their settings, a ``RunConfig``)."""
    from holoslam.lifelong.merge import to_occupancy_grid
    from holoslam.maps.settings import TopologyConfig
    from holoslam.maps.topology import topology_from_settings
    from holoslam.store.db import MapStore

    with MapStore.open(store_path, create=False) as store:
        subs = store.submaps(working=True, grids=True)
        grid = to_occupancy_grid(merged_map(subs))
        topology = topology_from_settings(grid, TopologyConfig(), anchors_wTa=np.array([s.wTa for s in subs]))
        latest = store.latest_objects()
        holo, planning = _maps(grid, topology, subs, latest, config) if maps else (None, None)
        return StoreExport(str(store_path), grid, topology, session_trajectories(store),
                           tuple(latest[k] for k in sorted(latest)), store.object_history(), store.counts(), holo,
                           planning)


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
