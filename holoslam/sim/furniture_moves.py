"""Furniture moved between simulated days (``holoslam.sim.days``): a free-standing piece (a chair, the armchair, a
table, the sofa rarely) is carried to a new free place in its room, turned or not, with the labels on it.

A place is accepted when (every threshold below, with its reason):

- the piece stays inside its room, ``WALL_GAP_M`` from the walls, and ``FURNITURE_GAP_M`` from every other piece
  (on the world's free-space raster without it, ``RASTER_M`` cells);
- it, and every label on it, moves at least ``days.MIN_MOVE_M`` (the small objects' rule: twice the 0.3 m that
  makes a "moved"), so its labels' truth is a clear "moved"; its labels land ``days.MIN_SPACING_M`` from every
  other label (as a moved object does);
- it keeps ``DOOR_CLEAR_M`` from every doorway's centre;
- the robot's route still drives: the space a planned path may use (clearance ``route.PLAN_CLEARANCE``) that was
  connected to the start and is not under the new place stays connected, every station of the day's tour lies in
  it, and every label that had a viewing spot (``route``'s: a standable place 0.8-2.2 m in front of it, no wall in
  between) keeps one.

Which piece is drawn by ``MOVABLE`` (relative weights: chairs are pulled out and pushed back nearly every day, a
table or the armchair now and then, the sofa rarely); wall-bound pieces (beds, wardrobes, counters, shelves,
appliances) never move. The place is drawn uniformly in the room, the turn uniformly in [-180, 180) deg; up to
``TRIES`` draws a piece, then another piece is drawn (the day has one move fewer when none fits)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from holoslam.sim.world import Furniture, World, WorldObject

__all__ = ["FurnitureChange", "MOVABLE", "WALL_GAP_M", "FURNITURE_GAP_M", "DOOR_CLEAR_M", "RASTER_M", "TRIES",
           "move_furniture", "polygon_points"]

# relative chance of each free-standing piece to be the one moved (module docstring)
MOVABLE = {"chair_w": 1.0, "chair_s1": 1.0, "chair_s2": 1.0, "chair_corner": 1.0, "office_chair": 1.0,
           "armchair": 0.3, "coffee_table": 0.2, "balcony_table": 0.2, "plant_pot": 0.2, "lamp": 0.2,
           "dining_table": 0.05, "sofa": 0.05}
WALL_GAP_M = 0.02  # m from a wall at least (the corner chair stands 2 cm off the walls in the reference household)
FURNITURE_GAP_M = 0.06  # m between two pieces: not pushed into each other (three raster cells)
RASTER_M = 0.02  # m: the free-space raster the gaps are checked on (the reference household's own resolution)
DOOR_CLEAR_M = 0.8  # m from a doorway's centre: nothing is put in a doorway (the robot is 0.5 m across)
TRIES = 300  # places drawn per piece: a chair fits in about 1 of 10 draws in the dining room


@dataclass(frozen=True, slots=True)
class FurnitureChange:
    """A piece of furniture moved before ``day``: its footprint before and after (counter-clockwise, map), the
    translation of its centroid, the turn, and the labels that moved with it."""

    day: int
    name: str
    room: str
    before: tuple[tuple[float, float], ...]
    after: tuple[tuple[float, float], ...]
    shift_m: float
    turn_rad: float
    objects: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"day": self.day, "name": self.name, "room": self.room,
                "before": [list(p) for p in self.before], "after": [list(p) for p in self.after],
                "shift_m": round(self.shift_m, 4), "turn_deg": round(math.degrees(self.turn_rad), 2),
                "objects": list(self.objects)}


def polygon_points(polygon: Any, step: float) -> np.ndarray:
    """Points every ``step`` (or less) along the edges of a closed polygon (its vertices included), (N, 2)."""
    P = np.asarray(polygon, np.float64).reshape(-1, 2)
    out = []
    for a, b in zip(P, np.roll(P, -1, axis=0), strict=True):
        n = max(int(math.ceil(math.dist(a, b) / step)), 1)
        out.append(a + np.linspace(0.0, 1.0, n, endpoint=False)[:, None] * (b - a))
    return np.vstack(out)


def _turned(xy: np.ndarray, c: np.ndarray, c_new: np.ndarray, turn: float) -> np.ndarray:
    R = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    return (np.asarray(xy, np.float64).reshape(-1, 2) - c) @ R.T + c_new


def _footprint_mask(fs: Any, polygon: np.ndarray) -> np.ndarray:
    import cv2

    mask = np.zeros(fs.clearance.shape, np.uint8)
    px = np.round(polygon / fs.resolution * 16).astype(np.int32)
    cv2.fillPoly(mask, [px], 1, cv2.LINE_8, 4)
    return mask > 0


def _plan_component(fs: Any) -> np.ndarray:
    """The cells a planned path may use (``PLAN_CLEARANCE``) connected to the tour's start."""
    import cv2

    from holoslam.sim.route import PLAN_CLEARANCE, START_POSE

    ok = (fs.clearance >= PLAN_CLEARANCE).astype(np.uint8)
    _, labels = cv2.connectedComponents(ok, connectivity=8)
    r, c = fs.cell_of(np.array([START_POSE[:2]]))
    return (labels == labels[r[0], c[0]]) & (ok > 0)


