"""The two-layer planning graph of seed 003 (SPEC.md §3): nine-square decomposition, layer 1 of free blocks,
layer 2 of convex safe regions.

Coordinates. Blocks and regions are axis-aligned rectangles of cells stored half-open in *cell-boundary*
coordinates ``(row0, col0, row1, col1)``: they cover rows ``row0 .. row1-1`` and columns ``col0 .. col1-1``.
In boundary coordinates cell (r, c) is the closed square [r, r+1] x [c, c+1], so the closed rectangle
``[row0, row1] x [col0, col1]`` is exactly the closed union of the rectangle's cells: the convex set a
planner may move in. World coordinates follow the grid: x = origin_x + col * resolution,
y = origin_y + row * resolution.

1. **Nine-square decomposition** (S1, :func:`decompose`). The grid is split into 3 x 3 blocks (split lines
   at ``start + (size * i) // 3``, so sizes differ by at most one cell and blocks thinner than 3 cells split
   into fewer, non-empty parts); every block holding both free and non-free cells is split again, until
   blocks are all free or all non-free. *Minimum block size*: a mixed block whose area is at most
   ``min_block_cells ** 2`` cells (``(min_block_cells * resolution) ** 2`` square metres) is not split and
   counts as occupied (S15-S16); ``min_block_cells=1`` gives the exact decomposition (every free cell ends in
   a free block). Unknown cells count as not free. Each level is one vectorised pass: block purity is O(1)
   from a summed-area table (integral image) of the free mask.
2. **Layer 1** (S2). A node per free block: id, centre, size, corners. Two blocks are adjacent when one
   dilated by one cell overlaps the other (so blocks touching at a side or only at a corner are adjacent:
   the 8-neighbourhood of the grid); the edge weight is the distance between centres in metres. Adjacency is
   read off the block label image along each block's right and top boundary lines in one compiled pass
   (``_fast.block_edges``; :func:`layer1_edges_join` is the numpy interval join giving the same pairs).
3. **Layer 2** (S3). Free blocks are visited largest first; an uncovered block seeds a rectangle that grows
   in all four directions over the cells of free blocks (round robin; a direction's step doubles while the
   strip it adds is free and halves when it is not; a direction stops when even a one-cell strip would leave
   the grid or hold a cell outside the free blocks). The result is a maximal obstacle-free rectangle
   containing the seed: a convex safe region. One compiled sequential pass (``_fast.grow_regions``: strip
   tests O(1) from the integral image, containment read off the label image);
   :func:`grow_regions_batched` is the numpy version (growth vectorised over batches of seeds) with the same
   result. Every still-uncovered free
   block lying wholly inside an accepted region is marked covered by it; ``TwoLayerGraph.blocks_of(region)``
   lists those blocks and ``TwoLayerGraph.region_of_block`` gives each block its (single, first) region.
   Regions may overlap. Two regions are adjacent when a layer-1 edge joins blocks of the two regions; their
   *portal* is the intersection of their closed rectangles (a segment, a corner point or, for overlapping
   regions, a rectangle), which is free by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid, world_to_cells

__all__ = [
    "TwoLayerGraph",
    "build_two_layer",
    "decompose",
    "integral_image",
    "rect_free",
    "block_label_image",
    "layer1_edges",
    "unique_int",
    "grow_regions",
    "grow_regions_batched",
    "layer1_edges_join",
]


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def integral_image(free: np.ndarray) -> np.ndarray:
    """(H+1, W+1) summed-area table: ``S[r, c]`` = number of free cells in rows < r, cols < c (int32 while the
    grid has fewer than 2**31 cells, else int64)."""
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    if h * w < 2**31 - 1:
        import cv2

        return cv2.integral(np.ascontiguousarray(free).view(np.uint8))
    dt = np.int64
    S = np.zeros((h + 1, w + 1), dtype=dt)
    np.cumsum(free, axis=0, dtype=dt, out=S[1:, 1:])
    np.cumsum(S[1:, 1:], axis=1, out=S[1:, 1:])
    return S


def rect_free(S: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Number of free cells in each half-open rectangle (N, 4) (row0, col0, row1, col1), vectorised."""
    r0, c0, r1, c1 = (rects[:, i] for i in range(4))
    # in the table's own integer type: every partial sum is a cell count of the grid, so nothing overflows
    W1 = S.shape[1]
    Sf = S.ravel()
    return (Sf[r1 * W1 + c1] - Sf[r0 * W1 + c1]) - (Sf[r1 * W1 + c0] - Sf[r0 * W1 + c0])


