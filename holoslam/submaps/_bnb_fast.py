"""Compiled kernels (numba, ``cache=True``) of the branch-and-bound scan matcher, :mod:`holoslam.submaps.bnb`,
and of the loop search's windows, :mod:`holoslam.submaps.bnb_window`: both search by :func:`top_bounds` then
:func:`descend` (one pair of kernels to compile, not a second copy of the descent for ``bnb.search``).

Imported lazily by :mod:`holoslam.submaps.bnb` (numba import ~0.5 s; the first call of each kernel compiles it,
a few seconds once per machine, then loads it from numba's on-disk cache next to this file).

Grids. Level 0 is the probability grid itself (float32, H x W). Level d >= 1 (block width w = 2^d) is stored
quantised (uint8, ``q = ceil((p - lo) / step)``, so ``lo + q * step >= p``) and padded to
(H + w - 1) x (W + w - 1): its cell (i, j) holds the maximum over the fine cells [i - w + 1, i] x [j - w + 1, j]
(cells outside the grid count as the outside value), i.e. the block of w x w fine cells *starting* at fine cell
(i - w + 1, j - w + 1). A point in fine cell (r, c) shifted by the candidate offset (x, y) looks up level d at
(r + y + w - 1, c + x + w - 1): the bound of every offset in [x, x + w) x [y, y + w). The levels are built
in numpy by :func:`holoslam.submaps.bnb.precompute` (once per submap, as quick as a kernel: not worth one's
compile).

Scores are sums over the points (the caller divides by N): exact ones in float64 of the float32 cells, in
point order (the same additions as the numpy reference, so the two agree bit for bit); bounds are
``N * lo + Q * step + slack`` with Q the integer sum of the quantised cells, never below the exact score of
any candidate they cover.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._common_fast import argsort_stable
from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT)
def quantise(prob, lo, step):  # pragma: no cover - compiled
    """uint8 codes q of the cells: ``ceil((p - lo) / step)`` in [0, 255], raised where float rounding left
    ``lo + q * step < p`` (in float64), so every code's value bounds its cell from above."""
    h, w = prob.shape
    flat = prob.ravel()
    q = np.empty(h * w, dtype=np.uint8)
    inv = 1.0 / step
    for i in range(h * w):
        k = math.ceil(min(max((np.float64(flat[i]) - lo) * inv, 0.0), 255.0))
        q[i] = np.uint8(k)
    for i in range(h * w):  # the check, apart so the first loop vectorises
        p = np.float64(flat[i])
        k = np.int64(q[i])
        while k < 255 and lo + k * step < p:
            k += 1
        q[i] = np.uint8(k)
    return q.reshape(h, w)


@nb.njit(**JIT, inline="always")
def _exact(prob, rows, cols, bb, a, x, y, p_out):  # pragma: no cover - compiled
    """Sum over the points of angle a of the cell at offset (x, y) (float64, in point order); bb[a] = the
    points' (row min, row max, col min, col max) at angle a: all inside, no bounds tests."""
    h, w = prob.shape
    s = 0.0
    if bb[a, 0] + y >= 0 and bb[a, 1] + y < h and bb[a, 2] + x >= 0 and bb[a, 3] + x < w:
        for i in range(rows.shape[1]):
            s += np.float64(prob[np.uint64(rows[a, i] + y), np.uint64(cols[a, i] + x)])
        return s
    for i in range(rows.shape[1]):
        r = rows[a, i] + y
        c = cols[a, i] + x
        if 0 <= r < h and 0 <= c < w:
            s += np.float64(prob[r, c])
        else:
            s += p_out
    return s


