"""The front end's anchor graph as it grows (``holoslam.submaps.frontend``): the relative poses found so far
(dead reckoning, scan matches, loop closures, breaks), the anchors' current world estimate, the graph distances
and relative covariances the loop search's windows come from, the dead-reckoning calibration against the scan
matches, and the re-solve after closures."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["AnchorGraph"]

_CHI2_3_MEDIAN = 2.366  # median of the chi-square distribution with 3 degrees of freedom
_CHI2_3_95 = 7.815  # its 95 % quantile


def _adjoints(aTb: np.ndarray) -> np.ndarray:
    """(N, 3, 3): ``geometry.adjoint`` of each pose of an (N, 3) batch."""
    c, s = np.cos(aTb[:, 2]), np.sin(aTb[:, 2])
    Ad = np.zeros((len(aTb), 3, 3))
    Ad[:, 0, 0], Ad[:, 0, 1], Ad[:, 0, 2] = c, -s, aTb[:, 1]
    Ad[:, 1, 0], Ad[:, 1, 1], Ad[:, 1, 2] = s, c, -aTb[:, 0]
    Ad[:, 2, 2] = 1.0
    return Ad


def _lookup(keys: np.ndarray, order: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The index in ``keys`` (unique; ``order`` sorts them) of each wanted key, -1 where absent."""
    if keys.size == 0:
        return np.full(wanted.shape, -1, np.int64)
    pos = np.minimum(np.searchsorted(keys[order], wanted), keys.size - 1)
    hit = keys[order][pos] == wanted
    return np.where(hit, order[pos], -1)


