"""Occupancy grid from synthetic scans of a known rectangular room; the compiled traversal against an exact
pure-Python reference."""

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from holoslam.errors import MapError
from holoslam.maps._raycast_fast import cast_counts
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


# --- the traversal against a pure-Python reference ------------------------------------------------------------


def reference_cells(o, e):
    """The cells (col, row) of the segment o -> e (cell units), in order: {floor(o + t (e - o)) : 0 <= t <= 1}
    in exact rational arithmetic, evaluated at every grid-line crossing and between consecutive ones."""
    o = [Fraction(float(v)) for v in o]
    e = [Fraction(float(v)) for v in e]
    d = [e[0] - o[0], e[1] - o[1]]
    ts = {Fraction(0), Fraction(1)}
    for k in range(2):
        if d[k] != 0:
            lo, hi = sorted((o[k], e[k]))
            ts.update((n - o[k]) / d[k] for n in range(math.ceil(lo), math.floor(hi) + 1))
    ts = sorted(t for t in ts if 0 <= t <= 1)
    probes = [ts[0]]
    for a, b in itertools.pairwise(ts):
        probes += [(a + b) / 2, b]
    cells = []
    for t in probes:
        cell = (math.floor(o[0] + t * d[0]), math.floor(o[1] + t * d[1]))
        if not cells or cells[-1] != cell:
            cells.append(cell)
    assert len(cells) == len(set(cells)), "a straight segment visits a (convex) cell once"
    return cells


def reference_counts(o, e, hit, h, w):
    hits = np.zeros((h, w), np.int64)
    misses = np.zeros((h, w), np.int64)
    for ob, eb, hb in zip(o, e, hit, strict=True):
        cells = reference_cells(ob, eb)
        end = cells[-1]
        for c, r in cells[:-1]:  # every cell before the end cell
            if 0 <= c < w and 0 <= r < h:
                misses[r, c] += 1
        if hb and 0 <= end[0] < w and 0 <= end[1] < h:
            hits[end[1], end[0]] += 1
    return hits, misses


def kernel_counts(o, e, hit, h, w):
    o, e = np.asarray(o, np.float64).reshape(-1, 2), np.asarray(e, np.float64).reshape(-1, 2)
    hits, misses = cast_counts(o[:, 0].copy(), o[:, 1].copy(), e[:, 0].copy(), e[:, 1].copy(),
                               np.asarray(hit, bool), h, w)
    return hits.reshape(h, w), misses.reshape(h, w)


def test_reference_corner_rule():
    """Half-open cells: through a corner up-right / down-left is diagonal; up-left / down-right passes the
    cell that owns the corner (upper row, right column); a beam on a grid line is in the cells above it."""
    assert reference_cells((0.5, 0.5), (1.5, 1.5)) == [(0, 0), (1, 1)]
    assert reference_cells((1.5, 1.5), (0.5, 0.5)) == [(1, 1), (0, 0)]
    assert reference_cells((1.5, 0.5), (0.5, 1.5)) == [(1, 0), (1, 1), (0, 1)]
    assert reference_cells((0.5, 1.5), (1.5, 0.5)) == [(0, 1), (1, 1), (1, 0)]
    assert reference_cells((0.0, 1.0), (3.0, 1.0)) == [(0, 1), (1, 1), (2, 1), (3, 1)]
    assert reference_cells((0.25, 0.25), (0.75, 0.5)) == [(0, 0)]


# quarter-cell coordinates: beams through corners, along borders, ending on borders, of zero length; the grid is
# 7 x 6 cells and coordinates reach 3 cells outside it (beams leave and re-enter, start or end outside)
quarter = st.integers(-12, 36).map(lambda k: k / 4)
far = st.floats(-60, 60, allow_nan=False).map(lambda v: round(v * 8) / 8)  # clipped to the grown grid
# "generic" positions on a 2^-16 cell lattice: differences and the kernel's cross products stay exact in float64
# (arbitrary floats can round a difference so that a beam passing 1e-250 cells from a corner hits it)
generic = st.integers(-3 * 2**16, 9 * 2**16).map(lambda k: k / 2**16)
coord = st.one_of(quarter, quarter, far, generic)
beam = st.tuples(coord, coord, coord, coord, st.booleans())


