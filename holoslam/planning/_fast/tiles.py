"""Compiled grid kernels of the planner: the free mask as 64-bit tiles, its clearance, and the exact segment
check the queries validate with (numba, :mod:`holoslam._jit` policy).

:func:`seg_free_tiles` is the exact segment test of ``holoslam.planning.segments.segments_free`` (the same
cut-at-grid-lines, midpoint-in-a-free-cell rule with the same ``eps``, tested equal) without allocation, on
the 64-bit tiles of :func:`tile_bits`, jumping over squares of free 4 x 4-cell blocks
(:func:`block_clearance`, from :func:`chessboard_clearance`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT


@nb.njit(**JIT)
def chessboard_clearance(free):
    """(h, w) uint8: for each free cell, its chessboard (L-infinity) distance in cells to the nearest cell that
    is not free, the outside of the grid counting as not free (so every cell within distance k - 1 of a cell
    of value k is free), saturated at 255; 0 on cells that are not free. Two raster passes (exact for this
    metric)."""
    h, w = free.shape
    d = np.empty((h, w), dtype=np.uint8)
    for r in range(h):
        for c in range(w):
            if not free[r, c]:
                d[r, c] = 0
            elif r == 0 or c == 0 or c == w - 1:
                d[r, c] = 1
            else:
                m = min(np.int64(d[r, c - 1]), np.int64(d[r - 1, c - 1]))
                m = min(m, np.int64(d[r - 1, c]), np.int64(d[r - 1, c + 1]))
                d[r, c] = min(m + 1, 255)
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            if d[r, c] <= 1:
                continue
            if r == h - 1:
                d[r, c] = 1
                continue
            m = min(np.int64(d[r, c + 1]), np.int64(d[r + 1, c + 1]))
            m = min(m, np.int64(d[r + 1, c]), np.int64(d[r + 1, c - 1]))
            d[r, c] = min(np.int64(d[r, c]), m + 1)
    return d


@nb.njit(**JIT)
def tile_bits(free):
    """The (h, w) free mask as 8 x 8 tiles of one uint64 each (row-major tiles; bit (r % 8) * 8 + c % 8 of
    tile (r // 8, c // 8) is cell (r, c)), cells outside the grid blocked: 1/8 of the bool mask's memory, so
    the grid checks of a query read few cache lines. Returns (bits (th * tw,), full (th, tw) bool: tiles
    with every cell free)."""
    h, w = free.shape
    th = (h + 7) >> 3
    tw = (w + 7) >> 3
    bits = np.zeros(th * tw, dtype=np.uint64)
    for r in range(h):
        base = (r >> 3) * tw
        sh = (r & 7) << 3
        for c in range(w):
            if free[r, c]:
                bits[base + (c >> 3)] |= np.uint64(1) << np.uint64(sh | (c & 7))
    full = np.empty((th, tw), dtype=np.bool_)
    for t in range(th * tw):
        full[t // tw, t % tw] = bits[t] == np.uint64(0xFFFFFFFFFFFFFFFF)
    return bits, full


def block_clearance(free):
    """(ceil(h / 4), ceil(w / 4)) uint8: the chessboard clearance (:func:`chessboard_clearance`), in blocks
    of 4 x 4 cells, of the blocks whose cells are all free (cells outside the grid blocked): the jumps of
    :func:`seg_free_tiles`."""
    h, w = free.shape
    f = np.zeros((-(-h // 4) * 4, -(-w // 4) * 4), dtype=np.bool_)
    f[:h, :w] = free
    return chessboard_clearance(f.reshape(f.shape[0] // 4, 4, f.shape[1] // 4, 4).all(axis=(1, 3)))


@nb.njit(**JIT)
def _cell_free(bits, w, r, c):
    """Cell (r, c) (inside the grid) is free in the tiled mask."""
    t = bits[(r >> 3) * ((w + 7) >> 3) + (c >> 3)]
    return (t >> np.uint64(((r & 7) << 3) | (c & 7))) & np.uint64(1) != np.uint64(0)


@nb.njit(**JIT)
def _point_free_bits(bits, h, w, u, v, eps):
    """Is the point (u, v) in the closed union of free cells of the tiled mask (a point within ``eps`` of a
    grid line touches the cells on both sides; ``segments._point_free``'s rule)?"""
    ru = np.rint(u)
    rv = np.rint(v)
    on_u = abs(u - ru) <= eps
    on_v = abs(v - rv) <= eps
    fu = np.int64(ru) if on_u else np.int64(math.floor(u))
    fv = np.int64(rv) if on_v else np.int64(math.floor(v))
    for du in range(2):
        if du == 1 and not on_u:
            break
        cu = fu - du
        for dv in range(2):
            if dv == 1 and not on_v:
                break
            cv = fv - dv
            if cu >= 0 and cu < w and cv >= 0 and cv < h and _cell_free(bits, w, cv, cu):
                return True
    return False


@nb.njit(**JIT)
def _crossings_upto(f, n, a, d, t):
    """How many of the n grid lines f .. f + n - 1 a segment crosses (visited in the direction of d, the
    line x crossed at parameter (x - a) / d) it crosses at a parameter <= t."""
    if n == 0:
        return np.int64(0)
    x = a + d * t
    if d > 0:
        c = np.int64(math.floor(x)) - f + 1
    else:
        c = f + n - np.int64(math.ceil(x))
    c = min(max(c, np.int64(0)), n)
    while c > 0:  # float rounding: never count a line crossed after t
        xl = f + c - 1 if d > 0 else f + n - c
        if (xl - a) / d <= t:
            break
        c -= 1
    return c


@nb.njit(**JIT)
def _lines_crossed(a, b, eps):
    """The grid lines x = f .. f + n - 1 that a segment from coordinate a to b crosses more than ``eps``
    inside its ends: (f, n)."""
    lo = min(a, b)
    hi = max(a, b)
    f = np.int64(math.floor(lo + eps)) + 1
    n = max(np.int64(math.ceil(hi - eps)) - 1 - f + 1, 0)
    return f, n


@nb.njit(**JIT)
def _crossing_t(f, n, a, d, i):
    """The parameter of the i-th crossing, in the direction of d, of the lines f .. f + n - 1 by a + t d
    (line x at (x - a) / d); 2.0, past the segment's end, when i >= n."""
    if i >= n:
        return 2.0
    x = f + i if d > 0 else f + n - 1 - i
    return (x - a) / d


@nb.njit(**JIT)
def _free_square_end(tclear, h, w, au, av, du, dv, mu, mv, eps):
    """Where (parameter te > 0) the segment a + t d leaves the square of free blocks around the piece whose
    midpoint is (mu, mv): with block clearance K >= 1 the (2K - 1)-block square around its 4 x 4-cell block
    is free. -1.0 when there is no such square (the piece is off the grid, in a block with a blocked cell, or
    within ``eps`` of a side of its cell)."""
    cu = np.int64(math.floor(mu))
    cv = np.int64(math.floor(mv))
    if cu < 0 or cu >= w or cv < 0 or cv >= h:
        return -1.0
    k = np.int64(tclear[cv >> 2, cu >> 2])
    if k < 1 or mu - cu <= eps or cu + 1 - mu <= eps or mv - cv <= eps or cv + 1 - mv <= eps:
        return -1.0
    tc = cu >> 2
    tr = cv >> 2
    te = 1.0
    if du > 0.0:
        te = min(te, ((tc + k) * 4 - au) / du)
    elif du < 0.0:
        te = min(te, ((tc - k + 1) * 4 - au) / du)
    if dv > 0.0:
        te = min(te, ((tr + k) * 4 - av) / dv)
    elif dv < 0.0:
        te = min(te, ((tr - k + 1) * 4 - av) / dv)
    return te


@nb.njit(**JIT)
def seg_free_tiles(bits, tclear, h, w, au, av, bu, bv, eps):
    """``segments_free`` (the same answer) on the tiled mask ``bits`` of an (h, w) grid (:func:`tile_bits`),
    jumping through free space: ``tclear`` (ceil(h / 4), ceil(w / 4)) uint8 is the chessboard clearance, in
    blocks of 4 x 4 cells, of the fully free blocks (:func:`block_clearance`), so after checking a piece of
    the segment inside a block of clearance K >= 1 (the (2K - 1)-block square around it is free) every piece
    up to where the segment leaves that square is free and skipped (:func:`_free_square_end`). The cost is
    the number of pieces in blocks with blocked cells plus the number of jumps, not the segment's length in
    cells, and the pieces it checks are pieces of ``segments_free``'s own cut (between consecutive grid-line
    crossings)."""
    if au == bu and av == bv:
        return _point_free_bits(bits, h, w, au, av, eps)
    f_u, n_u = _lines_crossed(au, bu, eps)
    f_v, n_v = _lines_crossed(av, bv, eps)
    du = bu - au
    dv = bv - av
    iu = np.int64(0)
    iv = np.int64(0)
    t_prev = 0.0
    # the next crossing of each axis in increasing t, recomputed only when passed
    tu = _crossing_t(f_u, n_u, au, du, iu)
    tv = _crossing_t(f_v, n_v, av, dv, iv)
    while True:
        if tu <= tv:
            t = tu
            iu += 1
            tu = _crossing_t(f_u, n_u, au, du, iu)
        else:
            t = tv
            iv += 1
            tv = _crossing_t(f_v, n_v, av, dv, iv)
        if t > 1.0:
            t = 1.0
        tm = 0.5 * (t_prev + t)
        mu = au + du * tm
        mv = av + dv * tm
        if not _point_free_bits(bits, h, w, mu, mv, eps):
            return False
        if t >= 1.0:
            return True
        t_prev = t
        te = _free_square_end(tclear, h, w, au, av, du, dv, mu, mv, eps)
        if te < 0.0:
            continue
        if te >= 1.0:
            return True
        ju = max(_crossings_upto(f_u, n_u, au, du, te), iu)
        jv = max(_crossings_upto(f_v, n_v, av, dv, te), iv)
        if ju > iu or jv > iv:
            iu = ju
            iv = jv
            # the next piece starts at the last crossing skipped
            if iu > 0:
                t_prev = max(t_prev, _crossing_t(f_u, n_u, au, du, iu - 1))
            if iv > 0:
                t_prev = max(t_prev, _crossing_t(f_v, n_v, av, dv, iv - 1))
            tu = _crossing_t(f_u, n_u, au, du, iu)
            tv = _crossing_t(f_v, n_v, av, dv, iv)
