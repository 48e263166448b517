"""Multi-day households: the reference household driven on several days, with its objects moved, removed and
added between days and a different start pose each day, and the ground truth of every change.

Day 1 is the reference household. Before each later day, ``changes`` of the small objects (labels up to
``route.STATION_MAX_LABEL``: the ones the operator stops at, cups, remotes, books...) change:

- **moved**: to a free spot on another piece of furniture (at least ``MIN_MOVE_M`` away);
- **removed**: taken out of the home;
- **added**: a new object (ids ``O36``, ``O37``...) put on a free spot.

A spot is on an edge of a surface (tables, counters, desk, nightstands, cabinet, TV stand) that faces free space:
every 0.15 m, the label 1 cm outside the edge at the surface's height plus 5 cm, facing out, at least ``MIN_SPACING_M`` from
every other label, with a viewing spot for the operator in front of it. The robot starts each day at a random
standable place with a random heading; its odometry starts at the identity there, so the world frame of the day
is unknown to the log. ``days.json`` beside the logs holds per day the log, the start pose, the changes (before
and after positions), every object's true position, the labels photographed, the objects of the robot's map
that day (``remembered``) and the remembered places checked.

Before the objects change, ``furniture`` (lo, hi) pieces of free-standing furniture (``FURNITURE_MOVES`` by
default) are carried to a new free place in their room, turned or not (``holoslam.sim.furniture_moves``: mostly
chairs, a table or the armchair now and then, the sofa rarely; the route still drives), with the labels on them:
each of those labels is a "moved" change of the day (they move at least ``MIN_MOVE_M``; any that moved less than
``MOVED_M`` would not be) and is not changed again that day. ``days.json`` holds per day the pieces moved
(``furniture``: footprint before and after, shift, turn, the labels on it). The furniture's draws have their own
random stream, so the objects' draws of a seed are those of a household whose furniture stays put up to the first
day a piece moves (from then on the free spots on the surfaces, and so the draws' outcomes, differ).

The robot checks on the objects it knows: from day 2 its route also stops in front of the places of the objects of
its map that no object of the day stands at (``route.plan_stations``), and its camera aims at those places
(``sensors.camera_snapshots``' ``remembered``); an image of a place whose object was moved or removed holds it
empty. The map is the robot's own memory, kept by the simulator from what the days' images held
(``robot_map``), not the day before's truth: each object where an image last read its label (moved: at its new
place once read there), dropped only on a day when ``FORGET_EMPTY_IMAGES`` images aimed at its place held it
empty and none read it. An object taken away on a day the robot did not look is so still checked on the next days
until a check finds its place empty, as a robot that does not know it is gone would; an object never
photographed is not in the map. Day 1 has no map, so its log is the single-day household's."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from holoslam.sim.furniture_moves import FurnitureChange, move_furniture
from holoslam.sim.world import World, WorldObject

__all__ = ["DayChange", "Day", "household_days", "simulate_days", "robot_map", "SURFACES", "MIN_MOVE_M",
           "MIN_SPACING_M", "NEW_KINDS", "DAY_NS", "MOVED_M", "FURNITURE_MOVES", "FORGET_EMPTY_IMAGES"]

# the furniture objects are put on (tables, counters, desk, nightstands, cabinet, TV stand, sofa, beds...)
SURFACES = ("coffee_table", "tv_stand", "balcony_table", "counter", "cabinet", "dining_table", "nightstand_1",
            "nightstand_2", "desk", "sofa", "armchair", "bed_1", "bed_2", "washing_machine")
MIN_MOVE_M = 0.6  # m: a moved object lands this far from its place at least (twice the 0.3 m "moved")
MIN_SPACING_M = 0.4  # m between two labels (two cups side by side still read apart)
MOVED_M = 0.3  # m: a label that moved more is a "moved" change (the change detection's and benchmark's threshold)
# pieces of furniture moved before each later day, drawn uniformly from (lo, hi): one a day on average, mostly a
# chair (holoslam.sim.furniture_moves.MOVABLE), so a chair moves on about two days of three and the sofa rarely
FURNITURE_MOVES = (0, 2)
NEW_KINDS = (("cup", 60, "g=handle,m=0.3"), ("book", 50, "g=side,m=0.6"), ("remote", 50, "g=top,m=0.2"),
             ("phone", 50, "g=side,m=0.2"), ("bottle", 60, "g=side,m=1.0"), ("toy", 60, "g=top,m=0.4"))
DAY_NS = 86_400 * 10**9
# images of one day aimed at a remembered object's place that held it empty (its label not read) before the robot
# drops the object from its map: the store calls an object gone on two such images, each aimed on its own
# (``holoslam.lifelong.changes.ChangeConfig.min_images``: one can cover the place while the label lay just outside
# it); after fewer the store still holds the object there, so the robot looks again on a later day
FORGET_EMPTY_IMAGES = 2


@dataclass(frozen=True, slots=True)
class DayChange:
    """One change before ``day``: ``kind`` moved / removed / added, label centres before and after (None when
    absent); ``furniture``: the piece of furniture the label moved with (None: the object itself was moved)."""

    day: int
    object_id: str
    kind: str
    before: tuple[float, float, float] | None
    after: tuple[float, float, float] | None
    furniture: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d = {"day": self.day, "id": self.object_id, "change": self.kind,
             "before": None if self.before is None else list(self.before),
             "after": None if self.after is None else list(self.after)}
        if self.furniture is not None:
            d["with"] = self.furniture
        return d


@dataclass(frozen=True, eq=False)
class Day:
    """One day: its world, the start pose (x, y, yaw in map), the changes of objects made before it (those moved
    with a piece of furniture included) and the furniture moved before it."""

    day: int
    world: World
    start: tuple[float, float, float]
    changes: tuple[DayChange, ...]
    furniture: tuple[FurnitureChange, ...] = ()


def _spots(world: World, fs: Any) -> list[tuple[str, tuple[float, float, float], float]]:
    """Candidate spots: (furniture, label centre, label yaw) every 0.25 m along the surfaces' free edges."""
    from holoslam.sim.world import segments_block

    out = []
    walls = world.wall_segments()
    for f in world.furniture:
        if f.name not in SURFACES:
            continue
        P = np.asarray(f.polygon, np.float64)
        for a, b in zip(P, np.roll(P, -1, axis=0), strict=True):
            e = b - a
            L = float(np.hypot(*e))
            n = np.array([e[1], -e[0]]) / L  # outward normal of a counter-clockwise polygon
            for s in np.arange(0.1, L - 0.099, 0.15):
                p = a + e * (s / L) + 0.01 * n
                view = p + 1.0 * n
                r, c = fs.cell_of(view[None])
                z = float(f.height) + 0.05
                blocks = np.vstack([walls, world.furniture_segments(min_height=z, exclude=f.name)])
                if not fs.standable[r[0], c[0]] or segments_block(blocks, view[None], p[None])[0]:
                    continue
                out.append((f.name, (round(float(p[0]), 3), round(float(p[1]), 3), round(z, 3)),
                            math.atan2(n[1], n[0])))
    return out


