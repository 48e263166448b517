"""How a merged map follows moved furniture (issue 27, ``benchmarks/bench_lifelong.py``'s sim part): for a piece
moved between two simulated days (``holoslam.sim.furniture_moves.FurnitureChange``), the cells its **old**
footprint's edges pass through, which the map after the day should no longer hold occupied (the laser hit them
the days before; now it sees through them), and the cells its **new** footprint's edges pass through, which it
should hold occupied (the sides of it the robot saw that day: the others stay unknown, or keep what was
behind them; ``new_free`` counts the new edge cells the map holds free, where the piece now stands).

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

# one cell (0.05 m) either way: the laser's hit on an edge lands in the cell on either side of it, and the store's
# frame is the first session's, a few centimetres off the truth's (the unchanged objects' fitted frame: 10-50 mm)
TOL_CELLS = 1
CLEAR_OF_M = 0.15  # m: the tolerance (one cell) plus a cell's diagonal and margin: farther from other obstacles
P_OCCUPIED = 0.65  # map_server's occupied (``OccupancyGrid.occupied_thresh``)
P_FREE = 0.196  # map_server's free (``OccupancyGrid.free_thresh``)


@dataclass(frozen=True, slots=True)
class FootprintShares:
    """The shares of one moved piece's edge cells (``module docstring``): of the old footprint's ``old_cells``,
    not held occupied and held free; of the new footprint's ``new_cells``, held occupied and held free (nan
    without cells)."""

    name: str
    old_cells: int
    old_not_occupied: float
    old_free: float
    new_cells: int
    new_occupied: float
    new_free: float


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


def _cells(merged: Any, wTm: np.ndarray, polygon: Any, avoid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the merged grid's cells the polygon's (map) edges pass through, the points within
    ``CLEAR_OF_M`` of ``avoid`` (map segments) left out; only cells inside the grid."""
    from holoslam.sim.furniture_moves import polygon_points

    pts = polygon_points(polygon, merged.resolution / 2)
    pts = pts[_seg_distance(pts, avoid) >= CLEAR_OF_M]
    w = g.transform_points(np.asarray(wTm, np.float64), pts)
    c = np.floor((w[:, 0] - merged.origin[0]) / merged.resolution).astype(np.int64)
    r = np.floor((w[:, 1] - merged.origin[1]) / merged.resolution).astype(np.int64)
    H, W = merged.prob.shape
    ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    rc = np.unique(np.column_stack([r[ok], c[ok]]), axis=0).reshape(-1, 2)
    return rc[:, 0], rc[:, 1]


def footprint_shares(merged: Any, wTm: Any, change: Any, world: Any) -> FootprintShares:
    """The shares for ``change`` (a ``FurnitureChange``, footprints in the map frame) on ``merged`` (a
    ``holoslam.lifelong.merge.MergedGrid`` in the store's world; ``wTm``: the map frame's pose in it) with the
    obstacles of ``world`` (the day's ``World``, the piece at its new place)."""
    import cv2

    occ = (merged.known & (merged.prob > P_OCCUPIED)).astype(np.uint8)
    k = 2 * TOL_CELLS + 1
    near_occ = cv2.dilate(occ, np.ones((k, k), np.uint8)) > 0
    free = merged.known & (merged.prob < P_FREE)
    others = np.vstack([world.wall_segments(), world.furniture_segments(exclude=change.name)])
    r, c = _cells(merged, wTm, change.before, np.vstack([others, _edges(change.after)]))
    rn, cn = _cells(merged, wTm, change.after, np.vstack([others, _edges(change.before)]))

    def share(x: np.ndarray) -> float:
        return float(np.mean(x)) if x.size else float("nan")

    return FootprintShares(change.name, int(r.size), share(~near_occ[r, c]), share(free[r, c]), int(rn.size),
                           share(near_occ[rn, cn]), share(free[rn, cn]))
