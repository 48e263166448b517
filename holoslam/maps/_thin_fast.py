"""Compiled thinning kernels (numba, ``cache=True``): the active-set Zhang-Suen subiterations, the topology
guard and the one-cell-thin passes of :func:`holoslam.maps.thinning.thin`, on a zero-padded flat uint8 grid.

Imported lazily by :mod:`holoslam.maps.thinning` (numba import ~0.5 s; the first call compiles, ~10 s once
per machine, then loads from numba's on-disk cache next to this file). Same semantics as the numpy path
(``thinning._thin_numpy``), cell for cell:

* a subiteration marks, from the neighbour codes at its start, every candidate cell its rule marks, then
  deletes the marked cells (bare rule: all together; guarded: in the classes (row % 2, col % 2) = 0..3 of the
  padded grid, in that order, each only if still removable at its class's turn);
* candidates of subiteration k are the set neighbours of the cells deleted in subiterations k - 1 and k - 2
  (the set cells touching a non-set cell for k < 2): any other cell the rule would mark has an unchanged
  neighbourhood since the same rule last looked at it, so it was not removable then and is a line tip
  (two touching neighbours), which deletions only keep a tip, so the guard would not delete it now;
* both subiterations repeat until two in a row delete nothing;
* one-cell-thin rounds mark every removable cell (first round: all set cells; later: the set neighbours of
  the cells deleted in the previous round), delete them class by class if still removable, until a round
  deletes nothing.

Every kernel is a plain function of numpy arrays; neighbour codes are kept up to date as cells are deleted.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT, inline="always")  # one call site: no kernel of its own to compile
def _offsets(w2):
    # p2 .. p9: north, north-east, east, south-east, south, south-west, west, north-west
    off = np.empty(8, dtype=np.int64)
    off[0] = -w2
    off[1] = -w2 + 1
    off[2] = 1
    off[3] = w2 + 1
    off[4] = w2
    off[5] = w2 - 1
    off[6] = -1
    off[7] = -w2 - 1
    return off


@nb.njit(**JIT, inline="always")  # one call site: no kernel of its own to compile
def _codes(a, off):
    """Neighbour code of every set cell (bit k = p(k+2) set); unset cells get 0xFF (no rule marks it). The
    grid's first and last rows and columns must be 0 (padding)."""
    n = a.shape[0]
    code = np.full(n, 0xFF, dtype=np.uint8)
    for i in range(n):
        if a[i]:
            c = 0
            for k in range(8):
                if a[i + off[k]]:
                    c |= 1 << k
            code[i] = c
    return code


@nb.njit(**JIT_INNER)
def _delete(a, code, off, i, touched, nt, tst, stamp):
    """Delete set cell i: clear it, update its set neighbours' codes, append them (once per stamp) to
    touched (room for 8 per deleted cell). Returns the new length of touched."""
    c = code[i]
    a[i] = 0
    for k in range(8):
        if c & (1 << k):
            q = i + off[k]
            code[q] &= 0xFF ^ (1 << ((k + 4) % 8))
            if tst[q] != stamp:
                tst[q] = stamp
                touched[nt] = q
                nt += 1
    code[i] = 0xFF
    return nt


@nb.njit(**JIT_INNER)
def _delete_marked(a, code, off, shift, marked, nm, guard, removable, touched, tst, stamp):
    """Delete marked[:nm] (sorted by row): all of them (guard False), or as if class by class (row % 2,
    col % 2 of the padded grid, rows of 2**shift cells; classes 0, 1, 2, 3 in turn), each if still removable
    at its class's turn. Returns (number deleted, number of touched cells).

    A cell's turn only depends on its 8 neighbours, which are of the other classes, so the classes need not
    be swept one after the other over the whole grid (four passes through memory): the cells of row r and
    class c are done at step r + c, the classes of a step in increasing order. Every neighbour of a lower
    class then comes earlier (a neighbour in row r + 1 of class c - 1 at the same step, before) and every
    neighbour of a higher class later, which is the class-by-class order; the four cursors stay within four
    rows of each other, so the work stays in cache."""
    nt = np.int64(0)  # not the literal 0: numba would compile _delete once more for its type
    if not guard:
        for j in range(nm):
            nt = _delete(a, code, off, marked[j], touched, nt, tst, stamp)
        return nm, nt
    ndel = 0
    if nm == 0:
        return 0, 0
    cur = np.zeros(4, dtype=np.int64)
    last_row = marked[nm - 1] >> shift
    t = marked[0] >> shift
    while t <= last_row + 3:
        for cls in range(4):
            row = t - cls
            j = cur[cls]
            while j < nm:
                i = marked[j]
                if (i >> shift) > row:
                    break
                if ((i >> shift) & 1) * 2 + (i & 1) == cls and removable[code[i]]:
                    nt = _delete(a, code, off, i, touched, nt, tst, stamp)
                    ndel += 1
                j += 1
            cur[cls] = j
        t += 1
    return ndel, nt


