"""Occupancy grid from synthetic scans of a known rectangular room."""

import numpy as np
import pytest

from holoslam.errors import MapError
from holoslam.maps.occupancy import beam_endpoints, build_grid
from holoslam.types import Scan

ROOM = (0.0, 0.0, 4.0, 3.0)  # walls at x = 0, x = 4, y = 0, y = 3


def ray_to_room(x, y, th):
    """Distance from (x, y) along direction th to the room's walls."""
    c, s = np.cos(th), np.sin(th)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (ROOM[2] - x) / c, np.where(c < 0, (ROOM[0] - x) / c, np.inf))
        ty = np.where(s > 0, (ROOM[3] - y) / s, np.where(s < 0, (ROOM[1] - y) / s, np.inf))
    return np.minimum(tx, ty)


def scan_at(pose, n=361, range_max=8.0, drop=None):
    angles = -np.pi + np.arange(n) * (2 * np.pi / n)
    r = ray_to_room(pose[0], pose[1], pose[2] + angles)
    r = np.where(r < range_max, r, np.inf).astype(np.float32)
    if drop is not None:
        r[drop] = np.inf
    return Scan(0, "laser", -np.pi, 2 * np.pi / n, 0.05, range_max, r, np.isfinite(r))


def test_room_walls_occupied_interior_free():
    poses = np.array([[1.0, 1.0, 0.3], [3.0, 2.0, -1.0], [2.0, 1.5, 2.0], [1.2, 2.4, 0.0]])
    grid = build_grid(poses, [scan_at(p) for p in poses], resolution=0.05, margin_m=0.3)
    # interior (away from the walls) is free, wall cells are occupied, the outside is unknown
    inner = grid.world_to_cell(
        np.array([[x, y] for x in np.arange(0.3, 3.7, 0.1) for y in np.arange(0.3, 2.7, 0.1)])
    )
    assert grid.free[inner[:, 0], inner[:, 1]].mean() > 0.99
    wall = np.array(
        [[x, 0.0] for x in np.arange(0.2, 3.8, 0.05)] + [[4.0, y] for y in np.arange(0.2, 2.8, 0.05)]
    )
    # a point exactly on a wall line may fall in either neighbouring cell: check both sides
    rc_in = grid.world_to_cell(wall + np.array([[0, 0.01]] * 72 + [[-0.01, 0]] * 52))
    rc_out = grid.world_to_cell(wall - np.array([[0, 0.01]] * 72 + [[-0.01, 0]] * 52))
    occ = grid.occupied[rc_in[:, 0], rc_in[:, 1]] | grid.occupied[rc_out[:, 0], rc_out[:, 1]]
    assert occ.mean() > 0.97
    outside = grid.world_to_cell(np.array([[-0.2, 1.5], [4.2, 1.5], [2.0, 3.2]]))
    assert grid.unknown[outside[:, 0], outside[:, 1]].all()
    # nothing occupied away from the walls
    occ_xy = grid.cell_to_world(np.argwhere(grid.occupied))
    d = np.minimum.reduce([occ_xy[:, 0], 4.0 - occ_xy[:, 0], occ_xy[:, 1], 3.0 - occ_xy[:, 1]])
    assert np.abs(d).max() < 0.08


def test_bounds_and_alignment():
    poses = np.array([[1.0, 1.0, 0.0]])
    grid = build_grid(poses, [scan_at(poses[0])], resolution=0.1, margin_m=0.5)
    assert grid.origin_x == pytest.approx(-0.5) and grid.origin_y == pytest.approx(-0.5)
    h, w = grid.shape
    assert w * 0.1 >= 5.0 - 1e-9 and h * 0.1 >= 4.0 - 1e-9
    local = build_grid(poses, [scan_at(poses[0])], resolution=0.1, bounds=(0.0, 0.0, 2.0, 2.0))
    assert local.shape == (20, 20) and local.origin_x == 0.0


def test_no_return_beams_clear_but_do_not_mark():
    pose = np.array([[2.0, 1.5, 0.0]])
    # beam pointing along +x with the room much bigger: use a room-free scan with every beam without return
    n = 90
    r = np.full(n, np.inf, dtype=np.float32)
    scan = Scan(0, "laser", -0.2, 0.4 / n, 0.05, 5.0, r, np.zeros(n, bool))
    g = build_grid(pose, [scan], resolution=0.1, no_return_clear_m=2.0)
    assert not g.occupied.any()
    ahead = g.world_to_cell(np.array([[3.5, 1.5]]))[0]
    beyond = g.world_to_cell(np.array([[4.3, 1.5]]))
    assert g.free[ahead[0], ahead[1]]
    assert not g.contains(beyond)[0] or g.unknown[beyond[0, 0], beyond[0, 1]]
    g0 = build_grid(pose, [scan], resolution=0.1, no_return_clear_m=0.0, bounds=(0, 0, 5, 3))
    assert g0.unknown.all()


def test_nan_and_short_beams_are_ignored():
    pose = np.array([[2.0, 1.5, 0.0]])
    s = scan_at(pose[0])
    r = s.ranges.copy()
    r[:100] = np.nan
    r[100:110] = 0.01  # below range_min
    s2 = Scan(0, "laser", s.angle_min, s.angle_increment, 0.05, 8.0, r, np.isfinite(r))
    o, e, hit = beam_endpoints(pose, [s2])
    assert o.shape[0] == len(r) - 110 and hit.all()


def test_bad_input_is_reported():
    s = scan_at((1.0, 1.0, 0.0))
    with pytest.raises(MapError, match="one pose per scan"):
        build_grid(np.zeros((2, 3)), [s])
    with pytest.raises(MapError, match="not finite"):
        build_grid(np.array([[np.nan, 0, 0]]), [s])
    with pytest.raises(MapError, match="resolution"):
        build_grid(np.zeros((1, 3)), [s], resolution=-1)
    with pytest.raises(MapError, match="no scans"):
        build_grid(np.zeros((0, 3)), [])