def _viewable(world: World, fs: Any) -> set[str]:
    from holoslam.sim.route import _view_spot

    return {o.object_id for o in world.objects if _view_spot(world, fs, o) is not None}


def _drives(old: World, new: World, viewable: set[str]) -> bool:
    """The route check of the module docstring on the 0.05 m raster the route plans on."""
    from holoslam.sim.route import PLAN_CLEARANCE, plan_stations
    from holoslam.sim.world import free_space

    fs_old, fs_new = free_space(old, resolution=0.05), free_space(new, resolution=0.05)
    before, after = _plan_component(fs_old), _plan_component(fs_new)
    if not after.any() or np.any(before & (fs_new.clearance >= PLAN_CLEARANCE) & ~after):
        return False  # some space the route used is cut off
    st = np.array([(s.x, s.y) for s in plan_stations(new)])
    r, c = fs_new.cell_of(st)
    return bool(after[r, c].all()) and viewable <= _viewable(new, fs_new)


def _fits(world: World, f: Furniture, poly: np.ndarray, fs_rest: Any) -> bool:
    """The room, gap and doorway rules of the module docstring for ``f`` at ``poly``."""
    room = next(r for r in world.rooms if r.name == f.room)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    if lo[0] < room.xmin + WALL_GAP_M or lo[1] < room.ymin + WALL_GAP_M or hi[0] > room.xmax - WALL_GAP_M \
            or hi[1] > room.ymax - WALL_GAP_M:
        return False
    edge = polygon_points(poly, fs_rest.resolution / 2)
    for d in world.doorways:
        if np.min(np.hypot(*(edge - np.array(d.centre)).T)) < DOOR_CLEAR_M:
            return False
    inside = _footprint_mask(fs_rest, poly)
    near = fs_rest.clearance[inside]
    return bool(near.size) and float(near.min()) >= FURNITURE_GAP_M + fs_rest.resolution / 2


