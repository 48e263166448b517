"""The teleoperated-looking route: collision-free, within Pioneer limits, every room, every doorway twice,
loops."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoslam.sim import SimConfig
from holoslam.sim.route import A_MAX, V_MAX, W_MAX, household_trajectory, plan_stations
from holoslam.sim.world import ROBOT_RADIUS, free_space, reference_household, segments_block


@pytest.fixture(scope="module")
def world():
    return reference_household()


@pytest.fixture(scope="module")
def traj(world):
    return household_trajectory(world, SimConfig().duration_s, 20.0, seed=2)


def test_stamped_at_the_odometry_rate(traj):
    dt = np.diff(traj.stamps_ns)
    assert np.all(dt == 50_000_000)
    assert len(traj.stamps_ns) == int(SimConfig().duration_s * 20) + 1
    assert np.all((traj.wTb[:, 2] >= -math.pi) & (traj.wTb[:, 2] < math.pi))


def test_collision_free_against_walls_and_furniture(world, traj):
    fs = free_space(world, resolution=0.01)
    clearance = fs.clearance_at(traj.wTb[:, :2])
    assert clearance.min() >= ROBOT_RADIUS + 0.02
    # no step jumps through a wall or a piece of furniture
    segs = world.obstacle_segments()
    assert not segments_block(segs, traj.wTb[:-1, :2], traj.wTb[1:, :2]).any()


def test_pioneer_like_speeds(traj):
    dt = 0.05
    d = np.diff(traj.wTb, axis=0)
    v = np.hypot(d[:, 0], d[:, 1]) / dt
    w = np.abs((d[:, 2] + math.pi) % (2 * math.pi) - math.pi) / dt
    assert v.max() <= V_MAX + 1e-6 and V_MAX <= 0.4
    assert w.max() <= W_MAX + 1e-6 and W_MAX <= math.radians(40)
    a = np.abs(np.diff(v)) / dt
    assert np.percentile(a, 99.5) <= A_MAX * 1.5
    # a differential drive base: motion along the heading (no sideways slip)
    heading = np.column_stack([np.cos(traj.wTb[:-1, 2]), np.sin(traj.wTb[:-1, 2])])
    lateral = np.abs(heading[:, 0] * d[:, 1] - heading[:, 1] * d[:, 0])
    assert lateral.max() < 0.004  # m per 50 ms step (turning while moving along a smoothed curve)


def test_visits_every_room_and_passes_every_doorway_more_than_once(world, traj):
    rooms = set(world.room_of(traj.wTb[:, :2]))
    assert rooms == {r.name for r in world.rooms}
    for d in world.doorways:
        door = np.array([[*d.p0, *d.p1]])
        crossings = int(np.count_nonzero(segments_block(door, traj.wTb[:-1, :2], traj.wTb[1:, :2])))
        assert crossings >= 2, (d.name, crossings)


def test_revisits_make_loops(traj):
    xy = traj.wTb[::20, :2]  # 1 Hz
    path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    far_along = (path[None, :] - path[:, None]) > 15.0
    loops = np.argwhere((d < 0.5) & far_along)
    # several distinct loop closures (places come back after more than 15 m of travel)
    assert len(np.unique(loops[:, 0] // 30)) >= 3


def test_stops_and_turns_in_front_of_small_labels(world, traj):
    stations = [s for s in plan_stations(world) if s.object_id]
    assert stations, "the operator stops in front of objects"
    for s in stations[:8]:
        o = world.object(s.object_id)
        i = np.argmin(np.hypot(traj.wTb[:, 0] - s.x, traj.wTb[:, 1] - s.y))
        # stopped there facing the label
        assert math.hypot(traj.wTb[i, 0] - s.x, traj.wTb[i, 1] - s.y) < 0.05
        yaw = math.atan2(o.position[1] - s.y, o.position[0] - s.x)
        near = np.hypot(traj.wTb[:, 0] - s.x, traj.wTb[:, 1] - s.y) < 0.05
        dy = np.abs((traj.wTb[near, 2] - yaw + math.pi) % (2 * math.pi) - math.pi)
        assert dy.min() < math.radians(2)
        assert np.count_nonzero(dy < math.radians(2)) >= 20  # >= 1 s dwell


def test_deterministic_for_a_seed(world):
    a = household_trajectory(world, 60.0, seed=5)
    b = household_trajectory(world, 60.0, seed=5)
    c = household_trajectory(world, 60.0, seed=6)
    assert np.array_equal(a.wTb, b.wTb)
    assert not np.array_equal(a.wTb, c.wTb)