@nb.njit(**JIT, inline="always")
def _bound(levels, start, hd, wd, sh, rows, cols, bb, a, x, y, q_out):  # pragma: no cover - compiled
    """Integer sum over the points of angle a of the level cells (padded dims hd x wd, shift sh = w - 1)."""
    s = 0
    ys, xs = y + sh, x + sh
    if bb[a, 0] + ys >= 0 and bb[a, 1] + ys < hd and bb[a, 2] + xs >= 0 and bb[a, 3] + xs < wd:
        base = start + ys * wd + xs
        for i in range(rows.shape[1]):
            s += levels[np.uint64(base + rows[a, i] * wd + cols[a, i])]
        return s
    for i in range(rows.shape[1]):
        r = rows[a, i] + ys
        c = cols[a, i] + xs
        if 0 <= r < hd and 0 <= c < wd:
            s += levels[start + r * wd + c]
        else:
            s += q_out
    return s


@nb.njit(**JIT_INNER)
def _score(prob, levels, starts, d, rows, cols, bb, a, x, y, quant):  # pragma: no cover - compiled
    """The exact sum (d = 0) or the bound (d >= 1) of candidate (a, x, y); quant = (lo, step, q_out, p_out,
    slack)."""
    lo, step, q_out, p_out, slack = quant
    if d == 0:
        return _exact(prob, rows, cols, bb, a, x, y, p_out)
    h, w = prob.shape
    sh = (1 << d) - 1
    q = _bound(levels, starts[d], h + sh, w + sh, sh, rows, cols, bb, a, x, y, np.int64(q_out))
    return rows.shape[1] * lo + q * step + slack


@nb.njit(**JIT)
def top_bounds(prob, levels, starts, rows, cols, bb, box, d_top, quant):  # pragma: no cover - compiled
    """The bounds of the top level's nodes (angle-major, then x, then y) and their order, best first (ties in
    node order): (bounds (A nx ny,), order). ``bb`` (A, 4): :func:`discretise`'s cell boxes of the points."""
    n_ang = rows.shape[0]
    x_lo, x_hi, y_lo, y_hi = box
    w = 1 << d_top
    nx = (x_hi - x_lo) // w + 1
    ny = (y_hi - y_lo) // w + 1
    top = np.empty(n_ang * nx * ny, dtype=np.float64)
    for a in range(n_ang):
        for ix in range(nx):
            for iy in range(ny):
                top[(a * nx + ix) * ny + iy] = _score(prob, levels, starts, d_top, rows, cols, bb, a,
                                                      x_lo + ix * w, y_lo + iy * w, quant)
    return top, argsort_stable(-top)  # np.argsort(-top, kind="mergesort")


@nb.njit(**JIT_INNER)
def _defer(buf, n, a, x, y, d, bound):  # pragma: no cover - compiled
    """Append the node (a, x, y, level d, bound) to the (capacity, 5) buffer holding n rows (doubled when full)."""
    if n == buf.shape[0]:
        grown = np.empty((2 * buf.shape[0], 5), dtype=np.float64)
        for i in range(n):  # a loop, not grown[:n] = buf[:n]: that slice copy cost 5-9 s of numba's compile
            for c in range(5):
                grown[i, c] = buf[i, c]
        buf = grown
    buf[n, 0], buf[n, 1], buf[n, 2], buf[n, 3], buf[n, 4] = a, x, y, d, bound
    return buf, n + 1


@nb.njit(**JIT, inline="always")  # one call site: no kernel of its own to compile
def _workspace(box, d_top, defer):  # pragma: no cover - compiled
    """:func:`descend`'s arrays: the top level's node counts (nx, ny), the depth-first stack (angle, x, y, level,
    bound), the children scratch (cx, cy, cs) and the set-aside buffer."""
    w = 1 << d_top
    cap = 4 * d_top + 4
    st = (np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64),
          np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.float64))
    return ((box[1] - box[0]) // w + 1, (box[3] - box[2]) // w + 1, st,
            np.empty(4, dtype=np.int64), np.empty(4, dtype=np.int64), np.empty(4, dtype=np.float64),
            np.empty((64 if defer >= 0 else 0, 5), dtype=np.float64))


