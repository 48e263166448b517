"""Graphs to files and back: GraphML (scalar attributes) and JSON node-link, both lossless.

Lossless means a graph read back equals the one written, attribute by attribute, including the graph class
(Graph / MultiGraph / DiGraph / MultiDiGraph), integer node ids and multigraph edge keys, numpy arrays (dtype
and shape), NaN and exact floats.

- **GraphML** holds only scalars (int, float, bool, str). Any other value (a numpy array such as an edge's
  ``path`` or a covariance, a list, None) is written as a compact string ``"json:" + JSON`` with arrays as
  ``{"__ndarray__": dtype, "shape": [...], "data": [...]}``; a genuine string that starts with ``json:`` or
  ``str:`` is written as ``"str:" + text``. numpy scalars become Python scalars. An attribute whose values mix
  types across nodes is written in the ``json:`` form everywhere, so GraphML's one-type-per-key rule holds.
  Node ids that are not all strings are written as JSON text; the graph attributes ``holoslam_graph_class``,
  ``holoslam_node_ids`` and ``holoslam_edge_keys`` record what to restore (and are removed on reading).
- **JSON node-link** (``networkx.node_link_data`` with ``edges="edges"``) holds lists natively; numpy arrays
  are the same ``{"__ndarray__": ...}`` objects.

Writers take the path the caller names (``write_graph_files`` an output folder and a file stem) and write only
there; readers raise ``MapError`` saying which file is malformed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.errors import MapError

__all__ = [
    "encode_value",
    "decode_value",
    "to_graphml_graph",
    "from_graphml_graph",
    "to_node_link",
    "from_node_link",
    "write_graphml",
    "read_graphml",
    "write_node_link_json",
    "read_node_link_json",
    "write_graph_files",
]

_JSON = "json:"
_STR = "str:"


def _to_jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return {
            "__ndarray__": v.dtype.str if v.dtype.kind != "U" else "str",
            "shape": list(v.shape),
            "data": [_to_jsonable(x) for x in v.ravel().tolist()],
        }
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {str(k): _to_jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_to_jsonable(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return {"__float__": repr(v)}
    return v


def _from_jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        if "__ndarray__" in v:
            dt = v["__ndarray__"]
            data = [_from_jsonable(x) for x in v["data"]]
            arr = np.array(data, dtype=str if dt == "str" else np.dtype(dt))
            return arr.reshape(v["shape"])
        if "__float__" in v:
            return float(v["__float__"])
        return {k: _from_jsonable(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_from_jsonable(x) for x in v]
    return v


def encode_value(v: Any) -> Any:
    """A GraphML-safe scalar for any attribute value (module docstring)."""
    if isinstance(v, bool | np.bool_):
        return bool(v)
    if isinstance(v, int | np.integer):
        return int(v)
    if isinstance(v, float | np.floating):
        return float(v)
    if isinstance(v, str):
        return _STR + v if v.startswith((_JSON, _STR)) else v
    return _JSON + json.dumps(_to_jsonable(v), separators=(",", ":"))


def decode_value(v: Any) -> Any:
    """Inverse of :func:`encode_value`."""
    if isinstance(v, str):
        if v.startswith(_JSON):
            return _from_jsonable(json.loads(v[len(_JSON) :]))
        if v.startswith(_STR):
            return v[len(_STR) :]
    return v


def _graph_class(G) -> str:
    return ("Multi" if G.is_multigraph() else "") + ("DiGraph" if G.is_directed() else "Graph")


def _scalar_kind(v: Any) -> str:
    if isinstance(v, bool | np.bool_):
        return "bool"
    if isinstance(v, int | np.integer):
        return "int"
    if isinstance(v, float | np.floating):
        return "float"
    if isinstance(v, str):
        return "str"
    return "other"


def _mixed_keys(items) -> set[str]:
    kinds: dict[str, set[str]] = {}
    for d in items:
        for k, v in d.items():
            kinds.setdefault(k, set()).add(_scalar_kind(v))
    return {k for k, s in kinds.items() if len(s) > 1}


def _encode_attrs(d: dict, force_json: set[str]) -> dict:
    out = {}
    for k, v in d.items():
        if k in force_json:
            out[k] = _JSON + json.dumps(_to_jsonable(v), separators=(",", ":"))
        else:
            out[k] = encode_value(v)
    return out


def to_graphml_graph(G):
    """A copy of G with only scalar attributes and string node ids, ready for ``networkx.write_graphml``."""
    import networkx as nx

    nodes = list(G.nodes)
    if all(isinstance(n, str) for n in nodes):
        id_mode, key_of = "str", (lambda n: n)
    elif all(isinstance(n, int | np.integer) and not isinstance(n, bool) for n in nodes):
        id_mode, key_of = "int", (lambda n: str(int(n)))
    else:
        id_mode, key_of = "json", (lambda n: json.dumps(_to_jsonable(n), separators=(",", ":")))
    H = nx.MultiDiGraph() if G.is_directed() else nx.MultiGraph()
    if not G.is_multigraph():
        H = nx.DiGraph() if G.is_directed() else nx.Graph()
    gmixed: set[str] = set()
    H.graph.update(_encode_attrs(dict(G.graph), gmixed))
    H.graph["holoslam_graph_class"] = _graph_class(G)
    H.graph["holoslam_node_ids"] = id_mode
    nmixed = _mixed_keys(d for _, d in G.nodes(data=True))
    for n, d in G.nodes(data=True):
        H.add_node(key_of(n), **_encode_attrs(d, nmixed))
    emixed = _mixed_keys(d for *_, d in G.edges(data=True))
    if G.is_multigraph():
        keys = [k for _u, _v, k in G.edges(keys=True)]
        if all(isinstance(k, int | np.integer) for k in keys):
            kmode = "int"
        elif all(isinstance(k, str) for k in keys):
            kmode = "str"
        else:
            raise MapError("multigraph edge keys must be all ints or all strings to be written to GraphML")
        H.graph["holoslam_edge_keys"] = kmode
        for u, v, k, d in G.edges(keys=True, data=True):
            H.add_edge(key_of(u), key_of(v), key=str(k), **_encode_attrs(d, emixed))
    else:
        for u, v, d in G.edges(data=True):
            H.add_edge(key_of(u), key_of(v), **_encode_attrs(d, emixed))
    return H


def from_graphml_graph(H):
    """Inverse of :func:`to_graphml_graph` on a graph read by ``networkx.read_graphml``."""
    import networkx as nx

    ga = {k: v for k, v in H.graph.items() if k not in ("node_default", "edge_default")}  # reader's own keys
    cls_name = ga.pop("holoslam_graph_class", _graph_class(H))
    id_mode = ga.pop("holoslam_node_ids", "str")
    kmode = ga.pop("holoslam_edge_keys", None)
    classes = {
        "Graph": nx.Graph,
        "MultiGraph": nx.MultiGraph,
        "DiGraph": nx.DiGraph,
        "MultiDiGraph": nx.MultiDiGraph,
    }
    if cls_name not in classes:
        raise MapError(f"unknown graph class {cls_name!r} in GraphML")
    G = classes[cls_name]()
    G.graph.update({k: decode_value(v) for k, v in ga.items()})

    def node(n: str):
        if id_mode == "int":
            return int(n)
        if id_mode == "json":
            v = _from_jsonable(json.loads(n))
            return tuple(v) if isinstance(v, list) else v
        return n

    for n, d in H.nodes(data=True):
        G.add_node(node(n), **{k: decode_value(v) for k, v in d.items()})
    if H.is_multigraph():
        for u, v, k, d in H.edges(keys=True, data=True):
            attrs = {a: decode_value(x) for a, x in d.items() if a != "id"}
            key = int(k) if kmode == "int" else k
            if G.is_multigraph():
                G.add_edge(node(u), node(v), key=key, **attrs)
            else:
                G.add_edge(node(u), node(v), **attrs)
    else:
        for u, v, d in H.edges(data=True):
            attrs = {a: decode_value(x) for a, x in d.items() if a != "id"}
            G.add_edge(node(u), node(v), **attrs)
    return G


def to_node_link(G) -> dict:
    """JSON-ready node-link dict (networkx node_link_data, ``edges="edges"``) with arrays encoded."""
    import networkx as nx

    data = nx.node_link_data(G, edges="edges")
    return _to_jsonable(data)


def from_node_link(data: dict):
    """Inverse of :func:`to_node_link`."""
    import networkx as nx

    try:
        d = _from_jsonable(data)
        # JSON turns tuple node ids into lists; node ids must be hashable
        for n in d.get("nodes", []):
            if isinstance(n.get("id"), list):
                n["id"] = tuple(n["id"])
        for e in d.get("edges", []):
            for k in ("source", "target"):
                if isinstance(e.get(k), list):
                    e[k] = tuple(e[k])
        return nx.node_link_graph(d, edges="edges")
    except (KeyError, TypeError, ValueError, nx.NetworkXError) as exc:
        raise MapError(f"not a node-link graph: {exc}") from exc


def write_graphml(G, path: str | Path) -> Path:
    import networkx as nx

    path = Path(path)
    nx.write_graphml(to_graphml_graph(G), path, named_key_ids=True)
    return path


def read_graphml(path: str | Path):
    import networkx as nx

    path = Path(path)
    try:
        H = nx.read_graphml(path, force_multigraph=True)
    except (OSError, nx.NetworkXError, ValueError, KeyError) as exc:
        raise MapError(f"{path}: not a readable GraphML graph ({exc})") from exc
    except Exception as exc:  # the XML parser's own errors
        raise MapError(f"{path}: malformed GraphML ({exc})") from exc
    return from_graphml_graph(H)


def write_node_link_json(G, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(to_node_link(G), separators=(",", ":")))
    return path


def read_node_link_json(path: str | Path):
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise MapError(f"{path}: not a readable JSON file ({exc})") from exc
    try:
        return from_node_link(data)
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from exc


def write_graph_files(G, out_dir: str | Path, stem: str) -> tuple[Path, Path]:
    """Write ``<out_dir>/<stem>.graphml`` and ``<out_dir>/<stem>.json`` (the folder must exist)."""
    out_dir = Path(out_dir)
    if "/" in stem or "\\" in stem or stem in ("", ".", ".."):
        raise MapError(f"graph file stem {stem!r} must be a plain file name inside the output folder")
    if not out_dir.is_dir():
        raise MapError(f"output folder {out_dir} does not exist; create it first")
    return write_graphml(G, out_dir / f"{stem}.graphml"), write_node_link_json(G, out_dir / f"{stem}.json")
