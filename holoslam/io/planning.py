"""``planning.json``: both layers of the two-layer planning graph (seed 003), and back.

Version 2 (written since issue 26; version 1 files are still read). The JSON holds what a reader needs to
plan on layer 2 and to locate layer 1, sized to the building; layer 1's blocks (a building floor has ~750,000
of them) are in a compressed array file beside it, ``<stem>_layer1.npz``::

    {"format": "holoslam-planning", "version": 2,
     "grid": {"resolution", "origin_x", "origin_y", "shape": [H, W], "min_block_cells", "min_block_m"},
     "layer1": {"count": N, "file": "planning_layer1.npz",
                "arrays": {"cells": "(N, 4) int32 half-open cell rectangles [row0, col0, row1, col1]",
                           "region": "(N,) int32 region id of each block"}},
     "layer2": {"cells": [[row0, col0, row1, col1], ...]  (half-open cell rectangles, id = row index),
                "edges": [[i, j], ...], "portals": [[row_lo, col_lo, row_hi, col_hi], ...]}}

Not stored, rebuilt on reading from the blocks (each is a function of them, so a read graph equals the written
one): the block label image (the blocks tile the free blocks exactly), layer 1's edges (blocks sharing a side,
``layer1_edges``) and weights (centre distances), and the blocks of each region. Cell (row, col) has its
lower-left corner at (origin_x + col * resolution, origin_y + row * resolution).

Version 1 held layer 1 inline (``"layer1": {"cells", "centres_xy", "sizes_m", "corners_xy", "region", "edges",
"weights"}``) and ``"layer2": {"blocks", "corners_xy"}``: 180 MB and 32 s of ``json.load`` on the 7,000 x
5,000-cell test floor (``benchmarks/bench_building.py``), against 3.5 MB + a 3.1 MB array file in version 2. A
rectangle's world corners are (origin_x + col * resolution, origin_y + row * resolution).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from holoslam.errors import MapError
from holoslam.planning.twolayer import TwoLayerGraph, block_label_image

__all__ = ["to_planning_dict", "from_planning_dict", "write_planning", "read_planning", "layer1_file", "layer1_arrays"]

FORMAT = "holoslam-planning"
VERSION = 2


def layer1_file(path: str | Path) -> Path:
    """The layer-1 array file beside a planning JSON file: ``<stem>_layer1.npz``."""
    path = Path(path)
    return path.with_name(path.stem + "_layer1.npz")


def to_planning_dict(tl: TwoLayerGraph, layer1_name: str = "planning_layer1.npz") -> dict:
    """The JSON document (module docstring); layer 1's arrays go to the file ``layer1_name`` beside it
    (:func:`layer1_arrays`)."""
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
            "count": tl.n_blocks,
            "file": layer1_name,
            "arrays": {
                "cells": "(N, 4) int32 half-open cell rectangles [row0, col0, row1, col1]",
                "region": "(N,) int32 region id of each block",
            },
        },
        "layer2": {
            "cells": tl.regions.tolist(),
            "edges": tl.region_edges.tolist(),
            "portals": tl.portals.tolist(),
        },
    }


def layer1_arrays(tl: TwoLayerGraph) -> dict[str, np.ndarray]:
    """Layer 1's stored arrays, in the smallest integer type that holds them (int32: grids up to 2^31 cells)."""
    return {"cells": tl.blocks.astype(np.int32), "region": tl.region_of_block.astype(np.int32)}


def _arr(v, shape_tail: tuple[int, ...], dtype, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=dtype)
    if a.size == 0:
        a = a.reshape((0,) + shape_tail)
    if a.shape[1:] != shape_tail:
        raise MapError(f"planning.json: {what} must have rows of shape {shape_tail}, got {a.shape}")
    a.setflags(write=False)
    return a


