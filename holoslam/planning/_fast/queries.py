"""Compiled planning query (numba, :mod:`holoslam._jit` policy): one whole query between two located points
(see ``holoslam.planning.routes`` for the steps).

:func:`query` finds the regions holding the start and the goal (:func:`_regions_at`, a bucket index), the
corridor (``astar.corridor_astar`` over the ports, trimmed to the last region holding the start and the
first holding the goal: :func:`_corridor`), the path through it and through its greedy shortcut
(``smoothing.corridor_path``, :func:`shortcut_corridor_adj`; :func:`_corridor_polyline`), the string pull on
the grid and the final checks (``smoothing.string_pull``, ``smoothing.simplify_validate``:
:func:`_pull_and_validate`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT
from holoslam.planning._fast.astar import corridor_astar
from holoslam.planning._fast.smoothing import _length, corridor_path, simplify_validate, string_pull


@nb.njit(**JIT)
def shortcut_corridor_adj(regs, rptr, rids, E, nr):
    """Greedy corridor shortcut: from each kept region of ``regs`` jump to the last later region adjacent to it;
    returns the portal (region edge) ids of the shortened corridor (empty when two consecutive regions are not
    adjacent). Read through the region adjacency (CSR ``rptr`` / ``rids`` of each region's edges ``E``), not a
    search over all later regions: O(m * degree), not O(m^2 log F); the tests compare it with that search."""
    return _shortcut_adj(regs, rptr, rids, E, np.full(nr, -1, dtype=np.int64))


@nb.njit(**JIT)
def _shortcut_adj(regs, rptr, rids, E, last):
    """:func:`shortcut_corridor_adj` with the (nr,) scratch ``last``, all -1 on entry and on return (the
    query reuses one, so it costs O(m), not O(nr))."""
    m = regs.shape[0]
    for i in range(m):
        last[regs[i]] = i
    out = np.empty(max(m - 1, 0), dtype=np.int64)
    n = 0
    i = 0
    while i < m - 1:
        a = regs[i]
        best = -1
        bk = -1
        for k in range(rptr[a], rptr[a + 1]):
            f = rids[k]
            o = E[f, 0] + E[f, 1] - a
            j = last[o]
            if j > i and j > best:
                best = j
                bk = f
        if best < 0:  # consecutive regions of a corridor are always adjacent; keep the rest as it is
            n = 0
            break
        out[n] = bk
        n += 1
        i = best
    for i in range(m):
        last[regs[i]] = -1
    return out[:n].copy()


@nb.njit(**JIT)
def _ports_of(rs, rptr, rids, pp, pslot):
    """The ports of the portals of the regions ``rs`` (portal f's ports: ``pslot[pp[f]:pp[f + 1]]``)."""
    n = 0
    for r in rs:
        for k in range(rptr[r], rptr[r + 1]):
            f = rids[k]
            n += pp[f + 1] - pp[f]
    out = np.empty(n, dtype=np.int64)
    n = 0
    for r in rs:
        for k in range(rptr[r], rptr[r + 1]):
            f = rids[k]
            for q in range(pp[f], pp[f + 1]):
                out[n] = pslot[q]
                n += 1
    return out


@nb.njit(**JIT)
def _regions_of(rs, portals, E, rg):
    """The regions of a corridor: ``rs``, the region each pair of consecutive portals shares, ``rg``."""
    m = portals.shape[0]
    regs = np.empty(m + 1, dtype=np.int64)
    regs[0] = rs
    for i in range(m - 1):
        a0, a1 = E[portals[i], 0], E[portals[i], 1]
        b0, b1 = E[portals[i + 1], 0], E[portals[i + 1], 1]
        regs[i + 1] = a0 if (a0 == b0 or a0 == b1) else a1
    regs[m] = rg
    return regs


@nb.njit(**JIT)
def _contains_at(regions, r, u, v):
    """The closed rectangle of region r (``regions[r]`` = row0, col0, row1, col1) holds the point (u, v); by
    scalar reads (no row view: the scan over all regions of a query is 20-30x faster)."""
    return regions[r, 1] <= u and u <= regions[r, 3] and regions[r, 0] <= v and v <= regions[r, 2]


@nb.njit(**JIT)
def _regions_at(regions, bptr, bids, shift, nbx, u, v, out):
    """The regions whose closed rectangle holds the point (u, v), ascending, written to ``out``; returns their
    number. Candidates come from the point's bucket (``bptr`` / ``bids`` CSR over square buckets of
    2**shift cells, ``nbx`` buckets a row, listing every region whose closed rectangle meets the bucket)."""
    bu = np.int64(math.floor(u)) >> shift
    bv = np.int64(math.floor(v)) >> shift
    n = 0
    if bu < 0 or bu >= nbx or bv < 0 or (bv + 1) * nbx >= bptr.shape[0]:
        return n
    b = bv * nbx + bu
    for k in range(bptr[b], bptr[b + 1]):
        r = bids[k]
        if _contains_at(regions, r, u, v):
            out[n] = r
            n += 1
    return n


@nb.njit(**JIT)
def _end_regions(regions, bptr, bids, bgrid, su, sv, gu, gv, rs, rg):
    """Every region holding the start, every region holding the goal (ascending; ``rs`` / ``rg`` when the
    point was snapped into a region's cell from outside every region), and the first region holding both
    (-1 if none): regions overlap, and any of them may start (end) the best corridor."""
    sr = np.empty(max(bgrid[2], 1), dtype=np.int64)
    gr = np.empty(max(bgrid[2], 1), dtype=np.int64)
    shift, nbx = bgrid[0], bgrid[1]
    ns = _regions_at(regions, bptr, bids, shift, nbx, su, sv, sr)
    ng = _regions_at(regions, bptr, bids, shift, nbx, gu, gv, gr)
    both = -1
    for i in range(ns):  # the first region holding both (sr is ascending)
        r = sr[i]
        if _contains_at(regions, r, gu, gv):
            both = r
            break
    if ns == 0:
        sr[0] = rs
        ns = 1
    if ng == 0:
        gr[0] = rg
        ng = 1
    return sr[:ns], gr[:ng], both


@nb.njit(**JIT)
def _portals_of(seq, port_portal):
    """The portals a port sequence passes, each once per visit."""
    portals = np.empty(seq.shape[0], dtype=np.int64)
    m = 0
    for i in range(seq.shape[0]):
        f = port_portal[seq[i]]
        if m == 0 or portals[m - 1] != f:
            portals[m] = f
            m += 1
    return portals[:m]


@nb.njit(**JIT)
def _trim(portals, E, regions, su, sv, gu, gv):
    """The corridor of a portal sequence, (portals, regions), trimmed to enter at the last region holding
    the start and leave at the first holding the goal."""
    m = portals.shape[0]
    # the corridor's end regions: those of the first (last) portal holding the start (goal)
    f0, f1 = E[portals[0], 0], E[portals[0], 1]
    rs = f0 if _contains_at(regions, f0, su, sv) else f1
    l0, l1 = E[portals[m - 1], 0], E[portals[m - 1], 1]
    rg = l0 if _contains_at(regions, l0, gu, gv) else l1
    regs = _regions_of(rs, portals, E, rg)
    i0 = 0
    for i in range(regs.shape[0]):
        if _contains_at(regions, regs[i], su, sv):
            i0 = i
    i1 = regs.shape[0] - 1
    for i in range(i0, regs.shape[0]):
        if _contains_at(regions, regs[i], gu, gv):
            i1 = i
            break
    return portals[i0:i1].copy(), regs[i0 : i1 + 1].copy()


@nb.njit(**JIT)
def _corridor(graph, links, regions, sr, gr, su, sv, gu, gv, hw, scratch):
    """The trimmed corridor (portals, regions) of the best port route from the start's regions ``sr`` to
    the goal's ``gr``; no regions when there is none (arguments: :func:`query`)."""
    cuv, port_portal, pp, pslot, rptr, rids, E, _ = links
    first = _ports_of(sr, rptr, rids, pp, pslot)
    last = _ports_of(gr, rptr, rids, pp, pslot)
    d0 = np.empty(first.shape[0], dtype=np.float64)
    for i in range(first.shape[0]):
        d0[i] = math.hypot(cuv[first[i], 0] - su, cuv[first[i], 1] - sv)
    ws, hn, hk, _ = scratch
    seq = corridor_astar(graph, first, d0, last, gr, gu, gv, hw, ws, hn, hk)
    if seq.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return _trim(_portals_of(seq, port_portal), E, regions, su, sv, gu, gv)


@nb.njit(**JIT)
def _straight(su, sv, gu, gv):
    """The two-point path start -> goal."""
    raw = np.empty((2, 2), dtype=np.float64)
    raw[0, 0], raw[0, 1], raw[1, 0], raw[1, 1] = su, sv, gu, gv
    return raw


@nb.njit(**JIT)
def _corridor_polyline(su, sv, gu, gv, portals, regs, boxes, rptr, rids, E, rlast):
    """The path through the corridor's portal boxes and through those of its greedy shortcut, the shorter,
    with its regions."""
    if portals.shape[0] == 0:
        return _straight(su, sv, gu, gv), regs
    raw = corridor_path(su, sv, gu, gv, boxes[portals], 200)
    short = _shortcut_adj(regs, rptr, rids, E, rlast)
    if 0 < short.shape[0] < portals.shape[0]:
        alt = corridor_path(su, sv, gu, gv, boxes[short], 200)
        if _length(alt) < _length(raw):
            return alt, _regions_of(regs[0], short, E, regs[regs.shape[0] - 1])
    return raw, regs


@nb.njit(**JIT)
def _pull_and_validate(bits, tclear, gh, gw, raw, eps):
    """String pull on the grid: all pairs on short paths (where a shortcut through regions off the corridor
    matters most), only the next-but-one point on long ones (each check costs the segment's length); then
    collinear points dropped and every segment the string pull did not check checked. (points, ok)."""
    if 2 < raw.shape[0] <= 9:
        raw, chk = string_pull(bits, tclear, gh, gw, raw, 8, 1, eps)
    elif raw.shape[0] > 9:
        raw, chk = string_pull(bits, tclear, gh, gw, raw, 2, 1, eps)
    else:
        chk = np.zeros(max(raw.shape[0] - 1, 0), dtype=np.bool_)
    return simplify_validate(bits, tclear, gh, gw, raw, chk, eps, 1e-9)


@nb.njit(**JIT)
def _unique_runs(regs):
    """``regs`` with consecutive repeats dropped."""
    out = np.empty(regs.shape[0], dtype=np.int64)
    n = 0
    for i in range(regs.shape[0]):
        if n == 0 or out[n - 1] != regs[i]:
            out[n] = regs[i]
            n += 1
    return out[:n].copy()


@nb.njit(**JIT)
def _to_world(pts, world):
    """Cell-boundary points to world metres: x = origin_x + u * resolution, y = origin_y + v * resolution
    (``world`` = (origin_x, origin_y, resolution))."""
    ox, oy, res = world[0], world[1], world[2]
    wp = np.empty_like(pts)
    for i in range(pts.shape[0]):
        wp[i, 0] = ox + pts[i, 0] * res
        wp[i, 1] = oy + pts[i, 1] * res
    return wp


@nb.njit(**JIT)
def _query(graph, links, locate, grid, su, sv, rs, gu, gv, rg, hw, eps, scratch):
    """One whole query between two located points (start (su, sv) in region ``rs``, goal (gu, gv) in ``rg``,
    same component): corridor A* over the ports, corridor trimmed to the last region holding the start and
    the first holding the goal, the funnel path through it and through its greedy shortcut (the shorter
    wins), collinear points dropped and every segment checked on the grid. Returns (waypoints (K, 2) in
    world metres, regions crossed, length in metres, status): status 0 ok, 1 no corridor, 2 a segment failed
    the grid check.

    The planner's arrays (``routes._query_arrays``), in groups: ``graph`` = (rp_ptr, rp_id, rp_uv, node, ea,
    eb), the port graph of ``astar.corridor_astar``; ``links`` = (cuv, port_portal, pp, pslot, rptr, rids, E,
    boxes): each port's (u, v) and portal, each portal's ports (CSR ``pp``, slots ``pslot``), each region's
    portals (CSR ``rptr`` / ``rids``), the region edges and the portal boxes; ``locate`` = (regions, bptr,
    bids, bgrid): the region rectangles and their bucket index (:func:`_regions_at`; ``bgrid`` = shift,
    buckets a row, most regions in a bucket); ``grid`` = (bits, tclear, gh, gw, world): the (gh, gw) free
    mask's tiles and their clearance (``tiles.seg_free_tiles``) and (origin_x, origin_y, resolution), which
    maps cells to metres. ``hw`` weights the search's heuristic, ``eps`` is the grid checks' tolerance in
    cells and ``scratch`` = (ws, hn, hk, rlast) the search workspace of ``corridor_astar`` and the (R,) int64
    scratch of :func:`_shortcut_adj`, all -1."""
    regions, bptr, bids, bgrid = locate
    bits, tclear, gh, gw, world = grid
    sr, gr, both = _end_regions(regions, bptr, bids, bgrid, su, sv, gu, gv, rs, rg)
    if rs == rg or both >= 0:
        raw = _straight(su, sv, gu, gv)
        regs = np.full(1, rs if rs == rg else both, dtype=np.int64)
    else:
        portals, regs = _corridor(graph, links, regions, sr, gr, su, sv, gu, gv, hw, scratch)
        if regs.shape[0] == 0:
            return np.zeros((0, 2), dtype=np.float64), np.zeros(0, dtype=np.int64), 0.0, 1
        _, _, _, _, rptr, rids, E, boxes = links
        raw, regs = _corridor_polyline(su, sv, gu, gv, portals, regs, boxes, rptr, rids, E, scratch[3])
    pts, ok = _pull_and_validate(bits, tclear, gh, gw, raw, eps)
    wp = _to_world(pts, world)
    return wp, _unique_runs(regs), _length(wp), 0 if ok else 2


# fmt: off
@nb.njit(**JIT)
def query(
    rp_ptr, rp_id, rp_uv, node, ea, eb,  # graph
    cuv, port_portal, pp, pslot, rptr, rids, E, boxes,  # links
    regions, bptr, bids, bgrid,  # locate
    bits, tclear, gh, gw, world,  # grid
    su, sv, rs, gu, gv, rg, hw, eps,
    ws, hn, hk, rlast,  # scratch
):
    """:func:`_query` (see there) with the arrays of its groups as separate arguments: numba dispatches flat
    array arguments faster than nested tuples of them (23 arrays: 5.9 against 7.4 us a call, where a query
    on the household takes about 25 us)."""
    return _query(
        (rp_ptr, rp_id, rp_uv, node, ea, eb),
        (cuv, port_portal, pp, pslot, rptr, rids, E, boxes),
        (regions, bptr, bids, bgrid),
        (bits, tclear, gh, gw, world),
        su, sv, rs, gu, gv, rg, hw, eps,
        (ws, hn, hk, rlast),
    )
# fmt: on
