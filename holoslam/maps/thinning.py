"""Thinning of free space to a one-cell-wide skeleton (seed 000, SPEC.md §2: the Zhang-Suen rule).

Free cells are 1, obstacle / unknown cells and everything outside the grid are 0. For a free cell p1 the
neighbours are p2 north, p3 north-east, p4 east, ..., p9 north-west, clockwise. "North" is row - 1 of the
array as it is indexed (the direction the seed's figure draws upwards); the rule is not symmetric, so
``thin_reference`` and the vectorised code use the same convention. N(p1) is the number of free neighbours,
S(p1) the number of 0 -> 1 transitions in the cyclic sequence p2, p3, ..., p9, p2.

- subiteration 1 deletes p1 when 2 <= N <= 6, S = 1, p2*p4*p6 = 0 and p4*p6*p8 = 0;
- subiteration 2 deletes p1 when 2 <= N <= 6, S = 1, p2*p4*p8 = 0 and p2*p6*p8 = 0;
- cells are only marked during a subiteration, then deleted together; endpoints (N = 1) and isolated cells
  (N = 0) are never deleted (N >= 2 already excludes them); both subiterations repeat until nothing changes.

Vectorised form: the 8 neighbours of a cell are packed into an 8-bit code (bit k = p(k+2)), and each rule is a
256-entry lookup table. Only cells that can still change are looked at: in the first two subiterations the
free cells that touch a non-free cell (a cell whose 8 neighbours are all free has N = 8 and stays), later the
free neighbours of the cells deleted in the previous two subiterations (a cell whose neighbourhood has not
changed since the last time the same rule looked at it gives the same answer). So the work is proportional to
the number of deleted cells, not to grid size times iterations. Details that matter for speed at 4000 x 4000
(measured in benchmarks/bench_thinning.py): the codes are kept up to date as cells are deleted (a deleted
cell's own code says which neighbours to update; its code then becomes 0xFF, which no rule marks, so stale
candidates drop out by code alone); the neighbours of a batch are looked up once, for both rules, right after
it (``_zs_passes``); indices are intp (numpy converts int32 index arrays before every gather and scatter,
several times slower) and scatters are ``a[idx] = v`` rather than ``np.put``; rows are padded to a power of
two so a cell's class (row % 2, col % 2) is two bit tests; the first codes come from one cv2.filter2D.
A whole-array pass per subiteration (a lookup table on the filter2D code) costs ~16 M cells x 4 guarded
classes x ~100 subiterations on a 4000 x 4000 map of small rooms, an order of magnitude more than this.

Compiled form (what ``thin`` and ``zhang_suen`` run; :mod:`holoslam.maps._thin_fast`, numba): the same
active-set subiterations, guard and one-cell-thin passes as numba kernels over the padded uint8 grid and a cell
queue, cell for cell equal to the numpy path (kept as ``_thin_numpy``: the fallback without numba and the
reference of the tests). What made it fast at 4000 x 4000 is memory order, not compilation alone (a plain
port was no faster than numpy): each subiteration's candidates are counting-sorted by row, and the guard's
four classes are done in one wavefront sweep (row r, class c at step r + c) instead of four sweeps of the grid.

What the seed asks for but the bare rule does not give (``thin``), each a documented addition:

1. **Topology guard.** The parallel rule can delete a whole small region (a 2 x 2 block of free cells is
   deleted entirely in subiteration 1) or cut a two-cell-thick diagonal line. ``thin`` deletes the cells the
   rule marked in four interleaved classes (row % 2, col % 2); cells of one class are never 8-adjacent, so
   deleting them one class after the other is the same as deleting them one by one, and a marked cell is
   deleted only if, at its turn, it is still a *simple point* (8-connected free space, 4-connected obstacles:
   deleting it changes neither the number of free components nor the number of holes) and not a line tip.
   Hence every free component keeps at least one cell and every hole stays a hole. A *tip* (the seed's
   "endpoint", which the seed says must be detected and kept at every step) is a cell with one free
   neighbour, or with two free neighbours that touch each other: on a diagonal or staircase line the end
   cell has two such neighbours, and the bare rule (N >= 2) erodes those lines from their ends, one cell
   per iteration, until they vanish.
2. **One cell thin.** The bare rule leaves two-cell staircases (on diagonals and at corners, e.g. the L
   ``(0,0),(0,1),(1,1)``) whose corner cell could be deleted without changing topology. ``thin`` ends with
   passes that delete, in the same four classes, every cell that is simple and not a tip, until none is
   left: the result has no *removable* cell (``count_removable`` is 0).
3. **Pre-processing (optional).** ``erode_cells`` erodes free space by a disc of that radius (the robot
   radius in cells: the skeleton then only runs where the robot fits) and ``close_cells`` first closes
   obstacle gaps narrower than about twice that radius in free space (a morphological opening of the free
   mask: a one-cell speckle of "free" inside a wall is not a passage). Both change topology on purpose and
   are off by default.

Connectivity used throughout: free cells (and skeleton cells) are 8-connected, obstacles 4-connected.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from holoslam.errors import MapError

__all__ = [
    "thin",
    "thin_reference",
    "zhang_suen",
    "count_removable",
    "removable_mask",
    "neighbour_codes",
    "preprocess_free",
]

# (drow, dcol) of p2 .. p9: north, north-east, east, south-east, south, south-west, west, north-west.
NEIGHBOUR_OFFSETS: tuple[tuple[int, int], ...] = (
    (-1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
    (1, 0),
    (1, -1),
    (0, -1),
    (-1, -1),
)


def _bits(code: int) -> list[int]:
    return [(code >> k) & 1 for k in range(8)]  # p2 .. p9


def _n_s(code: int) -> tuple[int, int]:
    p = _bits(code)
    n = sum(p)
    s = sum(1 for k in range(8) if p[k] == 0 and p[(k + 1) % 8] == 1)
    return n, s


def _zs_rule(code: int, step: int) -> bool:
    p2, p3, p4, p5, p6, p7, p8, p9 = _bits(code)
    n, s = _n_s(code)
    if not (2 <= n <= 6 and s == 1):
        return False
    if step == 1:
        return p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
    return p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0


def _is_simple(code: int) -> bool:
    """(8, 4) simple point: the free neighbours form exactly one 8-connected component and the obstacle
    neighbours exactly one 4-connected component that touches the centre's 4-neighbours (topological numbers
    T8 = 1 and T4bar = 1). Deleting such a cell changes neither free components nor holes."""
    p = _bits(code)
    pos = NEIGHBOUR_OFFSETS
    fg = [k for k in range(8) if p[k]]
    bg = [k for k in range(8) if not p[k]]

    def components(cells: list[int], adjacent) -> list[set[int]]:
        comps: list[set[int]] = []
        todo = set(cells)
        while todo:
            stack = [todo.pop()]
            comp = set(stack)
            while stack:
                a = stack.pop()
                for b in list(todo):
                    if adjacent(pos[a], pos[b]):
                        todo.discard(b)
                        comp.add(b)
                        stack.append(b)
            comps.append(comp)
        return comps

    def adj8(a, b) -> bool:
        return max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1

    def adj4(a, b) -> bool:
        return abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1

    t8 = len(components(fg, adj8))
    four = {0, 2, 4, 6}  # p2, p4, p6, p8: the 4-neighbours of the centre
    t4bar = sum(1 for c in components(bg, adj4) if c & four)
    return t8 == 1 and t4bar == 1


def _is_tip(code: int) -> bool:
    """An endpoint of a line: isolated, one free neighbour, or two free neighbours that touch each other
    (consecutive around the ring, e.g. east and south-east: the end of a diagonal or staircase line)."""
    n = bin(code).count("1")
    rot = ((code << 1) | (code >> 7)) & 0xFF
    return n <= 1 or (n == 2 and (code & rot) != 0)


@cache
def _tables() -> dict[str, np.ndarray]:
    codes = range(256)
    n = np.array([_n_s(c)[0] for c in codes], dtype=np.int8)
    simple = np.array([_is_simple(c) for c in codes], dtype=bool)
    return {
        "zs1": np.array([_zs_rule(c, 1) for c in codes], dtype=bool),
        "zs2": np.array([_zs_rule(c, 2) for c in codes], dtype=bool),
        "n": n,
        "simple": simple,
        "tip": np.array([_is_tip(c) for c in codes], dtype=bool),
        "removable": simple & ~np.array([_is_tip(c) for c in codes], dtype=bool),
    }


def _as_mask(free: np.ndarray) -> np.ndarray:
    a = np.asarray(free)
    if a.ndim != 2:
        raise MapError(f"thinning needs a 2-D (H, W) mask of free cells, got shape {a.shape}")
    return a.astype(bool, copy=False)


def neighbour_codes(mask: np.ndarray) -> np.ndarray:
    """(H, W) uint8: bit k set when neighbour p(k+2) is set (outside the grid counts as 0). One cv2.filter2D
    correlation with the powers of two (exact: the sum is at most 255)."""
    import cv2

    m = np.ascontiguousarray(_as_mask(mask)).view(np.uint8)
    kernel = np.zeros((3, 3), dtype=np.float32)
    for k, (dr, dc) in enumerate(NEIGHBOUR_OFFSETS):
        kernel[1 + dr, 1 + dc] = 1 << k
    return cv2.filter2D(m, cv2.CV_8U, kernel, borderType=cv2.BORDER_CONSTANT)


def removable_mask(skeleton: np.ndarray) -> np.ndarray:
    """(H, W) bool: set cells that are simple points and not line tips (see ``_is_tip``: one neighbour, or
    two neighbours touching each other), i.e. cells that could be deleted without changing the number of
    components or holes and without shortening a line."""
    m = _as_mask(skeleton)
    return m & _tables()["removable"][neighbour_codes(m)]


def count_removable(skeleton: np.ndarray) -> int:
    """Number of skeleton cells that could still be removed without changing topology (see removable_mask)."""
    return int(np.count_nonzero(removable_mask(skeleton)))


def thin_reference(free: np.ndarray) -> np.ndarray:
    """The bare seed rule, written out cell by cell (slow; for tests on small grids)."""
    img = _as_mask(free).astype(np.uint8)
    h, w = img.shape

    def px(r: int, c: int) -> int:
        return int(img[r, c]) if 0 <= r < h and 0 <= c < w else 0

    changed = True
    while changed:
        changed = False
        for step in (1, 2):
            marked = []
            for r in range(h):
                for c in range(w):
                    if not img[r, c]:
                        continue
                    p2, p3, p4, p5, p6, p7, p8, p9 = (px(r + dr, c + dc) for dr, dc in NEIGHBOUR_OFFSETS)
                    seq = [p2, p3, p4, p5, p6, p7, p8, p9, p2]
                    n = p2 + p3 + p4 + p5 + p6 + p7 + p8 + p9
                    s = sum(1 for i in range(8) if seq[i] == 0 and seq[i + 1] == 1)
                    if not (2 <= n <= 6 and s == 1):
                        continue
                    if step == 1 and p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0:
                        marked.append((r, c))
                    if step == 2 and p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0:
                        marked.append((r, c))
            for r, c in marked:
                img[r, c] = 0
            changed = changed or bool(marked)
    return img.astype(bool)


class _Flat:
    """A zero-padded copy of a mask as a flat uint8 array ``a``, with the neighbour code of every cell kept
    up to date in ``code`` as cells are deleted (so a cell's code is one lookup, not eight)."""

    def __init__(self, mask: np.ndarray) -> None:
        h, w = mask.shape
        # rows padded to a power of two (at least w + 2): a cell's row and column parity are then bit tests
        self.shift = (w + 1).bit_length()
        self.h, self.w, self.w2 = h, w, 1 << self.shift
        pad = np.zeros((h + 2, self.w2), dtype=np.uint8)
        pad[1:-1, 1 : w + 1] = mask
        self.a = pad.ravel()
        self.code = neighbour_codes(pad).ravel()
        # intp indices: numpy gathers/scatters with int32 indices convert them first (several times slower)
        self.itype = np.intp
        self.offsets = [self.itype(dr * self.w2 + dc) for dr, dc in NEIGHBOUR_OFFSETS]
        # clearing bit (k + 4) % 8 of the cell at d + offset[k] tells it that d was deleted
        self.clear = [np.uint8(0xFF ^ (1 << ((k + 4) % 8))) for k in range(8)]

    def unique(self, idx: np.ndarray) -> np.ndarray:
        """Distinct values of idx, sorted (a sort beat a scratch-array stamp here, and leaves the later
        gathers in memory order)."""
        if idx.shape[0] < 2:
            return idx
        s = np.sort(idx)
        keep = np.empty(s.shape[0], dtype=bool)
        keep[0] = True
        np.not_equal(s[1:], s[:-1], out=keep[1:])
        return s[keep]

    def delete(self, idx: np.ndarray) -> np.ndarray:
        """Delete the set cells idx (repeats are harmless); return their neighbours that were set before
        this call (with repeats). A cell's own code says which neighbours are set, so only those codes are
        touched. A deleted cell's code becomes 0xFF (eight neighbours), which no rule marks and which is not
        removable, so callers can drop deleted cells by their code alone, without looking at ``a``."""
        if idx.size == 0:
            return idx
        a, code = self.a, self.code
        c = np.take(code, idx)
        a[idx] = 0
        nbs = []
        for k, (off, clear) in enumerate(zip(self.offsets, self.clear, strict=True)):
            q = idx[(c & np.uint8(1 << k)) != 0] + off
            code[q] = np.take(code, q) & clear  # setitem: much faster than np.put
            nbs.append(q)
        code[idx] = 0xFF
        return np.concatenate(nbs)  # not deduplicated: callers deduplicate the (fewer) cells they mark

    def parity(self, idx: np.ndarray) -> np.ndarray:
        """Class (row % 2) * 2 + (col % 2) of each cell."""
        return ((idx >> self.shift) & 1) * 2 + (idx & 1)

    def boundary(self) -> np.ndarray:
        """Set cells with at least one unset 8-neighbour."""
        return np.flatnonzero((self.a != 0) & (self.code != 0xFF)).astype(self.itype)

    def mask(self) -> np.ndarray:
        return self.a.reshape(self.h + 2, self.w2)[1:-1, 1 : self.w + 1].astype(bool)


def _zs_passes(g: _Flat, guard: bool) -> None:
    """Zhang-Suen subiterations on g in place; with guard, deletions go through the topology guard.

    A cell's answer to a rule changes only when its neighbourhood does. So right after subiteration k the
    set neighbours of its deleted cells (``touched``) are looked up once, for both rules: those the next
    rule marks are exactly the next subiteration's marks from this batch (``now``); those the rule after
    marks (``later``) are checked again two subiterations on, in case their neighbourhood changed in
    between (then they are also in that batch's ``touched``). Cells that neither rule marks are dropped;
    they come back only if a neighbour is deleted. The first two subiterations start from the free cells
    that touch a non-free cell."""
    t = _tables()
    rules = (t["zs1"], t["zs2"])
    boundary = g.boundary()
    c = np.take(g.code, boundary)
    now = boundary[np.take(rules[0], c)]
    later_prev = boundary[:0]  # to check again at k
    later_new = boundary[np.take(rules[1], c)]  # to check again at k + 1
    k = 0
    quiet = 0
    while quiet < 2:
        rule = rules[k % 2]
        old = later_prev[np.take(rule, np.take(g.code, later_prev))]  # deleted cells have code 0xFF
        marked = g.unique(np.concatenate([now, old])) if old.size else g.unique(now)
        if guard:
            deleted, touched = _guarded_delete(g, marked)
        else:
            deleted, touched = marked, g.delete(marked)
        c = np.take(g.code, touched)  # cells deleted since have code 0xFF: no rule marks them
        now = touched[np.take(rules[(k + 1) % 2], c)]
        later_prev, later_new = later_new, touched[np.take(rule, c)]
        quiet = quiet + 1 if deleted.size == 0 else 0
        k += 1


def _guarded_delete(g: _Flat, marked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Delete marked cells class by class (no two cells of a class are 8-adjacent), each only if it is still
    a simple point and not an endpoint when its class is deleted. Returns the deleted cells and their set
    neighbours."""
    if marked.size == 0:
        return marked, marked
    removable = _tables()["removable"]
    par = g.parity(marked)
    out, touched = [], []
    for cls in range(4):
        sel = marked[par == cls]
        sel = sel[removable[g.code[sel]]]
        touched.append(g.delete(sel))
        out.append(sel)
    return np.concatenate(out), np.concatenate(touched)


def _one_cell_thin(g: _Flat) -> None:
    """Delete simple non-endpoint cells, class by class, until none is left."""
    removable = _tables()["removable"]
    cand = np.flatnonzero(g.a).astype(g.itype)
    while cand.size:
        cand = cand[g.a[cand] != 0]
        deleted, cand = _guarded_delete(g, g.unique(cand[removable[g.code[cand]]]))
        if deleted.size == 0:
            break


def zhang_suen(free: np.ndarray) -> np.ndarray:
    """The bare seed rule, vectorised (equal to ``thin_reference`` on every input)."""
    return _thin_mask(_as_mask(free), guard=False, one_cell=False)


def _kernels():
    """The compiled kernels (:mod:`holoslam.maps._thin_fast`), or None when numba is missing (then the numpy
    active-set path ``_thin_numpy`` runs: same result, slower)."""
    try:
        from holoslam.maps import _thin_fast
    except ImportError:  # pragma: no cover - numba is a declared dependency
        return None
    return _thin_fast


def _thin_numpy(m: np.ndarray, *, guard: bool, one_cell: bool) -> np.ndarray:
    """The numpy active-set implementation (``_Flat``, ``_zs_passes``, ``_one_cell_thin``): the fallback when
    numba is missing and the reference the compiled kernels are tested against."""
    g = _Flat(m)
    _zs_passes(g, guard=guard)
    if one_cell:
        _one_cell_thin(g)
    return g.mask()


def _thin_mask(m: np.ndarray, *, guard: bool, one_cell: bool, numba: bool = True) -> np.ndarray:
    """Zhang-Suen (guarded or bare), then optionally the one-cell-thin passes, on the bool mask m; compiled
    (:func:`holoslam.maps._thin_fast.thin_flat` on a zero-padded flat grid) unless numba is off or missing."""
    fast = _kernels() if numba else None
    if fast is None:
        return _thin_numpy(m, guard=guard, one_cell=one_cell)
    h, w = m.shape
    shift = (w + 1).bit_length()  # rows padded to a power of two: a cell's class is two bit tests
    if (h + 2) << shift >= 2**31:  # the kernels index with int32
        return _thin_numpy(m, guard=guard, one_cell=one_cell)
    pad = np.zeros((h + 2, 1 << shift), dtype=np.uint8)
    pad[1:-1, 1 : w + 1] = m
    t = _tables()
    fast.thin_flat(pad.reshape(-1), shift, t["zs1"], t["zs2"], t["removable"], guard, one_cell)
    return pad[1:-1, 1 : w + 1].astype(bool)


def preprocess_free(free: np.ndarray, *, erode_cells: int = 0, close_cells: int = 0) -> np.ndarray:
    """Optional clean-up before thinning (changes topology on purpose): remove free specks narrower than
    about 2 * close_cells + 1 cells (a morphological opening of free space), then erode free space by a
    disc of radius erode_cells (the robot radius in cells)."""
    import cv2

    m: np.ndarray = _as_mask(free).astype(np.uint8)
    if close_cells < 0 or erode_cells < 0:
        raise MapError(f"close_cells and erode_cells must be >= 0, got {close_cells} and {erode_cells}")
    if close_cells:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_cells + 1, 2 * close_cells + 1))
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    if erode_cells:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode_cells + 1, 2 * erode_cells + 1))
        m = cv2.erode(m, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return m.astype(bool)


def thin(
    free: np.ndarray,
    *,
    preserve_topology: bool = True,
    one_cell: bool = True,
    erode_cells: int = 0,
    close_cells: int = 0,
) -> np.ndarray:
    """Skeleton of free space: the seed's rule plus the documented additions (module docstring).

    With ``preserve_topology`` the rule's deletions go through the topology guard (addition 1); with
    ``one_cell`` the result is left without removable cells (addition 2); ``erode_cells`` / ``close_cells``
    pre-process free space (addition 3). With both flags off this is the bare rule (``zhang_suen``).
    """
    m = _as_mask(free)
    if erode_cells or close_cells:
        m = preprocess_free(m, erode_cells=erode_cells, close_cells=close_cells)
    return _thin_mask(m, guard=preserve_topology, one_cell=one_cell)