def _ro(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def from_planning_dict(d: dict, layer1: dict | None = None) -> TwoLayerGraph:
    """Rebuild a :class:`TwoLayerGraph` from the JSON document and, for version 2, the layer-1 arrays
    (``cells``, ``region``: the array file's content); raises ``MapError`` for a malformed document."""
    from holoslam.planning.twolayer import layer1_edges

    try:
        if d.get("format") != FORMAT:
            raise MapError(f"not a {FORMAT} document (format = {d.get('format')!r})")
        version = int(d.get("version", 0))
        if version > VERSION:
            raise MapError(f"planning.json version {d['version']} is newer than this holoslam ({VERSION})")
        g, l1, l2 = d["grid"], d["layer1"], d["layer2"]
        shape = (int(g["shape"][0]), int(g["shape"][1]))
        if version >= 2:
            if layer1 is None:
                raise MapError("planning.json version 2 needs its layer-1 array file")
            blocks = _arr(layer1["cells"], (4,), np.int64, "layer1 cells")
            rob = _arr(np.asarray(layer1["region"]).reshape(-1), (), np.int64, "layer1 region")
            if blocks.shape[0] != int(l1["count"]):
                raise MapError(f"the layer-1 file holds {blocks.shape[0]} blocks, the JSON says {l1['count']}")
        else:
            blocks = _arr(l1["cells"], (4,), np.int64, "layer1.cells")
            rob = _arr(l1["region"], (), np.int64, "layer1.region") if blocks.shape[0] else np.zeros(0, np.int64)
        regions = _arr(l2["cells"], (4,), np.int64, "layer2.cells")
        if rob.shape[0] != blocks.shape[0]:
            raise MapError("planning.json: layer1.region must give one region per block")
        if blocks.shape[0] and (
            blocks[:, 2].max() > shape[0] or blocks[:, 3].max() > shape[1] or blocks.min() < 0
        ):
            raise MapError("planning.json: a layer-1 block lies outside the grid")
        if rob.shape[0] and (rob.min() < 0 or rob.max() >= regions.shape[0]):
            raise MapError("planning.json: a layer-1 block names a region that does not exist")
        labels = block_label_image(blocks, shape)
        ids = np.argsort(rob, kind="stable")
        ptr = np.searchsorted(rob[ids], np.arange(regions.shape[0] + 1))
        if version >= 2:
            edges = layer1_edges(blocks, labels)
            res = float(g["resolution"])
            cen = np.column_stack([(blocks[:, 1] + blocks[:, 3]) * 0.5, (blocks[:, 0] + blocks[:, 2]) * 0.5]) * res
            dd = cen[edges[:, 0]] - cen[edges[:, 1]]
            weights = np.hypot(dd[:, 0], dd[:, 1]) if edges.shape[0] else np.zeros(0)
        else:
            edges = _arr(l1["edges"], (2,), np.int64, "layer1.edges")
            weights = _arr(l1["weights"], (), np.float64, "layer1.weights").reshape(-1)
        return TwoLayerGraph(
            resolution=float(g["resolution"]),
            origin_x=float(g["origin_x"]),
            origin_y=float(g["origin_y"]),
            shape=shape,
            min_block_cells=int(g["min_block_cells"]),
            blocks=blocks,
            edges=_ro(edges),
            weights=_ro(weights),
            regions=regions,
            region_block_ptr=_ro(ptr),
            region_block_ids=_ro(ids),
            region_of_block=rob,
            region_edges=_arr(l2["edges"], (2,), np.int64, "layer2.edges"),
            portals=_arr(l2["portals"], (4,), np.int64, "layer2.portals"),
            labels=_ro(labels),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise MapError(f"planning.json is malformed: {exc!r}; rewrite it with holoslam") from exc


def write_planning(tl: TwoLayerGraph, path: str | Path) -> Path:
    """Write ``path`` (the JSON document) and its layer-1 array file beside it (:func:`layer1_file`);
    returns ``path``."""
    path = Path(path)
    arrays = layer1_file(path)
    a = layer1_arrays(tl)
    np.savez_compressed(arrays, cells=a["cells"], region=a["region"])
    path.write_text(json.dumps(to_planning_dict(tl, arrays.name), separators=(",", ":")))
    return path


def read_planning(path: str | Path) -> TwoLayerGraph:
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise MapError(f"{path}: not a readable JSON file ({exc})") from exc
    if not isinstance(d, dict):
        raise MapError(f"{path}: planning.json must hold a JSON object")
    layer1 = None
    if isinstance(d.get("layer1"), dict) and "file" in d["layer1"]:
        name = str(d["layer1"]["file"])
        f = path.parent / Path(name).name
        try:
            with np.load(f, allow_pickle=False) as z:
                layer1 = {k: z[k] for k in ("cells", "region")}
        except (OSError, ValueError, KeyError) as exc:
            raise MapError(
                f"{path}: its layer-1 array file {f} is missing or unreadable ({exc}); keep the two files "
                "together or rewrite them with holoslam"
            ) from exc
    try:
        return from_planning_dict(d, layer1)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from exc
