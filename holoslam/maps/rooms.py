"""Rooms of a floor plan: a label image of the rooms and the doorways between them (the room and doorway nodes
of the holographic graph, :mod:`holoslam.maps.holographic`).

The method cuts the free space at its constrictions and merges the pieces by rules; every threshold is a
setting of :class:`RoomRules` in metres or m^2, set by how buildings are built, not by a map it was tried on:

1. **Candidates** along the skeleton of the free space (the topology's edge paths), where its width (twice
   the clearance: the distance transform) is smallest within ``window_m``:

   - *doors*: width in [``door_width_min_m``, ``door_width_max_m``]: the clear width of a door leaf, from the
     narrowest interior door (0.6 m) to the widest single leaf (1.2 m, an accessible door), plus a grid cell
     of map noise;
   - *wide openings*: width up to ``opening_width_max_m`` (3 m: a double door, an arch, an open office front
     or a bay as wide as its mouth). A plateau of the width (a bay) is cut at its end where the space widens
     (the bay's mouth), not in its middle.

   Each is cut by the line from its nearest obstacle cell to the nearest one on the other side.
2. **Only openings in walls**: a cut that ends on a piece of free-standing furniture is dropped: an obstacle
   island (not joined to the building's walls) of at most ``furniture_area_max_m2`` that is not wall-like
   (wall-like: at most ``wall_thickness_max_m`` thick and at least ``wall_length_min_m`` long, a partition
   between two doors). A wide opening is kept only if it is a constriction: on one of its sides the space is at
   least ``opening_widening`` times as wide along the opening's line (a cabinet narrowing a room is not). Two
   cuts closer than the sum of their half widths describe one opening. Of two such whose lines end on the same
   jamb (within ``wall_thickness_max_m`` of each other, a wall's thickness), the one at least
   ``room_to_door_clearance`` times as wide as the other whose far end runs head-on into a wall (the wall's
   face goes on to both sides of it, at least a wall's thickness each way in twice that) is not the opening:
   it runs from the door's jamb into the space behind the door (to the corridor's far wall, a room's side
   wall), which step 4 c would drop as a narrowing and so lose the door; it gives way (a line ending on the
   end of another wall, a jamb, or at a corner is an opening of its own and does not). Of the rest, the one whose line
   continues into wall beyond both ends (a door set in a wall rather than a line from a jamb to a table in
   front of it) is kept, then the narrowest.
3. **Regions**: the space where a disc of half the narrowest door fits (gaps narrower than any door join
   nothing), with the cuts drawn in, 4-connected.
4. **Merging**, one rule per round, in this order (:func:`merge_round`). A region's *largest clearance* is
   measured between walls: the free-standing furniture of step 2 counts as floor (a table, a desk or a bed in a
   room does not make the room narrower, so a furnished room is no more a fragment or a narrowing than an
   empty one); the cuts' own clearance is the free space's.

   a. a cut with the same region (or none) on both sides separates nothing;
   b. a *fragment* (less than ``min_room_area_m2``, the smallest room, a WC compartment of about 0.9 x 1.4 m,
      or no point ``min_room_clearance_m`` from obstacles: no room is narrower than 0.9 m everywhere) joins a
      neighbour, smallest first, through the cut that opens most widely relative to that neighbour's largest
      clearance (pieces of a cluttered room join each other, not the room behind a doorway);
   c. a cut between regions whose largest clearance is below ``room_to_door_clearance`` x the cut's
      clearance is a narrowing inside one room, not a doorway: the weakest goes.

   The cuts left are the doorways. Two doors between the same two rooms both stay.
5. **Rooms**: every region of at least ``min_room_area_m2`` is a room, numbered 1, 2, ... in the raster order of
   the map; the label image then gives every free cell joined to a room through free space the room nearest
   to it along free cells (4-connected, the larger id among equally near ones): cut lines, cells along walls
   outside the robot-sized space, fragments too small to be rooms. 0 = not a room (obstacles, unknown, free
   space that reaches no room).

Measured on the room-segmentation benchmark of Bormann et al. (ICRA 2016): ``benchmarks/bench_rooms.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoslam.errors import MapError

__all__ = ["RoomRules", "Doorway", "RoomSegmentation", "segment_rooms", "rooms_of_grid", "merge_round"]

DOOR, OPENING = "door", "opening"


@dataclass(frozen=True, slots=True)
class RoomRules:
    """The settings of room segmentation (module docstring), in metres and m^2."""

    door_width_min_m: float = 0.6  # m: narrowest interior door leaf; gaps narrower than this join no rooms
    door_width_max_m: float = (
        1.3  # m: widest single door leaf (1.2 m, accessible door) plus a cell of map noise
    )
    opening_width_max_m: float = 3.0  # m: widest opening between rooms (double door, arch, open office front)
    window_m: float = (
        0.6  # m: a doorway is the narrowest point within this length of skeleton (> wall thickness)
    )
    min_room_area_m2: float = (
        1.2  # m^2: smallest room (a WC compartment, about 0.9 x 1.4 m); less is a fragment
    )
    min_room_clearance_m: float = 0.45  # m: every room is at least 0.9 m wide somewhere (a WC compartment)
    opening_widening: float = 1.5  # ratio: beside a wide opening the space is this much wider along its line
    room_to_door_clearance: float = (
        1.2  # ratio: a room is 20 % wider than its doorway somewhere (0.9 m door, 1.1 m corridor)
    )
    wall_thickness_max_m: float = (
        0.4  # m: interior walls are 0.1-0.3 m (drawn up to 0.4 m); thicker islands are furniture
    )
    wall_length_min_m: float = 1.0  # m: a free-standing wall piece (between two doors) is at least this long
    furniture_area_max_m2: float = (
        2.5  # m^2: largest free-standing furniture (kitchen island, sofa); larger islands are building
    )

    def __post_init__(self) -> None:
        for name in self.__slots__:
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise MapError(f"room rules: {name} must be a non-negative number, got {v}")
        if not self.door_width_min_m <= self.door_width_max_m <= self.opening_width_max_m:
            raise MapError(
                "room rules: need door_width_min_m <= door_width_max_m <= opening_width_max_m, got "
                f"{self.door_width_min_m}, {self.door_width_max_m}, {self.opening_width_max_m}"
            )


@dataclass(frozen=True, slots=True)
class Doorway:
    """A cut left after merging: its skeleton ``cell`` (row, col), ``direction`` along the passage (row, col),
    free ``width_m``, ``kind`` (``"door"`` or ``"opening"``), the ``rooms`` (ids, 0 = no room) on its two sides
    and its ``line``: the obstacle cells it joins ((row, col), (row, col)), None when it has none."""

    cell: tuple[int, int]
    direction: tuple[float, float]
    width_m: float
    kind: str
    rooms: tuple[int, int]
    line: tuple[tuple[int, int], tuple[int, int]] | None


@dataclass(frozen=True, eq=False)
class RoomSegmentation:
    """``labels`` (H, W) int32: 0 = not a room, k = room k (1..n) on every free cell of it; ``room_cells``
    (n, 2) int64: row k - 1 is room k's cell farthest from obstacles (the last in raster order among equals);
    ``area_m2`` (n,): each room's free floor area; ``doorways``; ``rules`` it was made with."""

    labels: np.ndarray
    room_cells: np.ndarray
    area_m2: np.ndarray
    doorways: tuple[Doorway, ...]
    rules: RoomRules

    @property
    def n_rooms(self) -> int:
        return int(self.room_cells.shape[0])