@settings(max_examples=300, deadline=None)
@given(st.lists(beam, min_size=1, max_size=12))
@example([(0.5, 0.5, 2.0, 2.0, True), (2.0, 2.0, 0.25, 3.75, True), (3.0, 0.0, 3.0, 5.0, False)])
@example([(1.0, 1.0, 1.0, 1.0, True), (6.75, 5.75, 7.0, 6.0, True), (-2.0, 3.0, 10.0, 3.0, False)])
@example([(-40.0, -37.0, 50.0, 53.0, True), (45.0, 1.5, -30.0, 1.5, False), (3.5, -50.0, 3.5, 50.0, True)])
@example([(-50.0, 47.0, 50.0, -53.0, False), (-1.0, 2.0, 2.0, -1.0, True), (2.0, 0.0, 0.0, 2.0, True)])
def test_kernel_matches_reference(beams):
    h, w = 6, 7
    b = np.array(beams, dtype=np.float64)
    o, e, hit = b[:, :2], b[:, 2:4], b[:, 4].astype(bool)
    kh, km = kernel_counts(o, e, hit, h, w)
    rh, rm = reference_counts(o, e, hit, h, w)
    np.testing.assert_array_equal(kh, rh)
    np.testing.assert_array_equal(km, rm)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(*[st.integers(-2 * 2**20, 14 * 2**20).map(lambda k: k / 2**20)] * 4),
                min_size=1, max_size=20))
def test_kernel_matches_reference_on_generic_beams(beams):
    h, w = 11, 12
    b = np.array(beams, dtype=np.float64)
    hit = np.arange(len(b)) % 2 == 0
    kh, km = kernel_counts(b[:, :2], b[:, 2:], hit, h, w)
    rh, rm = reference_counts(b[:, :2], b[:, 2:], hit, h, w)
    np.testing.assert_array_equal(kh, rh)
    np.testing.assert_array_equal(km, rm)


def test_build_grid_counts_cells_of_the_exact_traversal():
    """build_grid in world coordinates (dyadic resolution, so exact): a beam along the border y = 1 m marks
    the cells above it, a beam along x = 1 m the cells right of it, a zero-length return its own cell."""
    def one_beam(angle, r):
        return Scan(0, "laser", angle, 1.0, 0.0, 10.0, np.array([r], np.float32), np.ones(1, bool))

    poses = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, np.pi / 2], [1.375, 1.375, 0.0]])
    scans = [one_beam(0.0, 1.0), one_beam(0.0, 0.75), one_beam(0.3, 0.0)]
    g = build_grid(poses, scans, 0.25, bounds=(0.0, 0.0, 1.5, 1.5), p_miss=0.1)
    assert g.shape == (6, 6) and g.origin_x == 0.0 and g.origin_y == 0.0
    want = np.full((6, 6), "u")
    want[4, 0:4] = "f"  # y = 1.0: row 4, up to its end cell (4, 4)
    want[4, 4] = "o"
    want[0:3, 4] = "f"  # x = 1.0: column 4, up to its end cell (3, 4)
    want[3, 4] = "o"
    want[5, 5] = "o"  # zero-length beam: a hit, no miss
    got = np.where(g.occupied, "o", np.where(g.free, "f", "u"))
    np.testing.assert_array_equal(got, want)


def test_household_like_grid_matches_reference_counts():
    """build_grid's log-odds equal those recomputed from the reference traversal, cell for cell, on the room
    scans (361 beams x 2 poses, world coordinates as build_grid converts them)."""
    poses = np.array([[1.0, 1.0, 0.3], [3.0, 2.0, -1.0]])
    scans = [scan_at(p, n=361) for p in poses]
    res, bounds = 0.1, (-0.3, -0.3, 4.3, 3.3)
    g = build_grid(poses, scans, res, bounds=bounds, p_hit=0.7, p_miss=0.3)
    o, e, hit = beam_endpoints(poses, scans)
    lo = np.floor(np.array(bounds[:2]) / res + 1e-6) * res
    h, w = g.shape
    rh, rm = reference_counts((o - lo) / res, (e - lo) / res, hit, h, w)
    L = np.clip(rh * np.log(0.7 / 0.3) + rm * np.log(0.3 / 0.7), -6.0, 6.0)
    want = np.where(rh + rm > 0, np.rint(100.0 / (1.0 + np.exp(-L))), -1)
    np.testing.assert_array_equal(g.occupancy, want)