def _free_spot(rng: np.random.Generator, spots: list, objects: list[WorldObject], away_from=None):
    taken = np.array([o.position[:2] for o in objects]).reshape(-1, 2)
    for k in rng.permutation(len(spots)).tolist():
        f, p, yaw = spots[k]
        if len(taken) and np.min(np.hypot(*(taken - np.array(p[:2])).T)) < MIN_SPACING_M:
            continue
        if away_from is not None and math.dist(p[:2], away_from[:2]) < MIN_MOVE_M:
            continue
        return f, p, yaw
    return None


def _label(oid: str, kind: str, mm: int, attrs: str) -> str:
    from holoslam.vision.label import ObjectLabel, encode_label

    pairs = tuple((kv.split("=", 1)[0], kv.split("=", 1)[1]) for kv in attrs.split(",")) + (("s", str(mm)),)
    return encode_label(ObjectLabel(oid, kind, pairs))


def _change_day(rng: np.random.Generator, day: int, world: World, spots: list, n_changes: int, next_id: int,
                done: tuple[DayChange, ...] = ()) -> tuple[World, tuple[DayChange, ...], int]:
    """The world of ``day`` from the day before's, with ``n_changes`` changes after ``done`` (the labels moved with
    the furniture: not changed again)."""
    from holoslam.sim.route import STATION_MAX_LABEL

    objs = list(world.objects)
    changes: list[DayChange] = list(done)
    for _ in range(n_changes):
        kind = ("moved", "removed", "added")[int(rng.choice(3, p=[0.5, 0.3, 0.2]))]
        small = [k for k, o in enumerate(objs) if o.label_size <= STATION_MAX_LABEL
                 and o.object_id not in {c.object_id for c in changes}]
        if kind != "added" and not small:
            kind = "added"
        if kind == "removed":
            k = int(rng.choice(small))
            changes.append(DayChange(day, objs[k].object_id, kind, objs[k].position, None))
            del objs[k]
            continue
        if kind == "moved":
            k = int(rng.choice(small))
            spot = _free_spot(rng, spots, objs[:k] + objs[k + 1:], away_from=objs[k].position)
            if spot is None:
                continue
            f, p, yaw = spot
            room = world.room_of(np.array([p[:2]]))[0] or objs[k].room
            changes.append(DayChange(day, objs[k].object_id, kind, objs[k].position, p))
            objs[k] = replace(objs[k], position=p, label_yaw=yaw, furniture=f, room=room)
            continue
        spot = _free_spot(rng, spots, objs)
        if spot is None:
            continue
        f, p, yaw = spot
        name, mm, attrs = NEW_KINDS[int(rng.integers(len(NEW_KINDS)))]
        oid = f"O{next_id:02d}"
        next_id += 1
        room = world.room_of(np.array([p[:2]]))[0] or ""
        objs.append(WorldObject(oid, name, room, _label(oid, name, mm, attrs), p, yaw, mm / 1000.0, f))
        changes.append(DayChange(day, oid, kind, None, p))
    return replace(world, objects=tuple(objs)), tuple(changes), next_id