def _undirected_csr(n_nodes: int, i: np.ndarray, j: np.ndarray, w: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arcs of the undirected graph of the edges (i, j) with weights w as scipy's ``csgraph.dijkstra(
    coo_matrix((w, (i, j))).tocsr(), directed=False)`` sees them (the parallel edges of one ordered pair summed,
    either direction traversable), in CSR form for ``_graph_fast.dijkstra``: (indptr (N + 1,), heads, weights)."""
    keys, which = np.unique(np.asarray(i, np.int64) * n_nodes + np.asarray(j, np.int64), return_inverse=True)
    summed = np.zeros(len(keys))
    np.add.at(summed, which.reshape(-1), np.asarray(w, np.float64))
    a, b = keys // n_nodes, keys % n_nodes
    tail, head, weight = np.concatenate([a, b]), np.concatenate([b, a]), np.concatenate([summed, summed])
    order = np.argsort(tail, kind="stable")
    indptr = np.concatenate([[0], np.cumsum(np.bincount(tail, minlength=n_nodes))]).astype(np.int64)
    return indptr, np.ascontiguousarray(head[order]), np.ascontiguousarray(weight[order])


def _shortest_paths(csr: tuple[np.ndarray, np.ndarray, np.ndarray], source: int) -> tuple[np.ndarray, np.ndarray]:
    """Dijkstra from ``source`` over ``_undirected_csr``'s arcs: (dist (N,), inf where unreached; pred (N,), -1 for
    the source and the unreached), scipy's distances and predecessors without its sparse matrix's set-up
    (``_graph_fast.dijkstra``; that set-up cost ~10x the search on the anchor graph, at every loop search)."""
    from holoslam.submaps._graph_fast import dijkstra
    from holoslam.warmup import wait_for_kernels

    wait_for_kernels("holoslam.submaps._graph_fast")  # a first run's pool compiling it: not twice
    return dijkstra(*csr, int(source))


class AnchorGraph:
    """The relative poses found so far and the anchors' current world estimate."""

    def __init__(self, first_wTa: np.ndarray) -> None:
        self.i: list[int] = []
        self.j: list[int] = []
        self.T: list[np.ndarray] = []
        self.cov: list[np.ndarray] = []
        self.kind: list[str] = []
        self.est: list[np.ndarray] = [np.asarray(first_wTa, np.float64)]
        # each anchor by dead reckoning alone (odometry and compass, chained from the first): independent of the
        # scan matches and closures the estimate follows (``dead_reckoning_disagreement``)
        self.dr: list[np.ndarray] = [np.asarray(first_wTa, np.float64)]
        self.part: list[int] = [0]  # the part of the run each anchor is in: breaks of local SLAM ("lost") before it
        self.travel: list[float] = [0.0]  # odometer path length at each anchor
        self._dist: tuple[int, int, np.ndarray] | None = None
        self._csr: dict[str, tuple[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}  # ``_arcs``
        self._infl: tuple[int, float] | None = None
        self._rel: tuple[int, int, np.ndarray] | None = None
        self._meas: tuple[int, Any] | None = None
        self._drs: tuple[tuple[int, int], Any] | None = None
        self._fused: tuple[int, tuple[np.ndarray, np.ndarray]] | None = None
        self._arrays: tuple[np.ndarray, ...] = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                                                np.zeros((0, 3, 3)), np.zeros(0, object))

    def edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The relative poses as arrays (i, j, T (E, 3), cov (E, 3, 3), kind): the lists' rows, converted only
        where they grew since the last call (the edges are only ever appended)."""
        n0 = len(self._arrays[0])
        if n0 < len(self.i):
            new = (np.array(self.i[n0:], np.int64), np.array(self.j[n0:], np.int64),
                   np.array(self.T[n0:], np.float64).reshape(-1, 3), np.array(self.cov[n0:]).reshape(-1, 3, 3),
                   np.array(self.kind[n0:], dtype=object))
            self._arrays = tuple(np.concatenate([a, b]) for a, b in zip(self._arrays, new, strict=True))
        i, j, T, cov, kind = self._arrays
        return i, j, T, cov, kind

    def graph_distance(self, n: int) -> np.ndarray:
        """Shortest path length from every anchor to anchor n: chain edges weigh the distance travelled
        between their anchors, loop edges nothing (``loops`` module docstring). Cached until the graph grows."""
        key = (n, len(self.i))
        if self._dist is None or self._dist[:2] != key:
            ii, jj, _, _, kinds = self.edges()
            trav = np.array(self.travel)
            # a break (kind "lost") is as long as the building is large: a window across it covers everything
            w = np.where(kinds == "loop", 1e-6, np.where(kinds == "lost", 1e6, np.abs(trav[jj] - trav[ii]) + 1e-6))
            self._dist = (*key, _shortest_paths(self._arcs("distance", len(self.est), ii, jj, w), n)[0])
        return self._dist[2]

    def _arcs(self, name: str, n_nodes: int, i: np.ndarray, j: np.ndarray, w: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``_undirected_csr`` of the edges (i, j, w), cached under ``name`` until the graph grows (the weights are
        functions of the edges)."""
        key = (len(self.i), n_nodes)
        if name not in self._csr or self._csr[name][0] != key:
            self._csr[name] = (key, _undirected_csr(n_nodes, i, j, w))
        return self._csr[name][1]

    def add_anchor(self, m: int, est_mTn: np.ndarray, dr_mTn: np.ndarray, travelled: float, lost: bool) -> None:
        """A new anchor n after anchor m: its estimate ``est_mTn`` (the scan match, or the odometry across a break)
        and its dead reckoning ``dr_mTn`` from m, the odometer at it, and whether local SLAM broke between them."""
        self.est.append(g.compose(self.est[m], est_mTn))
        self.dr.append(g.compose(self.dr[m], dr_mTn))
        self.part.append(self.part[m] + int(lost))
        self.travel.append(float(travelled))

    def dead_reckoning_disagreement(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(N,) m and (N,) rad: how far the current estimate of anchor n relative to each anchor m lies from
        dead reckoning's alone (position, heading); inf for anchors across a break of local SLAM (the odometry
        is all either has there). The estimate follows the scan matches and closures, dead reckoning the
        odometer and the compass: two independent measures of mTn. Where they agree, neither can be far off
        (``LoopConfig.agreement_factor``)."""
        est, dr = np.array(self.est), np.array(self.dr)
        d = g.between(g.between(dr, np.broadcast_to(dr[n], dr.shape)),
                      g.between(est, np.broadcast_to(est[n], est.shape)))
        other = np.array(self.part) != self.part[n]
        xy = np.where(other, np.inf, np.hypot(d[:, 0], d[:, 1]))
        th = np.where(other, np.inf, np.abs(g.wrap(d[:, 2])))
        return xy, th

    def relative_covariances(self, n: int) -> np.ndarray:
        """(N, 3, 3): the covariance of anchor n relative to each anchor m (right perturbation, n's frame) along
        the most certain path between them (Dijkstra over the relative poses, the parallel ones fused by their
        information), propagated at the current estimates. One path ignores the others, so this is an upper
        bound of the marginal covariance of mTn where the graph has loops; anchors reached only across a break of
        local SLAM get (1e12 m², 1e12 m², pi²). Cached until the graph grows."""
        key = (n, len(self.i))
        if self._rel is not None and self._rel[:2] == key:
            return self._rel[2]
        N = len(self.est)
        pairs, covs = self._fused_pairs()
        w = np.sqrt(covs[:, 0, 0] + covs[:, 1, 1]) + 5.0 * np.sqrt(covs[:, 2, 2]) + 1e-9
        dist, pred = _shortest_paths(self._arcs("certainty", N, pairs[:, 0], pairs[:, 1], w), n)
        est = np.array(self.est)
        # Ad(nTp) of every anchor p at once (geometry.adjoint's matrix, between's arithmetic)
        nTp = g.between(np.broadcast_to(est[n], est.shape), est)
        Ad = _adjoints(nTp)
        # every reached anchor m and its predecessor p on the path: the edge's covariance of mTp (at p). An edge
        # (m, p) measures mTp; an edge (p, m) measures pTm (covariance at m): mTp is its inverse, at p
        reached = np.flatnonzero(pred >= 0)
        p_of = pred[reached]
        pk = pairs[:, 0] * N + pairs[:, 1]
        korder = np.argsort(pk, kind="stable")
        fwd = _lookup(pk, korder, reached * N + p_of)
        rev = _lookup(pk, korder, p_of * N + reached)
        C = np.empty((len(reached), 3, 3))
        C[fwd >= 0] = covs[fwd[fwd >= 0]]
        back = np.flatnonzero(fwd < 0)
        J = _adjoints(g.between(est[p_of[back]], est[reached[back]]))
        C[back] = np.einsum("mij,mjk,mlk->mil", J, covs[rev[back]], J)
        # mTn = mTp ∘ pTn: cov(mTn) = Ad(nTp) cov(mTp) Ad(nTp)^T + cov(pTn), summed from n outwards
        step = np.full((N, 3, 3), np.nan)
        step[reached] = np.einsum("mij,mjk,mlk->mil", Ad[p_of], C, Ad[p_of])
        out = np.full((N, 3, 3), np.nan)
        out[n] = 0.0
        for m in reached[np.argsort(dist[reached], kind="stable")].tolist():
            out[m] = step[m] + out[pred[m]]
        unreached = ~np.isfinite(out[:, 0, 0])
        out[unreached] = np.diag([1e12, 1e12, np.pi ** 2])
        self._rel = (*key, out)
        return out

    def _fused_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The anchor pairs (P, 2) the relative poses join, in the order first measured, and the covariance (P, 3,
        3) of their fused measurements (the parallel ones' information summed, in the order measured)."""
        if self._fused is not None and self._fused[0] == len(self.i):
            return self._fused[1]
        meas = self.measurements()
        keep = meas.kind != "lost"  # a break says nothing the window could use: the other part is anywhere
        N = max(len(self.est), max(self.i) + 1, max(self.j) + 1)  # keys i N + j, unique per pair
        keys, first, which = np.unique(meas.i[keep] * N + meas.j[keep], return_index=True, return_inverse=True)
        order = np.argsort(first, kind="stable")  # pairs by first measurement
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        info = np.zeros((len(keys), 3, 3))
        np.add.at(info, rank[which.reshape(-1)], np.linalg.inv(meas.cov_iTj[keep]))
        pairs = np.stack([keys[order] // N, keys[order] % N], axis=1)
        self._fused = (len(self.i), (pairs, np.linalg.inv(info)))  # cached until the graph grows
        return self._fused[1]

    def add(self, i: int, j: int, T, cov, kind: str) -> None:
        self.i.append(i)
        self.j.append(j)
        self.T.append(np.asarray(T, float))
        self.kind.append(kind)
        self.cov.append(np.asarray(cov, float) + np.eye(3) * 1e-10)

    def _dr_vs_scan(self, min_pairs: int = 5) -> tuple[np.ndarray, np.ndarray] | None:
        """(rows of the dead-reckoning relative poses, d^T C_dr^-1 d of each against the scan match between the same
        anchors), or None with fewer than ``min_pairs`` pairs. Both are added together for every new anchor."""
        key = (len(self.i), min_pairs)
        if self._drs is not None and self._drs[0] == key:
            return self._drs[1]
        _, _, T, C, kinds = self.edges()
        dr, sm = np.flatnonzero(kinds == "dead_reckoning"), np.flatnonzero(kinds == "scan_match")
        out = None
        if len(dr) >= min_pairs and len(dr) == len(sm):
            C = C[dr]
            d = g.between(T[dr], T[sm])
            d[:, 2] = g.wrap(d[:, 2])
            out = dr, np.einsum("ni,ni->n", d, np.linalg.solve(C, d[..., None])[..., 0])
        self._drs = (key, out)  # cached until the graph grows
        return out

    def dead_reckoning_inflation(self, min_pairs: int = 5) -> float:
        """How much the dead-reckoning covariances must grow to explain their disagreement with the scan matches
        between the same anchors: median(d^T C_dr^-1 d) over the anchor pairs divided by the chi-square(3) median
        (2.366), at least 1. The scan match of a pair is taken as its truth: it is millimetres where the dead
        reckoning is centimetres, and its own covariance (conservative on a well-filled submap, the lattice floor)
        would otherwise hide the dead reckoning's excess. Wheel odometry on real floors slips and drifts more than
        any fixed noise model says (and a robot's may be worse than the defaults); the scan matches of the same
        log measure by how much. Cached until the graph grows."""
        key = len(self.i)
        if self._infl is None or self._infl[0] != key:
            pairs = self._dr_vs_scan(min_pairs)
            f = 1.0 if pairs is None else max(1.0, float(np.median(pairs[1])) / _CHI2_3_MEDIAN)
            self._infl = (key, f)
        return self._infl[1]

    def dead_reckoning_slips(self) -> dict[int, float]:
        """Dead-reckoning segments that disagree with their scan match beyond the chi-square(3) 95 % gate once
        scaled by ``dead_reckoning_inflation``: row -> the further factor that brings them to the typical
        (median) disagreement. Wheel odometry errors are heavy-tailed (a wheel spins on a threshold, the base is
        pushed): a Gaussian factor scaled to the typical segment is far too sure of the few that slipped, and
        those pull the anchors off (simulated household, two 300 s logs: anchors 10.6 / 10.7 -> 9.3 / 9.9 mm)."""
        pairs = self._dr_vs_scan()
        if pairs is None:
            return {}
        rows, m2 = pairs[0], pairs[1] / self.dead_reckoning_inflation()
        slipped = m2 > _CHI2_3_95
        return {int(r): float(v) / _CHI2_3_MEDIAN for r, v in zip(rows[slipped], m2[slipped], strict=True)}

    def loop_groups(self) -> dict[tuple[int, int], int]:
        """How many loop closures join each pair of anchors."""
        out: dict[tuple[int, int], int] = {}
        for i, j, k in zip(self.i, self.j, self.kind, strict=True):
            if k == "loop":
                out[(i, j)] = out.get((i, j), 0) + 1
        return out

    def measurements(self):
        """The relative poses as the solver sees them: dead reckoning scaled by ``dead_reckoning_inflation`` (and
        the segments that slipped further, ``dead_reckoning_slips``), and the k loop closures found between one
        pair of anchors (scans of the same two submaps) each scaled by k. Those k matches share both submaps' map
        errors (on the simulated household they scatter about their mean 8-25 times less, in variance, than their
        covariances say), so together they know what one of them knows; taken as independent they make the
        anchors k times too sure (95 % ellipses holding 77-81 % of the true anchors on a simulated robot with 3x
        the noise, 92-96 % with the scaling; the closures of one pair keep their relative weights)."""
        from holoslam.graph.problem import RelativePoseMeasurements

        if not self.i:
            return RelativePoseMeasurements.empty()
        if self._meas is not None and self._meas[0] == len(self.i):  # the edges only grow: cached until they do
            return self._meas[1]
        ii, jj, T, cov, kinds = self.edges()
        cov = cov.copy()
        cov[kinds == "dead_reckoning"] *= self.dead_reckoning_inflation()
        for row, f in self.dead_reckoning_slips().items():
            cov[row] *= f
        loop = np.flatnonzero(kinds == "loop")
        if loop.size:  # each closure scaled by the number of closures between its pair
            key = ii[loop] * (ii.max() + jj.max() + 2) + jj[loop]
            _, which, count = np.unique(key, return_inverse=True, return_counts=True)
            cov[loop] *= count[which.reshape(-1)][:, None, None]
        meas = RelativePoseMeasurements(ii, jj, T, cov, kinds)
        self._meas = (len(self.i), meas)
        return meas

    def disagree(self, closures: Sequence[Any], min_d2: float) -> bool:
        """Whether any closure's relative pose is further than ``min_d2`` (squared Mahalanobis, its own
        covariance) from what the current estimate says (``LoopConfig.resolve_min_d2``)."""
        for c in closures:
            r = g.between(c.mTn, g.between(self.est[c.old], self.est[c.new]))
            if float(r @ np.linalg.solve(c.cov_mTn, r)) > min_d2:
                return True
        return False

    def reoptimise(self, optimize: Callable[[object], np.ndarray] | None) -> None:
        if optimize is None:
            return
        from holoslam.graph.problem import SlamProblem

        n = len(self.est)
        problem = SlamProblem(num_poses=n, relative=self.measurements(), initial_wTa=np.array(self.est))
        wTa = np.asarray(optimize(problem))
        self.est = list(wTa)