def decompose(free: np.ndarray, min_block_cells: int = 1, S: np.ndarray | None = None) -> np.ndarray:
    """Nine-square decomposition of a boolean free mask: the free blocks, (N, 4) int64 half-open
    (row0, col0, row1, col1), in the order the recursion emits them (level by level).

    Mixed blocks of area <= ``min_block_cells ** 2`` count as occupied (see the module docstring). ``S`` is
    the free mask's integral image when the caller already has it.
    """
    free = np.asarray(free, dtype=bool)
    if free.ndim != 2 or free.size == 0:
        raise MapError(f"decompose needs a non-empty 2-D free mask, got shape {free.shape}")
    if int(min_block_cells) < 1:
        raise MapError(f"min_block_cells must be >= 1 cell, got {min_block_cells}")
    min_area = int(min_block_cells) ** 2
    if S is None:
        S = integral_image(free)
    h, w = free.shape
    blocks = np.array([[0, 0, h, w]], dtype=np.int64)
    leaves: list[np.ndarray] = []
    k = np.arange(4, dtype=np.int64)
    while blocks.shape[0]:
        cnt = rect_free(S, blocks)
        bh = blocks[:, 2] - blocks[:, 0]
        bw = blocks[:, 3] - blocks[:, 1]
        area = bh * bw
        full = cnt == area
        if full.any():
            leaves.append(blocks[full])
        split = (cnt > 0) & (cnt < area) & (area > min_area)
        if not split.any():
            break
        b = blocks[split]
        bh, bw = bh[split], bw[split]
        # split lines start + (size * i) // 3, i = 0..3 -> (M, 4)
        rl = b[:, 0:1] + (bh[:, None] * k[None, :]) // 3
        cl = b[:, 1:2] + (bw[:, None] * k[None, :]) // 3
        # children (M, 3, 3, 4), row-major i (rows) then j (cols)
        r0 = np.broadcast_to(rl[:, :3, None], (b.shape[0], 3, 3))
        r1 = np.broadcast_to(rl[:, 1:, None], (b.shape[0], 3, 3))
        c0 = np.broadcast_to(cl[:, None, :3], (b.shape[0], 3, 3))
        c1 = np.broadcast_to(cl[:, None, 1:], (b.shape[0], 3, 3))
        ch = np.stack([r0, c0, r1, c1], axis=-1).reshape(-1, 4)
        keep = (ch[:, 2] > ch[:, 0]) & (ch[:, 3] > ch[:, 1])
        blocks = ch[keep]
    if not leaves:
        return np.zeros((0, 4), dtype=np.int64)
    return np.concatenate(leaves, axis=0)


def block_label_image(blocks: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) int32 image holding each cell's block id, -1 outside every block (one compiled pass writing each
    block's cells; the blocks are disjoint)."""
    from holoslam.planning import _fast

    h, w = shape
    if blocks.shape[0] >= 2**31 - 2:
        raise MapError(f"{blocks.shape[0]} blocks do not fit int32 block ids; use a coarser grid")
    return _fast.label_image(np.ascontiguousarray(blocks, dtype=np.int64), int(h), int(w))


def unique_int(keys: np.ndarray) -> np.ndarray:
    """Sorted unique values of an int array (sort + diff; faster than ``np.unique`` on large arrays)."""
    if keys.shape[0] == 0:
        return keys
    k = np.sort(keys)
    keep = np.empty(k.shape[0], dtype=bool)
    keep[0] = True
    np.not_equal(k[1:], k[:-1], out=keep[1:])
    return k[keep]


