"""The local geometric map of a submap as a probability grid (seed 002's "local geometric map"; SPEC §8).

Each scan inserted into a submap raises the odds of the cells that hold its returns and lowers those its beams
cross (each cell updated at most once per scan, a return never cleared by its own scan). The grid grows as
scans reach beyond it. :meth:`GridBuilder.freeze` gives a :class:`ProbGrid`: the probability that a cell is
occupied, clamped to [``p_min``, ``p_max``], unknown cells at ``p_min`` so a scan never matches into unexplored
space. Scan matching (``scanmatch``) and loop-closure search (``bnb``) read that array.

Defaults (:class:`GridConfig`) are Cartographer's published 2D settings (Hess et al. 2016, SPEC §8), chosen for
real laser scanners, not for holoslam's simulator: 0.05 m cells, hit probability 0.55, miss 0.49, probabilities
clamped to [0.1, 0.9] (odds 9:1), returns beyond 30 m not inserted, and a beam without a return clearing 5 m.

A slower laser hits each wall cell fewer times over the same travel, so its walls would build up over a longer
stretch behind the frontier: a probability ramp that scan matching climbs backwards, shortening straight motion
(``GridConfig.for_rate``). Its odds updates are scaled up by the ratio of rates, so that a wall gathers the same
evidence per metre travelled as at the rate the defaults were measured at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["GridConfig", "ProbGrid", "GridBuilder", "scan_endpoints", "cells_at", "bridge_returns"]


@dataclass(frozen=True, slots=True)
class GridConfig:
    resolution: float = 0.05  # m per cell
    hit_probability: float = 0.55  # odds update of a cell holding a return
    miss_probability: float = 0.49  # odds update of a cell a beam crosses
    p_min: float = 0.1  # probabilities clamped to [p_min, p_max]; unknown cells read p_min
    p_max: float = 0.9
    max_range: float = 30.0  # m: returns farther than this are treated as no return
    missing_ray_length: float = 5.0  # m of free space cleared along a beam without a return
    grow_margin: float = 5.0  # m added around the scans when the grid grows
    # Hz: the scan rate the odds updates above were measured at (the three Freiburg logs at full rate, 4.6-5.4 Hz;
    # Cartographer's lasers are faster still). A slower laser's updates are scaled by reference / rate in log-odds
    # (``for_rate``); 0 turns the scaling off. Measured on the same logs at 1.0-1.25 Hz with half the beams: local
    # SLAM shortened straight motion by 3.1-6.5 % (the wheels 1.1 %) with the plain updates
    reference_rate_hz: float = 4.6
    # A laser whose neighbouring returns lie farther apart than a cell at its median range (``for_beams``: every
    # second beam of intel and ACES dropped, 2 deg, 6.8 and 8.2 cm) leaves a wall one scan sees as dotted cells, and
    # scans match into it worse. With this > 0, when the gap exceeds this many cells each scan's neighbouring returns
    # on one surface are joined in the submaps by hits a cell apart (``bridge_returns``; the matched points stay the
    # returns). Off by default: it maps such lasers better (whole runs at the laser, 2 deg beams: intel 0.0319 m /
    # 0.520 deg -> 0.0180 / 0.330, ACES 0.0467 / 0.505 -> 0.0370 / 0.350; fr079 with a quarter of its beams 0.0525 /
    # 0.585 -> 0.0470 / 0.498), but bridged submaps score scans like a full-rate laser's, the loop search's score
    # scale no longer lowers the map check's threshold, and ACES at 1.4 Hz with half its beams kidnapped in its
    # middle is not joined (its right matches agree 0.74-0.95 with the other side's walls, under 0.9). 1: bridge
    # every laser whose gap exceeds a cell (README: *Coarse beams*). The shared logs' own lasers (1.6-4.1 cm), the
    # household's and the simulated building's (3.2-4.3 cm) are not bridged at 1
    bridge_over_cells: float = 0.0
    # deg: two neighbouring returns are one surface when their chord is at most the gap r dphi of a wall seen at
    # this incidence (r dphi / cos: 2.9 gaps at 70 deg); farther apart they are an edge and what lies behind it
    bridge_max_incidence_deg: float = 70.0
    bridge: bool = False  # set by ``for_beams``

    def for_beams(self, beam_step_rad: float, median_range_m: float) -> GridConfig:
        """These settings for a laser whose beams are ``beam_step_rad`` apart and whose returns lie at
        ``median_range_m`` (median): returns bridged (``bridge``) when the gap between two neighbouring returns
        there exceeds ``bridge_over_cells`` cells (> 0); unchanged otherwise."""
        gap = abs(beam_step_rad) * median_range_m
        if self.bridge_over_cells <= 0 or not gap > self.bridge_over_cells * self.resolution:  # nan included
            return self
        return replace(self, bridge=True)

    def for_rate(self, rate_hz: float) -> GridConfig:
        """These settings for a laser scanning at ``rate_hz``: below ``reference_rate_hz`` the hit and miss
        updates' log-odds are multiplied by reference / rate (a wall seen by a third as many scans per metre gets
        three times the evidence from each), unchanged at or above it."""
        if self.reference_rate_hz <= 0 or not rate_hz > 0 or rate_hz >= self.reference_rate_hz:
            return self
        k = self.reference_rate_hz / rate_hz

        def scaled(p: float) -> float:
            return 1.0 / (1.0 + math.exp(-k * _logit(p)))

        return replace(self, hit_probability=scaled(self.hit_probability),
                       miss_probability=scaled(self.miss_probability))


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


@dataclass(frozen=True, eq=False)
class ProbGrid:
    """A finished probability grid: ``prob`` float32 (rows, cols) in [p_min, p_max], cell (r, c) covering
    x in [ox + c res, ...), y in [oy + r res, ...) of the submap's anchor frame."""

    prob: np.ndarray
    origin: tuple[float, float]
    resolution: float
    p_min: float = 0.1
    known: np.ndarray | None = None  # (rows, cols) bool: cells a scan updated (None: not recorded)

    def known_bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the cells above p_min (the explored part)."""
        r, c = np.nonzero(self.prob > self.p_min)
        if r.size == 0:
            return (self.origin[0], self.origin[1], self.origin[0], self.origin[1])
        res = self.resolution
        return (self.origin[0] + c.min() * res, self.origin[1] + r.min() * res,
                self.origin[0] + (c.max() + 1) * res, self.origin[1] + (r.max() + 1) * res)


def cells_at(prob: np.ndarray, known: np.ndarray, origin, resolution: float, pts: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """The cells of a grid (``prob`` and its ``known`` mask, cell (r, c) at ``origin`` + (c, r) ``resolution``)
    holding points ``pts`` (N, 2) of its frame: (explored (N,) bool: inside the grid and known; probability (N,),
    of the nearest cell of the grid where a point is outside it)."""
    c = np.floor((pts[:, 0] - origin[0]) / resolution).astype(np.int64)
    r = np.floor((pts[:, 1] - origin[1]) / resolution).astype(np.int64)
    H, W = prob.shape
    inside = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    rr, cc = np.clip(r, 0, H - 1), np.clip(c, 0, W - 1)
    return inside & (known[rr, cc] != 0), prob[rr, cc]


def scan_endpoints(ranges: np.ndarray, angles: np.ndarray, aTs: np.ndarray, cfg: GridConfig
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beam end points in the grid frame (x, y) and which are returns: a finite range within ``max_range``
    is a return at its range; any other beam is free space for ``missing_ray_length``."""
    return _endpoints(ranges, angles, np.asarray(aTs, np.float64), cfg)[:3]


