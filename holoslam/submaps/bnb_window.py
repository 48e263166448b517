"""One branch-and-bound window search of the loop search (``holoslam.submaps.loops``), kept so that its second
peaks re-use its discretised points and bounds, and the covariance of a match with such peaks. The compiled
descent (``_bnb_fast.descend``, the one ``bnb.search`` runs) sets aside the nodes it prunes within a margin of
the best, so that the second-peak search resumes from them instead of from the top."""

from __future__ import annotations

import math

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
        c = self.cand
        self.top, self.order = bnb._kernels().top_bounds(pre.prob, pre.levels, pre.starts, c.rows, c.cols,
                                                         c.cells_box, c.box, self.d_top, self.quant)
        a = c.angles
        self.angle_step = abs(float(a[1] - a[0])) if a.size > 1 else math.pi
        self.margin = -1.0  # best()'s margin: the nodes it set aside (aside) and where its top level stopped
        self.aside, self.k_break = np.zeros((0, 5)), 0

    def _descend(self, min_score: float, centres=None, ex=(0, 0), first: bool = False, defer: float = -1.0,
                 resume: bool = False):
        """The kernel's descent above ``min_score`` (mean probability) outside the boxes; ``defer`` >= 0 (score
        units) keeps what it sets aside for a later ``resume`` (see ``_bnb_fast.descend``)."""
        from holoslam.submaps import bnb

        pre, c = self.pre, self.cand
        seeds, k0 = (self.aside, self.k_break) if resume else (np.zeros((0, 5)), 0)
        s, a, x, y, k_break, aside = bnb._kernels().descend(
            pre.prob, pre.levels, pre.starts, c.rows, c.cols, c.cells_box, c.box, self.d_top, self.quant,
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

    def _box_cells(self, exclude_xy: float, exclude_rad: float) -> tuple[int, int]:
        """A box of +-``exclude_xy`` m and +-``exclude_rad`` around a candidate, in cells and angle steps."""
        return (int(math.floor(exclude_xy / self.pre.res + 1e-9)),
                int(math.floor(exclude_rad / self.angle_step + 1e-9)))

    def on_edge(self, match, exclude_xy: float = 0.0, exclude_rad: float = 0.0) -> bool:
        """Whether the box of +-``exclude_xy`` m and +-``exclude_rad`` around ``match`` (a ``bnb.Match`` of this
        window; the match's own peak, as ``second_peaks`` cuts it out) reaches the window's edge: its x or y within
        that many cells of the box's outer cells, or its heading within that many angles of the outer ones of a
        window short of a full turn. The window then does not hold the peak's neighbourhood: the match may be the
        flank of a better place just beyond it (0, 0: the outer cells and angles only)."""
        a, x, y = self.indices(match.aTb)
        ex, ea = self._box_cells(exclude_xy, exclude_rad)
        x_lo, x_hi, y_lo, y_hi = self.cand.box
        n_a = self.cand.angles.size
        turn = n_a > 1 and float(self.cand.angles[-1] - self.cand.angles[0]) >= 2 * math.pi - 1.5 * self.angle_step
        return (x - x_lo <= ex or x_hi - x <= ex or y - y_lo <= ex or y_hi - y <= ex
                or (n_a > 1 and not turn and (a <= ea or n_a - 1 - a <= ea)))

    def second_peaks(self, best, margin: float, exclude_xy: float, exclude_rad: float, count: int = 1,
                     first: bool = False) -> list:
        """Up to ``count`` candidates of the window scoring strictly above ``best.score - margin`` outside
        boxes of +-``exclude_xy`` m (x and y) and +-``exclude_rad`` around ``best`` (a ``bnb.Match`` of this
        window) and around each other: each the exact best outside the boxes so far, or with ``first`` any
        candidate above the threshold (the first the search meets: enough to know that there is one)."""
        ex = self._box_cells(exclude_xy, exclude_rad)
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