def _start(rng: np.random.Generator, fs: Any) -> tuple[float, float, float]:
    """A random place with room to turn (clearance 0.1 m over the route's) and a random heading."""
    from holoslam.sim.route import PLAN_CLEARANCE

    rr, cc = np.nonzero(fs.standable & (fs.clearance >= PLAN_CLEARANCE + 0.1))
    k = int(rng.integers(len(rr)))
    xy = fs.xy_of(rr[k : k + 1], cc[k : k + 1])[0]
    return (round(float(xy[0]), 3), round(float(xy[1]), 3), round(float(rng.uniform(-math.pi, math.pi)), 4))


def _carried(day: int, before: World, after: World, moves: tuple[FurnitureChange, ...]) -> tuple[DayChange, ...]:
    """The labels carried with the moved furniture as "moved" changes (those that moved more than ``MOVED_M``)."""
    out = []
    for m in moves:
        for oid in m.objects:
            a, b = before.object(oid).position, after.object(oid).position
            if math.dist(a[:2], b[:2]) > MOVED_M:
                out.append(DayChange(day, oid, "moved", a, b, m.name))
    return tuple(out)


def household_days(days: int, seed: int = 0, changes: tuple[int, int] = (5, 10),
                   furniture: tuple[int, int] = FURNITURE_MOVES) -> tuple[Day, ...]:
    """``days`` days of the reference household (module docstring); ``changes`` (lo, hi): changes of small objects
    per day, ``furniture`` (lo, hi): pieces of furniture moved per day, each drawn uniformly. Deterministic for a
    seed."""
    from holoslam.sim.route import START_POSE
    from holoslam.sim.world import free_space, reference_household

    rng = np.random.default_rng(np.random.SeedSequence([seed, 2701]))
    rng_f = np.random.default_rng(np.random.SeedSequence([seed, 2702]))  # the furniture's own stream
    world = reference_household()
    fs = free_space(world, resolution=0.05)
    spots = _spots(world, fs)
    out = [Day(1, world, START_POSE, ())]
    next_id = len(world.objects) + 1
    for d in range(2, days + 1):
        n = int(rng.integers(changes[0], changes[1] + 1))
        moved, moves = move_furniture(rng_f, d, world, int(rng_f.integers(furniture[0], furniture[1] + 1)),
                                      MIN_MOVE_M, MIN_SPACING_M)
        if moves:  # the surfaces' free edges and the standable places are those of the new arrangement
            fs = free_space(moved, resolution=0.05)
            spots = _spots(moved, fs)
        world, ch, next_id = _change_day(rng, d, moved, spots, n, next_id, _carried(d, world, moved, moves))
        out.append(Day(d, world, _start(rng, fs), ch, moves))
    return tuple(out)


