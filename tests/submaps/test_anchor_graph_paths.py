"""The anchor graph's shortest paths (``anchor_graph._undirected_csr`` + ``_fast.dijkstra``) are scipy's
``csgraph.dijkstra`` of the summed sparse matrix, undirected: the same distances and predecessors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from holoslam.submaps.anchor_graph import _shortest_paths, _undirected_csr


@pytest.mark.parametrize("seed", range(6))
def test_shortest_paths_are_scipys(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 60))
    m = int(rng.integers(1, 4 * n))
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    # chain edges, parallel ones (both orders), loops of weight 1e-6 and a break's 1e6
    w = rng.choice([1e-6, 1e6, 0.0], m, p=[0.2, 0.05, 0.75]) + (rng.random(m) * 3 if seed % 2 else 0.5)
    i, j, w = np.concatenate([i, i[: m // 3]]), np.concatenate([j, j[: m // 3]]), np.concatenate([w, w[: m // 3]])
    A = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    csr = _undirected_csr(n, i, j, w)
    for s in range(n):
        d0, p0 = dijkstra(A, directed=False, indices=s, return_predecessors=True)
        d1, p1 = _shortest_paths(csr, s)
        assert np.array_equal(d0, d1)
        # predecessors may differ only between paths of exactly equal length
        differ = np.flatnonzero(np.where(p0 < 0, -1, p0) != p1)
        for v in differ:
            assert d1[p1[v]] + A[p1[v], v] == d1[v] or d1[p1[v]] + A[v, p1[v]] == d1[v]
