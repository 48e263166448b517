"""A teleoperated-looking route through the reference household and its smooth true trajectory.

The route is a tour of "stations": for every object with a small label (``STATION_MAX_LABEL``) a viewing
spot about a metre in front of it, where the robot stops, turns to face the label and dwells (so the PTZ
camera can take its zoomed snapshot; bigger labels are read in passing), and the rooms in an order that
passes every doorway several times and comes back to places already seen (loops). A robot that checks on the
objects of its map (``remembered``: where it believes they are) also stops in front of each of their places
that no object of the day stands at (a moved object's old place, a removed one's), as it would in front of the
object, so that its camera checks the place from there (``sensors.camera_snapshots``).
Consecutive stations are joined by A* paths on the free-space raster with a cost that keeps the robot
away from walls and furniture; the joined path is smoothed and time-parameterised with Pioneer-like
limits (``V_MAX`` forward speed, ``W_MAX`` turn rate, ``A_MAX`` acceleration) and sampled at the odometry
rate. The robot drives like a differential-drive base: it moves along its heading, or turns on the spot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam.geometry import wrap
from holoslam.sim.world import World, free_space

__all__ = [
    "Trajectory",
    "Station",
    "plan_stations",
    "household_trajectory",
    "V_MAX",
    "W_MAX",
    "A_MAX",
    "PLAN_CLEARANCE",
    "tour_duration_s",
    "START_POSE",
    "STATION_MAX_LABEL",
]

V_MAX = 0.4  # m/s
W_MAX = math.radians(40.0)  # rad/s
A_MAX = 0.4  # m/s^2
PLAN_CLEARANCE = 0.32  # m, minimum clearance of planned paths (robot radius 0.25 + margin)
START_POSE = (3.0, 4.8, 0.0)
STATION_MAX_LABEL = 0.065  # m: the operator stops in front of objects whose labels are this small

# Room visits of one tour: two loops through the home in opposite directions.
_TOUR = [
    "living_room",
    "balcony",
    "living_room",
    "bedroom_1",
    "living_room",
    "bedroom_2",
    "living_room",
    "dining_room",
    "kitchen",
    "dining_room",
    "study",
    "dining_room",
    "living_room",
    "dining_room",
    "study",
    "dining_room",
    "kitchen",
    "dining_room",
    "living_room",
    "bedroom_2",
    "living_room",
    "bedroom_1",
    "living_room",
    "balcony",
    "living_room",
]


@dataclass(frozen=True)
class Trajectory:
    """The true base trajectory: ``stamps_ns`` (N,) int64 and ``wTb`` (N, 3)."""

    stamps_ns: np.ndarray
    wTb: np.ndarray


@dataclass(frozen=True, slots=True)
class Station:
    """A place on the route: stop at (x, y), face ``yaw``, wait ``dwell_s``; ``object_id`` when it is a
    viewing spot."""

    x: float
    y: float
    yaw: float | None
    dwell_s: float
    object_id: str | None = None


def _view_spot(world: World, fs, obj) -> Station | None:
    lx, ly = obj.position[0], obj.position[1]
    for d in (1.0, 1.2, 0.8, 1.5, 1.8, 2.2):
        for off in (0.0, 25.0, -25.0, 45.0, -45.0):
            a = obj.label_yaw + math.radians(off)
            x, y = lx + d * math.cos(a), ly + d * math.sin(a)
            if not (0 < x < world.width and 0 < y < world.height):
                continue
            r, c = fs.cell_of(np.array([[x, y]]))
            if fs.standable[r[0], c[0]] and fs.clearance[r[0], c[0]] >= PLAN_CLEARANCE + 0.02:
                from holoslam.sim.world import segments_block

                if segments_block(world.wall_segments(), np.array([[x, y]]), np.array([[lx, ly]]))[0]:
                    continue
                return Station(x, y, math.atan2(ly - y, lx - x), 1.5, obj.object_id)
    return None


def plan_stations(world: World, start: tuple[float, float, float] = START_POSE, remembered: tuple = ()
                  ) -> list[Station]:
    """The ordered stations of one tour from ``start``; ``remembered``: the robot's map (``WorldObject``
    records), whose places that no object of ``world`` with the same id stands at get a station too."""
    fs = free_space(world, resolution=0.05)
    centres = {r.name: ((r.xmin + r.xmax) / 2, (r.ymin + r.ymax) / 2) for r in world.rooms}
    centres["living_room"] = (3.2, 5.2)
    centres["balcony"] = (2.6, 1.0)
    centres["dining_room"] = (6.6, 4.6)
    centres["kitchen"] = (7.4, 1.8)
    centres["bedroom_1"] = (2.2, 7.9)
    centres["bedroom_2"] = (4.9, 8.0)
    centres["study"] = (7.0, 7.9)
    spots: dict[str, list[Station]] = {}
    here = {o.object_id: o.position for o in world.objects}
    for o in tuple(world.objects) + tuple(r for r in remembered if here.get(r.object_id) != r.position):
        if o.label_size > STATION_MAX_LABEL:
            continue  # big labels are read in passing; the operator stops for the small ones
        s = _view_spot(world, fs, o)
        if s is not None:
            spots.setdefault(o.room, []).append(s)
    seen: dict[str, int] = {}
    stations: list[Station] = []
    pos = start[:2]
    for room in _TOUR:
        k = seen.get(room, 0)
        seen[room] = k + 1
        todo = list(spots.get(room, [])) if k == 0 else []  # objects are looked at on the first visit
        # nearest-neighbour order from where we are
        while todo:
            j = min(range(len(todo)), key=lambda i: math.dist(pos, (todo[i].x, todo[i].y)))
            s = todo.pop(j)
            stations.append(s)
            pos = (s.x, s.y)
        cx, cy = centres[room]
        stations.append(Station(cx, cy, None, 0.0))
        pos = (cx, cy)
    return stations


def _astar(fs, weights: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
    import pyastar2d

    ra, ca = fs.cell_of(np.array([a]))
    rb, cb = fs.cell_of(np.array([b]))
    path = pyastar2d.astar_path(
        weights, (int(ra[0]), int(ca[0])), (int(rb[0]), int(cb[0])), allow_diagonal=True
    )
    if path is None:
        raise RuntimeError(f"no path from {a} to {b} in the household; the route stations are not connected")
    return fs.xy_of(path[:, 0], path[:, 1])


def _smooth(xy: np.ndarray, sigma_pts: float) -> np.ndarray:
    if len(xy) < 3:
        return xy
    h = int(3 * sigma_pts)
    k = np.exp(-0.5 * (np.arange(-h, h + 1) / sigma_pts) ** 2)
    k /= k.sum()
    pad = np.vstack([np.repeat(xy[:1], h, 0), xy, np.repeat(xy[-1:], h, 0)])
    out = np.column_stack([np.convolve(pad[:, 0], k, "valid"), np.convolve(pad[:, 1], k, "valid")])
    out[0], out[-1] = xy[0], xy[-1]
    return out


def _resample(xy: np.ndarray, step: float) -> np.ndarray:
    d = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    if d[-1] < 1e-9:
        return xy[:1]
    s = np.linspace(0.0, d[-1], max(2, int(math.ceil(d[-1] / step)) + 1))
    return np.column_stack([np.interp(s, d, xy[:, 0]), np.interp(s, d, xy[:, 1])])


def _leg_keyframes(xy: np.ndarray, v_cap: float) -> tuple[np.ndarray, np.ndarray]:
    """Poses along one smooth leg (moving along the tangent) and the time of each, with an acceleration
    limited speed profile that starts and ends at rest."""
    seg = np.diff(xy, axis=0)
    ds = np.hypot(seg[:, 0], seg[:, 1])
    th = np.arctan2(seg[:, 1], seg[:, 0])
    th = np.r_[th, th[-1]]
    dth = np.abs(wrap(np.diff(th)))
    with np.errstate(divide="ignore"):
        v_seg = np.minimum(v_cap, np.where(dth > 1e-12, 0.9 * W_MAX * ds / dth, np.inf))
    u = np.r_[0.0, np.minimum(v_seg[:-1], v_seg[1:]), 0.0]  # speeds at the keyframes
    for j in range(1, len(u)):  # acceleration limit forward ...
        u[j] = min(u[j], math.sqrt(u[j - 1] ** 2 + 2 * A_MAX * ds[j - 1]))
    for j in range(len(u) - 2, -1, -1):  # ... and braking limit backward
        u[j] = min(u[j], math.sqrt(u[j + 1] ** 2 + 2 * A_MAX * ds[j]))
    vm = np.maximum(0.5 * (u[1:] + u[:-1]), 0.02)
    dt = np.maximum(ds / vm, dth / W_MAX)
    T = np.r_[0.0, np.cumsum(dt)]
    # dense samples (10 ms) with constant acceleration inside each segment, so the speed is continuous
    tt = np.r_[np.arange(0.0, T[-1], 0.01), T[-1]]
    piece = np.clip(np.searchsorted(T, tt, side="right") - 1, 0, len(ds) - 1)
    tau = tt - T[piece]
    ua, ub = u[piece], u[piece + 1]
    acc = (ub - ua) / dt[piece]
    full = 0.5 * (ua + ub) * dt[piece]
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(full > 1e-12, (ua * tau + 0.5 * acc * tau**2) / full, tau / dt[piece])
    f = np.clip(f, 0.0, 1.0)
    pos = xy[piece] + f[:, None] * (xy[piece + 1] - xy[piece])
    heading = th[piece] + f * wrap(th[piece + 1] - th[piece])
    return np.column_stack([pos, heading]), tt


def household_trajectory(
    world: World,
    duration_s: float | None,
    rate_hz: float = 20.0,
    seed: int = 2,
    t0_ns: int = 1_700_000_000_000_000_000,
    start: tuple[float, float, float] = START_POSE,
    remembered: tuple = (),
) -> Trajectory:
    """The true trajectory of the tour from ``start`` (x, y, yaw in map), looped or cut to ``duration_s`` (None:
    exactly one tour), sampled at ``rate_hz``; ``remembered``: the robot's map, whose places get stations too
    (``plan_stations``).

    ``seed`` varies the operator's cruising speed per leg (0.3 m/s to ``V_MAX``) and the dwell times."""
    P, T, t_end = _keyframes(world, seed, duration_s, start, remembered)
    if duration_s is None:
        duration_s = t_end
    n = int(math.floor(duration_s * rate_hz)) + 1
    ts = np.arange(n) / rate_hz
    th = np.unwrap(P[:, 2])
    out = np.column_stack(
        [np.interp(ts, T, P[:, 0]), np.interp(ts, T, P[:, 1]), wrap(np.interp(ts, T, th))]
    )
    stamps = t0_ns + np.round(ts * 1e9).astype(np.int64)
    return Trajectory(stamps, out)


