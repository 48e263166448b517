"""Passages of the holographic graph: shortest paths along the topology skeleton between places.

The skeleton cells of the topology's edge paths (with each edge's two node cells) form a graph of 8-connected
steps weighted in metres, kept as a symmetric compressed sparse row matrix. Shortest paths: one search per
source place for all its passages, stopped once they are all settled (numba, ``_holographic_fast``; without
it ``scipy.sparse.csgraph.dijkstra`` bounded by a few times the straight distance to the farthest target,
searched again without a bound if one is beyond it), and one multi-source scipy search per step when joining
the components of the environment graph. A place sits at the
skeleton cell nearest to it in L1 distance (the first in row-major order among equals).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SkeletonPaths", "EdgePaths"]


def kernels():
    """The compiled kernels (:mod:`holoslam.maps._holographic_fast`), or None when numba is missing."""
    try:
        from holoslam.maps import _holographic_fast
    except ImportError:  # pragma: no cover - numba is a declared dependency
        return None
    return _holographic_fast


class EdgePaths:
    """The cell paths of a topology's edges with their two node cells, concatenated: ``cells`` (M, 2) int64,
    ``starts`` (E + 1) offsets, and per edge whether the node at its first / last cell is an ``endpoint``
    (edges without a ``path``, or with an empty one, are left out). A path runs from the node ``path_from``;
    the paths stop next to a junction cluster's representative cell, so without the node cells they would
    not join."""

    def __init__(self, topology) -> None:
        nodes = topology.nodes
        paths, heads, tails, has, first_end, last_end = [], [], [], [], [], []
        for u, v, d in topology.edges(data=True):
            q = d.get("path")
            if q is None:
                continue
            q = np.asarray(q, dtype=np.int64).reshape(-1, 2)
            if q.shape[0] == 0:
                continue
            nu, nv = nodes[u], nodes[v]
            if d.get("path_from", u) != u:
                nu, nv = nv, nu
            ok = "row" in nu and "row" in nv
            paths.append(q)
            has.append(ok)
            heads.append((int(nu["row"]), int(nu["col"])) if ok else (0, 0))
            tails.append((int(nv["row"]), int(nv["col"])) if ok else (0, 0))
            first_end.append(nu.get("kind") == "endpoint")
            last_end.append(nv.get("kind") == "endpoint")
        k = np.array([q.shape[0] for q in paths], dtype=np.int64)
        h = np.array(has, dtype=bool)
        lens = k + 2 * h
        self.starts = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        self.cells = np.empty((int(self.starts[-1]), 2), dtype=np.int64)
        body = np.ones(self.cells.shape[0], dtype=bool)
        if h.any():
            hs, he = self.starts[:-1][h], self.starts[1:][h] - 1
            self.cells[hs] = np.array(heads, dtype=np.int64).reshape(-1, 2)[h]
            self.cells[he] = np.array(tails, dtype=np.int64).reshape(-1, 2)[h]
            body[hs] = body[he] = False
        if paths:
            self.cells[body] = np.concatenate(paths)
        self.first_is_endpoint = np.array(first_end, dtype=bool)
        self.last_is_endpoint = np.array(last_end, dtype=bool)

    def __len__(self) -> int:
        return int(self.starts.shape[0] - 1)


class SkeletonPaths:
    """Shortest paths over the skeleton cells of a topology graph (module docstring)."""

    def __init__(self, topology, res: float, edge_paths: EdgePaths | None = None) -> None:
        from scipy.sparse import csr_matrix

        ep = edge_paths if edge_paths is not None else EdgePaths(topology)
        self.res = float(res)
        self._tree: Any = None  # scipy's cKDTree of the cells, built on first need
        if len(ep) == 0:
            self.cells = np.zeros((0, 2), dtype=np.int64)
            self.csr: Any = None  # scipy's csr_matrix of the cell graph (none without cells)
            return
        allc = ep.cells
        key = allc[:, 0] * (int(allc[:, 1].max()) + 2) + allc[:, 1]
        uk, inv = np.unique(key, return_inverse=True)
        cells = np.zeros((uk.shape[0], 2), dtype=np.int64)
        cells[inv] = allc
        a, b = inv[:-1], inv[1:]
        valid = np.ones(a.shape[0], dtype=bool)
        valid[ep.starts[1:-1] - 1] = False  # no step between two different paths
        valid &= a != b
        a, b = a[valid], b[valid]
        n = cells.shape[0]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        pk = np.unique(lo * n + hi)
        lo, hi = pk // n, pk % n
        wgt = np.hypot(*(cells[lo] - cells[hi]).T) * self.res
        self.cells = cells
        self.csr = csr_matrix(
            (np.concatenate([wgt, wgt]), (np.concatenate([lo, hi]), np.concatenate([hi, lo]))), shape=(n, n)
        )

    def __len__(self) -> int:
        return int(self.cells.shape[0])

    def nearest(self, rc: np.ndarray) -> np.ndarray:
        """(K,) index of the skeleton cell nearest (L1) to each of the (K, 2) cells, lowest index among ties."""
        from scipy.spatial import cKDTree

        rc = np.asarray(rc, dtype=np.int64).reshape(-1, 2)
        if self._tree is None:
            self._tree = cKDTree(self.cells)
        dist, _ = self._tree.query(rc, k=1, p=1)
        out = np.empty(rc.shape[0], dtype=np.int64)
        for i, (q, dq) in enumerate(zip(rc, dist.tolist(), strict=True)):
            near = self._tree.query_ball_point(q, r=dq + 0.5, p=1)
            d = np.abs(self.cells[near] - q).sum(1)
            out[i] = min(j for j, dd in zip(near, d.tolist(), strict=True) if dd == round(dq))
        return out

    def paths_from(self, source: int, targets, limit: float = np.inf) -> dict[int, list[int] | None]:
        """Cell index sequences of the shortest paths from ``source`` to each target (None: not joined).
        Compiled (``_holographic_fast.dijkstra_to``): the search stops once every target is settled. Without
        numba, scipy's search first stops at ``limit`` metres (a bound the caller expects the paths within:
        most passages are local) and searches again without one when a target is beyond it."""
        targets = list(targets)
        fast = kernels()
        if fast is not None:
            c = self.csr
            dist, pred = fast.dijkstra_to(
                c.indptr, c.indices, c.data, int(source), np.asarray(targets, dtype=np.int64)
            )
        else:
            from scipy.sparse.csgraph import dijkstra

            dist, pred = dijkstra(
                self.csr, directed=True, indices=source, return_predecessors=True, limit=limit
            )
            if np.isfinite(limit) and not all(np.isfinite(dist[t]) for t in targets):
                return self.paths_from(source, targets)
        out: dict[int, list[int] | None] = {}
        for t in targets:
            if not np.isfinite(dist[t]):
                out[t] = None
                continue
            seq = [t]
            while seq[-1] != source:
                seq.append(int(pred[seq[-1]]))
            out[t] = seq[::-1]
        return out

    def multi_source(self, sources) -> tuple[np.ndarray, np.ndarray]:
        """(distance to the nearest source, that source) for every cell (inf / -9999 where none reaches)."""
        from scipy.sparse.csgraph import dijkstra

        dist, _pred, src = dijkstra(
            self.csr, directed=True, indices=sorted(sources), min_only=True, return_predecessors=True
        )
        return dist, src
