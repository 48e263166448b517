"""A simulated large building: the stand-in for a real hospital floor (issue 26) as a deterministic simulation
that writes an MCAP log like the household's.

The floor (:func:`building_world`): ``BuildingPlan.width_m`` x ``height_m`` (350 m x 110 m by default), three
east-west corridors 2.4 m wide (a hospital's clear corridor width for beds) joined by four north-south ones, so
the corridor graph holds loops of 300-860 m and straight runs of 115-345 m. Rooms line both sides of each
east-west corridor: 4-8 m wide (seeded), 7 m deep, walls 0.15 m thick, one 0.9-1.2 m door each at a seeded
place along the corridor wall, and in most rooms a piece of furniture (a bed or desk, 0.8-2.2 m) standing free
of the walls. The space behind the rooms is solid (a hospital's cores). Walls are the boundary of the free
space, traced on a 5 cm raster of the rooms, corridors and doors (axis-aligned, exact at that raster).

The drive (:func:`building_trajectory`): a walk over the corridor graph's junctions that takes the least-driven
corridor next (ties by the seed), so it drives every corridor and comes back around the loops; along each
corridor it turns into a passed room with probability ``BuildingPlan.room_visit_p`` (to the room's middle and
back out), at a seeded cruise speed per leg (``cruise_m_s``: a service robot in a hospital corridor) with the
household's acceleration and turn limits; it stops and turns on the spot at junctions and in rooms.

The laser of the hospital's log (:func:`building_config`): 1.4 Hz, 180 beams over 180 deg, ``range_max``
20 m, and a fraction of beams without return (``laser_dropout``: glass, dark or shiny surfaces), so that with
the beams beyond range about 12 % of beams return nothing, as in the held-out log.

    from holoslam.sim.building import simulate_building_to_file
    simulate_building_to_file("building.mcap", duration_s=4800.0)   # 80 minutes
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from holoslam.errors import ConfigError
from holoslam.sim.core import T0_NS, SimConfig, SimulatedRun
from holoslam.sim.world import Doorway, Furniture, Room, World

__all__ = ["BuildingPlan", "building_world", "building_trajectory", "building_config", "simulate_building",
           "simulate_building_to_file"]

_RES = 0.05  # m: the raster the free space is traced on (every coordinate of the plan is on it)


@dataclass(frozen=True)
class BuildingPlan:
    """The floor and the drive (module docstring); lengths in metres."""

    seed: int = 26
    width_m: float = 350.0
    height_m: float = 110.0
    corridor_y_m: tuple[float, ...] = (12.0, 55.0, 98.0)  # east-west corridors' centre lines
    corridor_x_m: tuple[float, ...] = (4.0, 118.0, 233.0, 346.0)  # north-south corridors' centre lines
    corridor_width_m: float = 2.4  # m: a hospital corridor two beds pass in
    room_depth_m: float = 7.0
    room_width_m: tuple[float, float] = (4.0, 8.0)  # m: range of a room's width along the corridor
    wall_m: float = 0.15  # m: interior wall thickness
    door_width_m: tuple[float, float] = (0.9, 1.2)  # m: single leaf to accessible door
    furniture_p: float = 0.8  # share of rooms with a piece of free-standing furniture
    room_visit_p: float = 0.12  # probability the robot turns into a room it passes
    cruise_m_s: tuple[float, float] = (0.5, 0.8)  # m/s: a service robot's corridor speed range

    def __post_init__(self) -> None:
        if len(self.corridor_y_m) < 1 or len(self.corridor_x_m) < 2:
            raise ConfigError("BuildingPlan: need at least one east-west and two north-south corridors")
        if not 0 <= self.room_visit_p <= 1 or not 0 <= self.furniture_p <= 1:
            raise ConfigError("BuildingPlan: room_visit_p and furniture_p are probabilities in [0, 1]")


@dataclass(frozen=True)
class _Layout:
    """A building's world and its drive graph: junctions (J, 2) m; per east-west corridor k and side, the
    doors as (x of the door's middle, door-front point y, room middle (x, y))."""

    world: World
    junctions: np.ndarray
    doors: dict[tuple[int, int], list[tuple[float, float, float, float]]]


def _snap(v: float) -> float:
    return round(v / _RES) * _RES


def _boundary_walls(free: np.ndarray) -> list[tuple[float, float, float, float]]:
    """The free raster's boundary as axis-aligned segments (x0, y0, x1, y1) in m, row 0 at y = 0: runs of
    cell edges between a free and a non-free cell, merged along each row and column line."""
    pad = np.pad(free, 1)
    out: list[tuple[float, float, float, float]] = []
    for axis in (0, 1):
        diff = np.diff(pad.view(np.int8), axis=axis) != 0  # edges between consecutive cells along axis
        diff = diff[:, 1:-1] if axis == 0 else diff[1:-1, :]
        lines = diff if axis == 0 else diff.T  # lines along x (axis 0) or along y (axis 1)
        for i in np.flatnonzero(lines.any(axis=1)):
            run = np.flatnonzero(np.diff(np.r_[0, lines[i].view(np.int8), 0]))
            for a, b in run.reshape(-1, 2):
                if axis == 0:
                    out.append((a * _RES, i * _RES, b * _RES, i * _RES))
                else:
                    out.append((i * _RES, a * _RES, i * _RES, b * _RES))
    return out


def _layout(plan: BuildingPlan) -> _Layout:  # noqa: PLR0915 - one floor plan, drawn in order
    rng = np.random.default_rng(np.random.SeedSequence([plan.seed, 1]))
    nx, ny = int(round(plan.width_m / _RES)), int(round(plan.height_m / _RES))
    free = np.zeros((ny, nx), dtype=bool)

    def fill(x0: float, y0: float, x1: float, y1: float) -> None:
        free[int(round(y0 / _RES)):int(round(y1 / _RES)), int(round(x0 / _RES)):int(round(x1 / _RES))] = True

    hw = 0.5 * plan.corridor_width_m
    ys, xs = plan.corridor_y_m, plan.corridor_x_m
    rooms: list[Room] = []
    for k, y in enumerate(ys):
        fill(xs[0] - hw, y - hw, xs[-1] + hw, y + hw)
        rooms.append(Room(f"corridor_ew{k}", xs[0] - hw, y - hw, xs[-1] + hw, y + hw))
    for k, x in enumerate(xs):
        fill(x - hw, ys[0] - hw, x + hw, ys[-1] + hw)
        rooms.append(Room(f"corridor_ns{k}", x - hw, ys[0] - hw, x + hw, ys[-1] + hw))
    doors: dict[tuple[int, int], list[tuple[float, float, float, float]]] = {}
    doorways: list[Doorway] = []
    furniture: list[Furniture] = []
    w = plan.wall_m
    for k, y in enumerate(ys):
        for side in (-1, 1):
            face = y + side * hw  # the corridor wall the rooms open from
            near, far = face + side * w, face + side * (w + plan.room_depth_m)
            if min(near, far) < 0.5 or max(near, far) > plan.height_m - 0.5:
                continue
            lo, hi = min(near, far), max(near, far)
            doors[(k, side)] = []
            for a, b in zip(xs[:-1], xs[1:], strict=True):
                x = a + hw + w
                while True:
                    rw = _snap(float(rng.uniform(*plan.room_width_m)))
                    if x + rw > b - hw - w:
                        break
                    name = f"room_{k}{'s' if side < 0 else 'n'}_{len(rooms)}"
                    fill(x, lo, x + rw, hi)
                    rooms.append(Room(name, x, lo, x + rw, hi))
                    dw = _snap(float(rng.uniform(*plan.door_width_m)))
                    dx = _snap(x + float(rng.uniform(0.3, max(rw - dw - 0.3, 0.31))))
                    fill(dx, min(face, near), dx + dw, max(face, near))
                    doorways.append(Doorway(f"door_{name}", (f"corridor_ew{k}", name), (dx, face), (dx + dw, face)))
                    mid_y = 0.5 * (lo + hi)
                    doors[(k, side)].append((dx + 0.5 * dw, y, dx + 0.5 * dw, mid_y))
                    if rng.random() < plan.furniture_p:  # free-standing: 0.6 m or more from every wall
                        fw, fd = float(rng.uniform(0.8, 2.2)), float(rng.uniform(0.6, 1.2))
                        fx = x + 0.6 + float(rng.uniform(0.0, max(rw - fw - 1.2, 0.0)))
                        back = hi - 0.6 - fd if side > 0 else lo + 0.6
                        if rw - fw >= 1.2:
                            furniture.append(Furniture(f"furniture_{name}", name, (
                                (fx, back), (fx + fw, back), (fx + fw, back + fd), (fx, back + fd)), 0.75))
                    x += rw + w
    walls = _boundary_walls(free)
    junctions = np.array([(x, y) for y in ys for x in xs], dtype=np.float64)
    world = World(plan.width_m, plan.height_m, tuple(rooms), tuple(walls), tuple(doorways), tuple(furniture), ())
    return _Layout(world, junctions, doors)


def building_world(plan: BuildingPlan = BuildingPlan()) -> World:
    """The floor of ``plan`` (module docstring) as a simulator ``World`` (no labelled objects)."""
    return _layout(plan).world


def _route_legs(plan: BuildingPlan, lay: _Layout, length_m: float) -> list[np.ndarray]:
    """Waypoint polylines (each (K, 2) m, the robot stops at each one's end) of a walk of about
    ``length_m`` metres over the corridor graph (module docstring)."""
    rng = np.random.default_rng(np.random.SeedSequence([plan.seed, 2]))
    xs, ys = plan.corridor_x_m, plan.corridor_y_m
    nx_, ny_ = len(xs), len(ys)
    driven: dict[tuple[int, int], int] = {}
    cur = (0, 0)  # (column, row) of the junction
    legs: list[np.ndarray] = []
    total = 0.0
    while total < length_m:
        i, j = cur
        nbs = [(i + di, j + dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
               if 0 <= i + di < nx_ and 0 <= j + dj < ny_]
        here = i + j * nx_
        key = [driven.get((min(here, a + b * nx_), max(here, a + b * nx_)), 0) + rng.random() for a, b in nbs]
        nxt = nbs[int(np.argmin(key))]
        edge = (min(here, nxt[0] + nxt[1] * nx_), max(here, nxt[0] + nxt[1] * nx_))
        driven[edge] = driven.get(edge, 0) + 1
        p0 = np.array([xs[i], ys[j]])
        p1 = np.array([xs[nxt[0]], ys[nxt[1]]])
        pts = [p0]
        if nxt[1] == j:  # east-west: rooms along it
            lo, hi = sorted((p0[0], p1[0]))
            passing = [d for side in (-1, 1) for d in lay.doors.get((j, side), []) if lo + 3 < d[0] < hi - 3]
            passing.sort(key=lambda d: d[0] if p1[0] > p0[0] else -d[0])
            for dx, cy, _rx, ry in passing:
                if rng.random() < plan.room_visit_p:
                    front = np.array([dx, cy])
                    pts.append(front)
                    legs.append(np.array(pts))
                    inside = np.array([dx, ry])
                    legs.append(np.array([front, inside]))
                    legs.append(np.array([inside, front]))
                    total += 2 * abs(ry - cy)
                    pts = [front]
        pts.append(p1)
        legs.append(np.array(pts))
        total += float(np.abs(p1 - p0).sum())
        cur = nxt
    return legs


def building_trajectory(plan: BuildingPlan, lay: _Layout, duration_s: float, rate_hz: float, t0_ns: int = T0_NS):
    """The true trajectory (``route.Trajectory``) of the drive over ``duration_s`` seconds sampled at
    ``rate_hz``: each leg smoothed and timed as the household's (``route``), a turn on the spot before each."""
    from holoslam.geometry import wrap
    from holoslam.sim.route import W_MAX, Trajectory, _leg_keyframes, _resample, _smooth

    rng = np.random.default_rng(np.random.SeedSequence([plan.seed, 3]))
    legs = _route_legs(plan, lay, duration_s * max(plan.cruise_m_s) * 1.2)
    first = legs[0][1] - legs[0][0]
    cur = np.array([legs[0][0][0], legs[0][0][1], math.atan2(first[1], first[0])])
    poses, times, t = [cur[None, :].copy()], [np.array([0.0])], 0.0
    for pts in legs:
        if t >= duration_s:
            break
        xy = _resample(_smooth(_resample(pts, 0.05), 4.0), 0.05)
        if len(xy) < 2 or np.hypot(*(xy[-1] - xy[0])) < 0.05:
            continue
        d = float(wrap(math.atan2(*(xy[1] - xy[0])[::-1]) - cur[2]))
        if abs(d) > 1e-6:  # turn on the spot, cosine profile, peak rate W_MAX
            n = max(2, int(abs(d) / math.radians(2)))
            dur = abs(d) / W_MAX * math.pi / 2
            u = np.linspace(0, 1, n + 1)[1:]
            poses.append(np.column_stack([np.full(n, cur[0]), np.full(n, cur[1]),
                                          cur[2] + d * (0.5 - 0.5 * np.cos(np.pi * u))]))
            times.append(t + dur * u)
            t += dur
            cur = np.array([cur[0], cur[1], cur[2] + d])
        kp, kt = _leg_keyframes(xy, float(rng.uniform(*plan.cruise_m_s)))
        kp[:, 2] = cur[2] + np.cumsum(np.r_[0.0, wrap(np.diff(kp[:, 2]))])
        poses.append(kp[1:])
        times.append(t + kt[1:])
        t += float(kt[-1])
        cur = kp[-1].copy()
        pause = float(rng.uniform(0.0, 1.0))
        poses.append(cur[None, :].copy())
        times.append(np.array([t + pause]))
        t += pause
    if t < duration_s:
        raise ConfigError(f"building drive: the route ends at {t:.0f} s, before {duration_s:.0f} s")
    P, T = np.vstack(poses), np.concatenate(times)
    keep = np.r_[True, np.diff(T) > 1e-9]
    P, T = P[keep], T[keep]
    ts = np.arange(int(math.floor(duration_s * rate_hz)) + 1) / rate_hz
    th = np.unwrap(P[:, 2])
    out = np.column_stack([np.interp(ts, T, P[:, 0]), np.interp(ts, T, P[:, 1]), wrap(np.interp(ts, T, th))])
    return Trajectory(t0_ns + np.round(ts * 1e9).astype(np.int64), out)


def building_config(duration_s: float = 4800.0, seed: int = 26) -> SimConfig:
    """The sensors of the held-out hospital log (module docstring) for a drive of ``duration_s`` (80 min
    default); the household's odometer and compass models, no camera."""
    return SimConfig(seed=seed, duration_s=duration_s, laser_rate_hz=1.4, laser_beams=180, laser_fov_deg=180.0,
                     laser_range_max_m=20.0, laser_dropout=0.09, image_rate_hz=0.0)


def simulate_building(config: SimConfig | None = None, plan: BuildingPlan = BuildingPlan()) -> SimulatedRun:
    """Simulate the drive through the building of ``plan`` with ``config`` (default :func:`building_config`);
    pure and deterministic for the two."""
    from holoslam.sim.sensors import compass, laser_scans, odometry

    config = building_config() if config is None else config
    if config.duration_s is None:
        raise ConfigError("simulate_building: duration_s must be a number of seconds (the drive has no tour)")
    lay = _layout(plan)
    traj = building_trajectory(plan, lay, float(config.duration_s), config.odom_rate_hz)

    def rng(stream: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([config.seed, stream]))

    c = config
    odo = odometry(traj.stamps_ns, traj.wTb, rng(1), scale=c.odom_scale, slip_sigma=c.odom_slip_sigma,
                   slip_event_rate=c.odom_slip_event_rate, turn_scale=c.odom_turn_scale,
                   drift=math.radians(c.odom_drift_deg_per_m), turn_sigma=c.odom_turn_sigma,
                   heading_sigma=math.radians(c.odom_heading_sigma_deg), lateral_sigma=c.odom_lateral_sigma,
                   covariance=c.odom_covariance)
    com = compass(lay.world, traj.stamps_ns, traj.wTb, rng(2), rate_hz=c.compass_rate_hz,
                  sigma=math.radians(c.compass_sigma_deg), bias=math.radians(c.compass_bias_deg),
                  disturbance_radius=c.compass_disturbance_radius, disturbance_scale=c.compass_disturbance_scale)
    scans = laser_scans(lay.world, traj.stamps_ns, traj.wTb, rng(3), rate_hz=c.laser_rate_hz, sigma=c.laser_sigma,
                        beams=c.laser_beams, fov_deg=c.laser_fov_deg, range_max=c.laser_range_max_m,
                        dropout=c.laser_dropout)
    return SimulatedRun(config, lay.world, traj.stamps_ns, traj.wTb, odo, com, scans, ())


def simulate_building_to_file(path: str | Path, duration_s: float = 4800.0, seed: int = 26,
                              plan: BuildingPlan | None = None) -> dict:
    """Simulate the building drive and write it as an MCAP log; returns a summary (path, size, counts, the
    share of beams without return, the path driven)."""
    from holoslam.sim.writer import write_household_log

    plan = BuildingPlan(seed=seed) if plan is None else plan
    run = simulate_building(building_config(duration_s, seed), plan)
    meta = {"generator": "holoslam.sim.building.simulate_building", "world": f"building (plan {plan})"}
    counts = write_household_log(run, path, metadata=meta)
    steps = np.hypot(*np.diff(run.wTb[:, :2], axis=0).T)
    return {
        "path": str(path),
        "bytes": Path(path).stat().st_size,
        "duration_s": round(float((run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9), 3),
        "messages": counts,
        "scans": int(run.scans.stamps_ns.shape[0]),
        "no_return": round(float(np.mean(~np.isfinite(run.scans.ranges))), 4),
        "path_m": round(float(steps.sum()), 1),
        "walls": len(run.world.walls),
        "rooms": sum(r.name.startswith("room_") for r in run.world.rooms),
        "plan": dataclasses.asdict(plan),
    }
