"""One branch-and-bound window search of the loop search (``holoslam.submaps.loops``), kept so that its second
peaks re-use its discretised points and bounds, and the covariance of a match with such peaks. The compiled
descent (numba, built on first use and cached on disk like ``_bnb_fast``) sets aside the nodes it prunes within
a margin of the best, so that the second-peak search resumes from them instead of from the top."""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["SearchWindow", "spanning_covariance"]


class SearchWindow:
    """One branch-and-bound search of a scan against a precomputed submap (``bnb.search``'s candidates and
    algorithm), kept so that the ambiguity search re-uses its discretised points and its top level's bounds:
    a second peak costs only the descent."""

    def __init__(self, pre, b_pts, seed, wxy: float, wth: float) -> None:
        from holoslam.submaps import bnb

        self.pre = pre
        self.cand = bnb._candidates(pre, b_pts, seed, wxy, wth, None)
        n = self.cand.rows.shape[1]
        self.n = n
        self.quant = (pre.q_lo, pre.q_step, float(pre.q_out), float(bnb.OUTSIDE), bnb._SLACK * n)
        self.d_top = bnb._top_level(pre, self.cand.box)
        k = _kernels()
        self.top, self.order = k[0](pre.prob, pre.levels, pre.starts, self.cand.rows, self.cand.cols,
                                    self.cand.box, self.d_top, self.quant)
        a = self.cand.angles
        self.angle_step = abs(float(a[1] - a[0])) if a.size > 1 else math.pi
        self.margin = -1.0  # best()'s margin: the nodes it set aside (aside) and where its top level stopped
        self.aside, self.k_break = np.zeros((0, 5)), 0

    def _descend(self, min_score: float, centres=None, ex=(0, 0), first: bool = False, defer: float = -1.0,
                 resume: bool = False):
        """The kernel's descent above ``min_score`` (mean probability) outside the boxes; ``defer`` >= 0 (score
        units) keeps what it sets aside for a later ``resume`` (see ``_descend_py``)."""
        from holoslam.submaps import bnb

        pre, c = self.pre, self.cand
        seeds, k0 = (self.aside, self.k_break) if resume else (np.zeros((0, 5)), 0)
        s, a, x, y, k_break, aside = _kernels()[1](
            pre.prob, pre.levels, pre.starts, c.rows, c.cols, c.box, self.d_top, self.quant,
            float(min_score) * self.n, self.top, self.order, k0, seeds,
            np.asarray(centres if centres is not None else np.zeros((0, 3)), np.int64).reshape(-1, 3),
            np.asarray(ex, np.int64), first, float(defer) * self.n if defer >= 0 else -1.0)
        if defer >= 0:
            self.aside, self.k_break = aside[np.argsort(-aside[:, 4], kind="stable")], k_break
        return None if a < 0 else bnb._match(self.cand, self.pre.res, a, x, y, s)

    def best(self, min_score: float, margin: float = -1.0):
        """``bnb.search``: the best candidate strictly above ``min_score`` (None if there is none). With
        ``margin`` >= 0 the nodes it prunes within ``margin`` of the best are kept: a second peak search with
        that margin then starts from them instead of from the top (the same result for less work)."""
        self.margin = margin
        # a hair more than the margin: rounding of (best - margin) n can never leave a node out
        return self._descend(min_score, defer=margin + 1e-9 if margin >= 0 else -1.0)

    def indices(self, aTb: np.ndarray) -> tuple[int, int, int]:
        """The candidate (angle, x, y) indices of a pose on the window's lattice."""
        c, res = self.cand, self.pre.res
        a = int(np.argmin(np.abs(g.wrap(c.angles - aTb[2]))))
        return a, int(round((aTb[0] - c.seed[0]) / res)), int(round((aTb[1] - c.seed[1]) / res))

    def second_peaks(self, best, margin: float, exclude_xy: float, exclude_rad: float, count: int = 1,
                     first: bool = False) -> list:
        """Up to ``count`` candidates of the window scoring strictly above ``best.score - margin`` outside
        boxes of +-``exclude_xy`` m (x and y) and +-``exclude_rad`` around ``best`` (a ``bnb.Match`` of this
        window) and around each other: each the exact best outside the boxes so far, or with ``first`` any
        candidate above the threshold (the first the search meets: enough to know that there is one)."""
        ex = (int(math.floor(exclude_xy / self.pre.res + 1e-9)),
              int(math.floor(exclude_rad / self.angle_step + 1e-9)))
        centres = [self.indices(best.aTb)]
        found = []
        for k in range(max(0, int(count))):
            # the first resumes from what best() set aside when it kept that much (it holds every node that can
            # lead to a candidate above best - margin); later ones, with more boxes, start from the top
            resume = k == 0 and 0 <= margin <= self.margin
            p = self._descend(best.score - margin, centres, ex, first, resume=resume)
            if p is None:
                break
            found.append(p)
            centres.append(self.indices(p.aTb))
        return found