@nb.njit(**JIT_INNER)
def _by_row(l1, n1, l2, n2, shift, nrows):
    """l1[:n1] and l2[:n2] together, ordered by row (counting sort; order within a row kept)."""
    cnt = np.zeros(nrows + 1, dtype=np.int64)
    for j in range(n1):
        cnt[(l1[j] >> shift) + 1] += 1
    for j in range(n2):
        cnt[(l2[j] >> shift) + 1] += 1
    for r in range(nrows):
        cnt[r + 1] += cnt[r]
    out = np.empty(n1 + n2, dtype=np.int32)
    for j in range(n1):
        r = l1[j] >> shift
        out[cnt[r]] = l1[j]
        cnt[r] += 1
    for j in range(n2):
        r = l2[j] >> shift
        out[cnt[r]] = l2[j]
        cnt[r] += 1
    return out


@nb.njit(**JIT_INNER)
def _collect(a, code, boundary_only):
    """Set cells (with boundary_only: those with an unset neighbour), in memory order."""
    n = a.shape[0]
    m = 0
    for i in range(n):
        if a[i] and (not boundary_only or code[i] != 0xFF):
            m += 1
    out = np.empty(m, dtype=np.int32)
    m = 0
    for i in range(n):
        if a[i] and (not boundary_only or code[i] != 0xFF):
            out[m] = i
            m += 1
    return out


@nb.njit(**JIT_INNER)
def _next_stamp(stamp, tst, cst):
    """Stamps are uint8: after 255 subiterations both stamp arrays are cleared and numbering starts again."""
    if stamp == 255:
        tst[:] = 0
        cst[:] = 0
        return 1
    return stamp + 1


@nb.njit(**JIT)
def thin_flat(a, shift, zs1, zs2, removable, guard, one_cell):
    """Thin the zero-padded flat grid a (uint8, rows of 2**shift cells, first/last row and column 0, fewer
    than 2**31 cells) in place: Zhang-Suen subiterations (through the topology guard when guard), then, with
    one_cell, the one-cell-thin rounds. zs1, zs2, removable: the 256-entry rule tables of
    ``thinning._tables`` (none of them marks code 0xFF, the code unset and interior cells get). Returns the
    number of subiterations and of one-cell rounds run."""
    n = a.shape[0]
    nrows = n >> shift
    off = _offsets(np.int64(1) << shift)
    code = _codes(a, off)
    tst = np.zeros(n, dtype=np.uint8)  # stamp of the last subiteration that appended the cell to touched
    cst = np.zeros(n, dtype=np.uint8)  # stamp of the last subiteration that looked at the cell as a candidate
    # counts start as np.int64 and flags as np.bool_, not literals: numba compiles a kernel called with a
    # literal argument once more for each literal type (four _delete_marked, two _collect, ...)
    stamp = np.int64(0)
    bnd = _collect(a, code, np.bool_(True))
    prev2 = bnd  # touched at k - 2 (first two subiterations: the boundary)
    n2 = bnd.shape[0]
    prev1 = bnd  # touched at k - 1
    n1 = n2
    k = 0
    quiet = 0
    while quiet < 2:
        rule = zs1 if k % 2 == 0 else zs2
        stamp = _next_stamp(stamp, tst, cst)
        if k < 2:
            cand = bnd if k == 0 else _by_row(prev1, n1, bnd, bnd.shape[0], shift, nrows)
        else:
            cand = _by_row(prev1, n1, prev2, n2, shift, nrows)
        marked = np.empty(cand.shape[0], dtype=np.int32)
        nm = np.int64(0)
        for j in range(cand.shape[0]):
            i = cand[j]
            if cst[i] != stamp:
                cst[i] = stamp
                if rule[code[i]]:
                    marked[nm] = i
                    nm += 1
        touched = np.empty(min(8 * nm, n), dtype=np.int32)
        ndel, nt = _delete_marked(a, code, off, shift, marked, nm, guard, removable, touched, tst, stamp)
        prev2, n2 = prev1, n1
        prev1, n1 = touched, nt
        quiet = quiet + 1 if ndel == 0 else 0
        k += 1
    rounds = 0
    if one_cell:
        cand = _collect(a, code, np.bool_(False))  # first round: every set cell is a candidate
        nc = cand.shape[0]
        while nc:
            rounds += 1
            stamp = _next_stamp(stamp, tst, cst)
            if rounds > 1:
                cand = _by_row(cand, nc, cand, np.int64(0), shift, nrows)
            marked = np.empty(nc, dtype=np.int32)
            nm = np.int64(0)
            for j in range(nc):
                i = cand[j]
                if cst[i] != stamp:
                    cst[i] = stamp
                    if removable[code[i]]:
                        marked[nm] = i
                        nm += 1
            touched = np.empty(min(8 * nm, n), dtype=np.int32)
            ndel, nt = _delete_marked(a, code, off, shift, marked, nm, np.bool_(True), removable, touched, tst,
                                      stamp)
            if ndel == 0:
                break
            cand, nc = touched, nt
    return k, rounds
