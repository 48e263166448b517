"""Compact paths for the written graphs (issue 26): a traced path simplified to the map's resolution.

A topology edge's ``path`` holds every skeleton cell it runs through and a holographic passage's ``passage``
every waypoint along the skeleton: on a building floor that is hundreds of thousands of cells, most of them on
straight corridors. The files keep the polyline that stays within ``PATH_TOLERANCE_CELLS`` (one cell: the
map's own resolution) of the traced path, by Douglas-Peucker (Douglas & Peucker 1973; vertices are a subset
of the path's, both ends kept): a straight corridor of 2,000 cells becomes 2 vertices. The in-memory graphs
of a run are not changed; the edges keep their ``length`` (measured along the traced cells), and the written
graph records the tolerance (``path_tolerance_m``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["PATH_TOLERANCE_CELLS", "douglas_peucker", "simplify_path", "compact_paths"]

#: A written path is within this many cells of the traced one: the map's resolution (one cell), finer than
#: any width or clearance the graphs report.
PATH_TOLERANCE_CELLS = 1.0


def douglas_peucker(points: np.ndarray, epsilon: float) -> np.ndarray:
    """Indices (sorted, first and last included) of the vertices of ``points`` (K, 2) that Douglas-Peucker
    keeps: every dropped point lies within ``epsilon`` of the segment between the kept vertices around it
    (distances to the segment, so a path that turns back is kept where it does)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    k = p.shape[0]
    if k <= 2:
        return np.arange(k)
    keep = np.zeros(k, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, k - 1)]
    eps2 = float(epsilon) ** 2
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = p[a + 1 : b]
        d = p[b] - p[a]
        n2 = float(d @ d)
        rel = seg - p[a]
        if n2 == 0.0:  # a closed loop's ends: distance to the point
            dist2 = (rel * rel).sum(axis=1)
        else:  # distance to the segment (not its line: a path may turn back beyond an end)
            t = np.clip((rel @ d) / n2, 0.0, 1.0)
            off = rel - t[:, None] * d
            dist2 = (off * off).sum(axis=1)
        i = int(np.argmax(dist2))
        if dist2[i] > eps2:
            m = a + 1 + i
            keep[m] = True
            stack.append((a, m))
            stack.append((m, b))
    return np.flatnonzero(keep)


def simplify_path(points: np.ndarray, epsilon: float) -> np.ndarray:
    """The vertices of ``points`` Douglas-Peucker keeps (same dtype; a path of two points or fewer as is)."""
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[0] <= 2:
        return p
    return p[douglas_peucker(p, epsilon)]


def compact_paths(G, resolution: float | None = None, tolerance_cells: float = PATH_TOLERANCE_CELLS):
    """A copy of G whose edge ``path`` (cells) and ``passage`` (metres) arrays are simplified to
    ``tolerance_cells`` cells (``resolution`` metres per cell: the graph's own ``resolution`` attribute when not
    given, else 1); every other attribute is shared with G. The copy records ``path_tolerance_m``."""
    H = G.copy()
    res = float(resolution if resolution is not None else G.graph.get("resolution", 1.0))
    for *_e, d in H.edges(data=True):
        for key, eps in (("path", tolerance_cells), ("passage", tolerance_cells * res)):
            v = d.get(key)
            if isinstance(v, np.ndarray) and v.ndim == 2 and v.shape[0] > 2:
                d[key] = simplify_path(v, eps)
    H.graph["path_tolerance_m"] = tolerance_cells * res
    return H