def tour_duration_s(world: World, seed: int = 2) -> float:
    """Seconds of robot time of one complete tour (every station once) for ``seed``."""
    return _keyframes(world, seed, None)[2]


def _keyframes(world: World, seed: int, duration_s: float | None,
               start: tuple[float, float, float] = START_POSE, remembered: tuple = ()
               ) -> tuple[np.ndarray, np.ndarray, float]:
    """Keyframe poses and times of the tour until ``duration_s`` (None: one tour) and the end time."""
    one_tour = duration_s is None
    limit = math.inf if duration_s is None else duration_s
    rng = np.random.default_rng(np.random.SeedSequence([seed, 101]))
    fs = free_space(world, resolution=0.05)
    clear = fs.clearance
    weights = np.where(clear >= PLAN_CLEARANCE, 1.0 + 6.0 * np.clip(0.7 - clear, 0, None) / 0.4, np.inf)
    weights = np.ascontiguousarray(weights, dtype=np.float32)
    stations = plan_stations(world, start, remembered)
    poses: list[np.ndarray] = [np.array([start], dtype=np.float64)]
    times: list[np.ndarray] = [np.array([0.0])]
    t = 0.0
    cur = np.array(start, dtype=np.float64)

    def add(p: np.ndarray, tt: np.ndarray) -> None:
        poses.append(p)
        times.append(tt)

    def turn_to(yaw: float) -> None:
        nonlocal t, cur
        d = float(wrap(yaw - cur[2]))
        if abs(d) < 1e-6:
            return
        n = max(2, int(abs(d) / math.radians(2)))
        # smooth (cosine) turn profile with peak rate <= W_MAX
        dur = abs(d) / W_MAX * math.pi / 2
        u = np.linspace(0, 1, n + 1)[1:]
        frac = 0.5 - 0.5 * np.cos(np.pi * u)
        p = np.column_stack([np.full(n, cur[0]), np.full(n, cur[1]), cur[2] + d * frac])
        add(p, t + dur * u)
        t += dur
        cur = np.array([cur[0], cur[1], cur[2] + d])

    def dwell(sec: float) -> None:
        nonlocal t
        if sec > 0:
            add(cur[None, :].copy(), np.array([t + sec]))
            t += sec

    while t < limit:
        for st in stations:
            if t >= limit:
                break
            raw = _astar(fs, weights, (cur[0], cur[1]), (st.x, st.y))
            raw = (
                np.vstack([cur[None, :2], raw[1:-1], [[st.x, st.y]]])
                if len(raw) > 2
                else np.array([cur[:2], [st.x, st.y]])
            )
            xy = _smooth(_resample(raw, 0.05), 4.0)
            xy = _resample(xy, 0.05)
            if len(xy) >= 2 and np.hypot(*(xy[-1] - xy[0])) > 0.02:
                # turn on the spot towards the first direction of travel, then drive
                first = xy[1] - xy[0]
                turn_to(math.atan2(first[1], first[0]))
                kp, kt = _leg_keyframes(xy, float(rng.uniform(0.3, V_MAX)))
                kp[0, 2] = cur[2]
                kp[:, 2] = cur[2] + np.cumsum(np.r_[0.0, wrap(np.diff(kp[:, 2]))])
                add(kp[1:], t + kt[1:])
                t += kt[-1]
                cur = kp[-1].copy()
            if st.yaw is not None:
                turn_to(st.yaw)
                dwell(st.dwell_s + float(rng.uniform(0.0, 0.5)))
            else:
                dwell(float(rng.uniform(0.0, 0.5)))
        if one_tour:
            break
    P = np.vstack(poses)
    T = np.concatenate(times)
    keep = np.r_[True, np.diff(T) > 1e-9]
    return P[keep], T[keep], t
