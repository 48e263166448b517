"""The household holographic graph M = {V, E} of seed 002 (SPEC.md §1, Eq. 1-5), and its queries.

The graph is a ``networkx.Graph`` (simple: two places are joined by at most one passage). Every node has
``kind`` = ``"environment"`` or ``"object"``.

**Environment nodes** (V_e, carrying {H, L_m}), keyed ``"room:<id>"``, ``"door:<i>"``, ``"crossing:<i>"``,
``"dead_end:<i>"``, with ``place`` = room | doorway | crossing | dead_end, position ``x``, ``y`` (world m),
``region`` (room id) and their local frame: ``anchor`` (index of the nearest submap anchor, -1 without
anchors), ``submap`` (its submap id), ``frame_x``, ``frame_y``, ``frame_theta`` (wTa of that anchor; without
anchors the frame is the node's position with theta 0). L_m is summarised by scalars: ``submap``, ``area_m2``
(rooms), ``clearance`` (m), and ``feat_<name>`` counts when the caller gives per-submap feature counts (H).

How the places are found (vectorised on the grid, Python loops only over places and cuts; the passages are
:mod:`holoslam.maps.passages`):

- *Rooms* and *doorways*: the room segmentation of :mod:`holoslam.maps.rooms` (its docstring states the rules
  and their settings, :class:`~holoslam.maps.rooms.RoomRules`, in metres and m^2 set by building physics: door
  widths, the smallest room, wall thickness, furniture size). Room node ``room:<id>`` is room ``id`` (1, 2, ...)
  of its label image (``room_id``; the same ids as ``rooms.png``), at the room's cell farthest from obstacles,
  with ``area_m2`` its free floor area. Doorway node ``door:<i>`` is a cut left after merging, with
  ``width_m`` and ``door_kind`` (``door`` or ``opening``, a wide opening between rooms).
- *Crossings* and *dead ends*: topology junctions in narrow space (free width at most ``corridor_width_m``)
  where at least three branches at least ``branch_min_length_m`` long meet are corridor crossings; topology
  endpoints in narrow space whose edge is at least ``branch_min_length_m`` long and narrow on average are
  dead-end corridors (shorter branches are niches and corners: on a scanned map, ragged walls make many). Junctions and endpoints in open rooms (and room corners)
  belong to the room node; places within ``doorway_depth_m`` of a doorway are the doorway. ``region`` is the
  room id under a place (0: none).

**Environment edges** (E_e, {S_ij, w_ij}): doorway - room on each side; crossing / dead end - the room
(region) containing it. ``passage`` is S_ij: the waypoints (K, 2) world metres of the shortest path along the
topology skeleton between the two places (a straight segment, with ``passage_on_skeleton`` False, when the
skeleton does not join them), ``length`` its length in metres; ``w_x``, ``w_y``, ``w_theta`` is w_ij, the pose
of j's local frame in i's (``between(wTa_i, wTa_j)``) where (i, j) are the edge's ``w_from``, ``w_to``
attributes.

**Object nodes** (V_o, {F, G_m}), keyed by the object id: ``object_type``, ``attributes`` (``k=v,...``),
``payload``, ``x``, ``y``, ``z`` (world m), ``cov`` (3x3 position covariance, world frame), ``sightings`` (how
many sightings placed it; ``where_is`` calls it confirmed from ``CONFIRMING_SIGHTINGS``) and, when vision gives
them, scalar feature-set summaries ``feat_<name>`` (F: size, texture, colours, keypoint counts).

**Object edges** (E_o, {P_ij, k_ij}) exist only where the robot can reach the object from that room
(:class:`ReachModel`): some free cell of the room where the base fits (clearance >= ``robot_radius_m``,
connected to the room's node through such cells) lies within ``arm_reach_m`` (horizontal) of the object, the
object's height is within [``z_min_m``, ``z_max_m``], and the straight line from that cell to the object is
clear: from the object's home room (the room of the free cell nearest to the object) obstacles are allowed
only in the last ``reach_through_m`` (the furniture the object stands on), from any other room none at all (an
arm does not reach through a wall). ``relation`` (P_ij) is ``"in_room"`` for the home room and ``"near"`` for
others; ``k_x``, ``k_y``, ``k_z`` (k_ij) is the object's position in the room's local frame; ``reach_x``,
``reach_y`` is the standing point (the closest one), the goal of ``plan_to_object``. An unreachable object
stays in the graph without an edge.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from holoslam.errors import MapError, PlanningError
from holoslam.geometry import between, inverse, transform_points
from holoslam.maps.grid import OccupancyGrid, cells_to_world
from holoslam.maps.passages import EdgePaths, SkeletonPaths
from holoslam.maps.rooms import RoomRules, RoomSegmentation, segment_rooms

if TYPE_CHECKING:
    import networkx as nx

__all__ = [
    "ObjectInfo",
    "ReachModel",
    "PlaceParams",
    "build_holographic",
    "where_is",
    "route_to_object",
    "object_reach_points",
    "environment_nodes",
    "object_nodes",
    "CONFIRMING_SIGHTINGS",
]

CONFIRMING_SIGHTINGS = 2  # an object seen at least this often (sightings the solver kept) is confirmed


@dataclass(frozen=True, slots=True)
class ObjectInfo:
    """An object for the holographic graph: id, type, attributes, world position (3,) and its covariance, and
    ``sightings``: how many sightings the solver kept for it (0: unknown). An object seen once is unconfirmed:
    nothing can tell a single misread id from a real label, so treat its place as a hint."""

    object_id: str
    object_type: str
    w_position: np.ndarray
    cov_w_position: np.ndarray | None = None
    attributes: tuple[tuple[str, str], ...] = ()
    payload: str = ""
    features: Mapping[str, float] = field(default_factory=dict)
    sightings: int = 0

    def __post_init__(self) -> None:
        p = np.asarray(self.w_position, dtype=np.float64).reshape(-1)
        if p.shape[0] == 2:
            p = np.append(p, 0.0)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise MapError(f"object {self.object_id!r}: position must be finite (x, y[, z]) metres, got {p}")
        object.__setattr__(self, "w_position", p)
        c = np.full((3, 3), np.nan) if self.cov_w_position is None else np.asarray(self.cov_w_position, float)
        object.__setattr__(self, "cov_w_position", c.reshape(3, 3))


@dataclass(frozen=True, slots=True)
class ReachModel:
    """Where the robot can handle an object from (module docstring). A run builds it from the robot description
    (``holoslam.config.RobotConfig``, ``holoslam.mapping.reach_model``), whose defaults these are and where
    they are justified."""

    robot_radius_m: float = 0.26
    arm_reach_m: float = 0.9
    z_min_m: float = 0.0
    z_max_m: float = 2.5
    reach_through_m: float = 0.35


@dataclass(frozen=True, slots=True)
class PlaceParams:
    """Thresholds of the corridor places (module docstring); rooms and doorways follow
    :class:`~holoslam.maps.rooms.RoomRules`."""

    doorway_depth_m: float = 2.0  # m: a junction or endpoint this near a doorway is the doorway's place
    branch_min_length_m: float = 1.0  # m: a dead-end corridor, and 3 branches of a crossing, are this long (less: a niche)
    corridor_width_m: float = 1.4  # m: a corridor is at most this wide (two people pass: 1.2-1.4 m)


def _nearest_anchor(xy: np.ndarray, anchors: np.ndarray | None) -> np.ndarray:
    if anchors is None or len(anchors) == 0:
        return np.full(len(xy), -1, dtype=np.int64)
    d = ((xy[:, None, :] - anchors[None, :, :2]) ** 2).sum(-1)
    return np.argmin(d, axis=1)


def build_holographic(
    grid: OccupancyGrid,
    topology,
    anchors_wTa: np.ndarray | None = None,
    submap_ids: Sequence[int] | None = None,
    objects: Sequence[ObjectInfo] = (),
    reach_model: ReachModel | None = None,
    params: PlaceParams | None = None,
    submap_features: Mapping[int, Mapping[str, int]] | None = None,
    room_rules: RoomRules | None = None,
    rooms: RoomSegmentation | None = None,
    edge_paths: EdgePaths | None = None,
) -> nx.Graph:
    """Build the holographic graph (module docstring) from the global grid, its topology graph
    (``holoslam.maps.topology``), the optimised submap anchors wTa (K, 3) with their submap ids, and the
    objects. The rooms and doorways are ``rooms`` when given (``holoslam.maps.rooms.rooms_of_grid`` of this
    grid and topology: the caller keeps its label image, whose ids are the room nodes'), else segmented here
    with ``room_rules``; ``edge_paths``: the topology's ``passages.EdgePaths`` when the caller has them. Raises
    ``MapError`` for malformed inputs.

    Steps: places (rooms, doorways, crossings and dead ends in narrow space), their nodes in the frame of the
    nearest anchor, passages along the skeleton (rooms to their doorways and narrow places, then every
    component joined), and the objects with an edge to each room they can be handled from (reach)."""
    import networkx as nx

    from holoslam.maps.topology import cleaned_free, clearance_map

    reach_model = reach_model or ReachModel()
    p = params or PlaceParams()
    free = cleaned_free(grid, topology)  # the free space the topology was built on
    clr = clearance_map(free, grid.resolution)
    anchors, sids = _anchors(anchors_wTa, submap_ids)
    edge_paths = edge_paths if edge_paths is not None else EdgePaths(topology)
    if rooms is None:
        rooms = segment_rooms(free, grid.resolution, edge_paths, room_rules, clearance=clr)
    elif rooms.labels.shape != free.shape:
        raise MapError(f"room labels are {rooms.labels.shape}, the grid {free.shape}; segment this grid's rooms")

    G = nx.Graph(kind="holographic", resolution=grid.resolution)
    places, door_keys = _places(grid, topology, rooms, clr, p)
    cells = np.array([pl[2] for pl in places], dtype=np.int64).reshape(-1, 2)
    frames = _add_place_nodes(G, grid, places, cells, rooms, clr, anchors, sids, submap_features)
    passages = _Passages(G, grid, places, cells, frames, SkeletonPaths(topology, grid.resolution, edge_paths))
    room_of_label = {pl[3]: pl[0] for pl in places if pl[1] == "room"}
    pairs = [(room_of_label[lbl], key) for key, a, b in door_keys for lbl in (a, b) if lbl in room_of_label]
    pairs += [
        (room_of_label[region], key)
        for key, place, _cell, region in places
        if place in ("crossing", "dead_end") and region in room_of_label
    ]
    passages.add(pairs)
    # every place without a passage yet (e.g. a doorway whose side is no room, a crossing outside the rooms)
    # and every component left apart are joined to the nearest place along the skeleton, so the environment
    # graph is connected wherever the skeleton is
    _join_components(G, [pl[0] for pl in places], passages.sk, passages.sk_of, passages.add)
    _add_objects(G, grid, objects, reach_model, free, clr, rooms.labels, places, cells, frames)
    return G


# a place: (node key, place kind, (row, col) cell, room id; 0 for a doorway)
_Place = tuple[str, str, np.ndarray, int]


def _anchors(anchors_wTa: np.ndarray | None, submap_ids: Sequence[int] | None) -> tuple[np.ndarray | None, list]:
    """The anchors as (K, 3) and their submap ids (default 0..K-1)."""
    anchors = None if anchors_wTa is None else np.asarray(anchors_wTa, dtype=np.float64).reshape(-1, 3)
    if anchors is not None and submap_ids is not None and len(submap_ids) != len(anchors):
        raise MapError(f"{len(anchors)} anchors but {len(submap_ids)} submap ids; give one id per anchor")
    sids = (
        list(range(len(anchors))) if (anchors is not None and submap_ids is None) else list(submap_ids or [])
    )
    return anchors, sids


def _places(grid: OccupancyGrid, topology, rooms: RoomSegmentation, clr: np.ndarray,
            p: PlaceParams) -> tuple[list[_Place], list[tuple[str, int, int]]]:
    """The places: every room, every doorway (with the two room ids it joins), and the crossings and dead ends
    of the topology in narrow space inside a room, away from doorways."""
    lab = rooms.labels
    places: list[_Place] = [(f"room:{k}", "room", rooms.room_cells[k - 1], k) for k in range(1, rooms.n_rooms + 1)]
    door_keys = []
    for i, dw in enumerate(rooms.doorways):
        places.append((f"door:{i}", "doorway", np.array(dw.cell), 0))
        door_keys.append((f"door:{i}", *dw.rooms))
    room_ids = set(range(1, rooms.n_rooms + 1))
    door_xy = grid.cell_to_world(np.array([d.cell for d in rooms.doorways])) if rooms.doorways else np.zeros((0, 2))
    n_cross = n_dead = 0
    for n, d in topology.nodes(data=True):
        kind = d.get("kind")
        if kind not in ("junction", "endpoint"):
            continue
        r, c = int(d["row"]), int(d["col"])
        if 2.0 * clr[r, c] > p.corridor_width_m or lab[r, c] not in room_ids:
            continue
        xy = grid.cell_to_world(np.array([r, c]))[0]
        if door_xy.shape[0] and np.min(np.hypot(*(door_xy - xy).T)) < p.doorway_depth_m:
            continue
        if not _is_narrow_place(topology, n, kind, clr, p):
            continue
        if kind == "junction":
            places.append((f"crossing:{n_cross}", "crossing", np.array([r, c]), int(lab[r, c])))
            n_cross += 1
        else:
            places.append((f"dead_end:{n_dead}", "dead_end", np.array([r, c]), int(lab[r, c])))
            n_dead += 1
    return places, door_keys


def _is_narrow_place(topology, n, kind: str, clr: np.ndarray, p: PlaceParams) -> bool:
    """A junction with three branches of at least ``branch_min_length_m`` (a crossing), or an endpoint at the
    end of a long, narrow edge (a dead-end corridor)."""
    if kind == "junction":
        lengths = [float(ed.get("length", 0.0)) for _a, _b, ed in topology.edges(n, data=True)]
        return sum(1 for v in lengths if v >= p.branch_min_length_m) >= 3
    # a dead-end corridor: the edge leading to the endpoint is long and narrow on average
    inc = [ed for _a, _b, ed in topology.edges(n, data=True) if "path" in ed]
    if not inc:
        return False
    pth = np.asarray(inc[0]["path"], dtype=np.int64).reshape(-1, 2)
    return not (
        float(inc[0].get("length", 0.0)) < p.branch_min_length_m
        or 2.0 * float(np.mean(clr[pth[:, 0], pth[:, 1]])) > p.corridor_width_m
    )


def _add_place_nodes(G, grid: OccupancyGrid, places: list[_Place], cells: np.ndarray, rooms: RoomSegmentation,
                     clr: np.ndarray, anchors: np.ndarray | None, sids: list,
                     submap_features: Mapping[int, Mapping[str, int]] | None) -> np.ndarray:
    """One environment node per place, in the frame of its nearest anchor (the place itself, unrotated, when
    there are none); returns the places' frames (P, 3)."""
    pxy = grid.cell_to_world(cells)
    aidx = _nearest_anchor(pxy, anchors)
    frames = np.zeros((len(places), 3))
    for i, (key, place, cell, region) in enumerate(places):
        if aidx[i] >= 0:
            frames[i] = anchors[aidx[i]]  # type: ignore[index]
        else:
            frames[i] = (pxy[i, 0], pxy[i, 1], 0.0)
        sub = int(sids[aidx[i]]) if aidx[i] >= 0 else -1
        attrs = dict(
            kind="environment",
            place=place,
            x=float(pxy[i, 0]),
            y=float(pxy[i, 1]),
            row=int(cell[0]),
            col=int(cell[1]),
            region=int(region),
            clearance=float(clr[cell[0], cell[1]]),
            anchor=int(aidx[i]),
            submap=sub,
            frame_x=float(frames[i, 0]),
            frame_y=float(frames[i, 1]),
            frame_theta=float(frames[i, 2]),
        )
        if place == "room":
            attrs["room_id"] = int(region)
            attrs["area_m2"] = float(rooms.area_m2[region - 1])
        elif place == "doorway":
            dw = rooms.doorways[int(key.split(":")[1])]
            attrs["width_m"] = dw.width_m
            attrs["door_kind"] = dw.kind
        if submap_features and sub in submap_features:
            for fk, fv in submap_features[sub].items():
                attrs[f"feat_{fk}"] = int(fv)
        G.add_node(key, **attrs)
    return frames


class _Passages:
    """Passage edges between places along the skeleton (``SkeletonPaths``): the polyline from one place
    through the skeleton cells between them to the other, or the straight segment where the skeleton does
    not join them."""

    def __init__(self, G, grid: OccupancyGrid, places: list[_Place], cells: np.ndarray, frames: np.ndarray,
                 sk: SkeletonPaths) -> None:
        self.G, self.grid, self.places, self.frames, self.sk = G, grid, places, frames, sk
        self.pxy = grid.cell_to_world(cells)
        self.index = {pl[0]: i for i, pl in enumerate(places)}
        self.sk_of = sk.nearest(cells) if len(sk) and len(places) else np.zeros(0, dtype=np.int64)

    def _passage(self, i: int, j: int, seq: list[int] | None) -> tuple[np.ndarray, float, bool]:
        pxy = self.pxy
        if seq is not None:
            pts = np.vstack([pxy[i : i + 1], self.grid.cell_to_world(self.sk.cells[seq]), pxy[j : j + 1]])
            return pts, float(np.hypot(*np.diff(pts, axis=0).T).sum()), True
        pts = np.vstack([pxy[i], pxy[j]])
        return pts, float(np.hypot(*(pxy[j] - pxy[i]))), False

    def _skeleton_paths(self, todo: list[tuple[int, int]]) -> dict[tuple[int, int], list[int] | None]:
        """The skeleton path of each pair, one search per source place."""
        sk, sk_of = self.sk, self.sk_of
        if not len(sk):
            return {}
        by_source: dict[int, list[int]] = {}
        for i, j in todo:
            by_source.setdefault(int(sk_of[i]), []).append(int(sk_of[j]))
        found = {}
        for s, t in by_source.items():
            reach = float(np.abs(sk.cells[t] - sk.cells[s]).sum(axis=1).max()) * self.grid.resolution
            found[s] = sk.paths_from(s, t, limit=3.0 * reach + 2.0)
        return {(i, j): found[int(sk_of[i])][int(sk_of[j])] for i, j in todo}

    def add(self, pairs: list[tuple[str, str]]) -> None:
        """Passages for the pairs of place keys (in order; a pair already joined is skipped)."""
        G, places = self.G, self.places
        todo, seen = [], set()
        for ki, kj in pairs:
            if ki == kj or G.has_edge(ki, kj) or frozenset((ki, kj)) in seen:
                continue
            seen.add(frozenset((ki, kj)))
            todo.append((self.index[ki], self.index[kj]))
        seqs = self._skeleton_paths(todo)
        for i, j in todo:
            pts, length, on_sk = self._passage(i, j, seqs.get((i, j)))
            wij = between(self.frames[i], self.frames[j])
            G.add_edge(
                places[i][0],
                places[j][0],
                kind="passage",
                w_from=places[i][0],
                w_to=places[j][0],
                passage=pts,
                length=length,
                passage_on_skeleton=on_sk,
                w_x=float(wij[0]),
                w_y=float(wij[1]),
                w_theta=float(wij[2]),
            )


def _add_objects(G, grid: OccupancyGrid, objects: Sequence[ObjectInfo], reach_model: ReachModel, free: np.ndarray,
                 clr: np.ndarray, lab: np.ndarray, places: list[_Place], cells: np.ndarray,
                 frames: np.ndarray) -> None:
    """One node per object, with an edge to each room it can be handled from (``_reach``), its position in
    that room's frame on the edge."""
    import cv2

    # safe space for the base, and its components (reach model connectivity)
    safe = (clr >= reach_model.robot_radius_m).astype(np.uint8)
    _, safe_lab = cv2.connectedComponents(safe, connectivity=8)
    index = {pl[0]: i for i, pl in enumerate(places)}
    room_places = [(pl[0], pl[3], index[pl[0]]) for pl in places if pl[1] == "room"]
    res, ox, oy = grid.resolution, grid.origin_x, grid.origin_y
    for ob in objects:
        attrs = dict(
            kind="object",
            object_type=ob.object_type,
            attributes=",".join(f"{k}={v}" for k, v in ob.attributes),
            payload=ob.payload,
            sightings=int(ob.sightings),
            x=float(ob.w_position[0]),
            y=float(ob.w_position[1]),
            z=float(ob.w_position[2]),
            cov=np.asarray(ob.cov_w_position, dtype=np.float64),
        )
        for fk, fv in dict(ob.features).items():
            attrs[f"feat_{fk}"] = fv
        if ob.object_id in G:
            raise MapError(f"object id {ob.object_id!r} is used twice (or clashes with a place key)")
        G.add_node(ob.object_id, **attrs)
        found = _reach(ob.w_position, reach_model, free, clr, lab, safe_lab, room_places, cells, res, ox, oy)
        for key, dist, sxy, at_home in found or ():
            i = index[key]
            k = transform_points(inverse(frames[i]), ob.w_position[None, :2])[0]
            G.add_edge(
                ob.object_id,
                key,
                kind="object_edge",
                relation="in_room" if at_home else "near",
                k_x=float(k[0]),
                k_y=float(k[1]),
                k_z=float(ob.w_position[2]),
                reach_x=float(sxy[0]),
                reach_y=float(sxy[1]),
                reach_distance=float(dist),
            )


def _join_components(G, keys: list[str], sk: SkeletonPaths, sk_of: np.ndarray, add_env_edges) -> None:
    """Join the components of the environment graph: repeatedly, from the component of the first room, the
    place of another component nearest along the skeleton (one multi-source search from the component's
    skeleton cells; among equally near places the first) gets a passage to the place of the grown component
    where that search started. Places off every skeleton component stay apart."""
    import networkx as nx

    if len(sk) == 0 or len(keys) < 2:
        return
    owner: dict[int, list[str]] = {}
    for k, c in zip(keys, sk_of.tolist(), strict=True):
        owner.setdefault(c, []).append(k)
    cell_of = dict(zip(keys, sk_of.tolist(), strict=True))
    while True:
        comps = list(nx.connected_components(G.subgraph(keys)))
        if len(comps) < 2:
            return
        comps.sort(key=lambda c: (not any(G.nodes[k]["place"] == "room" for k in c), -len(c)))
        grown = comps[0]
        dist, src = sk.multi_source({cell_of[k] for k in grown})
        rest = [(float(dist[cell_of[k]]), n, k) for n, k in enumerate(keys) if k not in grown]
        rest = [q for q in rest if np.isfinite(q[0])]
        if not rest:
            return  # the rest is on skeleton components of its own
        _dd, _n, best = min(rest)
        start = min((k for k in owner.get(int(src[cell_of[best]]), ()) if k in grown), default=None)
        if start is None:
            return
        add_env_edges([(start, best)])


def _reach(pos, rm: ReachModel, free, clr, lab, safe_lab, rooms, cells, res, ox, oy):
    """[(room key, horizontal distance, standing point xy)] of the rooms the object can be handled from."""
    if not (rm.z_min_m <= pos[2] <= rm.z_max_m):
        return []
    h, w = free.shape
    k = int(np.ceil(rm.arm_reach_m / res)) + 1
    c0 = int(np.floor((pos[0] - ox) / res))
    r0 = int(np.floor((pos[1] - oy) / res))
    ra, rb, ca, cb = max(r0 - k, 0), min(r0 + k + 1, h), max(c0 - k, 0), min(c0 + k + 1, w)
    if ra >= rb or ca >= cb:
        return []
    rr, cc = np.mgrid[ra:rb, ca:cb]
    rr, cc = rr.ravel(), cc.ravel()
    sx, sy = cells_to_world(np.column_stack([rr, cc]), ox, oy, res).T
    dist = np.hypot(sx - pos[0], sy - pos[1])
    # the object's home region: the region of the free cell nearest to it
    lw = lab[rr, cc]
    if not np.any(lw > 0):
        return []
    home = int(lw[np.argmin(np.where(lw > 0, dist, np.inf))])
    ok = (dist <= rm.arm_reach_m) & (clr[rr, cc] >= rm.robot_radius_m)
    rr, cc, sx, sy, dist = rr[ok], cc[ok], sx[ok], sy[ok], dist[ok]
    if rr.shape[0] == 0:
        return []
    # line of sight from the standing point to the object: from the home region obstacles are allowed within
    # reach_through_m of the object (the furniture it stands on), from any other region none (no wall between)
    n = max(int(np.ceil(rm.arm_reach_m / (0.5 * res))), 2)
    t = np.linspace(0.0, 1.0, n + 1)[None, :]
    px = sx[:, None] + (pos[0] - sx[:, None]) * t
    py = sy[:, None] + (pos[1] - sy[:, None]) * t
    from_home = (lab[rr, cc] == home)[:, None]
    far = ((1.0 - t) * dist[:, None] > rm.reach_through_m) | ~from_home
    pc = np.floor((px - ox) / res).astype(np.int64)
    pr = np.floor((py - oy) / res).astype(np.int64)
    inside = (pr >= 0) & (pr < h) & (pc >= 0) & (pc < w)
    fr = np.zeros(pr.shape, dtype=bool)
    fr[inside] = free[pr[inside], pc[inside]]
    clear = np.all(fr | ~far, axis=1)
    rr, cc, sx, sy, dist = rr[clear], cc[clear], sx[clear], sy[clear], dist[clear]
    out = []
    for key, lbl, i in rooms:
        m = (lab[rr, cc] == lbl) & (safe_lab[rr, cc] == safe_lab[cells[i][0], cells[i][1]])
        if m.any():
            j = int(np.argmin(np.where(m, dist, np.inf)))
            out.append((key, float(dist[j]), (float(sx[j]), float(sy[j])), lbl == home))
    return out


# ---------------------------------------------------------------------------------------------------- queries


def environment_nodes(G) -> list[str]:
    return [n for n, d in G.nodes(data=True) if d.get("kind") == "environment"]


def object_nodes(G) -> list[str]:
    return [n for n, d in G.nodes(data=True) if d.get("kind") == "object"]


def where_is(G, id_or_type: str) -> list[dict]:
    """Objects whose id or type is ``id_or_type``: dicts with id, type, x, y, z and the places (environment
    node keys with their relation) the object is reachable from (empty for an unreachable one)."""
    out = []
    for n, d in G.nodes(data=True):
        if d.get("kind") != "object" or (n != id_or_type and d.get("object_type") != id_or_type):
            continue
        places = []
        for m in G.neighbors(n):
            e = G.edges[n, m]
            places.append({"place": m, "relation": e.get("relation"), "place_kind": G.nodes[m].get("place")})
        places.sort(key=lambda q: (q["relation"] != "in_room", q["place"]))
        out.append(
            {
                "id": n,
                "type": d.get("object_type"),
                "x": d.get("x"),
                "y": d.get("y"),
                "z": d.get("z"),
                "sightings": d.get("sightings", 0),
                "confirmed": d.get("sightings", 0) >= CONFIRMING_SIGHTINGS,
                "places": places,
                "reachable": bool(places),
            }
        )
    out.sort(key=lambda q: q["id"])
    return out


def object_reach_points(G, object_id: str) -> list[tuple[str, np.ndarray]]:
    """[(place key, standing point xy)] of an object; raises ``PlanningError`` for an unknown object or one no
    place reaches."""
    if object_id not in G or G.nodes[object_id].get("kind") != "object":
        known = sorted(object_nodes(G))
        raise PlanningError(
            f"unknown object {object_id!r}; the map knows {len(known)} objects"
            + (f" (e.g. {', '.join(known[:8])})" if known else "")
        )
    out = []
    for m in G.neighbors(object_id):
        e = G.edges[object_id, m]
        out.append((m, np.array([e["reach_x"], e["reach_y"]], dtype=np.float64)))
    if not out:
        raise PlanningError(
            f"object {object_id!r} is in the map but out of the robot's reach from every place "
            "(it has no object edge)"
        )
    return out


def route_to_object(G, from_xy, object_id: str, via: str | None = None) -> list[str]:
    """The places from the environment node nearest ``from_xy`` to the object: environment node keys along
    the shortest passage route (networkx Dijkstra on passage length), ending with the object id. ``via``
    forces the last environment node. Raises ``PlanningError`` for unknown / unreachable objects."""
    import networkx as nx

    reach = object_reach_points(G, object_id)
    env = environment_nodes(G)
    if not env:
        raise PlanningError("the holographic graph has no environment nodes")
    xy = np.array([[G.nodes[n]["x"], G.nodes[n]["y"]] for n in env])
    p = np.asarray(from_xy, dtype=np.float64).reshape(2)
    start = env[int(np.argmin(np.hypot(*(xy - p).T)))]
    H = G.subgraph(env)
    targets = [via] if via is not None else [k for k, _ in reach]
    best: list[str] | None = None
    best_len = np.inf
    for t in targets:
        try:
            length, path = nx.single_source_dijkstra(H, start, t, weight="length")
        except nx.NetworkXNoPath:
            continue
        if length < best_len:
            best, best_len = path, length
    if best is None:
        raise PlanningError(
            f"no passage joins the place {start!r} near the start to a place reaching {object_id!r}"
        )
    return list(best) + [object_id]