def test_infinite_range_max_without_clearing_distance_is_reported():
    s = Scan(0, "laser", 0.0, 0.1, 0.05, np.inf, np.array([np.inf, 1.0], np.float32), np.array([False, True]))
    with pytest.raises(MapError, match="no_return_clear_m"):
        build_grid(np.zeros((1, 3)), [s])
    g = build_grid(np.zeros((1, 3)), [s], no_return_clear_m=1.0)
    assert g.occupied.sum() == 1


def test_casting_in_chunks_gives_the_same_grid_and_names_the_scan_at_fault(monkeypatch):
    """A long dense log is cast in chunks of whole scans (memory: one chunk's beams, not the log's); the counts
    are sums, so chunks of 361 beams (one scan each) and of 500 (two scans at a time, the last alone) give the
    grid cast in one piece, bounds included; a bad scan in a later chunk is named by its index in the log."""
    from holoslam.maps import occupancy

    poses = np.array([[1.0, 1.0, 0.3], [3.0, 2.0, -1.0], [2.0, 1.5, 2.0]])
    scans = [scan_at(p, n=361) for p in poses]
    whole = build_grid(poses, scans, 0.1)
    for size in (361, 500):
        monkeypatch.setattr(occupancy, "CHUNK_BEAMS", size)
        assert len(occupancy._chunks(scans)) == (3 if size == 361 else 2)
        g = build_grid(poses, scans, 0.1)
        assert (g.origin_x, g.origin_y, g.shape) == (whole.origin_x, whole.origin_y, whole.shape)
        np.testing.assert_array_equal(g.occupancy, whole.occupancy)
    bad = Scan(0, "laser", 0.0, 0.1, 0.05, np.inf, np.array([np.inf, 1.0], np.float32), np.array([False, True]))
    with pytest.raises(MapError, match=r"scans \[3\] have beams without a return"):
        build_grid(np.vstack([poses, np.zeros((1, 3))]), [*scans, bad])


def test_occupancy_in_blocks_of_cells_equals_the_whole(monkeypatch):
    """Issue 26: counts become occupancy in blocks of ``CHUNK_CELLS`` cells (a building's grid would otherwise
    hold several full-size float64 arrays at once); blocks of 7 cells, which split rows, give the same grid."""
    from holoslam.maps import occupancy

    poses = np.array([[1.0, 1.0, 0.3], [3.0, 2.0, -1.0]])
    scans = [scan_at(p, n=361) for p in poses]
    whole = build_grid(poses, scans, 0.1)
    assert whole.occupancy.size > 7 and {-1, 0}.issubset(set(np.unique(whole.occupancy).tolist()))
    monkeypatch.setattr(occupancy, "CHUNK_CELLS", 7)
    np.testing.assert_array_equal(build_grid(poses, scans, 0.1).occupancy, whole.occupancy)


def test_counts_added_into_int32_arrays_equal_the_int64_counts():
    from holoslam.maps._raycast_fast import cast_counts_into

    rng = np.random.default_rng(3)
    o, e = rng.uniform(-2, 9, (200, 2)), rng.uniform(-2, 9, (200, 2))
    hit = rng.random(200) < 0.7
    h64, m64 = cast_counts(o[:, 0].copy(), o[:, 1].copy(), e[:, 0].copy(), e[:, 1].copy(), hit, 6, 7)
    h32, m32 = np.ones(42, np.int32), np.ones(42, np.int32)  # added into: start from 1
    cast_counts_into(o[:, 0].copy(), o[:, 1].copy(), e[:, 0].copy(), e[:, 1].copy(), hit, 6, 7, h32, m32)
    np.testing.assert_array_equal(h32, h64 + 1)
    np.testing.assert_array_equal(m32, m64 + 1)
    assert m64.sum() > 500 and h64.sum() > 30  # beams in and out of the grid, hits among them
