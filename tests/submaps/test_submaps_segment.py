"""Segmentation policy, doorway width, voxel decimation and the local occupancy grid of a submap."""

from __future__ import annotations

import math

import numpy as np

from holoslam.sim.world import raycast
from holoslam.submaps.segment import (
    SegmentConfig,
    local_grid,
    side_width,
    split_reason,
    voxel_append,
    voxel_downsample,
)

ROOM = np.array([[0, 0, 4, 0], [4, 0, 4, 3], [4, 3, 0, 3], [0, 3, 0, 0]], float)


def test_policy_rules():
    cfg = SegmentConfig(max_distance=3.0, max_turn_deg=150, max_time_s=60, min_distance=0.5)
    assert split_reason(cfg, 3.1, np.zeros(3), 0, False, 5.0) == "distance"
    assert split_reason(cfg, 1.0, np.array([0, 0, math.radians(160)]), 0, False, 5.0) == "turn"
    assert split_reason(cfg, 1.0, np.zeros(3), 61 * 10**9, False, 5.0) == "time"
    assert split_reason(cfg, 0.2, np.zeros(3), 61 * 10**9, False, 5.0) is None  # standing still: no split
    assert split_reason(cfg, 1.0, np.zeros(3), 10**9, True, 0.9) is None  # still inside the doorway
    assert split_reason(cfg, 1.0, np.zeros(3), 10**9, True, 2.0) == "doorway"
    assert split_reason(cfg, 1.0, np.zeros(3), 10**9, False, 2.0) is None


def test_side_width_in_a_doorway_and_a_room():
    door = np.array([[2, 0, 2, 1.0], [2, 1.9, 2, 3]], float)  # jambs of a 0.9 m door at x = 2
    ang = np.radians(np.arange(-90, 91, 1.0))
    # a forward 180 deg laser sees the jambs while approaching; once past them they are behind the scan
    for x, expect_narrow in ((1.6, True), (1.95, True), (2.1, False), (1.0, False), (3.2, False)):
        wTb = np.array([x, 1.45, 0.0])
        r = raycast(np.vstack([ROOM, door]), wTb[None, :2], ang[None], 8.0)[0]
        ok = np.isfinite(r)
        pts = np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])
        w = side_width(pts)
        assert (w < SegmentConfig().doorway_width) == expect_narrow, (x, w)
    assert side_width(np.zeros((0, 2))) == math.inf


def test_voxel_downsample_keeps_one_per_cell():
    p = np.array([[0.001, 0.001], [0.01, 0.02], [0.05, 0.0], [0.051, 0.001]])
    q, n = voxel_downsample(p, np.arange(8.0).reshape(4, 2), 0.03)
    np.testing.assert_array_equal(q, p[[0, 2]])
    np.testing.assert_array_equal(n, [[0, 1], [4, 5]])



def test_voxel_append_equals_downsampling_everything_again():
    # the front end adds each keyframe's points to its submap: appending must give what re-decimating the
    # stacked points gave (old points kept, a new one only in a new voxel and only the first there)
    rng = np.random.default_rng(3)
    for trial in range(40):
        offset = 1e8 if trial == 39 else 0.0  # voxel indices beyond 31 bits: the general path
        P, N, C = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64)
        ref_p, ref_n = P, N
        for _ in range(5):
            p = rng.normal(size=(int(rng.integers(0, 200)), 2)) * rng.uniform(0.05, 2.0) + offset
            if trial % 4 == 0:
                p = np.round(p, 1)  # many points on shared voxel corners and in one voxel
            n = rng.normal(size=p.shape)
            P, N, C = voxel_append(P, N, C, p, n, 0.03)
            ref_p, ref_n = voxel_downsample(np.vstack([ref_p, p]), np.vstack([ref_n, n]), 0.03)
            np.testing.assert_array_equal(P, ref_p)
            np.testing.assert_array_equal(N, ref_n)
    assert C.size == 0 or offset  # far from the origin no codes are kept


def test_local_grid_counts_the_samples_of_each_beam_exactly():
    # ranges on and next to multiples of the half-cell sample step: free samples stop a cell short of the hit
    res = 0.05
    r = np.array([0.05, 0.075, 0.1, 0.1 + 1e-12, 0.1 - 1e-12, 0.2, 0.325, 0.5, 1.0, 1.234, np.inf], float)
    a = np.linspace(-1.0, 1.0, r.size)
    aTs = np.array([[0.3, -0.2, 0.4], [1.0, 0.5, -2.0]])
    grid = local_grid(aTs, [r, r[::-1]], [a, a], res, clear_range=1.5)
    free, occ = np.zeros_like(grid.occupancy, dtype=int), np.zeros_like(grid.occupancy, dtype=int)
    for T, rr in zip(aTs, (r, r[::-1]), strict=True):
        for rng_, ang in zip(rr, a, strict=True):
            reach = rng_ if np.isfinite(rng_) else 1.5
            c, s = np.cos(T[2] + ang), np.sin(T[2] + ang)
            k = 0
            while k * 0.5 * res < reach - res and k < np.ceil(reach / (0.5 * res)):
                d = k * (0.5 * res)
                x, y = T[0] + d * c, T[1] + d * s
                free[int(np.floor((y - grid.origin_y) / res)), int(np.floor((x - grid.origin_x) / res))] += 1
                k += 1
            if np.isfinite(rng_):
                x, y = T[0] + rng_ * c, T[1] + rng_ * s
                occ[int(np.floor((y - grid.origin_y) / res)), int(np.floor((x - grid.origin_x) / res))] += 1
    prob = 1.0 / (1.0 + np.exp(-(0.85 * occ - 0.4 * free)))
    expect = np.where(free + occ > 0, np.round(prob * 100.0), -1).astype(np.int8)
    np.testing.assert_array_equal(grid.occupancy, expect)


def test_local_grid_of_a_known_room():
    ang = np.radians(np.arange(-180, 180, 1.0))
    aTs = np.array([[1.0, 1.0, 0.0], [3.0, 2.0, 1.0]])
    ranges = [raycast(ROOM, T[None, :2], (ang + T[2])[None], 8.0)[0] for T in aTs]
    grid = local_grid(aTs, ranges, [ang, ang], resolution=0.05)
    # walls occupied, the interior free, outside unknown
    wall = np.array([[2.0, 0.0], [4.0, 1.5], [2.0, 3.0], [0.0, 1.5]])
    rc = grid.world_to_cell(wall)
    occ = grid.occupied
    near = np.array([occ[r - 1:r + 2, c - 1:c + 2].any() for r, c in rc])  # a wall on a cell border
    assert near.all()
    assert occ.sum() * 0.05 < 2 * (2 * 4 + 2 * 3) / 0.05 * 0.05  # thin walls, not blobs
    inner = np.array([[2.0, 1.5], [0.5, 0.5], [3.5, 2.5]])
    rc = grid.world_to_cell(inner)
    assert grid.free[rc[:, 0], rc[:, 1]].all()
    rc = grid.world_to_cell(np.array([[-0.3, -0.3]]))
    assert grid.unknown[rc[:, 0], rc[:, 1]].all()
    xs = np.arange(0.2, 3.8, 0.05)
    rc = grid.world_to_cell(np.column_stack([xs, np.full(xs.size, 1.5)]))
    assert grid.free[rc[:, 0], rc[:, 1]].mean() > 0.95
