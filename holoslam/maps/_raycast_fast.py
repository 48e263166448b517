"""Compiled ray-casting kernel (numba, ``cache=True``) for :func:`holoslam.maps.occupancy.build_grid`: an exact
grid traversal (Amanatides & Woo 1987) of every beam, counting hits and misses per cell.

Imported lazily by :mod:`holoslam.maps.occupancy` (numba import ~0.5 s; the first call compiles, a few seconds
once per machine, then loads from numba's on-disk cache next to this file).

Coordinates are in cell units: ``u = (xy - grid origin) / resolution``, so cell (row, col) is the half-open
square [col, col + 1) x [row, row + 1) and the cell of a point is (floor(uy), floor(ux)) - the same rule as
``OccupancyGrid.world_to_cell``. For a beam from o to e:

* its cells are {cell(o + t (e - o)) : 0 <= t <= 1}, visited in order of t; each cell is one interval of t
  (cells are convex), so a cell is visited at most once per beam;
* every cell of the beam before its end cell (the cell of e) counts one miss; the end cell counts one hit when
  the beam has a return; cells outside the grid count nothing (the beam may leave and re-enter the grid);
* at an exact grid-line crossing the point on the line belongs to the cell on its upper side (half-open cells):
  a beam through a grid corner moving up-right or down-left steps diagonally (the two side cells only touch
  the beam at the corner, which is not theirs); moving up-left or down-right it visits the side cell on the
  upper row / right column (which owns the corner) between them; a beam lying on a grid line belongs to the
  cells above / right of the line.

Which grid line comes next is decided from the beam's origin at every step (the crossing parameters
(xb - x0) / dx and (yb - y0) / dy compared as cross products, no division and no accumulated increments), so
the traversal equals the exact cell set whenever those differences and products are exact in float64 (e.g. all
coordinates on a 2^-k cell lattice with few enough bits, as the tests use); otherwise it can differ only where
a beam passes within rounding error of a grid corner. Beams with an end point more than one cell outside the
grid are first clipped to the grid grown by one cell (Liang-Barsky), so a beam crossing a small local grid costs
the cells near it, not its whole length (rounding in the clipped entry / exit cells only touches cells outside
the grid). Every step moves closer to the last cell, so a traversal ends after at most |dcol| + |drow| steps
whatever the rounding. Cost: ~2 ns per cell visited (household log: 452,500 beams, 26 M cells, ~55 ms).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._common_fast import clip_segment
from holoslam._jit import JIT


@nb.njit(**JIT)
def _sign(v):
    return 1 if v > 0 else (-1 if v < 0 else 0)


@nb.njit(**JIT)
def _walk(misses, c, r, cs, rs, x0, y0, ax, ay, h, w):
    """Count one miss in every grid cell from (r, c) up to, not including, (rs, cs), along the line through
    (x0, y0) with direction (+-ax, +-ay) (signs: towards (rs, cs))."""
    sx = 1 if cs >= c else -1
    sy = 1 if rs >= r else -1
    nx = abs(cs - c)  # steps left along x and y: each step moves one closer, so the walk always ends
    ny = abs(rs - r)
    # every visited cell lies in the box of the first and last cells: no bounds test when both are inside
    inside = 0 <= c < w and 0 <= r < h and 0 <= cs < w and 0 <= rs < h
    # next vertical / horizontal grid line; which one comes first: t_x = (xb - x0) / dx against
    # t_y = (yb - y0) / dy, compared as (xb - x0) sx |dy| against (yb - y0) sy |dx| (no division, and
    # distances from the origin, not accumulated increments)
    xb = c + 1 if sx > 0 else c
    yb = r + 1 if sy > 0 else r
    kx = sx * ay
    ky = sy * ax
    while nx > 0 and ny > 0:
        if inside or (0 <= c < w and 0 <= r < h):
            misses[r * w + c] += 1
        gx = (xb - x0) * kx
        gy = (yb - y0) * ky
        if gx < gy:
            c += sx
            xb += sx
            nx -= 1
        elif gy < gx:
            r += sy
            yb += sy
            ny -= 1
        elif sx > 0 and sy < 0:  # corner moving down-right: the corner is in (r, c + 1)
            c += sx
            xb += sx
            nx -= 1
        elif sx < 0 and sy > 0:  # corner moving up-left: the corner is in (r + 1, c)
            r += sy
            yb += sy
            ny -= 1
        else:  # up-right or down-left through the corner: diagonal
            c += sx
            xb += sx
            nx -= 1
            r += sy
            yb += sy
            ny -= 1
    while nx > 0:  # straight on along a row
        if inside or (0 <= c < w and 0 <= r < h):
            misses[r * w + c] += 1
        c += sx
        nx -= 1
    while ny > 0:  # straight on along a column
        if inside or (0 <= c < w and 0 <= r < h):
            misses[r * w + c] += 1
        r += sy
        ny -= 1


@nb.njit(**JIT)
def cast_counts(ox, oy, ex, ey, hit, h, w):
    """Hit and miss counts (flat (h * w,) int64, row-major) of beams from (ox, oy) to (ex, ey) (cell units,
    finite) on an h x w grid; ``hit`` (bool) marks beams with a return (their end cell counts a hit)."""
    hits = np.zeros(h * w, dtype=np.int64)
    misses = np.zeros(h * w, dtype=np.int64)
    cast_counts_into(ox, oy, ex, ey, hit, h, w, hits, misses)
    return hits, misses


@nb.njit(**JIT)
def cast_counts_into(ox, oy, ex, ey, hit, h, w, hits, misses):
    """``cast_counts`` added into the caller's flat (h * w,) count arrays ``hits`` and ``misses`` (any integer
    type: a run's grid keeps int32 counts, 8 bytes a cell for both, and no full-size array per chunk)."""
    for b in range(ox.shape[0]):
        x0 = ox[b]
        y0 = oy[b]
        ce = int(math.floor(ex[b]))
        re = int(math.floor(ey[b]))
        if hit[b] and 0 <= ce < w and 0 <= re < h:
            hits[re * w + ce] += 1
        dx = ex[b] - x0
        dy = ey[b] - y0
        ax = abs(dx)
        ay = abs(dy)
        c = int(math.floor(x0))
        r = int(math.floor(y0))
        cs = ce  # the last cell of the traversal (the end cell unless clipped)
        rs = re
        if not (-1.0 <= x0 <= w + 1.0 and -1.0 <= y0 <= h + 1.0 and -1.0 <= ex[b] <= w + 1.0
                and -1.0 <= ey[b] <= h + 1.0):
            t0, t1 = clip_segment(x0, y0, dx, dy, -1.0, -1.0, w + 1.0, h + 1.0)
            if t0 > t1:
                continue  # never near the grid
            if t0 > 0.0:  # entry cell: outside the grid (on the grown box's border)
                c = int(math.floor(x0 + t0 * dx))
                r = int(math.floor(y0 + t0 * dy))
            if t1 < 1.0:  # exit cell: outside the grid too
                cs = int(math.floor(x0 + t1 * dx))
                rs = int(math.floor(y0 + t1 * dy))
        _walk(misses, c, r, cs, rs, x0, y0, ax, ay, h, w)