def spanning_covariance(aTb: np.ndarray, cov_aTb: np.ndarray, others) -> np.ndarray:
    """The covariance of a match about ``aTb`` when the poses ``others`` are as likely as it: the second moment
    of the equal mixture of all of them about ``aTb`` (errors in ``aTb``'s frame, as ``cov_aTb``) added."""
    d = np.array([g.between(aTb, np.asarray(o, float)) for o in others]).reshape(-1, 3)
    d[:, 2] = g.wrap(d[:, 2])
    return np.asarray(cov_aTb, float) + d.T @ d / (len(d) + 1)


def _top_py(prob, levels, starts, rows, cols, box, d_top, quant):  # pragma: no cover - compiled
    """The bounds of the top level's nodes (``_bnb_fast.branch_and_bound``'s first step) and their order, best
    first: (bounds (A nx ny,), order)."""
    n_ang = rows.shape[0]
    x_lo, x_hi, y_lo, y_hi = box
    w = 1 << d_top
    nx = (x_hi - x_lo) // w + 1
    ny = (y_hi - y_lo) // w + 1
    bb = _bnb_fast._boxes(rows, cols)
    top = np.empty(n_ang * nx * ny, dtype=np.float64)
    for a in range(n_ang):
        for ix in range(nx):
            for iy in range(ny):
                top[(a * nx + ix) * ny + iy] = _bnb_fast._score(prob, levels, starts, d_top, rows, cols, bb, a,
                                                                x_lo + ix * w, y_lo + iy * w, quant)
    return top, np.argsort(-top, kind="mergesort")


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


def _workspace(box, d_top, rows, cols, defer):  # pragma: no cover - compiled
    """``_descend_py``'s arrays: the top level's node counts (nx, ny), the scan's cell boxes, the depth-first
    stack (angle, x, y, level, bound), the children scratch (cx, cy, cs) and the set-aside buffer."""
    w = 1 << d_top
    cap = 4 * d_top + 4
    st = (np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64),
          np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.float64))
    return ((box[1] - box[0]) // w + 1, (box[3] - box[2]) // w + 1, _bnb_fast._boxes(rows, cols), st,
            np.empty(4, dtype=np.int64), np.empty(4, dtype=np.int64), np.empty(4, dtype=np.float64),
            np.empty((64 if defer >= 0 else 0, 5), dtype=np.float64))


def _seed(seeds, j):  # pragma: no cover - compiled
    """Row j of the seeds (angle, x, y, level, bound) as a stack entry."""
    return int(seeds[j, 0]), int(seeds[j, 1]), int(seeds[j, 2]), int(seeds[j, 3]), seeds[j, 4]


