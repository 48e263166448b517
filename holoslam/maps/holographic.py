"""The household holographic graph M = {V, E} of seed 002 (SPEC.md §1, Eq. 1-5), and its queries.

The graph is a ``networkx.Graph`` (simple: two places are joined by at most one passage). Every node has
``kind`` = ``"environment"`` or ``"object"``.

**Environment nodes** (V_e, carrying {H, L_m}), keyed ``"room:<i>"``, ``"door:<i>"``, ``"crossing:<i>"``,
``"dead_end:<i>"``, with ``place`` = room | doorway | crossing | dead_end, position ``x``, ``y`` (world m),
``region`` (room label) and their local frame: ``anchor`` (index of the nearest submap anchor, -1 without
anchors), ``submap`` (its submap id), ``frame_x``, ``frame_y``, ``frame_theta`` (wTa of that anchor; without
anchors the frame is the node's position with theta 0). L_m is summarised by scalars: ``submap``, ``area_m2``
(rooms), ``clearance`` (m), and ``feat_<name>`` counts when the caller gives per-submap feature counts (H).

How the places are found (all vectorised on the grid, Python loops only over places):

- *Doorways*: door-like constrictions of the free space. Candidates are skeleton cells (topology edge paths)
  whose free width (2 x clearance) lies between the robot's diameter and ``doorway_width_m`` and is the
  narrowest within ``doorway_window_m`` along the skeleton. Each candidate cuts the passage by the line from
  its nearest obstacle cell to the nearest obstacle cell on the other side. With all cuts drawn into the space
  the robot fits in, the free space falls into regions, and the regions are merged by dropping cuts, one per
  round, by these rules in this order: (1) a cut with the same region (or none) on both sides separates
  nothing; (2) two regions joined by two or more cuts are one room around furniture (an island, a table); (3)
  a *fragment* (less than ``fragment_area_m2`` of robot space, or no point ``min_room_clearance_m`` from
  obstacles) joins a neighbour, smallest fragment first, through the cut that opens most widely relative to
  that neighbour's largest clearance, so the pieces of a cluttered room (balcony, study) join each other
  rather than the wide room behind their doorway, and a fragment in front of a doorway joins the room it
  belongs to rather than the one behind the door; (4) a cut between regions whose largest clearance is less
  than ``room_to_doorway_clearance`` x the cut's clearance is a constriction inside one room: the weakest
  goes. The cuts left are the doorways; rooms in a loop (each reachable through two doors) keep them all.
  Known limits: two real doors between the same two rooms count as one room around furniture (rule 2), and a
  room with less than ``fragment_area_m2`` of robot space joins a neighbour (both measured on the simulated
  households: true rooms have at least 3.8 m2 of robot space, clutter pockets at most 2.7 m2).
- *Rooms* (open areas): the 4-connected regions of the robot space with the doorway cuts drawn in; every
  region of at least ``min_room_area_m2`` is a room, whatever clutter is inside, its node sits at its cell
  farthest from obstacles.
- *Crossings* and *dead ends*: topology junctions in narrow space (free width at most ``corridor_width_m``)
  are corridor crossings; topology endpoints in narrow space whose edge is at least ``dead_end_min_length_m``
  long and narrow on average are dead-end corridors. Junctions and endpoints in open rooms (and room corners)
  belong to the room node; places within ``doorway_depth_m`` of a doorway are the doorway.

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
from holoslam.maps.grid import OccupancyGrid

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
    """Where the robot can handle an object from (module docstring). Defaults: the reference household's
    robot (0.25 m radius base, 0.9 m horizontal arm reach, labels 0-2.5 m high)."""

    robot_radius_m: float = 0.25
    arm_reach_m: float = 0.9
    z_min_m: float = 0.0
    z_max_m: float = 2.5
    reach_through_m: float = 0.35


@dataclass(frozen=True, slots=True)
class PlaceParams:
    """Thresholds of place detection (module docstring)."""

    doorway_width_m: float = 1.3
    doorway_depth_m: float = 2.0
    dead_end_min_length_m: float = 1.0
    corridor_width_m: float = 1.4
    min_room_area_m2: float = 1.0
    min_room_clearance_m: float = 0.45
    fragment_area_m2: float = 3.0
    room_to_doorway_clearance: float = 1.1
    doorway_window_m: float = 0.6


def _nearest_anchor(xy: np.ndarray, anchors: np.ndarray | None) -> np.ndarray:
    if anchors is None or len(anchors) == 0:
        return np.full(len(xy), -1, dtype=np.int64)
    d = ((xy[:, None, :] - anchors[None, :, :2]) ** 2).sum(-1)
    return np.argmin(d, axis=1)


def _cut_line(
    mask: np.ndarray,
    rc: np.ndarray,
    direction: np.ndarray,
    half_len_cells: float,
    free: np.ndarray | None = None,
) -> None:
    """Draw (0) the line across the passage at ``rc`` (perpendicular to ``direction``) into ``mask``: with
    ``free``, on each side up to the first non-free cell (at most 2 x ``half_len_cells``) and one cell into it,
    so the cut closes the gap even when the skeleton cell is off the gap's middle; else ``half_len_cells``."""
    import cv2

    d = direction / (np.hypot(*direction) or 1.0)
    n = np.array([-d[1], d[0]])  # perpendicular, in (row, col)
    ends = []
    for sgn in (1.0, -1.0):
        reach = half_len_cells
        if free is not None:
            t = np.arange(1, int(2 * half_len_cells) + 2, dtype=np.float64)
            pts = np.rint(rc[None, :] + sgn * t[:, None] * n[None, :]).astype(np.int64)
            h, w = free.shape
            ok = (pts[:, 0] >= 0) & (pts[:, 0] < h) & (pts[:, 1] >= 0) & (pts[:, 1] < w)
            blocked = ~ok
            blocked[ok] = ~free[pts[ok, 0], pts[ok, 1]]
            hit = np.nonzero(blocked)[0]
            reach = float(t[hit[0]]) + 1.0 if hit.shape[0] else float(t[-1])
        ends.append(rc + sgn * n * reach)
    a, b = ends
    cv2.line(
        mask, (int(round(a[1])), int(round(a[0]))), (int(round(b[1])), int(round(b[0]))), 0, 1, cv2.LINE_8
    )


