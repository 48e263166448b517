"""Write 2D pose graphs as g2o text: VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY and FIX (the reader is
:mod:`holoslam.io.g2o`). Measurements read from g2o's own EDGE lines are copied as they stand; the others (TORO /
iSAM tags, graphs built in memory) are written from their covariances, floats at full precision."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from holoslam.io.g2o import G2oGraph

__all__ = ["to_g2o_text", "write_g2o", "with_estimate"]


def _rows(line: str, data: np.ndarray) -> str:
    """``line`` (a %-format of one row: ``%d`` ids, ``%r`` floats, ending in a newline) for every row of
    ``data`` in one formatting call; ``%r`` of a Python float is its shortest round-trip repr ('nan', 'inf')."""
    if data.shape[0] == 0:
        return ""
    return (line * data.shape[0]) % tuple(data.ravel().tolist())


def _native_lines(graph: G2oGraph, source_text: str) -> str | None:
    """The graph's EDGE_SE2 and EDGE_SE2_XY lines as they stand in ``source_text`` (the text it was parsed from),
    in file order; None when some measurement did not come from such a line (TORO / iSAM tags, built in
    memory): then the writer formats them."""
    el, ll = graph.edge_line, graph.landmark_line
    if el is None or ll is None:  # filled in by G2oGraph.__post_init__
        return None
    nums = np.concatenate([el, ll])
    if nums.size == 0 or nums.min() <= 0:
        return None
    lines = source_text.splitlines()
    if nums.max() > len(lines):
        return None
    picked = [lines[k - 1] for k in np.sort(nums).tolist()]
    tags = [line.split(None, 1)[0] for line in picked]
    if tags.count("EDGE_SE2") != el.size or tags.count("EDGE_SE2_XY") != ll.size:
        return None
    return "\n".join(picked) + "\n"


def to_g2o_text(graph: G2oGraph, source_text: str | None = None) -> str:
    """The g2o text of a graph: VERTEX_SE2, VERTEX_XY, EDGE_SE2 and EDGE_SE2_XY (information matrices, upper
    triangle), then FIX (last: gtsam's ``readG2o`` stops reading edges at a FIX line), floats written with full
    precision so that a write/read round trip is exact to 1 ulp. With ``source_text`` (the g2o text the graph's
    measurements were read from), measurements that stand there as EDGE_SE2 / EDGE_SE2_XY lines are copied as
    they are (exact, and no number is formatted again)."""
    f64 = np.float64
    vertices = _rows(
        "VERTEX_SE2 %d %r %r %r\n", np.column_stack([graph.vertex_ids.astype(f64), graph.vertex_poses])
    )
    points = _rows(
        "VERTEX_XY %d %r %r\n", np.column_stack([graph.point_ids.astype(f64), graph.point_positions])
    )
    fixed = _rows("FIX %d\n", graph.fixed_ids.astype(f64).reshape(-1, 1))
    native = None if source_text is None else _native_lines(graph, source_text)
    if native is not None:
        return vertices + points + native + fixed
    info = np.linalg.inv(graph.edge_cov) if graph.edge_cov.shape[0] else np.zeros((0, 3, 3))
    iu = np.triu_indices(3)
    upper = (0.5 * (info + np.swapaxes(info, 1, 2)))[:, iu[0], iu[1]]
    ids = np.column_stack([graph.edge_i, graph.edge_j]).astype(f64)
    edges = _rows("EDGE_SE2 %d %d" + " %r" * 9 + "\n", np.column_stack([ids, graph.edge_measured, upper]))
    linfo = np.linalg.inv(graph.landmark_cov) if graph.landmark_cov.shape[0] else np.zeros((0, 2, 2))
    lsym = 0.5 * (linfo + np.swapaxes(linfo, 1, 2))
    lids = np.column_stack([graph.landmark_pose, graph.landmark_id]).astype(f64)
    lvals = np.column_stack([graph.landmark_measured, lsym[:, 0, 0], lsym[:, 0, 1], lsym[:, 1, 1]])
    sightings = _rows("EDGE_SE2_XY %d %d" + " %r" * 5 + "\n", np.column_stack([lids, lvals]))
    text = vertices + points + edges + sightings + fixed
    return text if text else "\n"


def with_estimate(
    graph: G2oGraph,
    vertex_ids: np.ndarray,
    vertex_poses: np.ndarray,
    point_ids: Sequence[int] | np.ndarray,
    point_positions: np.ndarray,
) -> G2oGraph:
    """``graph``'s measurements with new vertices (an optimised graph): poses ``vertex_poses`` of ``vertex_ids``,
    points ``point_positions`` of ``point_ids``; the graph's FIX vertices stay fixed (none: the first vertex)."""
    vertex_ids = np.asarray(vertex_ids, dtype=np.int64)
    return G2oGraph(
        vertex_ids=vertex_ids,
        vertex_poses=vertex_poses,
        point_ids=np.asarray(point_ids, dtype=np.int64),
        point_positions=point_positions,
        edge_i=graph.edge_i,
        edge_j=graph.edge_j,
        edge_measured=graph.edge_measured,
        edge_cov=graph.edge_cov,
        landmark_pose=graph.landmark_pose,
        landmark_id=graph.landmark_id,
        landmark_measured=graph.landmark_measured,
        landmark_cov=graph.landmark_cov,
        edge_line=graph.edge_line,
        landmark_line=graph.landmark_line,
        fixed_ids=graph.fixed_ids if graph.fixed_ids.size else vertex_ids[:1],
        source=graph.source,
    )


def write_g2o(graph: G2oGraph, path: str | Path, source_text: str | None = None) -> Path:
    """Write a graph as g2o text (see :func:`to_g2o_text`)."""
    path = Path(path)
    path.write_text(to_g2o_text(graph, source_text), encoding="utf-8")
    return path