def _line_neighbours(
    line_of: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    q_line: np.ndarray,
    q_lo: np.ndarray,
    q_hi: np.ndarray,
    span: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Interval join: for each query i, the blocks j lying on line ``q_line[i]`` (``line_of[j] == q_line[i]``)
    whose interval [start_j, end_j) meets [q_lo_i - 1, q_hi_i + 1) (the one-cell dilation). Sorted keys and
    searchsorted give each query its range of candidates; one predecessor can start before the range."""
    key = line_of * span + (start + 1)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    lo = np.searchsorted(ks, q_line * span + q_lo, side="left")  # start >= q_lo - 1
    hi = np.searchsorted(ks, q_line * span + q_hi + 2, side="left")  # start <= q_hi
    cnt = hi - lo
    qi = np.repeat(np.arange(q_line.shape[0]), cnt)
    off = np.arange(qi.shape[0]) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    bj = order[lo[qi] + off]
    # the predecessor on the same line may start earlier and still reach into the range
    p = lo - 1
    ok = p >= 0
    pj = order[np.where(ok, p, 0)]
    ok &= (line_of[pj] == q_line) & (end[pj] >= q_lo)
    return np.concatenate([qi, np.nonzero(ok)[0]]), np.concatenate([bj, pj[ok]])


def layer1_edges(blocks: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """Adjacent block pairs (E, 2) int64 (each pair once, i < j in a row), by the one-cell dilation rule.

    Two disjoint blocks touch exactly when they share a grid line: a column line (one's ``col1`` is the
    other's ``col0``) with row intervals meeting after a one-cell dilation, or a row line likewise. Read off
    the block label image (``labels``, computed when not given) along each block's right and top boundary
    lines in one compiled pass (O(total block perimeter)); :func:`layer1_edges_join` is the pure-numpy interval
    join on sorted keys giving the same set."""
    n = blocks.shape[0]
    if n == 0:
        return np.zeros((0, 2), dtype=np.int64)
    from holoslam.planning import _fast

    b = np.ascontiguousarray(blocks, dtype=np.int64)
    if labels is None:
        h, w = int(b[:, 2].max()), int(b[:, 3].max())
        labels = block_label_image(b, (h, w))
    return _fast.block_edges(b, np.ascontiguousarray(labels))


def layer1_edges_join(blocks: np.ndarray) -> np.ndarray:
    """The pure-numpy layer-1 adjacency (same pairs as :func:`layer1_edges`, another order): interval joins on
    sorted keys (O(N log N), no pairwise loops, no pass over the cells)."""
    n = blocks.shape[0]
    if n == 0:
        return np.zeros((0, 2), dtype=np.int64)
    r0, c0, r1, c1 = (blocks[:, i].astype(np.int64) for i in range(4))
    span_r = int(r1.max()) + 3
    span_c = int(c1.max()) + 3
    a1, b1 = _line_neighbours(c0, r0, r1, c1, r0, r1, span_r)  # blocks to the right (and right diagonals)
    a2, b2 = _line_neighbours(r0, c0, c1, r1, c0, c1, span_c)  # blocks above (and upper diagonals)
    # each pair is found once, from its left (resp. lower) block, except contacts at a single corner point,
    # which both joins see: keep those from the column join only
    keep = (c0[b2] != c1[a2]) & (c1[b2] != c0[a2])
    a = np.concatenate([a1, a2[keep]])
    b = np.concatenate([b1, b2[keep]])
    return np.column_stack([np.minimum(a, b), np.maximum(a, b)])


def _grow_rectangles(S: np.ndarray, rects: np.ndarray, h: int, w: int) -> np.ndarray:
    """Grow rectangles (B, 4) half-open in four directions until blocked, vectorised over the batch.

    Round robin over up (row1), right (col1), down (row0), left (col0); a direction's step doubles while the
    strip it adds is obstacle-free and inside the grid and halves when it is not; it stops when a one-cell
    strip fails. Strip purity is O(1) from the integral image ``S``."""
    R = rects.astype(np.int64).copy()
    n = R.shape[0]
    step = np.ones((n, 4), dtype=np.int64)
    active = np.ones((n, 4), dtype=bool)
    lim = (h, w, 0, 0)
    while active.any():
        for d in range(4):
            idx = np.nonzero(active[:, d])[0]
            if idx.shape[0] == 0:
                continue
            r0, c0, r1, c1 = R[idx, 0], R[idx, 1], R[idx, 2], R[idx, 3]
            k = step[idx, d]
            if d == 0:
                k = np.minimum(k, lim[0] - r1)
                strip = (r1, c0, r1 + k, c1)
            elif d == 1:
                k = np.minimum(k, lim[1] - c1)
                strip = (r0, c1, r1, c1 + k)
            elif d == 2:
                k = np.minimum(k, r0)
                strip = (r0 - k, c0, r0, c1)
            else:
                k = np.minimum(k, c0)
                strip = (r0, c0 - k, r1, c0)
            a0, b0, a1, b1 = strip
            cnt = S[a1, b1].astype(np.int64) - S[a0, b1] - S[a1, b0] + S[a0, b0]
            ok = (k > 0) & (cnt == (a1 - a0) * (b1 - b0))
            col = (2, 3, 0, 1)[d]
            sign = 1 if d < 2 else -1
            R[idx[ok], col] += sign * k[ok]
            step[idx[ok], d] = k[ok] * 2
            bad = ~ok
            stop = bad & (k <= 1)
            active[idx[stop], d] = False
            shrink = bad & (k > 1)
            step[idx[shrink], d] = k[shrink] // 2
    return R


def grow_regions(
    blocks: np.ndarray,
    free: np.ndarray,
    S: np.ndarray | None = None,
    bucket: int = 32,
    labels: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Layer 2 (S31): convex safe regions grown from uncovered blocks, largest block first.

    Returns ``(regions (R, 4) int64 half-open, region_of_block (N,) int64, region_block_ptr (R+1,),
    region_block_ids (N,))`` where ``region_block_ids[ptr[k]:ptr[k+1]]`` are the blocks region k covers.
    One compiled sequential pass (``_fast.grow_regions``); ``labels`` is the blocks' label image (computed
    when not given); ``bucket`` is unused (kept for callers of the numpy version,
    :func:`grow_regions_batched`, which gives the same result).
    """
    from holoslam.planning import _fast

    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    if S is None:
        S = integral_image(free)
    n = blocks.shape[0]
    if n == 0:
        return (
            np.zeros((0, 4), np.int64),
            np.full(0, -1, np.int64),
            np.zeros(1, np.int64),
            np.zeros(0, np.int64),
        )
    b = np.ascontiguousarray(blocks, dtype=np.int64)
    if labels is None:
        labels = block_label_image(b, (h, w))
    areas = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    seeds = np.argsort(-areas, kind="stable")  # largest first, ties by block id
    return _fast.grow_regions(np.ascontiguousarray(S), b, np.ascontiguousarray(labels), seeds)


def grow_regions_batched(
    blocks: np.ndarray, free: np.ndarray, S: np.ndarray | None = None, bucket: int = 32
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The numpy version of :func:`grow_regions` (growth vectorised over batches of seeds, acceptance in seed
    order), kept as the reference the compiled pass is tested against.

    Returns ``(regions (R, 4) int64 half-open, region_of_block (N,) int64, region_block_ptr (R+1,),
    region_block_ids (N,))`` where ``region_block_ids[ptr[k]:ptr[k+1]]`` are the blocks region k covers.
    """
    free = np.asarray(free, dtype=bool)
    h, w = free.shape
    if S is None:
        S = integral_image(free)
    n = blocks.shape[0]
    region_of_block = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return np.zeros((0, 4), np.int64), region_of_block, np.zeros(1, np.int64), np.zeros(0, np.int64)
    # bucket the blocks by the tile of their lower-left cell for containment queries
    tr, tc = blocks[:, 0] // bucket, blocks[:, 1] // bucket
    ntc = (w + bucket - 1) // bucket
    ntr = (h + bucket - 1) // bucket
    tile = tr * ntc + tc
    order_t = np.argsort(tile, kind="stable")
    tile_ptr = np.searchsorted(tile[order_t], np.arange(ntr * ntc + 1))
    areas = (blocks[:, 2] - blocks[:, 0]) * (blocks[:, 3] - blocks[:, 1])
    seeds = np.lexsort((np.arange(n), -areas))
    B = blocks
    regions: list[tuple[int, int, int, int]] = []
    pos = 0
    chunk = 64
    while pos < n:
        # grow the next chunk of still-uncovered seeds at once (growth depends on obstacles only), then accept
        # them in order below; a seed covered by an earlier region of the chunk is skipped as before
        win = seeds[pos : pos + 4 * chunk]
        unc = np.nonzero(region_of_block[win] < 0)[0]
        if unc.shape[0] == 0:
            pos += win.shape[0]
            continue
        take = unc[:chunk]
        batch = win[take].tolist()
        pos += int(take[-1]) + 1
        chunk = min(chunk * 2, 8192)
        rects = _grow_rectangles(S, B[np.array(batch)], h, w).tolist()
        for s, (r0, c0, r1, c1) in zip(batch, rects, strict=True):
            if region_of_block[s] >= 0:  # covered by a region accepted earlier in this batch
                continue
            rid = len(regions)
            regions.append((r0, c0, r1, c1))
            # candidate blocks: those whose lower-left cell lies in a tile the rectangle touches
            t_c0, t_c1 = c0 // bucket, (c1 - 1) // bucket
            tiles = [
                (t * ntc + t_c0, t * ntc + t_c1 + 1) for t in range(r0 // bucket, (r1 - 1) // bucket + 1)
            ]
            if len(tiles) == 1:
                cand = order_t[tile_ptr[tiles[0][0]] : tile_ptr[tiles[0][1]]]
            else:
                cand = order_t[np.concatenate([np.arange(tile_ptr[a], tile_ptr[b]) for a, b in tiles])]
            bc = B[cand]
            inside = (
                (bc[:, 0] >= r0)
                & (bc[:, 1] >= c0)
                & (bc[:, 2] <= r1)
                & (bc[:, 3] <= c1)
                & (region_of_block[cand] < 0)
            )
            region_of_block[cand[inside]] = rid
    ids = np.argsort(region_of_block, kind="stable")
    ptr = np.searchsorted(region_of_block[ids], np.arange(len(regions) + 1))
    return np.array(regions, dtype=np.int64).reshape(-1, 4), region_of_block, ptr, ids


@dataclass(frozen=True, slots=True)
class TwoLayerGraph:
    """Both layers of seed 003's planning graph over one grid (arrays read-only).

    Layer 1: ``blocks`` (N, 4) half-open cell rectangles of the free blocks (id = row index);
    ``edges`` (E, 2) adjacent block ids (i < j) with ``weights`` (E,) centre distances in metres.
    Layer 2: ``regions`` (R, 4) half-open cell rectangles of the convex safe regions; ``region_block_ptr`` /
    ``region_block_ids`` (CSR) the blocks each region covers; ``region_of_block`` (N,) each block's region;
    ``region_edges`` (F, 2) adjacent regions (i < j) with ``portals`` (F, 4) = the intersection of their
    closed rectangles in boundary coordinates (row_lo, col_lo, row_hi, col_hi), possibly degenerate.
    ``labels`` (H, W) int32 is the block id of each cell (-1 outside free blocks): O(1) point location.
    """

    resolution: float
    origin_x: float
    origin_y: float
    shape: tuple[int, int]
    min_block_cells: int
    blocks: np.ndarray
    edges: np.ndarray
    weights: np.ndarray
    regions: np.ndarray
    region_block_ptr: np.ndarray
    region_block_ids: np.ndarray
    region_of_block: np.ndarray
    region_edges: np.ndarray
    portals: np.ndarray
    labels: np.ndarray

    # ---- layer 1 attributes (seed 003 S21: id, centre, width and height, corners) ----
    @property
    def n_blocks(self) -> int:
        return int(self.blocks.shape[0])

    @property
    def n_regions(self) -> int:
        return int(self.regions.shape[0])

    def rect_corners_xy(self, rects: np.ndarray) -> np.ndarray:
        """(N, 4) world (x_min, y_min, x_max, y_max) of half-open cell rectangles."""
        rects = np.asarray(rects).reshape(-1, 4)
        res = self.resolution
        return np.column_stack(
            [
                self.origin_x + rects[:, 1] * res,
                self.origin_y + rects[:, 0] * res,
                self.origin_x + rects[:, 3] * res,
                self.origin_y + rects[:, 2] * res,
            ]
        )

    @property
    def block_corners_xy(self) -> np.ndarray:
        """(N, 4) world (x_min, y_min, x_max, y_max): lower-left and upper-right corners of each block."""
        return self.rect_corners_xy(self.blocks)

    @property
    def block_centres_xy(self) -> np.ndarray:
        c = self.block_corners_xy
        return np.column_stack([(c[:, 0] + c[:, 2]) / 2, (c[:, 1] + c[:, 3]) / 2])

    @property
    def block_sizes_m(self) -> np.ndarray:
        """(N, 2) (width, height) in metres."""
        c = self.block_corners_xy
        return np.column_stack([c[:, 2] - c[:, 0], c[:, 3] - c[:, 1]])

    @property
    def region_corners_xy(self) -> np.ndarray:
        return self.rect_corners_xy(self.regions)

    def blocks_of(self, region: int) -> np.ndarray:
        return self.region_block_ids[self.region_block_ptr[region] : self.region_block_ptr[region + 1]]

    def block_at(self, xy: np.ndarray) -> np.ndarray:
        """Block id of the cell under each world point (N,) (-1 off the grid or outside free blocks)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        row, col = world_to_cells(xy, self.origin_x, self.origin_y, self.resolution).T
        h, w = self.shape
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        out = np.full(xy.shape[0], -1, dtype=np.int64)
        out[inside] = self.labels[row[inside], col[inside]]
        return out

    def region_at(self, xy: np.ndarray) -> np.ndarray:
        """Region id under each world point (N,), -1 where there is none (O(1) per point)."""
        b = self.block_at(xy)
        out = np.full(b.shape[0], -1, dtype=np.int64)
        out[b >= 0] = self.region_of_block[b[b >= 0]]
        return out

    def free_mask(self) -> np.ndarray:
        """(H, W) bool: the cells covered by free blocks (the grid as the planner sees it)."""
        return self.labels >= 0


def build_two_layer(
    grid: OccupancyGrid | np.ndarray, min_block_cells: int = 1, resolution: float | None = None
):
    """Build both layers from an occupancy grid (free = ``grid.free``) or a boolean free mask.

    ``min_block_cells`` is the minimum block side in cells (area threshold ``min_block_cells ** 2``); in
    metres it is ``min_block_cells * grid.resolution``. Raises ``MapError`` for an empty or malformed grid.
    """
    if isinstance(grid, OccupancyGrid):
        free = grid.free
        res, ox, oy = grid.resolution, grid.origin_x, grid.origin_y
    else:
        free = np.asarray(grid)
        if free.dtype != bool:
            raise MapError("build_two_layer takes an OccupancyGrid or a boolean free mask (True = free)")
        res, ox, oy = (1.0 if resolution is None else float(resolution)), 0.0, 0.0
    S = integral_image(free)
    blocks = decompose(free, min_block_cells, S)
    labels = block_label_image(blocks, free.shape)
    edges = layer1_edges(blocks, labels)
    cen = np.column_stack([(blocks[:, 1] + blocks[:, 3]) * 0.5, (blocks[:, 0] + blocks[:, 2]) * 0.5]) * res
    if edges.shape[0]:
        d = cen[edges[:, 0]] - cen[edges[:, 1]]
        weights = np.hypot(d[:, 0], d[:, 1])
    else:
        weights = np.zeros(0)
    # regions grow in the free space as layer 1 sees it (mixed blocks below the minimum size are occupied)
    eff = labels >= 0
    S_eff = S if min_block_cells == 1 else integral_image(eff)
    regions, region_of_block, ptr, ids = grow_regions(blocks, eff, S_eff, labels=labels)
    # region adjacency from layer-1 edges joining blocks of different regions
    if edges.shape[0]:
        ra, rb = region_of_block[edges[:, 0]], region_of_block[edges[:, 1]]
        m = ra != rb
        lo, hi = np.minimum(ra[m], rb[m]), np.maximum(ra[m], rb[m])
        nr = max(regions.shape[0], 1)
        key = unique_int(lo * nr + hi)
        redges = np.column_stack([key // nr, key % nr])
    else:
        redges = np.zeros((0, 2), dtype=np.int64)
    A, Bq = regions[redges[:, 0]], regions[redges[:, 1]]
    portals = np.column_stack(
        [
            np.maximum(A[:, 0], Bq[:, 0]),
            np.maximum(A[:, 1], Bq[:, 1]),
            np.minimum(A[:, 2], Bq[:, 2]),
            np.minimum(A[:, 3], Bq[:, 3]),
        ]
    )
    return TwoLayerGraph(
        resolution=float(res),
        origin_x=float(ox),
        origin_y=float(oy),
        shape=(int(free.shape[0]), int(free.shape[1])),
        min_block_cells=int(min_block_cells),
        blocks=_ro(blocks),
        edges=_ro(edges),
        weights=_ro(weights),
        regions=_ro(regions),
        region_block_ptr=_ro(ptr),
        region_block_ids=_ro(ids),
        region_of_block=_ro(region_of_block),
        region_edges=_ro(redges),
        portals=_ro(portals.reshape(-1, 4)),
        labels=_ro(labels),
    )