def _doorway_candidates(
    topology, clr: np.ndarray, res: float, p: PlaceParams, min_width_m: float = 0.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(cell (row, col), skeleton direction) of each doorway candidate along the topology edges (node cells
    included): a skeleton cell whose free width (2 x clearance) lies in [``min_width_m``,
    ``doorway_width_m``] and is the narrowest within ``doorway_window_m`` along the skeleton (one per plateau,
    one per place). Beyond a junction the skeleton goes on; towards an endpoint (a spur running into a wall or
    a furniture corner, clearance falling to its tip) there is no candidate within half a window of the tip.
    Whether a candidate separates anything is decided later by the regions it cuts."""
    out = []
    half = max(int(round(0.5 * p.doorway_window_m / res)), 1)
    for u, v, data in topology.edges(data=True):
        path = np.asarray(data.get("path", np.zeros((0, 2))), dtype=np.int64).reshape(-1, 2)
        if path.shape[0] == 0:
            continue
        nu, nv = topology.nodes[u], topology.nodes[v]
        if data.get("path_from", u) != u:
            nu, nv = nv, nu
        head, tail = [], []
        if "row" in nu and "row" in nv:
            head = [[int(nu["row"]), int(nu["col"])]]
            tail = [[int(nv["row"]), int(nv["col"])]]
        path = np.vstack(
            [
                np.array(head, dtype=np.int64).reshape(-1, 2),
                path,
                np.array(tail, dtype=np.int64).reshape(-1, 2),
            ]
        )
        if path.shape[0] < 3:
            continue
        c = clr[path[:, 0], path[:, 1]]
        narrow = (2.0 * c <= p.doorway_width_m) & (2.0 * c >= min_width_m)
        if not narrow.any():
            continue
        pads = [np.full(half, -np.inf if nd.get("kind") == "endpoint" else np.inf) for nd in (nu, nv)]
        win_min = np.lib.stride_tricks.sliding_window_view(
            np.concatenate([pads[0], c, pads[1]]), 2 * half + 1
        ).min(axis=1)
        idx = np.nonzero(narrow & (c <= win_min))[0]
        if idx.shape[0] == 0:
            continue
        groups = np.split(idx, np.nonzero(np.diff(idx) > 1)[0] + 1)
        for g in groups:
            i = int(g[g.shape[0] // 2])
            lo, hi = max(i - 3, 0), min(i + 3, path.shape[0] - 1)
            direction = (path[hi] - path[lo]).astype(np.float64)
            if direction.any():
                out.append((path[i], direction))
    # one candidate per place (two edges meeting at a junction both find it): the narrowest wins
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    sep = 0.5 * p.doorway_window_m / res
    for rc, dvec in sorted(out, key=lambda q: float(clr[q[0][0], q[0][1]])):
        if all(np.hypot(*(rc - k[0])) > sep for k in kept):
            kept.append((rc, dvec))
    return kept


def _orient_cuts(cands, free: np.ndarray, clr: np.ndarray, res: float):
    """The critical line of each candidate's gap: from the cell's nearest obstacle cell p1 to the nearest
    obstacle cell p2 on the other side (``(p2 - rc) . (p1 - rc) < 0``), whatever way the skeleton bends there.
    Returns ([(cell, direction along the passage = perpendicular to p1 p2)], {cell: (p1, p2)})."""
    h, w = free.shape
    out, lines = [], {}
    for rc, d in cands:
        k = int(np.ceil(2.0 * clr[rc[0], rc[1]] / res)) + 4
        r0, r1, c0, c1 = max(rc[0] - k, 0), min(rc[0] + k + 1, h), max(rc[1] - k, 0), min(rc[1] + k + 1, w)
        obs = np.argwhere(~free[r0:r1, c0:c1]) + np.array([r0, c0])
        if obs.shape[0] == 0:
            out.append((rc, d))
            continue
        v = (obs - rc).astype(np.float64)
        d2 = (v**2).sum(1)
        i1 = int(np.argmin(d2))
        other = (v @ v[i1]) < 0
        if not other.any() or d2[i1] == 0:
            out.append((rc, d))
            continue
        i2 = int(np.argmin(np.where(other, d2, np.inf)))
        p1, p2 = obs[i1].astype(np.float64), obs[i2].astype(np.float64)
        n = p2 - p1
        out.append((rc, np.array([n[1], -n[0]])))
        lines[(int(rc[0]), int(rc[1]))] = (p1, p2)
    return out, lines


def _side_labels(lab: np.ndarray, free: np.ndarray, rc: np.ndarray, direction: np.ndarray, max_cells: int):
    """Region labels on the two sides of a cut: walk from the cut along +-direction (stopping at the first
    obstacle cell, so a thin wall is never crossed) and take the first labelled cell."""
    d = direction / np.hypot(*direction)
    h, w = lab.shape
    sides = []
    for sgn in (1.0, -1.0):
        t = np.arange(1, max_cells + 1, dtype=np.float64)
        pts = np.rint(rc[None, :] + sgn * t[:, None] * d[None, :]).astype(np.int64)
        ok = (pts[:, 0] >= 0) & (pts[:, 0] < h) & (pts[:, 1] >= 0) & (pts[:, 1] < w)
        stop = np.nonzero(~ok)[0]
        pts = pts[: stop[0]] if stop.shape[0] else pts
        blocked = np.nonzero(~free[pts[:, 0], pts[:, 1]])[0]
        pts = pts[: blocked[0]] if blocked.shape[0] else pts
        v = lab[pts[:, 0], pts[:, 1]] if pts.shape[0] else np.zeros(0, dtype=lab.dtype)
        v = v[v > 0]
        sides.append(int(v[0]) if v.shape[0] else 0)
    return sides[0], sides[1]


def build_holographic(
    grid: OccupancyGrid,
    topology,
    anchors_wTa: np.ndarray | None = None,
    submap_ids: Sequence[int] | None = None,
    objects: Sequence[ObjectInfo] = (),
    reach_model: ReachModel | None = None,
    params: PlaceParams | None = None,
    submap_features: Mapping[int, Mapping[str, int]] | None = None,
) -> nx.Graph:
    """Build the holographic graph (module docstring) from the global grid, its topology graph
    (``holoslam.maps.topology``), the optimised submap anchors wTa (K, 3) with their submap ids, and the
    objects. Raises ``MapError`` for malformed inputs."""
    import cv2
    import networkx as nx

    from holoslam.maps.topology import clearance_map

    reach_model = reach_model or ReachModel()
    p = params or PlaceParams()
    res, ox, oy = grid.resolution, grid.origin_x, grid.origin_y
    free = grid.free
    h, w = free.shape
    clr = clearance_map(free, res)
    anchors = None if anchors_wTa is None else np.asarray(anchors_wTa, dtype=np.float64).reshape(-1, 3)
    if anchors is not None and submap_ids is not None and len(submap_ids) != len(anchors):
        raise MapError(f"{len(anchors)} anchors but {len(submap_ids)} submap ids; give one id per anchor")
    sids = (
        list(range(len(anchors))) if (anchors is not None and submap_ids is None) else list(submap_ids or [])
    )

    def rc_to_xy(rc: np.ndarray) -> np.ndarray:
        rc = np.asarray(rc, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([ox + (rc[:, 1] + 0.5) * res, oy + (rc[:, 0] + 0.5) * res])

    # ---- doorways and rooms -------------------------------------------------------------------------------
    rr_cells = reach_model.robot_radius_m / res
    cands, cut_lines = _orient_cuts(
        _doorway_candidates(topology, clr, res, p, min_width_m=2.0 * reach_model.robot_radius_m),
        free,
        clr,
        res,
    )
    # the space the robot can use: free cells covered by a robot-sized disc that fits (a morphological
    # opening); gaps in walls and between furniture narrower than the robot are not passages
    rad = max(int(np.floor(rr_cells)), 1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * rad + 1, 2 * rad + 1))
    nav = cv2.dilate((clr >= reach_model.robot_radius_m).astype(np.uint8), disc) & free.astype(np.uint8)
    free_u8 = nav
    min_room_cells = p.min_room_area_m2 / (res * res)
    fragment_cells = max(p.fragment_area_m2, p.min_room_area_m2) / (res * res)

    def draw(cs):
        """Regions with the cuts ``cs`` drawn: (count, labels, true area in cells, merge area in cells, max
        clearance per region, side labels per cut). The merge area of a region without room for a standing
        robot (a strip between furniture and a wall) is below the fragment size whatever its true area."""
        m = free_u8.copy()
        for rc, d in cs:
            ln = cut_lines.get((int(rc[0]), int(rc[1])))
            if ln is None:
                _cut_line(m, rc.astype(np.float64), d, clr[rc[0], rc[1]] / res + 2.0, free)
            else:  # obstacle to obstacle through the cell
                for q0, q1 in ((ln[0], rc), (rc, ln[1])):
                    cv2.line(m, (int(q0[1]), int(q0[0])), (int(q1[1]), int(q1[0])), 0, 1, cv2.LINE_8)
        n_l, lb = cv2.connectedComponents(m, connectivity=4)
        ar = np.bincount(lb.ravel(), minlength=n_l).astype(np.float64)
        mx = np.zeros(n_l)
        np.maximum.at(mx, lb.ravel(), clr.ravel())
        merge_ar = ar.copy()
        thin = mx < p.min_room_clearance_m
        merge_ar[thin] = np.minimum(merge_ar[thin], fragment_cells - 0.5)
        sd = [
            _side_labels(lb, free, rc.astype(np.float64), d, int(clr[rc[0], rc[1]] / res) + 8) for rc, d in cs
        ]
        return n_l, lb, ar, merge_ar, mx, sd

    # Region merging (module docstring), one cut dropped per round, in this order of the rules:
    # 1. a cut whose two sides are one region (or no region) separates nothing;
    # 2. two regions joined by two or more cuts are one room around furniture (an island, a table);
    # 3. a fragment (merge area < fragment_area_m2) joins a neighbour, smallest fragment first: the one its cut
    #    opens into most widely relative to the neighbour's max clearance, so the pieces of a cluttered room
    #    join each other (similar widths) rather than the wide room behind a doorway;
    # 4. a cut between two regions hardly wider than the gap itself (max clearance < room_to_doorway_clearance
    #    x the gap's half width) is a constriction inside one room: the weakest such cut goes.
    while True:
        n_lab, lab, area, merge_area, mx, sides = draw(cands)
        keep = [a != b and a > 0 and b > 0 for a, b in sides]
        if all(keep):
            pairs: dict[tuple[int, int], list[int]] = {}
            for i, (a, b) in enumerate(sides):
                pairs.setdefault((min(a, b), max(a, b)), []).append(i)
            parallel = [ii for ii in pairs.values() if len(ii) > 1]
            small = {k for k in range(1, n_lab) if merge_area[k] < fragment_cells}
            touching = [i for i, (a, b) in enumerate(sides) if a in small or b in small]
            if parallel:
                for i in min(parallel, key=lambda ii: min(merge_area[k] for k in sides[ii[0]])):
                    keep[i] = False
            elif touching:
                k_small = min(
                    (k for i in touching for k in sides[i] if k in small), key=lambda k: merge_area[k]
                )
                # through the cut that opens most widely relative to the neighbour's own width (the cut least
                # like a doorway of that neighbour)
                opening = [
                    (
                        clr[cands[i][0][0], cands[i][0][1]]
                        / max(mx[sides[i][0] + sides[i][1] - k_small], 1e-9),
                        -i,
                    )
                    for i in touching
                    if k_small in sides[i]
                ]
                via = -max(opening)[1]
                keep[via] = False
            else:
                weak = [
                    (min(mx[a], mx[b]) / max(clr[cands[i][0][0], cands[i][0][1]], 1e-9), i)
                    for i, (a, b) in enumerate(sides)
                ]
                weak = [q for q in weak if q[0] < p.room_to_doorway_clearance]
                if not weak:
                    break
                keep[min(weak)[1]] = False
        cands = [c for c, k in zip(cands, keep, strict=False) if k]
    # rooms: labels with enough area; node at max clearance
    room_labels = [int(k) for k in np.nonzero(area >= min_room_cells)[0] if k != 0]
    flat_lab = lab.ravel()
    order = np.lexsort((clr.ravel(), flat_lab))
    last = np.searchsorted(flat_lab[order], np.arange(n_lab), side="right") - 1
    room_cell = {k: np.array(np.unravel_index(order[last[k]], lab.shape)) for k in room_labels}

    # safe space for the base, and its components (reach model connectivity)
    safe = (clr >= reach_model.robot_radius_m).astype(np.uint8)
    _, safe_lab = cv2.connectedComponents(safe, connectivity=8)

    G = nx.Graph(kind="holographic", resolution=res)
    places: list[tuple[str, str, np.ndarray, int]] = []  # key, place, cell, region label
    for i, k in enumerate(room_labels):
        places.append((f"room:{i}", "room", room_cell[k], k))
    door_keys = []
    for i, ((rc, _d), (a, b)) in enumerate(zip(cands, sides, strict=False)):
        places.append((f"door:{i}", "doorway", rc, 0))
        door_keys.append((f"door:{i}", a, b))
    # crossings and dead ends in narrow space
    door_xy = rc_to_xy(np.array([c[0] for c in cands])) if cands else np.zeros((0, 2))
    n_cross = n_dead = 0
    for _n, d in topology.nodes(data=True):
        kind = d.get("kind")
        if kind not in ("junction", "endpoint"):
            continue
        r, c = int(d["row"]), int(d["col"])
        if 2.0 * clr[r, c] > p.corridor_width_m or lab[r, c] not in room_cell:
            continue
        xy = rc_to_xy(np.array([r, c]))[0]
        if door_xy.shape[0] and np.min(np.hypot(*(door_xy - xy).T)) < p.doorway_depth_m:
            continue
        if kind == "endpoint":
            # a dead-end corridor: the edge leading to the endpoint is long and narrow on average
            inc = [ed for _a, _b, ed in topology.edges(_n, data=True) if "path" in ed]
            if not inc:
                continue
            pth = np.asarray(inc[0]["path"], dtype=np.int64).reshape(-1, 2)
            if (
                float(inc[0].get("length", 0.0)) < p.dead_end_min_length_m
                or 2.0 * float(np.mean(clr[pth[:, 0], pth[:, 1]])) > p.corridor_width_m
            ):
                continue
        if kind == "junction":
            places.append((f"crossing:{n_cross}", "crossing", np.array([r, c]), int(lab[r, c])))
            n_cross += 1
        else:
            places.append((f"dead_end:{n_dead}", "dead_end", np.array([r, c]), int(lab[r, c])))
            n_dead += 1

    cells = np.array([pl[2] for pl in places], dtype=np.int64).reshape(-1, 2)
    pxy = rc_to_xy(cells)
    aidx = _nearest_anchor(pxy, anchors)
    frames = np.zeros((len(places), 3))
    for i, (key, place, cell, region) in enumerate(places):
        if aidx[i] >= 0:
            frames[i] = anchors[aidx[i]]
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
            attrs["area_m2"] = float(area[region] * res * res)
        if submap_features and sub in submap_features:
            for fk, fv in submap_features[sub].items():
                attrs[f"feat_{fk}"] = int(fv)
        G.add_node(key, **attrs)
    index = {pl[0]: i for i, pl in enumerate(places)}
    room_of_label = {pl[3]: pl[0] for pl in places if pl[1] == "room"}

    # ---- passages along the skeleton ----------------------------------------------------------------------
    sk_graph, sk_cells = _skeleton_cell_graph(topology, res)

    def passage(i: int, j: int) -> tuple[np.ndarray, float, bool]:
        a, b = cells[i], cells[j]
        if sk_cells.shape[0]:
            ia = int(np.argmin(np.abs(sk_cells - a).sum(1)))
            ib = int(np.argmin(np.abs(sk_cells - b).sum(1)))
            try:
                nodes = nx.shortest_path(sk_graph, ia, ib, weight="weight")
                pts = np.vstack([pxy[i : i + 1], rc_to_xy(sk_cells[nodes]), pxy[j : j + 1]])
                return pts, float(np.hypot(*np.diff(pts, axis=0).T).sum()), True
            except nx.NetworkXNoPath:
                pass
        pts = np.vstack([pxy[i], pxy[j]])
        return pts, float(np.hypot(*(pxy[j] - pxy[i]))), False

    def add_env_edge(ki: str, kj: str) -> None:
        if ki == kj or G.has_edge(ki, kj):
            return
        i, j = index[ki], index[kj]
        pts, length, on_sk = passage(i, j)
        wij = between(frames[i], frames[j])
        G.add_edge(
            ki,
            kj,
            kind="passage",
            w_from=ki,
            w_to=kj,
            passage=pts,
            length=length,
            passage_on_skeleton=on_sk,
            w_x=float(wij[0]),
            w_y=float(wij[1]),
            w_theta=float(wij[2]),
        )

    for key, a, b in door_keys:
        for lbl in (a, b):
            if lbl in room_of_label:
                add_env_edge(room_of_label[lbl], key)
    for key, place, _cell, region in places:
        if place in ("crossing", "dead_end") and region in room_of_label:
            add_env_edge(room_of_label[region], key)

    # every place without a passage yet (e.g. a doorway whose side is no room, a crossing outside the rooms)
    # and every component left apart are joined to the nearest place along the skeleton, so the environment
    # graph is connected wherever the skeleton is
    _join_components(G, places, index, cells, sk_graph, sk_cells, add_env_edge)

    # ---- objects ------------------------------------------------------------------------------------------
    rooms = [(pl[0], pl[3], index[pl[0]]) for pl in places if pl[1] == "room"]
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
        found = _reach(ob.w_position, reach_model, free, clr, lab, safe_lab, rooms, cells, res, ox, oy)
        if not found:
            continue
        for key, dist, sxy, at_home in found:
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
    return G


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
    sx, sy = ox + (cc + 0.5) * res, oy + (rr + 0.5) * res
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


def _join_components(G, places, index, cells, sk_graph, sk_cells, add_env_edge) -> None:
    """Join the components of the environment graph: repeatedly, from the component of the first room, the
    place of another component nearest along the skeleton (multi-source Dijkstra over skeleton cells) gets a
    passage to the nearest place of the grown component. Places off every skeleton component stay apart."""
    import networkx as nx

    if sk_cells.shape[0] == 0 or len(places) < 2:
        return
    keys = [pl[0] for pl in places]
    sk_of = {k: int(np.argmin(np.abs(sk_cells - cells[index[k]]).sum(1))) for k in keys}
    owner: dict[int, list[str]] = {}
    for k, c in sk_of.items():
        owner.setdefault(c, []).append(k)
    while True:
        comps = list(nx.connected_components(G.subgraph(keys)))
        if len(comps) < 2:
            return
        comps.sort(key=lambda c: (not any(G.nodes[k]["place"] == "room" for k in c), -len(c)))
        grown = comps[0]
        dist, paths = nx.multi_source_dijkstra(sk_graph, {sk_of[k] for k in grown}, weight="weight")
        best = None
        for c, dd in dist.items():
            for k in owner.get(c, ()):
                if k not in grown and (best is None or dd < best[0]):
                    best = (dd, k, c)
        if best is None:
            return  # the rest is on skeleton components of its own
        src_cell = paths[best[2]][0]
        src = min((k for k in owner.get(src_cell, ()) if k in grown), default=None)
        if src is None:
            return
        add_env_edge(src, best[1])


def _skeleton_cell_graph(topology, res: float):
    """A graph over the skeleton cells of the topology's edge paths (8-connected steps, weights in metres)."""
    import networkx as nx

    # each edge path with the cells of its two nodes (paths stop next to a junction cluster's representative
    # cell, so without them the paths would not join)
    paths = []
    for u, v, d in topology.edges(data=True):
        if "path" not in d:
            continue
        q = np.asarray(d["path"], dtype=np.int64).reshape(-1, 2)
        nu, nv = topology.nodes[u], topology.nodes[v]
        if d.get("path_from", u) != u:
            nu, nv = nv, nu
        if q.shape[0] and "row" in nu and "row" in nv:
            q = np.vstack([[int(nu["row"]), int(nu["col"])], q, [int(nv["row"]), int(nv["col"])]])
        paths.append(q)
    if not paths:
        return nx.Graph(), np.zeros((0, 2), dtype=np.int64)
    allc = np.concatenate(paths)
    key = allc[:, 0] * (int(allc[:, 1].max()) + 2) + allc[:, 1]
    uk, inv = np.unique(key, return_inverse=True)
    cells = np.zeros((uk.shape[0], 2), dtype=np.int64)
    cells[inv] = allc
    lens = np.array([q.shape[0] for q in paths])
    ends = np.cumsum(lens)
    a = inv[:-1]
    b = inv[1:]
    valid = np.ones(a.shape[0], dtype=bool)
    valid[ends[:-1] - 1] = False  # no step between two different paths
    a, b = a[valid], b[valid]
    wgt = np.hypot(*(cells[a] - cells[b]).T) * res
    G = nx.Graph()
    G.add_nodes_from(range(cells.shape[0]))
    G.add_weighted_edges_from(zip(a.tolist(), b.tolist(), wgt.tolist(), strict=False))
    return G, cells


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