# ---------------------------------------------------------------------------------------------- rules


def merge_round(a, b, cut_clr, area, mx, rules: RoomRules, res: float):
    """Which of the cuts (union-find root of the region on each side, 0 = none; clearance at the cut, m) stay
    after one round of the rules of the module docstring (4 a-c); None when no rule drops anything. ``area`` (cells) and ``mx`` (largest clearance, m) are indexed by root."""
    keep = (a != b) & (a > 0) & (b > 0)
    if not keep.all():
        return keep  # a: all at once
    fragment = rules.min_room_area_m2 / (res * res)

    def merge_area(k):
        ar = area[k]
        return np.where(mx[k] < rules.min_room_clearance_m, np.minimum(ar, fragment - 0.5), ar)

    ma, mb = merge_area(a), merge_area(b)
    sa, sb = ma < fragment, mb < fragment
    touching = sa | sb
    if touching.any():  # b: the smallest fragment (first found first) through its widest opening
        ks = np.column_stack([np.where(sa, a, -1), np.where(sb, b, -1)]).ravel()
        kv = np.column_stack([ma, mb]).ravel()
        sel = ks >= 0
        k_small = ks[sel][np.argmin(kv[sel])]
        hit = touching & ((a == k_small) | (b == k_small))
        other = np.where(hit, a + b - k_small, 0)
        opening = np.where(hit, cut_clr / np.maximum(mx[other], 1e-9), -np.inf)
        keep[np.argmax(opening)] = False
        return keep
    ratio = np.minimum(mx[a], mx[b]) / np.maximum(cut_clr, 1e-9)
    weak = ratio < rules.room_to_door_clearance
    if not weak.any():
        return None
    keep[np.argmin(np.where(weak, ratio, np.inf))] = False  # c: the weakest narrowing
    return keep


