"""The geometry of room segmentation (:mod:`holoslam.maps.rooms`, whose docstring states the rules): doorway and
opening candidates along the topology skeleton, the cut across each candidate's gap, and the incremental region
merging that drops cuts, round by round as the rules say, until the ones left are doorways.

Region merging is incremental: every cut's cells are drawn once (each cut on a canvas of its own bounding box,
so a cell knows how many cuts cover it), the robot space with all cuts drawn is labelled once (4-connected),
and dropping a cut gives back the cells no other cut covers, which join the regions they touch (union-find
with each region's area and largest clearance). The regions on the two sides of a cut are the first labelled
cells of two fixed walks from the cut (precomputed), looked up in the current labels. That is the same
partition, round for round, as redrawing every remaining cut and relabelling the whole map (what the rules
were first written as, ``cuts x cells`` work per round: minutes on a real office floor); the work per round is
now the cells of the dropped cut plus one gather over the walks. The last partition is labelled again by
``cv2.connectedComponents`` so region numbers follow the map's raster order as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoslam.maps.passages import kernels

__all__ = [
    "doorway_candidates",
    "opening_candidates",
    "orient_cuts",
    "segment_regions",
    "RegionSegmentation",
]


def _padded_clearance(ep, clr: np.ndarray, half: int):
    """The skeleton clearance of all edges in one buffer, each edge padded with ``half`` cells of +inf beyond a
    junction (the space goes on) and -inf beyond an endpoint (a spur's tip): (buffer, per-cell clearance,
    edge of each cell, index of each cell in the buffer)."""
    cells, starts = ep.cells, ep.starts
    lens = np.diff(starts)
    n_edges, m = lens.shape[0], cells.shape[0]
    c = clr[cells[:, 0], cells[:, 1]]
    edge = np.repeat(np.arange(n_edges), lens)
    local = np.arange(m) - starts[edge]
    pstarts = np.concatenate([[0], np.cumsum(lens + 2 * half)])
    buf = np.empty(int(pstarts[-1]))
    pad = np.arange(half)
    buf[(pstarts[:-1, None] + pad).ravel()] = np.repeat(np.where(ep.first_is_endpoint, -np.inf, np.inf), half)
    buf[(pstarts[1:, None] - half + pad).ravel()] = np.repeat(
        np.where(ep.last_is_endpoint, -np.inf, np.inf), half
    )
    body = pstarts[edge] + half + local
    buf[body] = c
    return buf, c, edge, body


def _directions(ep, idx: np.ndarray, edge: np.ndarray):
    """The skeleton direction (row, col) at the cells ``idx`` (from 3 cells before to 3 after on its edge) and
    which of them have one."""
    cells, starts = ep.cells, ep.starts
    lens = np.diff(starts)
    e = edge[idx]
    i = idx - starts[e]
    lo = starts[e] + np.maximum(i - 3, 0)
    hi = starts[e] + np.minimum(i + 3, lens[e] - 1)
    d = (cells[hi] - cells[lo]).astype(np.float64)
    return d, d.any(axis=1)


def opening_candidates(
    edge_paths, clr: np.ndarray, res: float, min_width_m: float, max_width_m: float, window_m: float
):
    """(cell, skeleton direction) of each wide-opening candidate: along the skeleton, a run of cells whose free
    width (2 x clearance) lies in (``min_width_m``, ``max_width_m``] and within one cell of the narrowest within
    ``window_m`` (a plateau, e.g. a bay as wide as its mouth). A short run (no longer than its half width)
    gives its middle cell; a longer one each end beyond which the clearance rises by more than a cell (the
    mouth of a bay, both ends of a narrowing), not an end that runs into a spur's tip."""
    ep = edge_paths
    if len(ep) == 0:
        return []
    half = max(int(round(0.5 * window_m / res)), 1)
    buf, c, edge, body = _padded_clearance(ep, clr, half)
    view = np.lib.stride_tricks.sliding_window_view(buf, 2 * half + 1)
    win_min = view.min(axis=1)[body - half]
    ok = (c <= win_min + res) & (2.0 * c > min_width_m) & (2.0 * c <= max_width_m)
    idx = np.flatnonzero(ok)
    if idx.shape[0] == 0:
        return []
    brk = np.flatnonzero((np.diff(idx) > 1) | (np.diff(edge[idx]) != 0)) + 1
    gs = np.concatenate([[0], brk])
    ge = np.concatenate([brk, [idx.shape[0]]]) - 1
    first, last = idx[gs], idx[ge]
    v = np.minimum.reduceat(c[idx], gs)
    # the largest clearance within a window before the run's first cell and after its last (pads included:
    # +inf beyond a junction is a rise, -inf beyond a spur's tip is none)
    wmax = np.lib.stride_tricks.sliding_window_view(buf, half).max(axis=1)
    before = wmax[body[first] - half]
    after = wmax[body[last] + 1]
    rise_a, rise_b = before > v + res, after > v + res
    short = (last - first) * res <= v
    mid = idx[(gs + ge) // 2]
    pick = np.concatenate(
        [mid[short & (rise_a | rise_b)], first[~short & rise_a], last[~short & rise_b]]
    )
    pick = np.unique(pick)
    d, has = _directions(ep, pick, edge)
    return [(ep.cells[j].copy(), dv) for j, dv in zip(pick[has].tolist(), d[has], strict=True)]


def doorway_candidates(topology, clr: np.ndarray, res: float, p, min_width_m: float = 0.0, edge_paths=None):
    """(cell (row, col), skeleton direction) of each doorway candidate along the topology edges (node cells
    included): a skeleton cell whose free width (2 x clearance) lies in [``min_width_m``,
    ``p.door_width_max_m``] and is the narrowest within ``p.window_m`` along the skeleton (one per plateau,
    one per place). Beyond a junction the skeleton goes on; towards an endpoint (a spur running into a wall or
    a furniture corner, clearance falling to its tip) there is no candidate within half a window of the tip.
    Whether a candidate separates anything is decided later by the regions it cuts. All edges at once: their
    paths concatenated with ``half`` a window of padding (+inf beyond a junction, -inf beyond an endpoint)
    between them, one sliding minimum."""
    from holoslam.maps.passages import EdgePaths

    ep = edge_paths if edge_paths is not None else EdgePaths(topology)
    if len(ep) == 0:
        return []
    half = max(int(round(0.5 * p.window_m / res)), 1)
    cells, starts = ep.cells, ep.starts
    lens = np.diff(starts)
    buf, c, edge, body = _padded_clearance(ep, clr, half)
    win_min = np.lib.stride_tricks.sliding_window_view(buf, 2 * half + 1).min(axis=1)[body - half]
    narrow = (2.0 * c <= p.door_width_max_m) & (2.0 * c >= min_width_m)
    idx = np.flatnonzero(narrow & (c <= win_min) & (lens[edge] >= 3))
    if idx.shape[0] == 0:
        return []
    brk = np.flatnonzero((np.diff(idx) > 1) | (np.diff(edge[idx]) != 0)) + 1
    gs = np.concatenate([[0], brk])
    gl = np.diff(np.concatenate([gs, [idx.shape[0]]]))
    mid = idx[gs + gl // 2]
    direction, ok = _directions(ep, mid, edge)
    out = [(cells[j].copy(), dv) for j, dv in zip(mid[ok].tolist(), direction[ok], strict=True)]
    if not out:
        return []
    # one candidate per place (two edges meeting at a junction both find it): the narrowest wins
    sep = 0.5 * p.window_m / res
    pos = cells[mid[ok]].astype(np.float64)
    order = np.argsort(c[mid[ok]], kind="stable")
    kept_xy = np.empty((len(out), 2))
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    for i in order.tolist():
        rc = pos[i]
        k = len(kept)
        if k and not np.all(np.hypot(kept_xy[:k, 0] - rc[0], kept_xy[:k, 1] - rc[1]) > sep):
            continue
        kept_xy[k] = rc
        kept.append(out[i])
    return kept


def orient_cuts(cands, free: np.ndarray, clr: np.ndarray, res: float):
    """The critical line of each candidate's gap: from the cell's nearest obstacle cell p1 to the nearest
    obstacle cell p2 on the other side (``(p2 - rc) . (p1 - rc) < 0``), whatever way the skeleton bends there.
    Returns ([(cell, direction along the passage = perpendicular to p1 p2)], {cell: (p1, p2)}). Compiled
    (``_holographic_fast.cut_lines``) when numba is there, the same lines."""
    h, w = free.shape
    out, lines = [], {}
    fast = kernels()
    if fast is not None and cands:
        cells = np.array([c[0] for c in cands], dtype=np.int64).reshape(-1, 2)
        reach = (np.ceil(2.0 * clr[cells[:, 0], cells[:, 1]] / res) + 4).astype(np.int64)
        p1s, p2s, ok = fast.cut_lines(np.ascontiguousarray(free), cells, reach)
        for (rc, d), p1, p2, has in zip(cands, p1s.astype(np.float64), p2s.astype(np.float64), ok, strict=True):
            if not has:
                out.append((rc, d))
                continue
            n = p2 - p1
            out.append((rc, np.array([n[1], -n[0]])))
            lines[(int(rc[0]), int(rc[1]))] = (p1, p2)
        return out, lines
    for rc, d in cands:
        k = int(np.ceil(2.0 * clr[rc[0], rc[1]] / res)) + 4
        r0, r1, c0, c1 = max(rc[0] - k, 0), min(rc[0] + k + 1, h), max(rc[1] - k, 0), min(rc[1] + k + 1, w)
        obs = np.argwhere(~free[r0:r1, c0:c1]) + np.array([r0, c0])
        if obs.shape[0] == 0:
            out.append((rc, d))
            continue
        v = (obs - rc).astype(np.float64)
        d2 = (v**2).sum(1)
        i1 = int(np.argmin(d2))
        other = (v @ v[i1]) < 0
        if not other.any() or d2[i1] == 0:
            out.append((rc, d))
            continue
        i2 = int(np.argmin(np.where(other, d2, np.inf)))
        p1, p2 = obs[i1].astype(np.float64), obs[i2].astype(np.float64)
        n = p2 - p1
        out.append((rc, np.array([n[1], -n[0]])))
        lines[(int(rc[0]), int(rc[1]))] = (p1, p2)
    return out, lines


def _cut_segments(rc: np.ndarray, d: np.ndarray, half_len_cells: float, free: np.ndarray, line):
    """The (x, y) integer end points of the segments that draw a cut: obstacle to obstacle through the cell
    (``line`` = (p1, p2)), or, without one, the line across the passage at ``rc`` (perpendicular to ``d``) on
    each side up to the first non-free cell (at most 2 x ``half_len_cells``) and one cell into it, so the cut
    closes the gap even when the skeleton cell is off the gap's middle."""
    if line is not None:
        return [
            ((int(q0[1]), int(q0[0])), (int(q1[1]), int(q1[0]))) for q0, q1 in ((line[0], rc), (rc, line[1]))
        ]
    rc = rc.astype(np.float64)
    dn = d / (np.hypot(*d) or 1.0)
    n = np.array([-dn[1], dn[0]])  # perpendicular, in (row, col)
    h, w = free.shape
    ends = []
    for sgn in (1.0, -1.0):
        t = np.arange(1, int(2 * half_len_cells) + 2, dtype=np.float64)
        pts = np.rint(rc[None, :] + sgn * t[:, None] * n[None, :]).astype(np.int64)
        ok = (pts[:, 0] >= 0) & (pts[:, 0] < h) & (pts[:, 1] >= 0) & (pts[:, 1] < w)
        blocked = ~ok
        blocked[ok] = ~free[pts[ok, 0], pts[ok, 1]]
        hit = np.nonzero(blocked)[0]
        reach = float(t[hit[0]]) + 1.0 if hit.shape[0] else float(t[-1])
        ends.append(rc + sgn * n * reach)
    a, b = ends
    return [((int(round(a[1])), int(round(a[0]))), (int(round(b[1])), int(round(b[0]))))]


def _segment_cells(segs, h: int, w: int) -> np.ndarray:
    """Sorted flat indices of the cells ``cv2.line`` (LINE_8, thickness 1) draws for the segments on an (h, w)
    image, drawn on a canvas of their bounding box: each segment first clipped to the image by
    ``cv2.clipLine``, as ``cv2.line`` clips it (integer end points, so the same cells; tested)."""
    import cv2

    clipped = []
    for a, b in segs:
        ok, p, q = cv2.clipLine((0, 0, w, h), a, b)
        if ok:
            clipped.append((p, q))
    if not clipped:
        return np.zeros(0, dtype=np.int64)
    xs = [q[0] for s in clipped for q in s]
    ys = [q[1] for s in clipped for q in s]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    canvas = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    for a, b in clipped:
        cv2.line(canvas, (a[0] - x0, a[1] - y0), (b[0] - x0, b[1] - y0), 1, 1, cv2.LINE_8)
    r, c = np.nonzero(canvas)
    return np.unique((r + y0).astype(np.int64) * w + (c + x0))


def _side_walks(rc: np.ndarray, d: np.ndarray, max_cells: int, free: np.ndarray) -> list[np.ndarray]:
    """Flat indices of the cells walked from the cut along +-direction, stopping at the grid's edge and at the
    first obstacle cell (a thin wall is never crossed); a side's region is its walk's first labelled cell."""
    d = d / np.hypot(*d)
    h, w = free.shape
    rc = rc.astype(np.float64)
    walks = []
    for sgn in (1.0, -1.0):
        t = np.arange(1, max_cells + 1, dtype=np.float64)
        pts = np.rint(rc[None, :] + sgn * t[:, None] * d[None, :]).astype(np.int64)
        ok = (pts[:, 0] >= 0) & (pts[:, 0] < h) & (pts[:, 1] >= 0) & (pts[:, 1] < w)
        stop = np.nonzero(~ok)[0]
        pts = pts[: stop[0]] if stop.shape[0] else pts
        blocked = np.nonzero(~free[pts[:, 0], pts[:, 1]])[0]
        pts = pts[: blocked[0]] if blocked.shape[0] else pts
        walks.append(pts[:, 0] * w + pts[:, 1])
    return walks


class _Walks:
    """All side walks concatenated, with the position of each walk's first labelled cell. Cells only ever gain
    a label (a dropped cut gives its cells back), so a walk's first labelled cell only moves towards its start:
    each round looks up the walks through the cells given back (cells sorted once, ``searchsorted``), not all
    walks."""

    def __init__(self, walks: list[np.ndarray], lab_flat: np.ndarray) -> None:
        lens = np.array([x.shape[0] for x in walks], dtype=np.int64)
        self.n = len(walks)
        self.cells = np.concatenate(walks) if walks else np.zeros(0, np.int64)
        self.group = np.repeat(np.arange(self.n), lens)
        self.order = np.argsort(self.cells, kind="stable")
        self.sorted_cells = self.cells[self.order]
        self.end = self.cells.shape[0]  # "no labelled cell"
        self.first = np.full(self.n, self.end, dtype=np.int64)
        pos = np.flatnonzero(lab_flat[self.cells] > 0)
        np.minimum.at(self.first, self.group[pos], pos)

    def restored(self, cells: np.ndarray) -> None:
        """Cells that just got a label."""
        if cells.shape[0] == 0 or self.end == 0:
            return
        lo = np.searchsorted(self.sorted_cells, cells, side="left")
        hi = np.searchsorted(self.sorted_cells, cells, side="right")
        k = hi - lo
        if not k.any():
            return
        q = self.order[np.repeat(lo - np.cumsum(k) + k, k) + np.arange(int(k.sum()))]
        np.minimum.at(self.first, self.group[q], q)

    def labels(self, lab_flat: np.ndarray, walks: np.ndarray) -> np.ndarray:
        """The label of the first labelled cell of each of the ``walks`` (0 where none)."""
        f = self.first[walks]
        out = np.zeros(walks.shape[0], dtype=np.int64)
        has = f < self.end
        out[has] = lab_flat[self.cells[f[has]]]
        return out


@dataclass(frozen=True)
class RegionSegmentation:
    """The merged partition: the doorway cuts left ([(cell, direction)]), region labels (H, W) int32 of the
    robot space with those cuts drawn (``cv2.connectedComponents``, 4-connected, 0 = not robot space or on a
    cut), their number, area per label in cells, and the (label, label) on the two sides of each cut."""

    cuts: list
    n_labels: int
    labels: np.ndarray
    area: np.ndarray
    sides: list


class _Regions:
    """Union-find over region labels: the current partition of the robot space while cuts are dropped."""

    def __init__(self, nav: np.ndarray, cover: np.ndarray, clr_flat: np.ndarray, extra: int) -> None:
        import cv2

        m = (nav & (cover == 0).reshape(nav.shape)).astype(np.uint8)
        n, lab = cv2.connectedComponents(m, connectivity=4)
        cap = n + extra + 1
        # int32 labels (cv2's own; ids stay below cap) unless the ids could outgrow them
        self.lab = lab.reshape(-1) if cap < 2**31 else lab.reshape(-1).astype(np.int64)
        self.parent = np.arange(cap, dtype=np.int64)
        self.area = np.zeros(cap)
        self.area[:n] = np.bincount(self.lab, minlength=n)
        self.mx = np.zeros(cap)
        self.mx[:n] = _label_max(clr_flat, self.lab, n)
        self.next = n
        self.w = nav.shape[1]
        self.size = self.lab.shape[0]

    def find(self, x: int) -> int:
        parent = self.parent
        root = x
        while parent[root] != root:
            root = int(parent[root])
        while parent[x] != root:  # path compression
            nx_ = int(parent[x])
            parent[x] = root
            x = nx_
        return root

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return
        if ra > rb:
            ra, rb = rb, ra
        self.parent[rb] = ra
        self.area[ra] += self.area[rb]
        self.mx[ra] = max(self.mx[ra], self.mx[rb])

    def restore(self, cells: np.ndarray, clr_flat: np.ndarray) -> None:
        """Give back cells (robot space no cut covers any more): new regions of one cell each, joined to every
        labelled 4-neighbour (compiled: ``_holographic_fast.restore``)."""
        k = cells.shape[0]
        if k == 0:
            return
        fast = kernels()
        if fast is not None:
            self.next = fast.restore(
                cells, self.lab, self.parent, self.area, self.mx, clr_flat, self.next, self.w
            )
            return
        ids = np.arange(self.next, self.next + k)
        self.next += k
        self.lab[cells] = ids
        self.area[ids] = 1.0
        self.mx[ids] = clr_flat[cells]
        w, size = self.w, self.size
        col = cells % w
        for off, ok in ((-w, cells >= w), (w, cells < size - w), (-1, col > 0), (1, col < w - 1)):
            nb = cells[ok] + off
            lv = self.lab[nb]
            sel = lv > 0
            for a, b in zip(ids[ok][sel].tolist(), lv[sel].tolist(), strict=True):
                self.union(a, b)

    def roots(self, ids: np.ndarray) -> np.ndarray:
        r = ids.copy()
        while True:
            pr = self.parent[r]
            if np.array_equal(pr, r):
                return r
            r = pr


def segment_regions(
    cands,
    cut_lines: dict,
    nav: np.ndarray,
    free: np.ndarray,
    clr: np.ndarray,
    res: float,
    merge_round,
    room_clr: np.ndarray | None = None,
) -> RegionSegmentation:
    """Region merging on the robot space ``nav`` (bool (H, W)) cut by the candidates ``cands``
    [(cell, direction)] (``cut_lines``: the obstacle-to-obstacle line of each oriented cell): every round,
    ``merge_round(a, b, active, area, mx)`` is given the region (union-find root, 0 = none) on each side of the
    cuts still drawn (``active``: their indices in ``cands``) with every region's area (cells) and largest
    clearance (m), and returns which of them stay (bool per active cut), or None when no rule drops anything
    (the rules are :func:`holoslam.maps.rooms.merge_round`). ``room_clr`` (m, (H, W), default ``clr``): the
    clearance a region's largest clearance is taken from (the rooms' width between walls, furniture not
    counted; float32 will do: it is read when the regions are made and at the cuts' cells, and not kept); ``clr``
    draws the cuts."""
    import cv2

    h, w = nav.shape
    clr_flat = clr.reshape(-1)
    nav_flat = nav.reshape(-1)
    cut_cells, walks = [], []
    for rc, d in cands:
        line = cut_lines.get((int(rc[0]), int(rc[1])))
        segs = _cut_segments(rc, d, clr[rc[0], rc[1]] / res + 2.0, free, line)
        cut_cells.append(_segment_cells(segs, h, w))
        walks.extend(_side_walks(rc, d, int(clr[rc[0], rc[1]] / res) + 8, free))
    n_cuts = len(cands)
    # how many cuts cover each cell: at most one per cut (a cut's cells are distinct)
    cover = np.zeros(h * w, dtype=np.uint16 if n_cuts < 2**16 else np.int32)
    for cc in cut_cells:
        cover[cc] += 1
    total = int(sum(cc.shape[0] for cc in cut_cells))
    # the rooms' width: read at the start and at the cuts' cells only, so that it need not stay in memory
    width_flat = clr_flat if room_clr is None else np.ascontiguousarray(room_clr).reshape(-1)
    regions = _Regions(nav, cover, width_flat, total)
    cut_width = None if room_clr is None else [width_flat[cc] for cc in cut_cells]
    del room_clr, width_flat
    side_walks = _Walks(walks, regions.lab)

    def drop(j: int) -> None:
        cc = cut_cells[j]
        cover[cc] -= 1
        sel = (cover[cc] == 0) & nav_flat[cc]
        back = cc[sel]
        first = regions.next
        regions.restore(back, clr_flat)
        if cut_width is not None and back.shape[0]:  # the regions' largest width: that of their walls
            roots = regions.roots(np.arange(first, first + back.shape[0]))
            np.maximum.at(regions.mx, roots, cut_width[j][sel])
        side_walks.restored(back)

    active = np.arange(n_cuts)
    while True:
        two = np.column_stack([2 * active, 2 * active + 1]).ravel()
        rt = regions.roots(side_walks.labels(regions.lab, two))
        keep = merge_round(rt[0::2], rt[1::2], active, regions.area, regions.mx)
        if keep is None:
            break
        for j in active[~keep].tolist():
            drop(j)
        active = active[keep]

    # the final partition, labelled in raster order
    m = (nav_flat & (cover == 0)).astype(np.uint8).reshape(h, w)
    n_lab, lab = cv2.connectedComponents(m, connectivity=4)
    area = np.bincount(lab.ravel(), minlength=n_lab).astype(np.float64)
    two = np.column_stack([2 * active, 2 * active + 1]).ravel()
    first = side_walks.labels(lab.reshape(-1), two).tolist()
    sides = list(zip(first[0::2], first[1::2], strict=True))
    return RegionSegmentation([cands[j] for j in active.tolist()], int(n_lab), lab, area, sides)


def _label_max(values: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """(n,) the largest value per label 0..n-1 (0 for a label without cells; values are >= 0)."""
    from holoslam.maps.passages import kernels

    v = np.ascontiguousarray(values).reshape(-1)
    lab = np.ascontiguousarray(labels).reshape(-1)
    fast = kernels()
    if fast is not None:
        return fast.label_max(v, lab, n)
    out = np.zeros(n)
    np.maximum.at(out, lab, v)
    return out