def _place(rng: np.random.Generator, world: World, f: Furniture, labels: list[WorldObject], min_move_m: float,
           min_spacing_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """A place for ``f`` by the rules of the module docstring (``min_move_m``, ``min_spacing_m``: the days'
    ``MIN_MOVE_M`` and ``MIN_SPACING_M``): (centroid before, after, new polygon, turn), or None after ``TRIES``
    draws."""
    from holoslam.sim.world import free_space

    room = next(r for r in world.rooms if r.name == f.room)
    P = np.asarray(f.polygon, np.float64)
    c = P.mean(axis=0)
    rest = replace(world, furniture=tuple(x for x in world.furniture if x.name != f.name))
    fs_rest = free_space(rest, resolution=RASTER_M)
    viewable = _viewable(world, free_space(world, resolution=0.05))
    lxy = np.array([o.position[:2] for o in labels]).reshape(-1, 2)
    others = np.array([o.position[:2] for o in world.objects if o.furniture != f.name]).reshape(-1, 2)
    for _ in range(TRIES):
        c_new = np.array([rng.uniform(room.xmin, room.xmax), rng.uniform(room.ymin, room.ymax)])
        turn = float(rng.uniform(-math.pi, math.pi))
        poly = _turned(P, c, c_new, turn)
        new_lxy = _turned(lxy, c, c_new, turn)
        if math.dist(c, c_new) < min_move_m or (len(lxy) and (
                np.min(np.hypot(*(new_lxy - lxy).T)) < min_move_m
                or np.min(np.hypot(*(new_lxy[:, None] - others[None]).transpose(2, 0, 1))) < min_spacing_m)):
            continue
        if not _fits(world, f, poly, fs_rest):
            continue
        new = _with_piece(world, f, c, c_new, turn)
        if _drives(world, new, viewable):
            return c, c_new, poly, turn
    return None


def _with_piece(world: World, f: Furniture, c: np.ndarray, c_new: np.ndarray, turn: float) -> World:
    """The world with ``f`` moved (its centroid ``c`` to ``c_new``, turned by ``turn``) and its labels with it."""
    poly = _turned(np.asarray(f.polygon), c, c_new, turn)
    moved = replace(f, polygon=tuple((round(float(x), 3), round(float(y), 3)) for x, y in poly))
    objs = []
    for o in world.objects:
        if o.furniture == f.name:
            xy = _turned(np.array(o.position[:2]), c, c_new, turn)[0]
            yaw = math.atan2(math.sin(o.label_yaw + turn), math.cos(o.label_yaw + turn))
            o = replace(o, position=(round(float(xy[0]), 3), round(float(xy[1]), 3), o.position[2]), label_yaw=yaw)
        objs.append(o)
    return replace(world, furniture=tuple(moved if x.name == f.name else x for x in world.furniture),
                   objects=tuple(objs))


def move_furniture(rng: np.random.Generator, day: int, world: World, n_moves: int, min_move_m: float,
                   min_spacing_m: float) -> tuple[World, tuple[FurnitureChange, ...]]:
    """The world of ``day`` with ``n_moves`` pieces of ``MOVABLE`` moved (each at most once a day; fewer when no
    place fits; each and its labels at least ``min_move_m``, the labels ``min_spacing_m`` from every other) and the
    changes; the labels on a moved piece move with it (their ``reachable`` computed again)."""
    from holoslam.sim.world import ARM_REACH, free_space

    out: list[FurnitureChange] = []
    names = [f.name for f in world.furniture if f.name in MOVABLE]
    for _ in range(n_moves):
        left = [n for n in names if n not in {x.name for x in out}]
        while left:
            w = np.array([MOVABLE[n] for n in left])
            name = left[int(rng.choice(len(left), p=w / w.sum()))]
            f = next(x for x in world.furniture if x.name == name)
            labels = [o for o in world.objects if o.furniture == name]
            placed = _place(rng, world, f, labels, min_move_m, min_spacing_m)
            if placed is None:
                left.remove(name)
                continue
            c, c_new, _poly, turn = placed
            world = _with_piece(world, f, c, c_new, turn)
            after = next(x for x in world.furniture if x.name == name).polygon
            out.append(FurnitureChange(day, name, f.room, f.polygon, after, float(math.dist(c, c_new)), turn,
                                       tuple(o.object_id for o in labels)))
            break
    if out:
        moved = {o for x in out for o in x.objects}
        fs = free_space(world)
        objs = tuple(replace(o, reachable=bool(fs.reachable_within(np.array([o.position[:2]]), ARM_REACH,
                                                                   world.wall_segments())[0]))
                     if o.object_id in moved else o for o in world.objects)
        world = replace(world, objects=objs)
    return world, tuple(out)