def _furniture_islands(free: np.ndarray, res: float, rules: RoomRules):
    """(8-connected obstacle component of every cell (H, W) int32, bool per component: free-standing
    furniture): islands not touching the map's edge of at most ``furniture_area_max_m2`` that are not
    wall-like. Wall-like: a mean thickness (area / bounding-box diagonal: a wall's thickness, about 0.7 x a
    square's side) of at most ``wall_thickness_max_m`` and a bounding-box diagonal of at least
    ``wall_length_min_m``."""
    import cv2

    obs = np.ascontiguousarray(~free).view(np.uint8)
    _n, lab, st, _ = cv2.connectedComponentsWithStats(obs, connectivity=8)
    edge = (
        (st[:, cv2.CC_STAT_LEFT] == 0)
        | (st[:, cv2.CC_STAT_TOP] == 0)
        | (st[:, cv2.CC_STAT_LEFT] + st[:, cv2.CC_STAT_WIDTH] == free.shape[1])
        | (st[:, cv2.CC_STAT_TOP] + st[:, cv2.CC_STAT_HEIGHT] == free.shape[0])
    )
    area = st[:, cv2.CC_STAT_AREA] * res * res
    diag = np.hypot(st[:, cv2.CC_STAT_WIDTH], st[:, cv2.CC_STAT_HEIGHT]) * res
    wall_like = (area / np.maximum(diag, res) <= rules.wall_thickness_max_m) & (
        diag >= rules.wall_length_min_m
    )
    furn = (area <= rules.furniture_area_max_m2) & ~wall_like & ~edge
    furn[0] = False  # the free cells' label
    return lab, furn