@nb.njit(**JIT, inline="always")  # one call site: no kernel of its own to compile
def _seed(seeds, j):  # pragma: no cover - compiled
    """Row j of the seeds (angle, x, y, level, bound) as a stack entry."""
    return int(seeds[j, 0]), int(seeds[j, 1]), int(seeds[j, 2]), int(seeds[j, 3]), seeds[j, 4]


@nb.njit(**JIT, inline="always")  # one call site: no kernel of its own to compile
def _top_node(k, nx, ny, x_lo, y_lo, d_top, top):  # pragma: no cover - compiled
    """Top-level node k (angle-major, then x, then y) as a stack entry (angle, x, y, level, bound)."""
    w = 1 << d_top
    a, rem = divmod(k, nx * ny)
    return a, x_lo + (rem // ny) * w, y_lo + (rem % ny) * w, d_top, top[k]


@nb.njit(**JIT)
def descend(prob, levels, starts, rows, cols, bb, box, d_top, quant, best0, top, order, k0, seeds, centres, ex,
            first, defer):  # pragma: no cover - compiled
    """Depth-first branch and bound (Hess et al. 2016, Alg. 3; best child first) over angles 0..A-1 (rows/cols
    (A, N): the points' cells at each angle) and integer offsets box = (x_lo, x_hi, y_lo, y_hi), below the top
    level d_top whose bounds and order :func:`top_bounds` gave (``bb``: :func:`discretise`'s cell boxes): first
    from the nodes ``seeds`` (m, 5: angle, x, y, level, bound), then from the top level's nodes ``order[k0:]``
    until their bound falls to the best.

    Boxes cut out: no candidate within +-ex[0] offsets (x and y) and +-ex[1] angle indices of any of ``centres``
    (k, 3: angle, x, y) is returned, and a node whose block lies inside one box is dropped (the bounds of the
    others are still upper bounds: the result is exact). ``first``: return the first candidate above best0 met
    instead of the best. ``defer`` >= 0: every node or candidate set aside with a bound above (best at the time -
    defer) is returned, so that a search for anything above (final best - defer) can start from them and from
    ``order[k_break:]`` instead of from the top (each node is set aside with a bound <= the best at the time, which
    never exceeds the final best). Returns (sum, a, x, y, k_break, set-aside nodes (m', 5)); a = -1 when nothing
    outside the boxes beats best0 (strictly).

    Counts and indices start as ``np.int64`` values, not literals: numba would compile ``_defer`` again for each
    literal type its first typing pass sees (0, -1)."""
    x_lo, x_hi, y_lo, y_hi = box
    nx, ny, st, cx, cy, cs, buf = _workspace(box, d_top, defer)
    nd = np.int64(0)
    best, ba, bx, by = best0, np.int64(-1), np.int64(0), np.int64(0)
    k_break = order.size
    for kk in range(-seeds.shape[0], order.size - k0):
        if kk < 0:  # a seed
            st[0][0], st[1][0], st[2][0], st[3][0], st[4][0] = _seed(seeds, kk + seeds.shape[0])
            if st[4][0] <= best:
                continue
        else:
            k = order[k0 + kk]
            if top[k] <= best:
                k_break = k0 + kk
                break
            st[0][0], st[1][0], st[2][0], st[3][0], st[4][0] = _top_node(k, nx, ny, x_lo, y_lo, d_top, top)
        sp = 1
        while sp > 0:
            sp -= 1
            a, x, y, d = st[0][sp], st[1][sp], st[2][sp], st[3][sp]
            if st[4][sp] <= best:
                if defer >= 0 and st[4][sp] > best - defer:
                    buf, nd = _defer(buf, nd, a, x, y, d, st[4][sp])
                continue
            span = (1 << d) - 1
            cut = False
            for c in range(centres.shape[0]):
                if (abs(a - centres[c, 0]) <= ex[1] and x >= centres[c, 1] - ex[0]
                        and x + span <= centres[c, 1] + ex[0] and y >= centres[c, 2] - ex[0]
                        and y + span <= centres[c, 2] + ex[0]):
                    cut = True
                    break
            if cut:
                continue
            if d == 0:
                if defer >= 0 and ba >= 0 and best > st[4][sp] - defer:  # the best so far, set aside
                    buf, nd = _defer(buf, nd, ba, bx, by, d, best)
                best, ba, bx, by = st[4][sp], a, x, y
                if first:
                    return best, ba, bx, by, k_break, buf[:nd]
                continue
            # the (up to four) children at level d - 1: those above the best pushed, best last (on top); with
            # defer, those dropped within defer of the best set aside
            h = 1 << (d - 1)
            ns = 0
            for dx in range(2):
                if x + dx * h > x_hi:
                    break
                for dy in range(2):
                    if y + dy * h > y_hi:
                        break
                    sc = _score(prob, levels, starts, d - 1, rows, cols, bb, a, x + dx * h, y + dy * h, quant)
                    if sc > best:
                        q = ns  # insertion sort, ascending
                        while q > 0 and cs[q - 1] > sc:
                            cx[q], cy[q], cs[q] = cx[q - 1], cy[q - 1], cs[q - 1]
                            q -= 1
                        cx[q], cy[q], cs[q] = x + dx * h, y + dy * h, sc
                        ns += 1
                    elif defer >= 0 and sc > best - defer:
                        buf, nd = _defer(buf, nd, a, x + dx * h, y + dy * h, d - 1, sc)
            for q in range(ns):
                st[0][sp], st[1][sp], st[2][sp], st[3][sp], st[4][sp] = a, cx[q], cy[q], d - 1, cs[q]
                sp += 1
    return best, ba, bx, by, k_break, buf[:nd]


@nb.njit(**JIT)
def discretise(px, py, angles, x0, y0, ox, oy, res, lim):  # pragma: no cover - compiled
    """The cells (rows, cols) (A, N) int32 of the points (px, py) rotated by each angle and moved to (x0, y0):
    floor((x - ox) / res), clamped to +-lim; and per angle the box of those cells, bb (A, 4) int64: (min row,
    max row, min col, max col), which lets :func:`top_bounds` and :func:`descend` score a candidate whose points
    all fall inside the grid without a bounds test per point. N >= 1."""
    n_ang, n = angles.size, px.size
    rows = np.empty((n_ang, n), dtype=np.int32)
    cols = np.empty((n_ang, n), dtype=np.int32)
    bb = np.empty((n_ang, 4), dtype=np.int64)
    for a in range(n_ang):
        c, s = math.cos(angles[a]), math.sin(angles[a])
        r_lo, r_hi, c_lo, c_hi = int(lim), -int(lim), int(lim), -int(lim)
        for i in range(n):
            x = (c * px[i] - s * py[i] + x0 - ox) / res
            y = (s * px[i] + c * py[i] + y0 - oy) / res
            ci = int(math.floor(min(max(x, -lim), lim)))
            ri = int(math.floor(min(max(y, -lim), lim)))
            cols[a, i], rows[a, i] = ci, ri
            r_lo, r_hi, c_lo, c_hi = min(r_lo, ri), max(r_hi, ri), min(c_lo, ci), max(c_hi, ci)
        bb[a, 0], bb[a, 1], bb[a, 2], bb[a, 3] = r_lo, r_hi, c_lo, c_hi
    return rows, cols, bb


@nb.njit(**JIT)
def exhaustive(prob, rows, cols, bb, box, p_out):  # pragma: no cover - compiled
    """Every candidate scored exactly (the compiled brute force, for benchmarks): (best sum, a, x, y), the
    first best in (a, y, x) order."""
    x_lo, x_hi, y_lo, y_hi = box
    best, ba, bx, by = -np.inf, -1, 0, 0
    for a in range(rows.shape[0]):
        for y in range(y_lo, y_hi + 1):
            for x in range(x_lo, x_hi + 1):
                s = _exact(prob, rows, cols, bb, a, x, y, p_out)
                if s > best:
                    best, ba, bx, by = s, a, x, y
    return best, ba, bx, by