def _checks(snapshots: Any) -> dict[str, list[int]]:
    """Per remembered place the camera checked: [images aimed at it, of them those that read its label]."""
    out: dict[str, list[int]] = {}
    for s in snapshots:
        if s.checked_id:
            c = out.setdefault(s.checked_id, [0, 0])
            c[0] += 1
            c[1] += s.checked_id in s.visible_ids
    return dict(sorted(out.items()))


def robot_map(memory: dict[str, WorldObject], world: World, snapshots: Any) -> dict[str, WorldObject]:
    """The robot's map after a day (module docstring) from its map before (``memory``: object id -> the
    ``WorldObject`` where it believes the object is), the day's home and the day's images: every object of
    ``world`` whose label an image read, where it stood; every remembered object whose place
    ``FORGET_EMPTY_IMAGES`` check images held empty and no image read, dropped; the others kept as they were.
    Ordered by object id (deterministic)."""
    read = {i for s in snapshots for i in s.visible_ids}
    empty: dict[str, int] = {}
    for s in snapshots:
        if s.checked_id and s.checked_id not in s.visible_ids:
            empty[s.checked_id] = empty.get(s.checked_id, 0) + 1
    out = dict(memory)
    for o in world.objects:
        if o.object_id in read:
            out[o.object_id] = o
    for oid, n in empty.items():
        if oid not in read and n >= FORGET_EMPTY_IMAGES:
            out.pop(oid, None)
    return dict(sorted(out.items()))


def simulate_days(out_dir: Any, days: int, seed: int = 0, duration_s: float | None = None,
                  changes: tuple[int, int] = (5, 10), config: Any = None,
                  furniture: tuple[int, int] = FURNITURE_MOVES) -> dict[str, Any]:
    """Write ``day_01.mcap`` ... and ``days.json`` (the ground truth of every change) into ``out_dir`` (created);
    each day a ``SimConfig`` run (``config``, default settings) with seed ``seed + day``, ``duration_s`` of
    robot time (None: one whole tour), its own start pose and its stamps a day after the day before's. Returns
    the summary (also what ``days.json`` holds)."""
    from pathlib import Path

    from holoslam.io.jsonsafe import dumps
    from holoslam.io.run_folder import prepare_output_folder
    from holoslam.sim.core import T0_NS, SimConfig, simulate_household
    from holoslam.sim.writer import write_household_log

    out = prepare_output_folder(Path(out_dir))
    base = config or SimConfig()
    summary: dict[str, Any] = {"format": "holoslam-days-1", "seed": seed, "changes": list(changes),
                               "furniture_moves": list(furniture), "days": []}
    memory: dict[str, WorldObject] = {}  # the robot's map: where its images last read each object (``robot_map``)
    for day in household_days(days, seed, changes, furniture):
        cfg = replace(base, seed=seed + day.day, duration_s=duration_s)
        run = simulate_household(cfg, world=day.world, start_pose=day.start, t0_ns=T0_NS + (day.day - 1) * DAY_NS,
                                 remembered=tuple(memory.values()))
        remembered = sorted(memory)
        memory = robot_map(memory, day.world, run.snapshots)
        name = f"day_{day.day:02d}.mcap"
        write_household_log(run, out / name)
        summary["days"].append({
            "day": day.day, "log": name, "start_pose": list(day.start),
            "changes": [c.to_dict() for c in day.changes],
            "furniture": [m.to_dict() for m in day.furniture],
            "objects": {o.object_id: list(o.position) for o in day.world.objects},
            "photographed": sorted({i for s in run.snapshots for i in s.visible_ids}),
            "checked": _checks(run.snapshots), "remembered": remembered})
    (out / "days.json").write_text(dumps(summary, indent=1))
    return summary