def bridge_returns(ranges: np.ndarray, angles: np.ndarray, spacing_m: float, max_incidence_deg: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The beams of a scan (``ranges`` with inf for no return, ``angles`` in the sensor frame) and, between each
    two neighbouring returns on one surface (their chord at most their gap r dphi / cos(``max_incidence_deg``),
    r the nearer range), beams to points of the chord ``spacing_m`` or less apart: a dotted wall made whole."""
    r = np.asarray(ranges, np.float64)
    a = np.asarray(angles, np.float64)
    if r.size < 2 or not spacing_m > 0:
        return r, a
    x, y = r * np.cos(a), r * np.sin(a)
    with np.errstate(invalid="ignore"):  # inf - inf where neither beam returned: no bridge
        dx, dy = np.diff(x), np.diff(y)
        chord = np.hypot(dx, dy)
        gap = np.minimum(r[:-1], r[1:]) * np.abs(np.diff(a))
        link = (np.isfinite(chord) & (chord > spacing_m)
                & (chord * math.cos(math.radians(max_incidence_deg)) <= gap))
    n = np.zeros(link.size, np.int64)
    n[link] = np.ceil(chord[link] / spacing_m).astype(np.int64) - 1
    if not n.any():
        return r, a
    i = np.repeat(np.arange(n.size), n)
    k = np.arange(i.size) - np.repeat(np.cumsum(n) - n, n) + 1
    t = k / (n[i] + 1.0)
    px, py = x[i] + t * dx[i], y[i] + t * dy[i]
    return np.concatenate([r, np.hypot(px, py)]), np.concatenate([a, np.arctan2(py, px)])


def _endpoints(ranges: np.ndarray, angles: np.ndarray, aTs: np.ndarray, cfg: GridConfig) -> tuple:
    """``scan_endpoints`` and the box (x0, y0, x1, y1) of the end points and the sensor (one compiled pass)."""
    from holoslam.submaps import _grid_fast as fast

    th = np.asarray(angles, np.float64) + aTs[2]
    return fast.endpoints(np.asarray(ranges, np.float64), np.cos(th), np.sin(th), float(aTs[0]), float(aTs[1]),
                          float(cfg.max_range), float(cfg.missing_ray_length))


class GridBuilder:
    """The growing log-odds grid of the active submap (mutable by design: scans are inserted one by one)."""

    def __init__(self, cfg: GridConfig) -> None:
        self.cfg = cfg
        self.res = cfg.resolution
        self.origin = (0.0, 0.0)
        self.logodds = np.zeros((0, 0), np.float32)
        self.prob = np.zeros((0, 0), np.float32)
        self.known = np.zeros((0, 0), np.uint8)
        self.marker = np.zeros((0, 0), np.int32)
        self.stamp = 0
        self.count = 0
        self._l_hit = _logit(cfg.hit_probability)
        self._l_miss = _logit(cfg.miss_probability)
        self._l_max = _logit(cfg.p_max)

    def _grow(self, x0: float, y0: float, x1: float, y1: float) -> None:
        res, m = self.res, self.cfg.grow_margin
        rows, cols = self.logodds.shape
        ox, oy = self.origin
        if rows and x0 >= ox and y0 >= oy and x1 < ox + cols * res and y1 < oy + rows * res:
            return
        if rows:
            x0, y0 = min(x0, ox), min(y0, oy)
            x1, y1 = max(x1, ox + cols * res), max(y1, oy + rows * res)
            # grow by at least a quarter of the current extent: amortised, a grid is copied a few times, not
            # once per scan that reaches a little further (that cost a tenth of the front end on ACES)
            m = max(m, 0.25 * max(cols, rows) * res)
        # new origin on the old lattice so existing cells keep their place
        nox = ox - math.ceil((ox - (x0 - m)) / res) * res if rows else math.floor((x0 - m) / res) * res
        noy = oy - math.ceil((oy - (y0 - m)) / res) * res if rows else math.floor((y0 - m) / res) * res
        ncols = int(math.ceil((x1 + m - nox) / res))
        nrows = int(math.ceil((y1 + m - noy) / res))
        lo = np.zeros((nrows, ncols), np.float32)
        pr = np.full((nrows, ncols), self.cfg.p_min, np.float32)
        kn = np.zeros((nrows, ncols), np.uint8)
        mk = np.zeros((nrows, ncols), np.int32)
        if rows:
            dc = int(round((ox - nox) / res))
            dr = int(round((oy - noy) / res))
            lo[dr:dr + rows, dc:dc + cols] = self.logodds
            pr[dr:dr + rows, dc:dc + cols] = self.prob
            kn[dr:dr + rows, dc:dc + cols] = self.known
            mk[dr:dr + rows, dc:dc + cols] = self.marker
        self.origin, self.logodds, self.prob, self.known, self.marker = (nox, noy), lo, pr, kn, mk

    def insert(self, ranges: np.ndarray, angles: np.ndarray, aTs: np.ndarray) -> None:
        """Insert a scan taken from sensor pose ``aTs`` (3,) in the grid's frame."""
        from holoslam.submaps import _grid_fast as fast

        if self.cfg.bridge:
            ranges, angles = bridge_returns(ranges, angles, self.res, self.cfg.bridge_max_incidence_deg)
        ex, ey, hit, x0, y0, x1, y1 = _endpoints(ranges, angles, np.asarray(aTs, np.float64), self.cfg)
        if ex.size == 0:
            return
        self._grow(x0, y0, x1, y1)
        self.stamp += 1
        fast.insert_scan(self.logodds, self.prob, self.known, self.marker, self.stamp, self.origin[0], self.origin[1],
                         self.res, float(aTs[0]), float(aTs[1]), ex, ey, hit, self._l_hit, self._l_miss,
                         self._l_max, self.cfg.p_min, self.cfg.p_max)
        self.count += 1

    def freeze(self) -> ProbGrid:
        """The finished grid, cropped to its known cells plus a small border."""
        p = self.prob
        r, c = np.nonzero(self.known)
        if r.size == 0:
            return ProbGrid(p.copy(), self.origin, self.res, self.cfg.p_min, self.known.astype(bool))
        pad = 2
        r0, r1 = max(r.min() - pad, 0), min(r.max() + pad + 1, p.shape[0])
        c0, c1 = max(c.min() - pad, 0), min(c.max() + pad + 1, p.shape[1])
        origin = (self.origin[0] + c0 * self.res, self.origin[1] + r0 * self.res)
        return ProbGrid(np.ascontiguousarray(p[r0:r1, c0:c1]), origin, self.res, self.cfg.p_min,
                        np.ascontiguousarray(self.known[r0:r1, c0:c1] > 0))