def _top_node(k, nx, ny, x_lo, y_lo, d_top, top):  # pragma: no cover - compiled
    """Top-level node k (angle-major, then x, then y) as a stack entry (angle, x, y, level, bound)."""
    w = 1 << d_top
    a, rem = divmod(k, nx * ny)
    return a, x_lo + (rem // ny) * w, y_lo + (rem % ny) * w, d_top, top[k]


def _descend_py(prob, levels, starts, rows, cols, box, d_top, quant, best0, top, order, k0, seeds, centres, ex,
                first, defer):  # pragma: no cover - compiled
    """The rest of ``_bnb_fast.branch_and_bound`` (depth first, best child first): first from the nodes
    ``seeds`` (m, 5: angle, x, y, level, bound), then from the top level's nodes ``order[k0:]`` until their bound
    falls to the best. With no seeds, k0 = 0 and no boxes: the same nodes in the same order as
    branch_and_bound, hence the same result.

    Boxes cut out: no candidate within +-ex[0] offsets (x and y) and +-ex[1] angle indices of any of ``centres``
    (k, 3: angle, x, y) is returned, and a node whose block lies inside one box is dropped (the bounds of the
    others are still upper bounds: the result is exact). ``first``: return the first candidate above best0 met
    instead of the best. ``defer`` >= 0: every node or candidate set aside with a bound above (best at the time -
    defer) is returned, so that a search for anything above (final best - defer) can start from them and from
    ``order[k_break:]`` instead of from the top (each node is set aside with a bound <= the best at the time, which
    never exceeds the final best). Returns (sum, a, x, y, k_break, set-aside nodes (m', 5)); a = -1 when nothing
    outside the boxes beats best0 (strictly)."""
    x_lo, x_hi, y_lo, y_hi = box
    nx, ny, bb, st, cx, cy, cs, buf = _workspace(box, d_top, rows, cols, defer)
    nd = 0
    best, ba, bx, by = best0, -1, 0, 0
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
                    buf, nd = _defer(buf, nd, ba, bx, by, 0, best)
                best, ba, bx, by = st[4][sp], a, x, y
                if first:
                    return best, ba, bx, by, k_break, buf[:nd]
                continue
            if defer < 0:
                sp, _ = _bnb_fast._push_children(prob, levels, starts, rows, cols, bb, a, x, y, d, box, quant,
                                                 best, st, sp, cx, cy, cs)
                continue
            # _bnb_fast._push_children, setting aside the children it drops
            h = 1 << (d - 1)
            ns = 0
            for dx in range(2):
                if x + dx * h > x_hi:
                    break
                for dy in range(2):
                    if y + dy * h > y_hi:
                        break
                    sc = _bnb_fast._score(prob, levels, starts, d - 1, rows, cols, bb, a, x + dx * h, y + dy * h,
                                          quant)
                    if sc > best:
                        q = ns
                        while q > 0 and cs[q - 1] > sc:
                            cx[q], cy[q], cs[q] = cx[q - 1], cy[q - 1], cs[q - 1]
                            q -= 1
                        cx[q], cy[q], cs[q] = x + dx * h, y + dy * h, sc
                        ns += 1
                    elif sc > best - defer:
                        buf, nd = _defer(buf, nd, a, x + dx * h, y + dy * h, d - 1, sc)
            for q in range(ns):
                st[0][sp], st[1][sp], st[2][sp], st[3][sp], st[4][sp] = a, cx[q], cy[q], d - 1, cs[q]
                sp += 1
    return best, ba, bx, by, k_break, buf[:nd]


_bnb_fast: Any = None  # holoslam.submaps._bnb_fast once _kernels() has run (the compiled functions call into it)
_KERNELS = None
_KERNELS_LOCK = threading.Lock()


def _kernels():
    """(``_top_py``, ``_descend_py``) compiled with numba on first use (this module does not import numba:
    the front end's other users of it load it lazily too); cached on disk like ``_bnb_fast``. Under a lock: the
    loop search's windows call it from a thread pool, and two threads compiling at once wrapped the same globals
    twice (numba's "jit decorator called on an already jitted function")."""
    global _bnb_fast, _KERNELS
    with _KERNELS_LOCK:
        if _KERNELS is not None:
            return _KERNELS
        import numba as nb

        from holoslam._jit import JIT
        from holoslam.submaps import _bnb_fast as fast

        _bnb_fast = fast
        jit = nb.njit(**JIT)
        global _defer, _workspace, _seed, _top_node
        # called by _descend_py: compiled first, as the globals it reads
        _defer, _workspace, _seed, _top_node = jit(_defer), jit(_workspace), jit(_seed), jit(_top_node)
        _KERNELS = (jit(_top_py), jit(_descend_py))
    return _KERNELS
