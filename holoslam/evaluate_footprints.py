"""How a merged map follows moved furniture (issue 27, ``benchmarks/bench_lifelong.py``'s sim part): for a piece
moved between two simulated days (``holoslam.sim.furniture_moves.FurnitureChange``), the cells its **old**
footprint's edges pass through that the map held occupied before the day, which the map after the day should no
longer hold occupied where the day's session saw them (the laser hit them the days before; now it sees through
them), and the cells its **new** footprint's edges pass through, which it should hold occupied (the sides of it
the robot saw that day: the others stay unknown, or keep what was behind them; ``new_free`` counts the new edge
cells the map holds free, where the piece now stands).

An edge point this close to another obstacle of the day (a wall, another piece, the piece's other footprint:
``CLEAR_OF_M``) is left out: its cell is occupied, or not, whatever the map makes of the move. A cell counts as
held occupied when a known cell within ``TOL_CELLS`` of it is above ``P_OCCUPIED``, as free when the cell itself
is known below ``P_FREE``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["FootprintShares", "footprint_shares", "TOL_CELLS", "CLEAR_OF_M", "P_OCCUPIED", "P_FREE"]

# one cell (0.05 m) either way: the laser's hit on an edge lands in the cell on either side of it, and the truth is
# put in the store's world by a fitted frame (the unchanged objects': 7-10 mm RMSE left, bench_lifelong)
TOL_CELLS = 1
CLEAR_OF_M = 0.15  # m: the tolerance (one cell) plus a cell's diagonal and margin: farther from other obstacles
P_OCCUPIED = 0.65  # map_server's occupied (``OccupancyGrid.occupied_thresh``)
P_FREE = 0.196  # map_server's free (``OccupancyGrid.free_thresh``)


@dataclass(frozen=True, slots=True)
class FootprintShares:
    """One moved piece's edge cells (module docstring) on the map after the day. The old footprint's ``old_cells``,
    of them ``old_held`` held occupied by the map before the day, and the share of those no longer held occupied
    after (``old_freed``), and the same of the ``old_seen`` of them the day's own map knows (``old_freed_seen``:
    what the merge makes of what the day saw); the new footprint's ``new_cells``, the shares held occupied and
    held free after, and of the ``new_seen`` of them the day's own map knows, the share held occupied after
    (``new_occupied_seen``). A share is nan without cells."""

    name: str
    old_cells: int
    old_held: int
    old_freed: float
    old_seen: int
    old_freed_seen: float
    new_cells: int
    new_occupied: float
    new_free: float
    new_seen: int
    new_occupied_seen: float


def _seg_distance(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distance of each point (N, 2) to the nearest of the segments (M, 4), (N,); inf without segments."""
    if not len(segs):
        return np.full(len(p), np.inf)
    a, b = segs[None, :, :2], segs[None, :, 2:]
    e = b - a
    L2 = np.maximum((e**2).sum(-1), 1e-18)
    t = np.clip((((p[:, None] - a) * e).sum(-1)) / L2, 0.0, 1.0)
    q = a + t[..., None] * e
    return np.asarray(np.sqrt(((p[:, None] - q) ** 2).sum(-1)).min(axis=1))


def _edges(polygon: Any) -> np.ndarray:
    P = np.asarray(polygon, np.float64).reshape(-1, 2)
    return np.hstack([P, np.roll(P, -1, axis=0)])


def _points(cell: float, wTm: np.ndarray, polygon: Any, avoid: np.ndarray) -> np.ndarray:
    """Points every half ``cell`` along the polygon's (map) edges, those within ``CLEAR_OF_M`` of ``avoid`` (map
    segments) left out, in the store's world."""
    from holoslam.sim.furniture_moves import polygon_points

    pts = polygon_points(polygon, cell / 2)
    return g.transform_points(np.asarray(wTm, np.float64), pts[_seg_distance(pts, avoid) >= CLEAR_OF_M])


def _states(merged: Any, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per world point: its cell (row * width + column, -1 outside), held occupied (within ``TOL_CELLS``), held
    free, known."""
    import cv2

    occ = (merged.known & (merged.prob > P_OCCUPIED)).astype(np.uint8)
    k = 2 * TOL_CELLS + 1
    near_occ = cv2.dilate(occ, np.ones((k, k), np.uint8)) > 0
    c = np.floor((w[:, 0] - merged.origin[0]) / merged.resolution).astype(np.int64)
    r = np.floor((w[:, 1] - merged.origin[1]) / merged.resolution).astype(np.int64)
    H, W = merged.prob.shape
    ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    r, c = np.where(ok, r, 0), np.where(ok, c, 0)
    free = merged.known[r, c] & (merged.prob[r, c] < P_FREE)
    return np.where(ok, r * W + c, -1), ok & near_occ[r, c], ok & free, ok & merged.known[r, c]


def _one_a_cell(merged: Any, w: np.ndarray) -> np.ndarray:
    """The points, one for each cell of ``merged`` they fall in (cells outside it left out)."""
    cell = _states(merged, w)[0]
    _, first = np.unique(cell, return_index=True)
    keep = first[cell[first] >= 0]
    return w[np.sort(keep)]


def footprint_shares(before: Any, after: Any, change: Any, world: Any, wTm: Any, day_only: Any = None
                     ) -> FootprintShares:
    """The shares for ``change`` (a ``FurnitureChange``, footprints in the map frame) on the merged maps
    (``holoslam.lifelong.merge.MergedGrid`` in the store's world; ``wTm``: the map frame's pose in it) ``before``
    and ``after`` the day's session, and the day's own map ``day_only`` (None: the seen shares are nan), with the
    obstacles of ``world`` (the day's ``World``, the piece at its new place)."""
    others = np.vstack([world.wall_segments(), world.furniture_segments(exclude=change.name)])
    old = _one_a_cell(after, _points(after.resolution, wTm, change.before, np.vstack([others, _edges(change.after)])))
    new = _one_a_cell(after, _points(after.resolution, wTm, change.after, np.vstack([others, _edges(change.before)])))
    held = _states(before, old)[1]
    old_after = _states(after, old)[1]
    seen = held & (_states(day_only, old)[3] if day_only is not None else np.zeros(len(old), bool))
    _, new_occ, new_free, _ = _states(after, new)
    new_seen = _states(day_only, new)[3] if day_only is not None else np.zeros(len(new), bool)

    def share(x: np.ndarray) -> float:
        return float(np.mean(x)) if x.size else float("nan")

    return FootprintShares(change.name, len(old), int(held.sum()), share(~old_after[held]), int(seen.sum()),
                           share(~old_after[seen]), len(new), share(new_occ), share(new_free), int(new_seen.sum()),
                           share(new_occ[new_seen]))
