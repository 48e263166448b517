"""``planning.json``: both layers of the two-layer planning graph (seed 003) as JSON, and back.

Layout (columnar, so a large map stays compact; ids are row indices)::

    {"format": "holoslam-planning", "version": 1,
     "grid": {"resolution", "origin_x", "origin_y", "shape": [H, W], "min_block_cells", "min_block_m"},
     "layer1": {"cells": [[row0, col0, row1, col1], ...]  (half-open cell rectangles),
                "centres_xy": [[x, y], ...], "sizes_m": [[w, h], ...], "corners_xy": [[x0, y0, x1, y1], ...],
                "region": [region id per block], "edges": [[i, j], ...], "weights": [metres, ...]},
     "layer2": {"cells": [[row0, col0, row1, col1], ...], "corners_xy": [...],
                "blocks": [[block ids], ...], "edges": [[i, j], ...],
                "portals": [[row_lo, col_lo, row_hi, col_hi], ...]}}

The block label image is not stored: reading rebuilds it from the blocks (they tile the free blocks exactly).
Derived columns (centres, sizes, corners) are written for readers in other languages and ignored on reading.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from holoslam.errors import MapError
from holoslam.planning.twolayer import TwoLayerGraph, block_label_image

__all__ = ["to_planning_dict", "from_planning_dict", "write_planning", "read_planning"]

FORMAT = "holoslam-planning"
VERSION = 1


def to_planning_dict(tl: TwoLayerGraph) -> dict:
    lens = np.diff(tl.region_block_ptr)
    blocks_of = np.split(tl.region_block_ids, np.cumsum(lens)[:-1]) if tl.n_regions else []
    return {
        "format": FORMAT,
        "version": VERSION,
        "grid": {
            "resolution": tl.resolution,
            "origin_x": tl.origin_x,
            "origin_y": tl.origin_y,
            "shape": list(tl.shape),
            "min_block_cells": tl.min_block_cells,
            "min_block_m": tl.min_block_cells * tl.resolution,
        },
        "layer1": {
            "cells": tl.blocks.tolist(),
            "centres_xy": tl.block_centres_xy.tolist(),
            "sizes_m": tl.block_sizes_m.tolist(),
            "corners_xy": tl.block_corners_xy.tolist(),
            "region": tl.region_of_block.tolist(),
            "edges": tl.edges.tolist(),
            "weights": tl.weights.tolist(),
        },
        "layer2": {
            "cells": tl.regions.tolist(),
            "corners_xy": tl.region_corners_xy.tolist(),
            "blocks": [b.tolist() for b in blocks_of],
            "edges": tl.region_edges.tolist(),
            "portals": tl.portals.tolist(),
        },
    }


def _arr(v, shape_tail: tuple[int, ...], dtype, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=dtype)
    if a.size == 0:
        a = a.reshape((0,) + shape_tail)
    if a.shape[1:] != shape_tail:
        raise MapError(f"planning.json: {what} must have rows of shape {shape_tail}, got {a.shape}")
    a.setflags(write=False)
    return a


def from_planning_dict(d: dict) -> TwoLayerGraph:
    """Rebuild a :class:`TwoLayerGraph`; raises ``MapError`` for a malformed document."""
    try:
        if d.get("format") != FORMAT:
            raise MapError(f"not a {FORMAT} document (format = {d.get('format')!r})")
        if int(d.get("version", 0)) > VERSION:
            raise MapError(f"planning.json version {d['version']} is newer than this holoslam ({VERSION})")
        g, l1, l2 = d["grid"], d["layer1"], d["layer2"]
        shape = (int(g["shape"][0]), int(g["shape"][1]))
        blocks = _arr(l1["cells"], (4,), np.int64, "layer1.cells")
        regions = _arr(l2["cells"], (4,), np.int64, "layer2.cells")
        members = [np.asarray(b, dtype=np.int64) for b in l2["blocks"]]
        if len(members) != regions.shape[0]:
            raise MapError("planning.json: layer2.blocks must list the blocks of every region")
        ptr = np.zeros(len(members) + 1, dtype=np.int64)
        np.cumsum([m.shape[0] for m in members], out=ptr[1:])
        ids = np.concatenate(members) if members else np.zeros(0, np.int64)
        rob = _arr(l1["region"], (), np.int64, "layer1.region") if blocks.shape[0] else np.zeros(0, np.int64)
        if rob.shape[0] != blocks.shape[0]:
            raise MapError("planning.json: layer1.region must give one region per block")
        if blocks.shape[0] and (
            blocks[:, 2].max() > shape[0] or blocks[:, 3].max() > shape[1] or blocks.min() < 0
        ):
            raise MapError("planning.json: a layer-1 block lies outside the grid")
        labels = block_label_image(blocks, shape)
        labels.setflags(write=False)
        ptr.setflags(write=False)
        ids.setflags(write=False)
        return TwoLayerGraph(
            resolution=float(g["resolution"]),
            origin_x=float(g["origin_x"]),
            origin_y=float(g["origin_y"]),
            shape=shape,
            min_block_cells=int(g["min_block_cells"]),
            blocks=blocks,
            edges=_arr(l1["edges"], (2,), np.int64, "layer1.edges"),
            weights=_arr(l1["weights"], (), np.float64, "layer1.weights").reshape(-1),
            regions=regions,
            region_block_ptr=ptr,
            region_block_ids=ids,
            region_of_block=rob,
            region_edges=_arr(l2["edges"], (2,), np.int64, "layer2.edges"),
            portals=_arr(l2["portals"], (4,), np.int64, "layer2.portals"),
            labels=labels,
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise MapError(f"planning.json is malformed: {exc!r}; rewrite it with holoslam") from exc


def write_planning(tl: TwoLayerGraph, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(to_planning_dict(tl), separators=(",", ":")))
    return path


def read_planning(path: str | Path) -> TwoLayerGraph:
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise MapError(f"{path}: not a readable JSON file ({exc})") from exc
    if not isinstance(d, dict):
        raise MapError(f"{path}: planning.json must hold a JSON object")
    try:
        return from_planning_dict(d)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from exc