def _wall_clearance(free: np.ndarray, res: float, islands) -> np.ndarray | None:
    """The clearance (m, float32 (H, W)) of the free space with the free-standing furniture (``islands``:
    :func:`_furniture_islands`) counted as floor: a room's width between its walls, which the merging rules
    compare (a table or a desk in a room does not make the room narrower, nor a room with one a fragment).
    None when there is no such furniture (then it is the clearance itself)."""
    import cv2

    olab, furn = islands
    if not furn[1:].any():
        return None
    floor = furn[olab]
    floor |= free
    pad = cv2.copyMakeBorder(floor.view(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    del floor
    out = np.ascontiguousarray(cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1])
    out *= np.float32(res)  # float32: 4 bytes a cell on a building's map (the clearance_map's float64 is 8)
    return out


def _label_stats(labels: np.ndarray, values: np.ndarray, n: int):
    """Per label 0..n-1: the largest value (>= 0), the last flat index (raster order) holding it (-1 for an
    empty label) and the number of cells."""
    from holoslam.maps.passages import kernels

    lab = np.ascontiguousarray(labels).reshape(-1)
    v = np.ascontiguousarray(values).reshape(-1)
    fast = kernels()
    if fast is not None:
        return fast.label_stats(lab, v, n)
    mx = np.zeros(n)
    np.maximum.at(mx, lab, v)
    at_max = np.flatnonzero(v == mx[lab])
    at = np.full(n, -1, dtype=np.int64)
    np.maximum.at(at, lab[at_max], at_max)
    return mx, at, np.bincount(lab, minlength=n)


def _sample_free(free: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Whether the cells nearest the (..., 2) (row, col) points are free (outside the map: not)."""
    h, w = free.shape
    q = np.rint(pts).astype(np.int64)
    ok = (q[..., 0] >= 0) & (q[..., 0] < h) & (q[..., 1] >= 0) & (q[..., 1] < w)
    out = np.zeros(q.shape[:-1], dtype=bool)
    out[ok] = free[q[ok][:, 0], q[ok][:, 1]]
    return out


def _wall_beyond(free: np.ndarray, p1: np.ndarray, p2: np.ndarray, length_cells: int) -> np.ndarray:
    """(N,) the smaller over the two ends of each cut p1 -> p2 ((N, 2) cells) of the fraction of the line's
    continuation beyond the end (``length_cells`` cells, a cell either side allowed) that is not free: 1 for a
    door set in a wall, low for a line from a jamb into the room behind it."""
    u = (p2 - p1).astype(np.float64)
    u /= np.maximum(np.hypot(u[:, 0], u[:, 1]), 1e-9)[:, None]
    v = np.column_stack([-u[:, 1], u[:, 0]])
    s = np.arange(1, length_cells + 1, dtype=np.float64)[None, :, None]
    out = np.ones(p1.shape[0])
    for p, sgn in ((p1, -1.0), (p2, 1.0)):
        pts = p[:, None, :] + sgn * s * u[:, None, :]
        blocked = ~_sample_free(free, pts)
        for o in (-1.0, 1.0):
            blocked |= ~_sample_free(free, pts + o * v[:, None, :])
        out = np.minimum(out, blocked.mean(axis=1))
    return out


def _widening(free: np.ndarray, p1: np.ndarray, p2: np.ndarray, res: float, enough: float) -> np.ndarray:
    """(N,) whether the free space beside each cut p1 -> p2 ((N, 2) cells) is at least ``enough`` times as wide
    as the cut along the cut's line: the longest free chord parallel to the cut through a point 0.4, 0.7 or 1.0 m
    off the cut's middle (either side), against ``enough`` x the cut's length (rays stop there)."""
    u = (p2 - p1).astype(np.float64)
    length = np.hypot(u[:, 0], u[:, 1])
    u /= np.maximum(length, 1e-9)[:, None]
    v = np.column_stack([-u[:, 1], u[:, 0]])
    mid = 0.5 * (p1 + p2)
    n = int(np.ceil(enough * float(length.max(initial=0.0)))) + 1
    offsets = [sgn * off / res for off in (0.4, 0.7, 1.0) for sgn in (-1.0, 1.0)]
    from holoslam.maps.passages import kernels

    fast = kernels()
    if fast is not None:
        best = fast.chords(np.ascontiguousarray(free), mid, u, v, np.array(offsets), n)
        return best >= enough * length
    s = np.arange(1, n + 1, dtype=np.float64)[None, :, None]
    best = np.zeros(p1.shape[0])
    for off in (0.4, 0.7, 1.0):
        for sgn in (-1.0, 1.0):
            q = mid + sgn * (off / res) * v
            chord = np.zeros(p1.shape[0])
            for d in (u, -u):
                run = _sample_free(free, q[:, None, :] + s * d[:, None, :])
                chord += np.where(run.all(axis=1), n, np.argmin(run, axis=1))
            best = np.maximum(best, np.where(_sample_free(free, q), chord, 0.0))
    return best >= enough * length


def _segment_distance(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """(N,) the distance between the segments p1 -> p2 and q1 -> q2 ((N, 2) each; 0 where they cross)."""

    def cross(o, a, b):
        return (a[:, 0] - o[:, 0]) * (b[:, 1] - o[:, 1]) - (a[:, 1] - o[:, 1]) * (b[:, 0] - o[:, 0])

    def to_segment(x, a, b):
        d = b - a
        t = np.clip(((x - a) * d).sum(axis=1) / np.maximum((d * d).sum(axis=1), 1e-12), 0.0, 1.0)
        e = a + t[:, None] * d - x
        return np.hypot(e[:, 0], e[:, 1])

    crossing = (cross(q1, q2, p1) * cross(q1, q2, p2) < 0) & (cross(p1, p2, q1) * cross(p1, p2, q2) < 0)
    ends = np.minimum.reduce(
        [to_segment(p1, q1, q2), to_segment(p2, q1, q2), to_segment(q1, p1, p2), to_segment(q2, p1, p2)]
    )
    return np.where(crossing, 0.0, ends)


def _head_on(free: np.ndarray, end: np.ndarray, cell: np.ndarray, length_cells: int) -> np.ndarray:
    """(N,) whether each cut line ends head-on on a wall at ``end`` ((N, 2) obstacle cells, each the cut's
    nearest obstacle cell on its side of the skeleton ``cell``, so ``end - cell`` is the wall's normal there):
    the obstacle runs on along the wall's face on both sides of the end (at least half of ``length_cells``
    either way, a cell into the wall allowed), as a wall the line runs into does; the end face of a jamb (a
    wall's end) is only the wall's thickness wide, and a corner runs on to one side."""
    n = (end - cell).astype(np.float64)
    n /= np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-9)[:, None]
    t = np.column_stack([-n[:, 1], n[:, 0]])
    s = np.arange(1, length_cells + 1, dtype=np.float64)[None, :, None]
    out = np.ones(end.shape[0], dtype=bool)
    for sgn in (-1.0, 1.0):
        pts = end[:, None, :] + sgn * s * t[:, None, :]
        blocked = ~_sample_free(free, pts) | ~_sample_free(free, pts + n[:, None, :])
        out &= blocked.mean(axis=1) >= 0.5
    return out


def _off_the_jamb(free, rc, half, seg, pairs, res: float, rules: RoomRules) -> np.ndarray:
    """(N,) bool: the candidates that give way to a narrower one of the same opening whose line ends on the
    same jamb while theirs runs head-on into a wall (step 2 of the module docstring). ``pairs`` (K, 2): the
    candidates closer than the sum of their half widths (cells, ``half``); ``seg`` (N, 2, 2) float: each
    line's ends, NaN without one."""
    out = np.zeros(half.shape[0], dtype=bool)
    ok = ~(np.isnan(seg[pairs[:, 0], 0, 0]) | np.isnan(seg[pairs[:, 1], 0, 0]))
    ratio = rules.room_to_door_clearance
    a, b = pairs[ok, 0], pairs[ok, 1]
    wide = np.concatenate([a[half[a] >= ratio * half[b]], b[half[b] >= ratio * half[a]]])
    narrow = np.concatenate([b[half[a] >= ratio * half[b]], a[half[b] >= ratio * half[a]]])
    if wide.shape[0] == 0:
        return out
    w1, w2, n1, n2 = seg[wide, 0], seg[wide, 1], seg[narrow, 0], seg[narrow, 1]
    jamb = rules.wall_thickness_max_m / res
    touch = _segment_distance(w1, w2, n1, n2) <= jamb
    # the wide line's far end: the one farther from the narrow line
    far1 = _segment_distance(w1, w1, n1, n2) >= _segment_distance(w2, w2, n1, n2)
    end = np.where(far1[:, None], w1, w2)
    hit = touch & _head_on(free, end, rc[wide], max(int(round(2.0 * jamb)), 1))
    out[wide[hit]] = True
    return out


def _one_per_opening(cands, lines, clr, free, res: float, keys, rules: RoomRules) -> list[int]:
    """Indices of the candidates kept when those closer than the sum of their half widths (one opening seen
    twice) keep one: a line from the jamb of a narrower one into the space behind it never (see
    :func:`_off_the_jamb`); then the line continuing into wall beyond both ends first, then the narrowest."""
    from scipy.spatial import cKDTree

    n = len(cands)
    if n < 2:
        return list(range(n))
    rc = np.array([c[0] for c in cands], dtype=np.float64)
    half = np.array([clr[int(c[0][0]), int(c[0][1])] for c in cands]) / res
    wall = np.zeros(n)
    seg = np.full((n, 2, 2), np.nan)
    has = [i for i, k in enumerate(keys) if lines.get(k) is not None]
    if has:
        p1 = np.array([lines[keys[i]][0] for i in has], dtype=np.float64)
        p2 = np.array([lines[keys[i]][1] for i in has], dtype=np.float64)
        wall[has] = _wall_beyond(free, p1, p2, max(int(round(0.3 / res)), 1))
        seg[has, 0], seg[has, 1] = p1, p2
    tree = cKDTree(rc)
    pairs = tree.query_pairs(r=2.0 * float(half.max()), output_type="ndarray").reshape(-1, 2)
    gap = rc[pairs[:, 0]] - rc[pairs[:, 1]]
    pairs = pairs[np.hypot(gap[:, 0], gap[:, 1]) < half[pairs[:, 0]] + half[pairs[:, 1]]]
    gives_way = _off_the_jamb(free, rc, half, seg, pairs, res, rules)
    order = np.lexsort((half, -np.round(wall, 1)))
    order = order[~gives_way[order]]
    near = tree.query_ball_point(rc, r=2.0 * float(half.max()))
    kept = np.zeros(n, dtype=bool)
    for i in order.tolist():
        nb = np.array(near[i], dtype=np.int64)
        nb = nb[kept[nb]]
        if nb.shape[0] and np.any(np.hypot(*(rc[nb] - rc[i]).T) < half[nb] + half[i]):
            continue
        kept[i] = True
    return np.flatnonzero(kept).tolist()


# ---------------------------------------------------------------------------------------------- segmentation


def _grow(labels: np.ndarray, free: np.ndarray, *, in_place: bool = False) -> np.ndarray:
    """Every free cell without a label gets the label of the nearest labelled cell along 4-connected free
    cells (the larger among equally near ones); cells no label reaches stay 0. ``in_place``: ``labels`` (a
    contiguous int32 array the caller gives away) is grown itself, not a copy."""
    from holoslam.maps.passages import kernels

    own = in_place and labels.dtype == np.int32 and labels.flags.c_contiguous and labels.flags.writeable
    out = labels if own else np.ascontiguousarray(labels, dtype=np.int32).copy()
    fast = kernels()
    if fast is not None:
        fast.grow_labels(out.reshape(-1), np.ascontiguousarray(free).reshape(-1), out.shape[1])
        return out
    todo = free & (out == 0)
    while todo.any():
        nb = np.zeros_like(out)
        nb[1:] = np.maximum(nb[1:], out[:-1])
        nb[:-1] = np.maximum(nb[:-1], out[1:])
        nb[:, 1:] = np.maximum(nb[:, 1:], out[:, :-1])
        nb[:, :-1] = np.maximum(nb[:, :-1], out[:, 1:])
        front = todo & (nb > 0)
        if not front.any():
            break
        out[front] = nb[front]
        todo &= ~front
    return out


def _cuts(free: np.ndarray, clr: np.ndarray, res: float, r: RoomRules, skeleton, islands):
    """Steps 1 and 2 of the module docstring: the candidate cuts left after the wall and constriction tests and
    one per opening, as ([(cell, direction)], kind per cut (door / opening), {cell: (p1, p2)} cut lines)."""
    from holoslam.maps.doorways import doorway_candidates, opening_candidates, orient_cuts

    doors = doorway_candidates(None, clr, res, r, r.door_width_min_m, skeleton)
    wide = opening_candidates(skeleton, clr, res, r.door_width_max_m, r.opening_width_max_m, r.window_m)
    cands, lines = orient_cuts(doors + wide, free, clr, res)
    keys = [(int(c[0][0]), int(c[0][1])) for c in cands]
    kind = np.array([DOOR] * len(doors) + [OPENING] * len(wide), dtype=object)
    has_line = np.array([lines.get(k) is not None for k in keys], dtype=bool)
    ok = has_line | (kind == DOOR)  # a wide opening needs its obstacle-to-obstacle line
    with_line = np.flatnonzero(has_line)
    if with_line.shape[0]:
        p1 = np.array([lines[keys[i]][0] for i in with_line], dtype=np.float64)
        p2 = np.array([lines[keys[i]][1] for i in with_line], dtype=np.float64)
        olab, furn = islands
        i1, i2 = p1.astype(np.int64), p2.astype(np.int64)
        ok[with_line] &= ~(furn[olab[i1[:, 0], i1[:, 1]]] | furn[olab[i2[:, 0], i2[:, 1]]])
        sel = np.flatnonzero(kind[with_line] == OPENING)
        if sel.shape[0]:
            ok[with_line[sel]] &= _widening(free, p1[sel], p2[sel], res, r.opening_widening)
    idx = np.flatnonzero(ok)
    cands, keys, kind = [cands[i] for i in idx], [keys[i] for i in idx], kind[idx]
    kept = _one_per_opening(cands, lines, clr, free, res, keys, r)
    return [cands[i] for i in kept], kind[kept], lines


def segment_rooms(
    free: np.ndarray,
    resolution: float,
    skeleton,
    rules: RoomRules | None = None,
    clearance: np.ndarray | None = None,
) -> RoomSegmentation:
    """Rooms and doorways of the free space ``free`` (bool (H, W), cleaned: :func:`topology.cleaned_free`) at
    ``resolution`` m/cell, with the skeleton of that free space as ``passages.EdgePaths`` (``skeleton``) and
    optionally its clearance (m). The module docstring states the method."""
    import cv2

    from holoslam.maps.doorways import segment_regions
    from holoslam.maps.topology import clearance_map

    r = rules or RoomRules()
    res = float(resolution)
    free = np.ascontiguousarray(np.asarray(free, dtype=bool))
    if free.ndim != 2:
        raise MapError(f"free space must be a 2-D mask, got shape {free.shape}")
    clr = clearance_map(free, res) if clearance is None else clearance

    islands = _furniture_islands(free, res, r)
    cands, kind, lines = _cuts(free, clr, res, r, skeleton, islands)  # 1, 2
    # 3. regions: the space a disc of half the narrowest door fits, cut
    rad = max(int(np.floor(0.5 * r.door_width_min_m / res)), 1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * rad + 1, 2 * rad + 1))
    nav = cv2.dilate((clr >= 0.5 * r.door_width_min_m).astype(np.uint8), disc).view(bool) & free
    # 4. merging
    cut_clr = np.array([clr[int(c[0][0]), int(c[0][1])] for c in cands], dtype=np.float64)

    def rules_round(a, b, active, area, mx):
        return merge_round(a, b, cut_clr[active], area, mx, r, res)

    width = [_wall_clearance(free, res, islands)]
    del islands
    # handed over (popped: no reference left here), so segment_regions frees it once it has read what it needs
    seg = segment_regions(cands, lines, nav, free, clr, res, rules_round, room_clr=width.pop())
    # 5. rooms
    return _rooms(seg, cands, kind, lines, free, clr, res, r)


def _rooms(seg, cands, kind, lines, free, clr, res: float, r: RoomRules) -> RoomSegmentation:
    """Step 5: the merged regions of at least ``min_room_area_m2`` numbered 1.. in raster order, grown over the
    free space, with each room's cell farthest from obstacles, its area and the doorways between rooms."""
    is_room = seg.area >= r.min_room_area_m2 / (res * res)
    is_room[0] = False
    n = int(is_room.sum())
    room_id = np.zeros(seg.n_labels, dtype=np.int32)
    room_id[is_room] = np.arange(1, n + 1, dtype=np.int32)
    labels = _grow(room_id[seg.labels], free, in_place=True)
    _mx, last, count = _label_stats(labels, clr, n + 1)
    room_cells = np.column_stack(np.unravel_index(last[1:], labels.shape)).astype(np.int64).reshape(-1, 2)
    kinds = dict(zip([(int(c[0][0]), int(c[0][1])) for c in cands], kind.tolist(), strict=True))
    doorways = []
    for (rc, d), (sa, sb) in zip(seg.cuts, seg.sides, strict=True):
        k = (int(rc[0]), int(rc[1]))
        line = lines.get(k)
        doorways.append(
            Doorway(
                cell=k,
                direction=(float(d[0]), float(d[1])),
                width_m=float(2.0 * clr[k]),
                kind=kinds[k],
                rooms=(int(room_id[sa]), int(room_id[sb])),
                line=None if line is None else (
                    (int(line[0][0]), int(line[0][1])), (int(line[1][0]), int(line[1][1]))
                ),
            )
        )
    return RoomSegmentation(labels, room_cells, count[1:] * res * res, tuple(doorways), r)


def rooms_of_grid(grid, topology, rules: RoomRules | None = None, edge_paths=None) -> RoomSegmentation:
    """:func:`segment_rooms` of a grid's free space cleaned as its topology (``topology_from_grid``) records,
    on that topology's skeleton (``edge_paths``: its ``passages.EdgePaths`` when the caller has them)."""
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.topology import cleaned_free

    ep = edge_paths if edge_paths is not None else EdgePaths(topology)
    return segment_rooms(cleaned_free(grid, topology), grid.resolution, ep, rules)
