"""Compiled kernels of the two-layer planner (numba, :mod:`holoslam._jit` policy), one module per job.

Imported lazily by :func:`holoslam.planning.routes.build_planner` and the builders of
:mod:`holoslam.planning.twolayer` (importing numba costs about half a second and the first call of each
kernel compiles it, about 10 s once per machine, then loads it from numba's on-disk cache next to its file).
Every kernel is a plain function of numpy arrays; this package re-exports the ones its callers and tests use.

* :mod:`.tiles` -- the free mask as 64-bit tiles (:func:`tile_bits`), the clearance of its free 4 x 4-cell
  blocks (:func:`block_clearance`) and the exact segment check :func:`seg_free_tiles`, the same answer as
  ``segments_free`` without allocation, jumping over squares of free blocks.
* :mod:`.astar` -- :func:`corridor_astar`, the weighted A* over the port graph with the Euclidean + ALT
  landmark heuristic and its reusable workspace (``WORKSPACE_DTYPE``).
* :mod:`.smoothing` -- the path through a corridor's portal boxes (:func:`corridor_path`: :func:`funnel`,
  polished by :func:`refine` where it turns back), the string pull on the grid (:func:`string_pull`) and the
  final simplification and checks (:func:`simplify_validate`).
* :mod:`.queries` -- :func:`query`, one whole planning query between two located points (regions at the
  points from a bucket index, corridor, paths, checks), and the greedy corridor shortcut
  (:func:`shortcut_corridor_adj`).
* :mod:`.build` -- the build kernels of the two-layer graph: :func:`label_image`, :func:`block_edges`
  (layer 1) and :func:`grow_regions` (layer 2).
"""

from holoslam.planning._fast.astar import WORKSPACE_DTYPE, corridor_astar
from holoslam.planning._fast.build import block_edges, grow_regions, label_image
from holoslam.planning._fast.queries import _regions_at, query, shortcut_corridor_adj
from holoslam.planning._fast.smoothing import (
    _box_interval,
    _box_interval_exact,
    corridor_path,
    funnel,
    refine,
    simplify_validate,
    string_pull,
)
from holoslam.planning._fast.tiles import block_clearance, chessboard_clearance, seg_free_tiles, tile_bits

__all__ = [
    "WORKSPACE_DTYPE",
    "_box_interval",
    "_box_interval_exact",
    "_regions_at",
    "block_clearance",
    "block_edges",
    "chessboard_clearance",
    "corridor_astar",
    "corridor_path",
    "funnel",
    "grow_regions",
    "label_image",
    "query",
    "refine",
    "seg_free_tiles",
    "shortcut_corridor_adj",
    "simplify_validate",
    "string_pull",
    "tile_bits",
]
